"""The protocol profile: where a protocol run's steps and wall time go (issue 20, scope 1).

Usage::

    python benchmarks/protocol_profile.py LABEL=RUN_FOLDER [LABEL=RUN_FOLDER ...] [--out FILE.md]

Each RUN_FOLDER is the output of ``python -m dem_taichi protocol`` (its ``summary.json`` with
the work ledger of :mod:`dem_taichi.engine.work_profile`, and its ``relaxed_states.nc`` with the
effective scene in its attributes). No simulation runs here. Per run it writes:

- the wall time by stage and by kind of work, summed over the stages (servo driving, the
  servo's relaxed checks, the compression to A's increments and relaxations, the confirmation
  of A, the increments discarded by the bisection of A, the probes' relaxations, the linear
  responses and dynamic sweeps, the overhead between kernel launches);
- the steps the loading paths would need at the inertial-number cap alone: for each increment
  between relaxed path states, ∫ max(|dε_xx|, |dε_yy|) / (ε̇_cap(p) Δt) with ε̇_cap =
  safety · I_max · sqrt(p/ρ) / d (:func:`dem_taichi.protocol.quasistatic.strain_rate_cap`) and p
  log-linear between the two states; the rest of the servo's steps are its approach to each
  target (slower than the cap near it, hunting, halved rates while UFR is high).

The wall times come with the machine's load; the steps do not (the serial engine is
deterministic).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import xarray as xr

#: how the work labels of the ledger group into kinds of work (first match wins)
KINDS = (
    ("servo/relax", "servo: relaxed checks"),
    ("servo/cap_ufr", "servo: at the cap lowered by a high UFR"),
    ("servo/cap", "servo: at the inertial-number cap"),
    ("servo/approach", "servo: approach below the cap (rate = gain x residual)"),
    ("servo", "servo: driving the cell (at or below the cap)"),
    ("search/strain", "to A: compression increments"),
    ("search/relax", "to A: relaxations"),
    ("confirm/", "to A: confirmation increments"),
    ("relax", "to A: relaxation of the gas"),
    ("probe/relax", "probes: relaxation to the probes' UFR"),
    ("probe/strain", "probes: dynamic strain steps"),
    ("hold", "ageing (hold)"),
    ("strain", "ageing (strain)"),
)
PATH_STAGES = ("A_to_B", "A_to_C", "C_to_B", "radial")


def kind_of(work: str) -> str:
    for prefix, kind in KINDS:
        if work == prefix or work.startswith(prefix):
            return kind
    return "other"


def _scene(folder: Path):
    """The run's effective scene (the history files keep its TOML)."""
    from dem_taichi.scene.config import scene_from_toml

    with xr.open_dataset(folder / "relaxed_states.nc") as ds:
        return scene_from_toml(ds.attrs["scene_toml_effective"])


def ideal_loading_steps(folder: Path) -> dict[str, float]:
    """Steps each path stage would take at the inertial-number cap alone (see module doc)."""
    from dem_taichi.scene.geometry import rod_geometry
    from dem_taichi.scene.protocol_sections import protocol_settings

    scene = _scene(folder)
    config = protocol_settings(scene)
    geo = rod_geometry(scene)
    rho = geo.mass / geo.solid_area
    i_cap = config.inertial_number_safety * scene.control.inertial_number_max
    ds = xr.open_dataset(folder / "relaxed_states.nc")
    stage_names = ds["stage"].attrs["flag_meanings"].split()
    stages = np.array([stage_names[int(c)] for c in ds["stage"].values])
    exx, eyy = ds["strain_xx"].values, ds["strain_yy"].values
    p = np.maximum(ds["mean_stress"].values, config.pressure_tolerance)
    ds.close()
    dt = scene.time_step
    a_index = int(np.flatnonzero(stages == "isotropic_to_A")[-1])
    c_index = int(np.flatnonzero(stages == "A_to_C")[-1]) if "A_to_C" in stages else a_index
    out = {}
    for stage in PATH_STAGES:
        rows = np.flatnonzero(stages == stage)
        if rows.size == 0:
            continue
        total = 0.0
        prev = c_index if stage == "C_to_B" else a_index
        for r in rows.tolist():  # Python ints (mypy: indices, not numpy integers)
            start = prev
            # a radial path starts again from A (its strains restart near 0)
            if stage == "radial" and r != rows[0] and _restarted(exx, eyy, prev, r):
                start = a_index
            strain = max(abs(exx[r] - exx[start]), abs(eyy[r] - eyy[start]))
            total += strain / (_mean_rate(p[start], p[r], i_cap, rho, geo.diameter) * dt)
            prev = r
        out[stage] = total
    return out


def _restarted(exx, eyy, prev: int, r: int) -> bool:
    return math.hypot(exx[r], eyy[r]) < 0.5 * math.hypot(exx[prev], eyy[prev])


def _mean_rate(p0: float, p1: float, i_cap: float, rho: float, d: float) -> float:
    """Harmonic mean of the cap ε̇ = i_cap sqrt(p/ρ)/d over p log-linear from p0 to p1."""
    c = i_cap / (d * math.sqrt(rho))
    if abs(math.log(p1 / p0)) < 1e-9:
        return c * math.sqrt(p0)
    mean_inverse = (p0**-0.5 - p1**-0.5) / (0.5 * math.log(p1 / p0))
    return c / mean_inverse


def discarded_steps(summary: dict) -> int:
    """Steps of the compression increments to A that the bisection threw away (restored)."""
    seq = summary["transition"].get("sequence", [])
    total, before = 0, None
    for entry in seq:
        if before is not None and entry.get("restored"):
            total += int(entry["step"]) - before
        if not entry.get("restored"):  # a restored increment leaves ``before`` as it was
            before = int(entry["step"])
    return total


def profile(label: str, folder: Path) -> list[str]:
    summary = json.loads((folder / "summary.json").read_text())
    rows = summary.get("work")
    if not rows:
        raise SystemExit(f"{folder}: summary.json has no work ledger (run before the profile)")
    total = summary["total_seconds"]
    workers = summary.get("workers", 1)
    kinds: dict[str, list[float]] = {}
    overhead = 0.0
    for r in rows:
        if r["work"] == "overhead":
            overhead += r["overhead_seconds"]
            continue
        k = kinds.setdefault(kind_of(r["work"]), [0, 0.0, 0.0])
        k[0] += r["steps"]
        k[1] += r["kernel_seconds"]
        k[2] += r["measure_seconds"]
    lin, dyn = summary["probing_linear_seconds"], summary["probing_dynamic_seconds"]
    steps_all = sum(v[0] for v in kinds.values())
    busy = sum(v[1] + v[2] for v in kinds.values()) + overhead + lin + dyn
    lines = [
        f"## {label}: `{summary['scene']}`, {summary['n_rods']} rods",
        "",
        f"Wall time {total:.0f} s ({total / 60:.1f} min) with --workers {workers}; "
        f"{steps_all:,} steps in all. Process seconds below add up over the worker processes "
        f"({busy:.0f} s in all).",
        "",
        "| stage | wall (s) | steps | relaxed states | servo checks |",
        "|---|---|---|---|---|",
    ]
    for name, st in summary["stages"].items():
        lines.append(
            f"| {name} | {st['seconds']:.0f} | {st['steps']:,} | {st['n_relaxed_states']} | "
            f"{st['servo_iterations']} |"
        )
    lines.append(f"| probing | {summary['probing_seconds']:.0f} | | | |")
    lines += [
        "",
        "| kind of work | steps | share of steps | kernel (s) | measures (s) | share of "
        "process time | steps per kernel s |",
        "|---|---|---|---|---|---|---|",
    ]
    for kind, (steps, kernel, measure) in sorted(kinds.items(), key=lambda kv: -kv[1][1]):
        rate = steps / kernel if kernel > 0 else float("nan")
        lines.append(
            f"| {kind} | {steps:,} | {100 * steps / max(steps_all, 1):.0f}% | {kernel:.0f} | "
            f"{measure:.0f} | {100 * (kernel + measure) / busy:.0f}% | {rate:,.0f} |"
        )
    lines.append(f"| probes: linear responses | | | {lin:.0f} | | {100 * lin / busy:.0f}% | |")
    lines.append(f"| probes: dynamic sweeps | | | {dyn:.0f} | | {100 * dyn / busy:.0f}% | |")
    lines.append(
        f"| overhead (Python, state copies, servo algebra, files) | | | {overhead:.0f} | | "
        f"{100 * overhead / busy:.0f}% | |"
    )
    ideal = ideal_loading_steps(folder)
    discarded = discarded_steps(summary)
    lines += [
        "",
        f"Compression to A: {discarded:,} steps in increments discarded by the bisection.",
        "",
        "| path stage | servo driving steps | at the cap alone | ratio |",
        "|---|---|---|---|",
    ]
    for stage, steps_cap in ideal.items():
        drive = sum(
            r["steps"]
            for r in rows
            if r["stage"] == stage and r["work"].startswith("servo") and r["work"] != "servo/relax"
        )
        ratio = drive / steps_cap if steps_cap > 0 else float("nan")
        lines.append(f"| {stage} | {drive:,} | {steps_cap:,.0f} | {ratio:.2f} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", help="LABEL=RUN_FOLDER")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    lines = ["# Protocol profile", ""]
    for item in args.runs:
        label, _, folder = item.partition("=")
        lines += profile(label, Path(folder)) + [""]
    text = "\n".join(lines)
    print(text)
    if args.out:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
