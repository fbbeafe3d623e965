"""The study's findings across protocol runs, side by side (reads finished runs; no simulation).

Usage::

    python benchmarks/validation_summary.py RUN_DIR [RUN_DIR ...] [--out FILE.md]

Each RUN_DIR is the output of ``python -m dem_taichi protocol ...`` (its folder name labels
the row); when it also holds
``anisotropy.json`` (``python -m dem_taichi.anisotropy RUN_DIR``) the interaction fabrics at C
are listed. Prints a markdown table per finding and writes it to ``--out``
(default ``benchmarks/results/protocol_validation_summary.md``).

Findings (model.md §1, the study): fabric isotropic along A→B within the sampling noise
sqrt(0.5/N) and E_oed,h ≈ E_oed,v there; along K0 the rods lie down (β_yy − β_xx falls) and
E_oed,h/E_oed,v > 1, growing; ln v linear in ln p beyond A; acidic looser than basic.
Moduli are the linear-response ones (the dynamic sweep runs only at some states on `paper`).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from dem_taichi.analysis import fabric_sampling_noise
from dem_taichi.io import open_history, open_probes
from dem_taichi.io.schema import stage_code
from dem_taichi.report import compressibility_slope

HERE = Path(__file__).resolve().parent


def _run_row(folder: Path) -> dict:
    summary = json.loads((folder / "summary.json").read_text())
    relaxed = open_history(folder / "relaxed_states.nc")
    probes = open_probes(folder / "probes.nc")
    stage = relaxed["stage"].values
    iso = stage == stage_code("A_to_B")
    k0 = stage == stage_code("A_to_C")
    states = summary["states"]
    n = int(summary["n_rods"])
    fit = compressibility_slope(
        np.r_[states["A"]["mean_stress"], relaxed["mean_stress"].values[iso]],
        np.r_[states["A"]["specific_volume"], relaxed["specific_volume"].values[iso]],
    )
    path = probes["path"].values.astype(str)
    labels = probes["state_label"].values.astype(str)
    ratio = probes["e_oed_h_linear"].values / probes["e_oed_v_linear"].values
    p = probes["mean_stress"].values
    on_iso = (path == "A_to_B") | (labels == "A")
    on_k0 = path == "A_to_C"
    order = np.argsort(p[on_k0])
    e_v = probes["e_oed_v_linear"].values
    iso_p = p[on_iso & (p > 0)]
    # moduli ∝ p^n along A→B: the slope of ln E_oed,v against ln p (the study: n ≈ 0.8)
    exponent = (
        float(np.polyfit(np.log(iso_p), np.log(e_v[on_iso & (p > 0)]), 1)[0])
        if len(iso_p) > 1 else float("nan")
    )  # fmt: skip
    at_b = np.flatnonzero(labels == "B")
    row = {
        "run": folder.name,
        "max_i": max(
            st["max_inertial_number"]
            for name, st in summary["stages"].items()
            if name != "isotropic_to_A"
        ),
        "n_rods": n,
        "noise": fabric_sampling_noise(n),
        "iso_fabric_max": float(
            np.max(np.abs(np.r_[states["A"]["fabric_deviator"], relaxed["fabric_deviator"][iso]]))
        ),
        "iso_ratio": [float(x) for x in ratio[on_iso]],
        "k0_fabric": [float(x) for x in relaxed["fabric_deviator"].values[k0]],
        "k0_p": [float(x) for x in p[on_k0][order]],
        "k0_ratio": [float(x) for x in ratio[on_k0][order]],
        "lambda_star": fit["lambda_star"],
        "r2": fit["r2"],
        "p_A": states["A"]["mean_stress"],
        "v_A": states["A"]["specific_volume"],
        "v_B": states["B"]["specific_volume"],
        "v_C": states["C"]["specific_volume"],
        "fabric_A": states["A"]["fabric_deviator"],
        "fabric_C": states["C"]["fabric_deviator"],
        "k0_C": states["C"]["stress_xx"] / states["C"]["stress_yy"],
        "modulus_exponent": exponent,
        "ev_over_p_B": float(e_v[at_b[-1]] / p[at_b[-1]]) if at_b.size else float("nan"),
        "seconds": summary["total_seconds"],
        "workers": summary.get("workers", 1),
    }
    aniso = folder / "anisotropy.json"
    if aniso.exists():
        rows = {r["state"]: r for r in json.loads(aniso.read_text())}
        row["anisotropy_C"] = rows.get("C")
    return row


def _f(x: float, digits: int = 3) -> str:
    return f"{x:.{digits}g}"


def table(rows: list[dict]) -> str:
    lines = [
        "# The study's findings on the DEM runs (linear-response moduli)",
        "",
        "| run | wall time | max I on the paths | p_A | v_A | v_B | v_C | fabric A → C | "
        "noise sqrt(0.5/N) | max abs fabric A→B | E_h/E_v on A→B (min–max) | "
        "E_h/E_v along K0 (p ↑) | λ* (R²) | K0 at C | E_v ∝ p^n on A→B | E_v/p at B |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['run']} | {r['seconds'] / 60:.1f} min"
            f"{' (' + str(r['workers']) + ' workers)' if r['workers'] > 1 else ''} | "
            f"{r['max_i']:.1e} | {_f(r['p_A'])} | {r['v_A']:.3f} | {r['v_B']:.3f} | "
            f"{r['v_C']:.3f} | "
            f"{r['fabric_A']:+.3f} → {r['fabric_C']:+.3f} | {r['noise']:.3f} | "
            f"{r['iso_fabric_max']:.3f} | {min(r['iso_ratio']):.2f}–{max(r['iso_ratio']):.2f} | "
            f"{' → '.join(f'{x:.2f}' for x in r['k0_ratio'])} | "
            f"{r['lambda_star']:.3g} ({r['r2']:.2f}) | {r['k0_C']:.3f} | "
            f"{r['modulus_exponent']:.2f} | {r['ev_over_p_B']:.0f} |"
        )
    lines += [
        "",
        "## Interaction fabrics at C (`python -m dem_taichi.anisotropy`)",
        "",
        "| run | rod β_yy−β_xx | contact-normal φ_yy−φ_xx | force-weighted | long-range normal | "
        "affine E_h/E_v (normal springs) | contact share of affine E_v |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        a = r.get("anisotropy_C")
        if not a:
            continue
        lines.append(
            f"| {r['run']} | {a['rod_fabric_deviator']:+.3f} | "
            f"{a['contact_normal_deviator']:+.3f} | {a['contact_force_weighted_deviator']:+.3f} | "
            f"{a['long_range_normal_deviator']:+.3f} | {a['affine_ratio']:.3f} | "
            f"{a['contact_share_v']:.3f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", help="protocol output folders")
    parser.add_argument("--out", default=str(HERE / "results" / "protocol_validation_summary.md"))
    args = parser.parse_args(argv)
    text = table([_run_row(Path(f)) for f in args.runs])
    print(text)
    Path(args.out).write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
