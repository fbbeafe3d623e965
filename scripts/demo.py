"""Main demo: the study's pipeline — DEM virtual experiments, TIV calibration, TIV element tests.

Usage::

    python scripts/demo.py --out results [--scene study_demo] [--workers 2] [--smoke] [--skip-dem]

Writes, under ``--out``:

- ``dem/``    the DEM protocol on a CPU-sized scene (``study_demo``: the study's clay at 300 rods;
  ``--scene demo``: 150 rigid rods, the cheap option; ``--smoke``: the ``smoke`` scene): history,
  relaxed states, probes, configurations (netCDF), Figures 1 and 2 of the study, ``report.md``;
- ``bridge/`` the TIV parameters calibrated on those DEM results, predictions, figures, report;
- ``tiv/``    the TIV element tests of the study with the Table 1 parameters;
- ``REPORT.md`` the study's findings on this run beside the same material's replicas (300 and
  1520 rods) and the study's own values, then an index with the headline numbers of each part.

TIV part (:func:`run_tiv_demo`): isotropic compression from 5 kPa to 280 kPa (the normal
compression line of Table 1 reaches v = 1 at p_c ≈ 286 kPa), K0 loading to σ_v = 250 kPa then
constant-p unloading to q = 0, anisotropy form A with constraint forces (the defaults); the full
run also compares form B and the variants without constraint forces at σ_v = 100 kPa.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from tiv_model import drivers  # noqa: E402
from tiv_model.params import TABLE1, ModelOptions  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
#: The replicas beside which the report sets this run (column title → the saved tables and the
#: columns taken from each, all when None): the demo's scene over three seeds, as the scene is
#: since 2026-12-03 (the sparser gas SP05: `study_demo_sp05_replicas.md`), and the `study` scene
#: at the study's size over seven seeds, the whole protocol with its radial paths and its
#: isotropic path to 200 kPa (`study_scene_seven_seeds.md`)
REFERENCES: dict[str, tuple[tuple[Path, tuple[str, ...] | None], ...]] = {
    "`study_demo`, 300 rods": ((RESULTS / "study_demo_sp05_replicas.csv", None),),
    "`study`, 1520 rods": ((RESULTS / "study_scene_seven_seeds_cells.csv", None),),
}
ISOTROPIC_P_MAX = 280.0  # kPa, safely below the v = 1 limit of Table 1 (p_c ≈ 286 kPa)
K0_SIGMA_V_MAX = 250.0  # kPa


def _log(message: str) -> None:
    print(f"[demo {time.strftime('%H:%M:%S')}] {message}", flush=True)


def _at_axial_stress(ds, sigma_v: float, name: str) -> float:
    """Interpolate a K0-stage variable at a given axial stress (kPa)."""
    k0 = ds.where(ds.stage == 0, drop=True) if "stage" in ds else ds
    return float(np.interp(sigma_v, k0.axial_stress.values, k0[name].values))


def sanity_summary(ds) -> dict[str, float]:
    """K0, β and E_h/E_v at σ_v = 100 kPa; plastic increments of the unloading stage."""
    k0_ratio = _at_axial_stress(ds, 100.0, "radial_stress") / 100.0
    unloading = ds.where(ds.stage == 1, drop=True) if "stage" in ds else None
    return {
        "K0 at 100 kPa": k0_ratio,
        "fabric at 100 kPa": _at_axial_stress(ds, 100.0, "fabric"),
        "E_h/E_v at 100 kPa": _at_axial_stress(ds, 100.0, "stiffness_ratio"),
        "E_h/E_v at end of K0": float(ds.where(ds.stage == 0, drop=True).stiffness_ratio[-1]),
        "end of K0 (kPa)": float(ds.where(ds.stage == 0, drop=True).axial_stress[-1]),
        "plastic unloading increments": (
            float(unloading.plastic.sum()) if unloading is not None else float("nan")
        ),
    }


def _figures(iso, k0u, out_dir: Path) -> list[Path]:
    k0 = k0u.where(k0u.stage == 0, drop=True)
    un = k0u.where(k0u.stage == 1, drop=True)
    paths = []

    def save(fig, name):
        path = out_dir / name
        fig.tight_layout()
        fig.savefig(path, dpi=120)
        plt.close(fig)
        paths.append(path)

    fig, ax = plt.subplots(figsize=(5, 4))
    ax.semilogx(iso.mean_stress, iso.specific_volume, label="isotropic (A→B)")
    ax.semilogx(k0.mean_stress, k0.specific_volume, label="K0 (A→C)")
    ax.semilogx(un.mean_stress, un.specific_volume, "o", ms=3, label="constant p (C→B)")
    ax.set(xlabel="mean stress p (kPa)", ylabel="specific volume v", title="Compressibility")
    ax.legend()
    save(fig, "tiv_v_lnp.png")

    fig, ax = plt.subplots(figsize=(5, 4))
    ax.plot(iso.mean_stress, iso.deviatoric_stress, label="isotropic")
    ax.plot(k0.mean_stress, k0.deviatoric_stress, label="K0")
    ax.plot(un.mean_stress, un.deviatoric_stress, "o", ms=3, label="constant p")
    pp = np.linspace(0, float(k0u.mean_stress.max()), 10)
    ax.plot(pp, TABLE1.M * pp, "k--", lw=0.8, label="q = M p")
    ax.set(xlabel="p (kPa)", ylabel="q (kPa)", title="Stress paths")
    ax.legend()
    save(fig, "tiv_p_q.png")

    fig, ax = plt.subplots(figsize=(5, 4))
    ax.plot(iso.mean_stress, iso.fabric, label="isotropic")
    ax.plot(k0.mean_stress, k0.fabric, label="K0")
    ax.plot(un.mean_stress, un.fabric, "o", ms=3, label="constant p")
    ax.axhline(TABLE1.maximum_fabric, color="k", ls=":", lw=0.8, label="M/z")
    ax.set(xlabel="p (kPa)", ylabel="fabric β (signed like q)", title="Fabric")
    ax.legend()
    save(fig, "tiv_fabric.png")

    fig, ax = plt.subplots(figsize=(5, 4))
    ax.plot(iso.mean_stress, iso.e_oed_v / 1e3, label="isotropic E_oed,v = E_oed,h")
    ax.plot(k0.mean_stress, k0.e_oed_v / 1e3, label="K0 E_oed,v")
    ax.plot(k0.mean_stress, k0.e_oed_h / 1e3, label="K0 E_oed,h")
    ax.plot(un.mean_stress, un.e_oed_v / 1e3, "o", ms=3, label="const. p E_oed,v")
    ax.plot(un.mean_stress, un.e_oed_h / 1e3, "s", ms=3, label="const. p E_oed,h")
    ax.set(xlabel="p (kPa)", ylabel="constrained modulus (MPa)", title="Elastic stiffness")
    ax.legend(fontsize=8)
    save(fig, "tiv_moduli.png")

    fig, ax = plt.subplots(figsize=(5, 4))
    ax.plot(iso.mean_stress, iso.stiffness_ratio, label="isotropic")
    ax.plot(k0.axial_stress, k0.stiffness_ratio, label="K0 (vs σ_v)")
    ax.set(xlabel="stress (kPa)", ylabel="E_oed,h / E_oed,v", title="Stiffness anisotropy")
    ax.legend()
    save(fig, "tiv_stiffness_ratio.png")
    return paths


def run_tiv_demo(out_dir: Path, smoke: bool) -> dict:
    """Run the TIV element tests of the study; write netCDF, figures and ``tiv_report.md``.

    Returns a dict with the written paths and the sanity figures per model variant.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    n_iso, n_k0, n_un = (12, 12, 4) if smoke else (150, 150, 40)
    started = time.perf_counter()
    _log(f"TIV isotropic compression 5 → {ISOTROPIC_P_MAX:g} kPa ({n_iso} increments)")
    iso = drivers.isotropic(ISOTROPIC_P_MAX, p0=5.0, increments=n_iso, on_error="stop")
    _log(f"TIV K0 loading to {K0_SIGMA_V_MAX:g} kPa ({n_k0}) then constant-p unloading ({n_un})")
    k0u = drivers.k0_then_unload(
        K0_SIGMA_V_MAX, p0=5.0, increments=n_k0, unload_increments=n_un, on_error="stop"
    )
    files = {"isotropic": out_dir / "tiv_isotropic.nc", "k0_unload": out_dir / "tiv_k0_unload.nc"}
    iso.to_netcdf(files["isotropic"])
    k0u.to_netcdf(files["k0_unload"])
    _log("figures")
    figures = _figures(iso, k0u, out_dir)

    variants = {"A, constraint forces": sanity_summary(k0u)}
    others = [] if smoke else [("B", True), ("A", False), ("B", False)]
    for form, cf in others:
        name = f"{form}, {'constraint forces' if cf else 'no constraint forces'}"
        _log(f"variant {name}: K0 to 120 kPa and unloading")
        ds = drivers.k0_then_unload(
            120.0, increments=60, unload_increments=10,
            options=ModelOptions(anisotropy=form, constraint_forces=cf), on_error="stop",
        )  # fmt: skip
        variants[name] = sanity_summary(ds)
    elapsed = time.perf_counter() - started

    lines = [
        "# TIV element tests (Table 1 parameters)",
        "",
        f"Run {'(smoke)' if smoke else ''} in {elapsed:.1f} s by `scripts/demo.py`.",
        "",
        f"- isotropic compression to {float(iso.mean_stress[-1]):.1f} kPa: "
        f"v = {float(iso.specific_volume[-1]):.4f}, termination: {iso.attrs['termination']}",
        f"- K0 to σ_v = {K0_SIGMA_V_MAX:g} kPa then constant-p unloading to q = 0: "
        f"termination: {k0u.attrs['termination']}",
        "",
        "Sanity values (docs/science/tiv-model.md §2.4 expects, form A with constraint forces: "
        "K0 ≈ 0.65–0.70, "
        "β ≈ 0.13 at σ_v = 100 kPa, E_h/E_v above 2 by 100 kPa, elastic constant-p unloading):",
        "",
        "| variant | K0 at 100 kPa | β at 100 kPa | E_h/E_v at 100 kPa | E_h/E_v end of K0 "
        "(σ_v) | plastic unloading increments |",
        "|---|---|---|---|---|---|",
    ]
    for name, s in variants.items():
        lines.append(
            f"| {name} | {s['K0 at 100 kPa']:.4f} | {s['fabric at 100 kPa']:.4f} | "
            f"{s['E_h/E_v at 100 kPa']:.3f} | {s['E_h/E_v at end of K0']:.3f} "
            f"({s['end of K0 (kPa)']:.0f} kPa) | "
            f"{s['plastic unloading increments']:.0f} |"
        )
    lines += ["", "Files:", ""]
    lines += [f"- `{p.name}`" for p in list(files.values()) + figures]
    report = out_dir / "tiv_report.md"
    report.write_text("\n".join(lines) + "\n")
    _log(f"TIV part done in {elapsed:.1f} s; report {report}")
    return {"files": files, "figures": figures, "report": report, "variants": variants}


def run_dem_demo(out_dir: Path, scene: str, workers: int = 2) -> dict:
    """Run the DEM virtual experiments of ``scene`` (needs Taichi); returns the run summary and
    the study's headline findings of the run (:func:`headline_findings`)."""
    from dem_taichi.analysis.findings import headline_findings, run_findings
    from dem_taichi.protocol.runner import run_protocol

    _log(f"DEM virtual experiments on scene '{scene}' (CPU, {workers} workers) -> {out_dir}")
    started = time.perf_counter()
    result = run_protocol(
        scene, out_dir, progress=True, command=f"scripts/demo.py --scene {scene}",
        workers=workers, overwrite=True,
    )  # fmt: skip  # the demo owns its output folder: a rerun replaces it
    _log(f"DEM part done in {time.perf_counter() - started:.1f} s")
    everything = run_findings(out_dir)
    states = {
        label: {k: float(state.measures[k]) for k in ("mean_stress", "specific_volume",
                                                       "fabric_deviator")}
        for label, state in result.states.items()
    }  # fmt: skip
    return {
        "files": dict(result.files),
        "seconds": result.total_seconds,
        "states": states,
        "scene": scene,
        "n_rods": result.n_rods,
        "findings": headline_findings(out_dir, everything),
        "k0_path": list(zip(everything["k0_p"], everything["k0_ratio"], strict=True)),
        "radial_paths": sum(label.startswith("R") for label in result.states),
    }


def run_bridge_demo(dem_dir: Path, out_dir: Path) -> dict:
    """Calibrate the TIV model on the DEM results in ``dem_dir`` (no Taichi needed)."""
    from bridge.pipeline import calibrate_from_results

    _log(f"TIV calibration on the DEM results -> {out_dir}")
    started = time.perf_counter()
    probes = dem_dir / "probes.nc"
    outcome = calibrate_from_results(
        dem_dir / "history.nc", probes if probes.exists() else None, out_dir, {}
    )
    _log(f"calibration done in {time.perf_counter() - started:.1f} s")
    return outcome.to_dict()


def _reference(files) -> dict[str, tuple[float, float, int]]:
    """Replica statistics (column → (mean, 95 % half-width, n)) from saved benchmark tables
    (``files``: each table, and the columns taken from it, all when None; one entry of
    :data:`REFERENCES`). Empty when the tables are absent (a demo run outside the repository)."""
    out: dict[str, tuple[float, float, int]] = {}
    for path, keys in files:
        if not path.exists():
            continue
        with path.open() as handle:
            row = next(csv.DictReader(handle))
        for key, value in row.items():
            if (keys is None or key in keys) and f"{key}_ci95" in row and f"{key}_n" in row:
                out[key] = (float(value), float(row[f"{key}_ci95"]), int(row[f"{key}_n"]))
    return out


def _number(value: float, digits: int) -> str:
    return f"{value:.{digits}g}" if math.isfinite(value) else "—"


def _interval(stat: tuple[float, float, int] | None, digits: int) -> str:
    if stat is None:
        return "—"
    mean, half, n = stat
    if n > 1 and math.isfinite(half):
        return f"{_number(mean, digits)} ± {_number(half, 2)} ({n} seeds)"
    return f"{_number(mean, digits)} ({n} seed{'s' if n != 1 else ''})"


#: (label, key of :func:`headline_findings`, significant digits, the study's value or how it is
#: read) — the rows of the report's first table
HEADLINE_ROWS = (
    ("E_h/E_v at B (isotropic, 100 kPa)", "ratio_B", 3, "≈ 1 (isotropic fabric)"),
    ("E_h/E_v at C (K0, p = 100 kPa)", "ratio_C", 3, "> 1"),
    ("C − B (same run)", "ratio_C_minus_B", 2, "> 0"),
    ("E_h/E_v at B′ (C unloaded to p_B)", "ratio_Bp", 3, "> 1"),
    ("B′ − B (same run)", "ratio_Bp_minus_B", 2, "> 0"),
    ("K0 at C", "k0_C", 3, "table1_k0"),
    ("λ* over 1–200 kPa", "lambda_window", 3, "table1_lambda"),
    ("E_v ∝ p^n over 1–200 kPa", "exponent_window_v", 3, "table1_exponent"),
    ("E_v/p at B", "ev_over_p_B", 3, "≈ 125"),
    ("N (v at 100 kPa), disc area", "N_disc", 3, "table1_N"),
    ("N, rod rectangle L × d", "N_rectangle", 3, "table1_N"),
    ("kPa per DEM unit (E_v/p = 125)", "stress_scale_kpa_measured", 3, "—"),
    ("largest contact overlap δ/d, labelled states", "max_overlap", 2, "< 0.01 (issue 19's bar)"),
)


def findings_lines(dem: dict, tiv: dict | None, references: dict | None = None) -> list[str]:
    """The report's first section: the study's findings on this run, beside replicas (title →
    statistics; default: :data:`REFERENCES` read from the saved tables) and the study's values
    (Table 1; the Table 1 model's K0 and E_h/E_v at σ_v = 100 kPa from this demo's TIV part)."""
    f = dem["findings"]
    if references is None:
        references = {title: _reference(files) for title, files in REFERENCES.items()}
    table1 = {
        "table1_lambda": f"{TABLE1.lambda_star:g} (Table 1)",
        "table1_exponent": f"{TABLE1.n + TABLE1.r:.2f} (n + r, Table 1)",
        "table1_N": f"{TABLE1.N:g} (Table 1)",
        "table1_k0": "—",
    }
    model = (tiv or {}).get("variants", {}).get("A, constraint forces")
    if model is not None:
        table1["table1_k0"] = f"{model['K0 at 100 kPa']:.3f} (Table 1 model, σ_v = 100 kPa)"
    k0 = ", ".join(f"{p:.3g}: {r:.3f}" for p, r in dem.get("k0_path", []))
    # the pages of the replica tables the columns read (REFERENCES: one table per column)
    demo_page, study_page = (
        files[0][0].with_suffix(".md").relative_to(ROOT).as_posix() for files in REFERENCES.values()
    )
    lines = [
        "## The study's findings on this run",
        "",
        f"Scene `{dem['scene']}` ({dem['n_rods']} rods; DEM stresses read as kPa, 1 DEM unit = "
        "1 kPa). Beside it, mean ± 95 % over replicas: the demo's scene on three seeds "
        f"(`{demo_page}`; one 300-rod sample scatters by about that much) and the same "
        f"material at the study's size (`{study_page}`). "
        "Moduli are the linear-response constrained moduli; E_v/p = 125 and the anisotropy "
        "along K0 are the study's DEM, the rest its Table 1.",
        "",
        "| finding | this run | " + " | ".join(references) + " | the study |",
        "|---|---|" + "---|" * len(references) + "---|",
    ]
    for label, key, digits, study in HEADLINE_ROWS:
        value = f.get(key, math.nan)
        replicas = " | ".join(_interval(stats.get(key), digits) for stats in references.values())
        lines.append(
            f"| {label} | {_number(float(value), digits)} | {replicas} | "
            f"{table1.get(study, study)} |"
        )
    if k0:
        lines += ["", f"E_h/E_v along K0 (p in kPa: ratio) on this run: {k0}."]
    if model is not None:
        lines.append(
            f"The Table 1 model along K0: E_h/E_v = {model['E_h/E_v at 100 kPa']:.2f} at "
            "σ_v = 100 kPa."
        )
    if dem.get("radial_paths") == 0:
        lines.append(
            "This run has no radial paths: the calibration below cannot determine the fabric "
            "law's c and s (K0 alone does not identify them); the `study` scene has three."
        )
    return lines + [""]


def write_index(out_dir: Path, parts: dict[str, dict | str]) -> Path:
    """``REPORT.md``: what each part wrote, its headline numbers, or why it did not run."""
    lines = ["# Multiscale clay study: demo run", ""]
    dem = parts.get("dem")
    if isinstance(dem, dict) and "findings" in dem:
        tiv_part = parts.get("tiv")
        lines += findings_lines(dem, tiv_part if isinstance(tiv_part, dict) else None)
    lines += ["## DEM virtual experiments", ""]
    if isinstance(dem, dict):
        lines += [f"Wall time {dem['seconds']:.0f} s. Report: `dem/report.md`.", ""]
        lines += ["| state | p (DEM units) | v | β_yy − β_xx |", "|---|---|---|---|"]
        for label, m in dem["states"].items():
            lines.append(
                f"| {label} | {m['mean_stress']:.4g} | {m['specific_volume']:.4f} | "
                f"{m['fabric_deviator']:+.4f} |"
            )
    else:
        lines.append(str(dem))
    lines += ["", "## TIV calibration on the DEM results", ""]
    bridge = parts.get("bridge")
    if isinstance(bridge, dict):
        report = bridge.get("files", {}).get("report")
        lines.append(f"Report: `{Path(report).relative_to(out_dir)}`." if report else "")
        errors = bridge.get("standard_errors") or {}
        lines += ["", "| parameter | value | standard error |", "|---|---|---|"]
        for name, value in (bridge.get("parameters") or {}).items():
            error = errors.get(name)
            shown = "— (fixed, or no finite standard error)" if error is None else f"{error:.3g}"
            if error is not None and not abs(error) < abs(value):
                shown += " (not determined by these data)"
            lines.append(f"| {name} | {value:.4g} | {shown} |")
        not_fitted = (bridge.get("data") or {}).get("stages not fitted")
        if not_fitted:
            lines += ["", f"Calibration stages that could not be fitted: {not_fitted}"]
        failed = (bridge.get("data") or {}).get("predictions not run")
        if failed:
            lines += ["", f"Predictions the calibrated model could not run: {failed}"]
    else:
        lines.append(str(bridge))
    lines += ["", "## TIV element tests (Table 1)", ""]
    tiv = parts["tiv"]
    assert isinstance(tiv, dict)  # the TIV part always runs (no "skipped" line)
    lines.append(f"Report: `{Path(tiv['report']).relative_to(out_dir)}`.")
    for name, summary in tiv["variants"].items():
        lines.append(
            f"- {name}: K0 = {summary['K0 at 100 kPa']:.3f}, β = {summary['fabric at 100 kPa']:.3f}"
            f", E_h/E_v = {summary['E_h/E_v at 100 kPa']:.2f} at σ_v = 100 kPa"
        )
    path = out_dir / "REPORT.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument(
        "--scene", default="study_demo",
        help="DEM scene (built-in name or TOML path; default %(default)s, the study's clay at 300 "
        "rods; 'demo' for 150 rigid rods, the cheap option)",
    )  # fmt: skip
    parser.add_argument(
        "--workers", type=int, default=2,
        help="processes for the branches from A (default %(default)s: one per core here)",
    )  # fmt: skip
    parser.add_argument(
        "--smoke", action="store_true", help="smoke scene and few increments (about a minute)"
    )
    parser.add_argument("--skip-dem", action="store_true", help="TIV element tests only")
    args = parser.parse_args(argv)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    parts: dict[str, dict | str] = {}
    if args.skip_dem:
        parts["dem"] = parts["bridge"] = "skipped (--skip-dem)"
    else:
        scene = "smoke" if args.smoke else args.scene
        parts["dem"] = run_dem_demo(out / "dem", scene, args.workers)
        try:
            parts["bridge"] = run_bridge_demo(out / "dem", out / "bridge")
        except Exception as error:  # noqa: BLE001 - the DEM results stay; say why it failed
            parts["bridge"] = f"calibration failed: {type(error).__name__}: {error}"
            _log(str(parts["bridge"]))
    parts["tiv"] = run_tiv_demo(out / "tiv", args.smoke)
    index = write_index(out, parts)
    _log(f"done: {index}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
