"""Full loading paths for variants of the default scene: E_h/E_v, rod fabric, compressibility.

Issue 8 ("full paths"): our rigid-rod DEM gives E_oed,h/E_oed,v < 1 along K0 where the study
finds E_h > E_v growing with loading. This script runs the whole protocol (gas → A → B, A → C
→ B′) on variants of the built-in ``default`` scene (300 rods of 5 discs, acidic) and reports how
the linear-response moduli, the rod fabric and the compressibility move. Nothing is tuned: each
variant changes one group of scene values, listed in :data:`VARIANTS`.

Usage::

    python benchmarks/full_path_variants.py                       # the whole queue, in order
    python benchmarks/full_path_variants.py --only base,kt1 --seeds 2,11
    python benchmarks/full_path_variants.py --stop-launch 11:35 --deadline 11:50
    python benchmarks/full_path_variants.py --summarise           # only read finished runs
    python benchmarks/full_path_variants.py --write-scenes        # only write the scene files

Common to every variant (on top of ``dem_taichi/scenes/default.toml``): ``[protocol]
servo_stiffness = "secant"``, ``[probing] dynamic_states = ""`` (linear-response probes only; the
dynamic sweep is ~1000× dearer) and ``[probing] every_n_increments = 1`` (a probe at every
relaxed increment of every path), ``[scene] seed`` from ``--seeds`` and ``[scene] name =
default_<variant>_s<seed>``. The scene files are written to ``<root>/scenes/`` (validated by
the scene loader: an unknown key fails there).

Each member runs ``python -m dem_taichi protocol SCENE --out <root>/<variant>_s<seed>
--workers 2``, one at a time (never two DEM protocol processes at once: before each launch the
queue also waits while any other ``dem_taichi protocol`` process is alive). A member whose
folder holds ``summary.json`` (written last by the protocol) is finished and skipped; a folder
without it is an interrupted run and is removed before the member is run again. The queue's own
wall time of each run goes to ``<folder>/queue_run.json``; its log to ``<root>/queue.log``.
After each run the results files are rewritten from all finished runs.

Summary of a run (from ``summary.json``, ``relaxed_states.nc`` and ``probes.nc``, read with
:mod:`dem_taichi.io` and ``benchmarks/validation_summary.py``): v at A, B, C, B′; the rod fabric
deviator β_yy − β_xx at A, C, B′; K0 = σ_xx/σ_yy at C; E_oed,v, E_oed,h and E_h/E_v of the
linear-response probes at every probed K0 state, at B, at B′ and on the isotropic path (min–max:
the control); λ* = −d ln v/d ln p fitted on A + A→B and on A + A→C
(:func:`dem_taichi.analysis.arrays.compressibility_slope`); the p-exponent of E_oed,v along A→B
(:func:`dem_taichi.analysis.arrays.power_law_exponent`, slope of ln E_oed,v against ln p over the
A→B probes, A excluded: A sits at the jamming transition; also over p ≥ 10 kPa only); E_oed,v/p at
B, and E_oed,v/p and E_h/E_v interpolated (in ln p) at 100 kPa on A→B and A→C (the same as at
B and C except for ``k0long``, whose B and C are at 700).

Outputs: ``benchmarks/results/stiffness_anisotropy_full_paths.csv`` (one row per run) and
``.md`` (per variant: mean ± 95 % Student-t interval over seeds, n − 1 dof, next to ``base``;
the paired differences to ``base`` on the same seeds; every run's K0 sequence and wall time).
"""

from __future__ import annotations

import argparse
import csv
import datetime as dt
import fcntl
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
from scipy import stats

from dem_taichi.analysis.arrays import (
    compressibility_slope,
    modulus_over_p_at,
    power_law_exponent,
    stiffness_ratio,
)
from dem_taichi.analysis.findings import mean_interval, path_arrays, probe_arrays
from dem_taichi.io import open_history, open_probes
from dem_taichi.scene.config import builtin_scene_path, scene_from_toml

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from validation_summary import _run_row  # noqa: E402  (benchmarks/ is not a package)

ROOT = Path("/work/runs/variants")
RESULTS = HERE / "results"
CSV_PATH = RESULTS / "stiffness_anisotropy_full_paths.csv"
MD_PATH = RESULTS / "stiffness_anisotropy_full_paths.md"

COMMON: dict[str, dict] = {
    "protocol": {"servo_stiffness": "secant"},
    "probing": {"dynamic_states": "", "every_n_increments": 1},
}

#: variant name → (scene changes, what it tests)
VARIANTS: dict[str, tuple[dict[str, dict], str]] = {
    "base": ({}, "default scene (k_t/k_n = 0.2, μ = 0.5, 5 discs, F_max = 10)"),
    "kt1": ({"contact": {"k_t": 1.0e5}}, "k_t/k_n = 1"),
    "mu02": ({"contact": {"mu": 0.2}}, "μ = 0.2"),
    "mu10": ({"contact": {"mu": 1.0}}, "μ = 1.0"),
    "ns3": ({"particles": {"n_spheres": 3, "n_rods": 500}}, "3 discs per rod, 500 rods"),
    "ns9": ({"particles": {"n_spheres": 9, "n_rods": 167}}, "9 discs per rod, 167 rods"),
    "k0long": (
        {"protocol": {"target_mean_stress": 700.0, "path_increments": 10}},
        "paths to p = 700 (K0 to σ_v ≈ 1000), 10 increments",
    ),
    "fmax100": (
        {
            "long_range": {
                "f_max_edge": 100.0,
                "f_max_inner": 100.0,
                "k_a_edge": 200.0,
                "k_a_inner": 200.0,
            }
        },
        "F_max = 100, k_a = 200 (same range, 10× force)",
    ),
}
SEEDS = (2, 11, 12)

#: the order of the queue: most informative first
ORDER: list[tuple[str, int]] = [
    *[(v, s) for s in SEEDS for v in ("base", "kt1", "ns9")],
    *[(v, 2) for v in ("k0long", "fmax100", "ns3", "mu10", "mu02")],
    *[(v, s) for s in SEEDS[1:] for v in ("k0long", "fmax100", "ns3", "mu10", "mu02")],
]

STUDY = (
    "The study's values: E_h > E_v along K0, growing with loading; λ* ≈ 0.25; "
    "moduli ∝ p^0.8; E_oed/p ≈ 125 at 100 kPa."
)


# ---------------------------------------------------------------------------------------------
# Scenes and the queue
# ---------------------------------------------------------------------------------------------


def member_name(variant: str, seed: int) -> str:
    return f"{variant}_s{seed}"


def _merge(base: dict, changes: dict) -> None:
    for section, values in changes.items():
        base.setdefault(section, {}).update(values)


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    return json.dumps(value, ensure_ascii=False)  # a TOML basic string


def scene_text(variant: str, seed: int) -> str:
    """The scene TOML of a member: ``default.toml``'s keys with the changes (validated).

    Only the keys of ``default.toml`` and the changed ones are written (every other key keeps
    the loader's default), so the file reads as a diff of the built-in scene.
    """
    data = tomllib.loads(builtin_scene_path("default").read_text())
    _merge(data, COMMON)
    _merge(data, VARIANTS[variant][0])
    _merge(data, {"scene": {"seed": seed, "name": f"default_{variant}_s{seed}"}})
    data["scene"]["description"] = (
        f"issue 8 full-path variant {variant!r} ({VARIANTS[variant][1]}), seed {seed}; "
        "benchmarks/full_path_variants.py"
    )
    lines = []
    for section, table in data.items():
        lines.append(f"[{section}]")
        lines += [f"{key} = {_toml_value(value)}" for key, value in table.items()]
        lines.append("")
    text = "\n".join(lines)
    scene = scene_from_toml(text)  # fails naming any unknown key or invalid value
    for section, table in data.items():
        loaded = getattr(scene, section, None) or scene.extensions[section]
        for key, value in table.items():
            if getattr(loaded, key) != value:  # pragma: no cover
                raise RuntimeError(f"[{section}] {key}: wrote {value!r}, loaded {loaded!r}")
    return text


def write_scene(root: Path, variant: str, seed: int) -> Path:
    folder = root / "scenes"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{member_name(variant, seed)}.toml"
    header = (
        f"# issue 8 full-path variant {variant} (seed {seed}), written by "
        "benchmarks/full_path_variants.py from dem_taichi/scenes/default.toml\n"
        f"# common: {json.dumps(COMMON)}\n# variant: {json.dumps(VARIANTS[variant][0])}\n"
    )
    path.write_text(header + scene_text(variant, seed))
    return path


def is_finished(folder: Path) -> bool:
    return (folder / "summary.json").exists()


def _log(root: Path, message: str) -> None:
    line = f"{dt.datetime.now():%Y-%m-%d %H:%M:%S} {message}"
    print(line, flush=True)
    with open(root / "queue.log", "a") as fh:
        fh.write(line + "\n")


def _other_protocol_processes() -> list[str]:
    """Command lines of live ``dem_taichi protocol`` processes (any user's, read from /proc)."""
    found = []
    me = os.getpid()
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == me:
            continue
        try:
            cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if "dem_taichi protocol" in cmd or "dem_taichi.protocol" in cmd:
            found.append(f"{entry.name}: {cmd.strip()}")
    return found


def _clock(text: str | None) -> dt.datetime | None:
    if not text:
        return None
    hh, mm = (int(x) for x in text.split(":"))
    return dt.datetime.now().replace(hour=hh, minute=mm, second=0, microsecond=0)


def run_queue(
    members: list[tuple[str, int]],
    root: Path,
    workers: int,
    stop_launch: dt.datetime | None,
    deadline: dt.datetime | None,
) -> None:
    root.mkdir(parents=True, exist_ok=True)
    lock = open(root / ".queue.lock", "w")
    try:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        raise SystemExit(f"another queue holds {root / '.queue.lock'}") from None
    _log(root, f"queue: {', '.join(member_name(*m) for m in members)}")
    for variant, seed in members:
        name = member_name(variant, seed)
        out = root / name
        if is_finished(out):
            _log(root, f"{name}: finished run present, skipped")
            continue
        while True:  # one DEM protocol process at a time, whoever started the other
            others = _other_protocol_processes()
            if not others:
                break
            if stop_launch and dt.datetime.now() >= stop_launch:
                break
            _log(root, f"{name}: waiting, protocol process alive: {others[0][:160]}")
            time.sleep(60)
        if stop_launch and dt.datetime.now() >= stop_launch:
            _log(root, f"stop-launch time {stop_launch:%H:%M} reached: no new runs")
            break
        if out.exists():
            assert out.resolve().parent == root.resolve(), out
            _log(root, f"{name}: unfinished folder removed before re-running")
            shutil.rmtree(out)
        scene = write_scene(root, variant, seed)
        cmd = [
            sys.executable, "-m", "dem_taichi", "protocol", str(scene),
            "--out", str(out), "--workers", str(workers),
        ]  # fmt: skip
        _log(root, f"{name}: start: {' '.join(cmd)}")
        t0 = time.time()
        log_path = root / f"{name}.log"
        with open(log_path, "w") as log:
            proc = subprocess.Popen(
                cmd, stdout=log, stderr=subprocess.STDOUT, cwd=HERE.parent, start_new_session=True
            )
            killed = False
            while proc.poll() is None:
                if deadline and dt.datetime.now() >= deadline and not killed:
                    _log(root, f"{name}: deadline {deadline:%H:%M} reached: killing pid {proc.pid}")
                    os.killpg(proc.pid, signal.SIGTERM)
                    killed = True
                    try:
                        proc.wait(timeout=30)
                    except subprocess.TimeoutExpired:
                        os.killpg(proc.pid, signal.SIGKILL)
                time.sleep(5)
        wall = time.time() - t0
        rc = proc.returncode
        info = {"command": cmd, "wall_seconds": wall, "returncode": rc, "killed": killed}
        if out.exists():
            (out / "queue_run.json").write_text(json.dumps(info, indent=2))
        status = "finished" if is_finished(out) else "FAILED (no summary.json)"
        _log(root, f"{name}: rc={rc} wall {wall / 60:.1f} min: {status}; log {log_path}")
        if rc != 0 and not killed:
            tail = log_path.read_text().splitlines()[-5:]
            _log(root, f"{name}: log tail: " + " | ".join(tail))
        try:
            write_results(root)
        except Exception as exc:  # noqa: BLE001 - a summary problem must not stop the queue
            _log(root, f"summary failed: {type(exc).__name__}: {exc}")
        if killed:
            break
    _log(root, "queue done")


# ---------------------------------------------------------------------------------------------
# Summary of finished runs
# ---------------------------------------------------------------------------------------------


def _interp_log(p: np.ndarray, y: np.ndarray, at: float) -> float:
    """y at p = ``at`` interpolated linearly in (ln p, ln y); NaN outside the sampled range."""
    ok = np.isfinite(p) & np.isfinite(y) & (p > 0) & (y > 0)
    p, y = p[ok], y[ok]
    # the end states sit within the servo tolerance of their targets (p_C = 99.96 for 100)
    if p.size < 2 or not (p.min() * 0.99 <= at <= p.max() * 1.01):
        return math.nan
    at = min(max(at, p.min()), p.max())
    order = np.argsort(p)
    return float(np.exp(np.interp(math.log(at), np.log(p[order]), np.log(y[order]))))


def _series(values) -> str:
    return ";".join(f"{x:.4g}" for x in values)


def summarise_run(folder: Path) -> dict:
    """Numbers of one finished run (see the module docstring). Every finding is computed by the
    functions of :mod:`dem_taichi.analysis.arrays` (the ones the run's report and
    :func:`dem_taichi.analysis.findings.run_findings` use), over the arrays of the run's files."""
    base = _run_row(folder)  # v, fabric at A and C, K0 at C, λ* on A + A→B, wall time
    summary = json.loads((folder / "summary.json").read_text())
    states = path_arrays(summary, open_history(folder / "relaxed_states.nc"))
    probes_file = open_probes(folder / "probes.nc")
    probes = probe_arrays(probes_file)
    fabric = probes_file["fabric_deviator"].values
    scale = float(summary.get("stress_scale_kpa", 1.0))

    path, label = probes.path, probes.label
    p = probes.mean_stress * scale
    ev = probes.e_oed_v * scale
    eh = probes.e_oed_h * scale
    ratio = stiffness_ratio(probes.e_oed_h, probes.e_oed_v)

    def at(lab: str) -> int:
        idx = np.flatnonzero(label == lab)
        if idx.size != 1:
            raise ValueError(f"{folder}: {idx.size} probes labelled {lab!r}")
        return int(idx[0])

    iB, iBp, iC, iA = at("B"), at("B'"), at("C"), at("A")
    iso = path == "A_to_B"  # A excluded (module docstring)
    k0 = path == "A_to_C"
    k0_order = probes.along_k0()
    fit_k0 = compressibility_slope(
        states.from_a("A_to_C", "mean_stress"), states.from_a("A_to_C", "specific_volume")
    )
    iso_p10 = iso & (p >= 10.0)

    queue = folder / "queue_run.json"
    queue_wall = json.loads(queue.read_text())["wall_seconds"] if queue.exists() else math.nan
    name = folder.name
    variant, _, seed = name.rpartition("_s")
    return {
        "run": name,
        "variant": variant,
        "seed": int(seed) if seed.isdigit() else -1,
        "n_rods": base["n_rods"],
        "wall_s": base["seconds"],
        "queue_wall_s": queue_wall,
        "max_inertial_number": base["max_i"],
        "p_A": base["p_A"],
        "v_A": base["v_A"],
        "v_B": base["v_B"],
        "v_C": base["v_C"],
        "v_Bp": states.at("B'", "specific_volume"),
        "p_B": states.at("B", "mean_stress") * scale,
        "p_C": states.at("C", "mean_stress") * scale,
        "sigma_v_C": states.at("C", "stress_yy") * scale,
        "fabric_noise": base["noise"],
        "fabric_A": base["fabric_A"],
        "fabric_C": base["fabric_C"],
        "fabric_Bp": states.at("B'", "fabric_deviator"),
        "fabric_iso_max_abs": base["iso_fabric_max"],
        "k0_C": base["k0_C"],
        "ev_A": ev[iA],
        "eh_A": eh[iA],
        "ratio_A": ratio[iA],
        "ev_B": ev[iB],
        "eh_B": eh[iB],
        "ratio_B": ratio[iB],
        "ev_C": ev[iC],
        "eh_C": eh[iC],
        "ratio_C": ratio[iC],
        "ev_Bp": ev[iBp],
        "eh_Bp": eh[iBp],
        "ratio_Bp": ratio[iBp],
        "ratio_Bp_minus_B": ratio[iBp] - ratio[iB],
        "ratio_C_minus_Bp": ratio[iC] - ratio[iBp],
        "ratio_iso_min": float(np.min(ratio[iso])),
        "ratio_iso_max": float(np.max(ratio[iso])),
        "ratio_iso_max_dev": float(np.max(np.abs(ratio[iso] - 1.0))),
        "ratio_iso_max_dev_p10": float(np.max(np.abs(ratio[iso_p10] - 1.0)))
        if iso_p10.any()
        else math.nan,
        "ratio_k0_max": float(np.max(ratio[k0])),
        "ratio_k0_at_p100": _interp_log(p[k0], ratio[k0], 100.0),
        "ev_over_p_B": modulus_over_p_at(probes, "B"),
        "ev_over_p_iso_at_p100": _interp_log(p[iso], ev[iso], 100.0) / 100.0,
        "lambda_star_iso": base["lambda_star"],
        "lambda_star_iso_r2": base["r2"],
        "lambda_star_k0": fit_k0["lambda_star"],
        "lambda_star_k0_r2": fit_k0["r2"],
        "ev_exponent_iso": power_law_exponent(p[iso], ev[iso]),
        "ev_exponent_iso_p10": power_law_exponent(p[iso_p10], ev[iso_p10]),
        "eh_exponent_iso": power_law_exponent(p[iso], eh[iso]),
        "k0_p_series": _series(p[k0_order]),
        "k0_ratio_series": _series(ratio[k0_order]),
        "k0_ev_series": _series(ev[k0_order]),
        "k0_eh_series": _series(eh[k0_order]),
        "k0_fabric_series": _series(fabric[k0_order]),
        "iso_p_series": _series(p[iso][np.argsort(p[iso])]),
        "iso_ratio_series": _series(ratio[iso][np.argsort(p[iso])]),
    }


def _is_member(name: str) -> bool:
    variant, _, seed = name.rpartition("_s")
    return variant in VARIANTS and seed.isdigit()


def finished_runs(root: Path) -> list[dict]:
    rows = []
    for folder in sorted(root.iterdir()) if root.exists() else []:
        if folder.is_dir() and _is_member(folder.name) and is_finished(folder):
            try:
                rows.append(summarise_run(folder))
            except Exception as exc:  # noqa: BLE001 - report, keep the others
                print(f"cannot summarise {folder}: {type(exc).__name__}: {exc}", file=sys.stderr)
    order = {m: k for k, m in enumerate(member_name(*m) for m in ORDER)}
    rows.sort(key=lambda r: (list(VARIANTS).index(r["variant"]), r["seed"], order.get(r["run"], 0)))
    return rows


def _fmt(m: float, h: float, digits: int = 3, signed: bool = False) -> str:
    if not np.isfinite(m):
        return "–"
    spec = f"+.{digits}f" if signed else f".{digits}g"
    text = f"{m:{spec}}"
    return text if not np.isfinite(h) else f"{text} ± {h:.2g}"


#: the per-variant tables: (title, [(key, header, digits, signed)])
AGG_TABLES = [
    (
        "Stiffness anisotropy and fabric",
        [
            ("ratio_C", "E_h/E_v at C", 3, False),
            ("ratio_Bp", "E_h/E_v at B′", 3, False),
            ("ratio_B", "E_h/E_v at B", 3, False),
            ("ratio_Bp_minus_B", "B′ − B (fabric part)", 2, True),
            ("ratio_C_minus_Bp", "C − B′ (stress part)", 2, True),
            ("ratio_iso_max_dev", "control: max abs(E_h/E_v − 1) on A→B", 2, False),
            ("ratio_iso_max_dev_p10", "same, p ≥ 10", 2, False),
            ("ratio_k0_at_p100", "E_h/E_v on K0 at p = 100", 3, False),
            ("fabric_C", "fabric at C", 3, True),
            ("fabric_Bp", "fabric at B′", 3, True),
            ("k0_C", "K0 at C", 3, False),
        ],
    ),
    (
        "Compressibility and stiffness level",
        [
            ("v_C", "v at C", 4, False),
            ("lambda_star_iso", "λ* A→B", 3, False),
            ("lambda_star_k0", "λ* A→C", 3, False),
            ("ev_exponent_iso", "n: E_v ∝ p^n on A→B", 2, False),
            ("ev_exponent_iso_p10", "n, p ≥ 10", 2, False),
            ("ev_over_p_B", "E_v/p at B", 3, False),
            ("ev_over_p_iso_at_p100", "E_v/p on A→B at p = 100", 3, False),
        ],
    ),
]


def _aggregate(rows: list[dict], title: str) -> list[str]:
    """Per-variant mean ± interval tables and the paired differences to ``base``."""
    by_variant: dict[str, list[dict]] = {}
    for r in rows:
        by_variant.setdefault(r["variant"], []).append(r)
    lines = [
        "",
        f"## {title}: mean ± 95 % interval over seeds (Student t, n − 1 dof; none for n = 1)",
    ]
    for table, columns in AGG_TABLES:
        lines += [
            "",
            f"### {table}",
            "",
            "| variant | change | n | "
            + " | ".join(c[1] for c in columns)
            + " | wall time (min) |",
            "|---|---|---|" + "---|" * len(columns) + "---|",
        ]
        for variant, (_, what) in VARIANTS.items():
            group = by_variant.get(variant, [])
            if not group:
                continue
            cells = []
            for key, _, digits, signed in columns:
                m, h, _ = mean_interval([r[key] for r in group])
                cells.append(_fmt(m, h, digits, signed))
            walls = ", ".join(f"{r['wall_s'] / 60:.1f} (s{r['seed']})" for r in group)
            lines.append(
                f"| {variant} | {what} | {len(group)} | " + " | ".join(cells) + f" | {walls} |"
            )
    base = {r["seed"]: r for r in by_variant.get("base", [])}
    lines += [
        "",
        f"### {title}: paired differences to `base` (same seed: part of the packing noise cancels)",
        "",
        "| variant | seeds | Δ E_h/E_v at C | Δ E_h/E_v at B′ | Δ fabric at C | Δ v at C | "
        "Δ λ* A→B | ratio of E_v at B to base |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for variant in VARIANTS:
        if variant == "base":
            continue
        pairs = [(r, base[r["seed"]]) for r in by_variant.get(variant, []) if r["seed"] in base]
        if not pairs:
            continue
        cells = []
        for key, digits in (("ratio_C", 3), ("ratio_Bp", 3), ("fabric_C", 3), ("v_C", 3),
                            ("lambda_star_iso", 3)):  # fmt: skip
            m, h, _ = mean_interval([a[key] - b[key] for a, b in pairs])
            cells.append(_fmt(m, h, digits, signed=True))
        m, h, _ = mean_interval([a["ev_B"] / b["ev_B"] for a, b in pairs])
        cells.append(_fmt(m, h, 3))
        lines.append(
            f"| {variant} | {','.join(str(a['seed']) for a, _ in pairs)} | "
            + " | ".join(cells)
            + " |"
        )
    return lines


def _fabric_regression(rows: list[dict]) -> list[str]:
    """E_h/E_v at C and B′ against the rod fabric there, across runs (least squares)."""
    lines = [
        "",
        "## E_h/E_v against the rod fabric across runs (least squares, each run one point)",
        "",
        "A slope b < 0 means runs whose rods lie flatter (more negative β_yy − β_xx) are stiffer "
        "horizontally. Fabric-induced anisotropy shows at B′ (q = 0); at C the stress-induced "
        "part adds to it.",
        "",
        "| runs | state | N | E_h/E_v = a + b · fabric: a | b (95 %) | R² |",
        "|---|---|---|---|---|---|",
    ]
    groups = [("all", rows), *[(v, [r for r in rows if r["variant"] == v]) for v in VARIANTS]]
    for name, group in groups:
        for state, rkey, fkey in (("C", "ratio_C", "fabric_C"), ("B′", "ratio_Bp", "fabric_Bp")):
            x = np.array([r[fkey] for r in group], dtype=float)
            y = np.array([r[rkey] for r in group], dtype=float)
            ok = np.isfinite(x) & np.isfinite(y)
            if ok.sum() < 4:
                continue
            fit = stats.linregress(x[ok], y[ok])
            half = stats.t.ppf(0.975, ok.sum() - 2) * fit.stderr
            lines.append(
                f"| {name} | {state} | {ok.sum()} | {fit.intercept:.3f} | "
                f"{fit.slope:+.2f} ± {half:.2f} | {fit.rvalue**2:.2f} |"
            )
    return lines


def markdown(rows: list[dict]) -> str:
    seeds = sorted({r["seed"] for r in rows})
    lines = [
        "# Stiffness anisotropy on full loading paths: variants of the default scene (issue 8)",
        "",
        "Written by `benchmarks/full_path_variants.py` from the finished runs under "
        f"`{ROOT}` ({len(rows)} runs). Scene: `dem_taichi/scenes/default.toml` (300 rods × 5 "
        'discs, acidic) with `servo_stiffness = "secant"`, linear-response probes at every '
        f"relaxed increment (no dynamic sweep); seeds {', '.join(str(x) for x in seeds)}. "
        "Moduli are the linear-response constrained moduli (stuck contacts). Fabric = rod "
        "β_yy − β_xx (negative: rods lie horizontal). Stresses in kPa (1 DEM unit = 1 kPa).",
        "",
        STUDY,
    ]
    lines += _aggregate(rows, f"All seeds ({', '.join(str(x) for x in seeds)})")
    lines += _fabric_regression(rows)
    if set(seeds) - set(SEEDS):
        core = [r for r in rows if r["seed"] in SEEDS]
        lines += _aggregate(core, f"Seeds {', '.join(str(x) for x in SEEDS)} only")
    lines += [
        "",
        "## Every run",
        "",
        "| run | rods | wall time (min) | p_A | v_A → v_B, v_C, v_B′ | fabric A → C, B′ | "
        "K0 at C | σ_v at C | E_v at B, C, B′ | E_h/E_v at A, B, C, B′ | "
        "E_h/E_v on A→B (min–max) | E_h/E_v along K0 (p ↑) | fabric along K0 | "
        "λ* A→B (R²), A→C | n(E_v), A→B | E_v/p at B |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        k0p = [float(x) for x in r["k0_p_series"].split(";")]
        k0r = [float(x) for x in r["k0_ratio_series"].split(";")]
        k0f = [float(x) for x in r["k0_fabric_series"].split(";")]
        lines.append(
            f"| {r['run']} | {r['n_rods']} | {r['wall_s'] / 60:.1f} | {r['p_A']:.3g} | "
            f"{r['v_A']:.3f} → {r['v_B']:.3f}, {r['v_C']:.3f}, {r['v_Bp']:.3f} | "
            f"{r['fabric_A']:+.3f} → {r['fabric_C']:+.3f}, {r['fabric_Bp']:+.3f} | "
            f"{r['k0_C']:.3f} | {r['sigma_v_C']:.4g} | "
            f"{r['ev_B']:.4g}, {r['ev_C']:.4g}, {r['ev_Bp']:.4g} | "
            f"{r['ratio_A']:.2f}, {r['ratio_B']:.2f}, {r['ratio_C']:.2f}, {r['ratio_Bp']:.2f} | "
            f"{r['ratio_iso_min']:.2f}–{r['ratio_iso_max']:.2f} | "
            + " → ".join(f"{x:.2f} ({q:.3g})" for x, q in zip(k0r, k0p, strict=True))
            + " | "
            + " → ".join(f"{x:+.3f}" for x in k0f)
            + " | "
            f"{r['lambda_star_iso']:.3g} ({r['lambda_star_iso_r2']:.2f}), "
            f"{r['lambda_star_k0']:.3g} | {r['ev_exponent_iso']:.2f} | {r['ev_over_p_B']:.0f} |"
        )
    lines += [
        "",
        "Along K0 each entry is E_h/E_v (p in kPa) at a probed relaxed increment; C is the "
        "last. λ* is the least-squares slope of ln v against ln p over A and the path's "
        "relaxed states; n(E_v) the slope of ln E_oed,v against ln p over the A→B probes "
        "(A excluded). Wall time: the protocol's own total (`summary.json`), 2 workers on a "
        "shared 2-core CPU.",
        "",
        "Reproduce: `.venv/bin/python benchmarks/full_path_variants.py` (runs, then "
        "summarises); `--summarise` only rewrites these files from the finished runs.",
    ]
    return "\n".join(lines) + "\n"


def write_results(root: Path) -> list[dict]:
    rows = finished_runs(root)
    RESULTS.mkdir(parents=True, exist_ok=True)
    if rows:
        with open(CSV_PATH, "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
            writer.writeheader()
            for r in rows:
                writer.writerow(
                    {k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()}
                )
    MD_PATH.write_text(markdown(rows))
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default="", help="comma-separated variants (default: all)")
    parser.add_argument("--seeds", default="", help="comma-separated seeds (default: 2,11,12)")
    parser.add_argument("--root", default=str(ROOT), help=f"run folders (default {ROOT})")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--summarise", action="store_true", help="only read finished runs")
    parser.add_argument("--write-scenes", action="store_true", help="only write the scenes")
    parser.add_argument("--stop-launch", default=None, help="HH:MM: launch no run after this")
    parser.add_argument("--deadline", default=None, help="HH:MM: kill a run still going")
    args = parser.parse_args(argv)
    root = Path(args.root)
    variants = [v.strip() for v in args.only.split(",") if v.strip()] or list(VARIANTS)
    unknown = sorted(set(variants) - set(VARIANTS))
    if unknown:
        parser.error(f"unknown variant(s) {unknown}; allowed: {', '.join(VARIANTS)}")
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()] or list(SEEDS)
    members = [m for m in ORDER if m[0] in variants and m[1] in seeds]
    # seeds beyond the listed order: seed by seed, so that a stop leaves every variant sampled
    members += [(v, s) for s in seeds for v in variants if (v, s) not in members]
    if args.summarise:
        rows = write_results(root)
        print(MD_PATH.read_text())
        print(f"{len(rows)} finished runs; wrote {CSV_PATH} and {MD_PATH}")
        return 0
    if args.write_scenes:
        for m in members:
            print(write_scene(root, *m))
        return 0
    run_queue(members, root, args.workers, _clock(args.stop_launch), _clock(args.deadline))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
