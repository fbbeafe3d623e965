"""Damped against FIRE relaxations on the same seeds (issue 20): steps, wall time and findings.

Usage::

    python benchmarks/relaxation_pairs.py RUNS_DIR [--out benchmarks/results/relaxation_demo]

RUNS_DIR holds protocol runs named ``damped_s<seed>`` and ``fire_s<seed>`` (the same scene and
seed, ``[integration] relaxation`` = "damped" | "fire", which integrates every minimising call:
the path relaxations, the probes' strict relaxations and the confirmations of A). Per method:
mean wall time, total steps and the steps of the probes' relaxations and of the servo (from
``summary.json``'s work ledger). Per finding (:func:`benchmarks.study_clay_pilots.run_row`):
the damped runs' mean and seed-to-seed sd, and the paired difference FIRE − damped over the
seeds, mean ± 95 % (Student t). The trajectories decorrelate (a chaotic path from the same
gas: ``benchmarks/results/protocol_speed.md``), so a paired difference is judged against the
seed-to-seed sd, not against zero alone. Writes ``<out>.md``.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from study_clay_pilots import run_row  # noqa: E402

from dem_taichi.analysis.findings import mean_interval  # noqa: E402

#: (key, label) of the findings compared
FINDINGS = (
    ("v_A", "v at A"),
    ("v_B", "v at B"),
    ("lambda_star", "λ* A→B"),
    ("fabric_C", "fabric deviator at C"),
    ("k0_C", "K0 at C"),
    ("ev_over_p_B", "E_v/p at B"),
    ("ratio_B", "E_h/E_v at B"),
    ("ratio_C", "E_h/E_v at C"),
    ("modulus_exponent", "E_v ∝ p^n on A→B"),
)


def work(folder: Path) -> dict[str, float]:
    """Total steps, the probes' relaxation steps and the servo's steps of a run."""
    entries = json.loads((folder / "summary.json").read_text())["work"]
    total = sum(e["steps"] for e in entries)
    probe = sum(e["steps"] for e in entries if e["work"].startswith("probe"))
    servo = sum(e["steps"] for e in entries if e["work"].startswith("servo"))
    return {"steps": total, "probe_steps": probe, "servo_steps": servo}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path)
    parser.add_argument("--out", type=Path, default=HERE / "results" / "relaxation_demo")
    args = parser.parse_args(argv)
    rows: dict[str, dict[int, dict]] = {"damped": {}, "fire": {}}
    for folder in sorted(args.runs.iterdir()):
        named = re.fullmatch(r"(damped|fire)_s(\d+)", folder.name)
        if named is None or not (folder / "summary.json").exists():
            continue
        row = run_row(folder)
        row.update(work(folder))
        rows[named.group(1)][int(named.group(2))] = row
    seeds = sorted(set(rows["damped"]) & set(rows["fire"]))
    if not seeds:
        parser.error(f"{args.runs}: no seed with both a damped_s<seed> and a fire_s<seed> run")
    lines = [f"# Damped against FIRE relaxations, paired on seeds {', '.join(map(str, seeds))}", ""]
    lines += ["| method | wall (s) | steps | probe steps | servo steps |", "|---|---|---|---|---|"]
    for method in ("damped", "fire"):
        cols = []
        for key in ("minutes", "steps", "probe_steps", "servo_steps"):
            values = [rows[method][s][key] * (60.0 if key == "minutes" else 1.0) for s in seeds]
            mean, half, _ = mean_interval(values)
            cols.append(f"{mean:.4g} ± {half:.2g}")
        lines.append(f"| {method} | " + " | ".join(cols) + " |")
    lines += ["", "| finding | damped mean | seed sd (damped) | FIRE − damped (paired) |",
              "|---|---|---|---|"]  # fmt: skip
    for key, label in FINDINGS:
        base = [rows["damped"][s].get(key, math.nan) for s in seeds]
        diff = [rows["fire"][s].get(key, math.nan) - b for s, b in zip(seeds, base, strict=True)]
        finite = [b for b in base if math.isfinite(b)]
        mean = sum(finite) / len(finite) if finite else math.nan
        sd = (
            math.sqrt(sum((b - mean) ** 2 for b in finite) / (len(finite) - 1))
            if len(finite) > 1
            else math.nan
        )
        d_mean, d_half, n = mean_interval([d for d in diff if math.isfinite(d)])
        lines.append(f"| {label} | {mean:.4g} | {sd:.3g} | {d_mean:+.3g} ± {d_half:.2g} (n={n}) |")
    text = "\n".join(lines) + "\n"
    args.out.with_suffix(".md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
