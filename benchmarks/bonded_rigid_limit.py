"""The stiff-bond limit of bonded rods against rigid rods on the smoke protocol (issue 10).

Runs the smoke protocol (gas -> A -> B, C, B'; no radial path) for several seeds with rigid rods
and with bonded rods whose bonds are ``--stiffness`` times stiffer than the defaults' contact
scale (k_bn = k_bt = s k_n, κ_b = s k_n d²), and compares the findings as mean ± 95 % interval
over the seeds: v, fabric and the linear-response moduli E_oed,v, E_oed,h at B and C. The two
models start from the same gas; the trajectories part chaotically, so they agree only within
the sampling scatter of a 40-rod sample, which is what is tested: the difference of the means
against its 95 % interval (Welch).

Usage::

    .venv/bin/python benchmarks/bonded_rigid_limit.py --seeds 1 2 3 --stiffness 10 --out DIR
    .venv/bin/python benchmarks/bonded_rigid_limit.py --summarise DIR

Writes DIR/<model>_seed<k>/ (protocol runs) and benchmarks/results/bonded_rigid_limit.md.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dem_taichi.analysis.findings import mean_interval, state_findings  # noqa: E402
from dem_taichi.scene.config import load_scene  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
FINDINGS = ("specific_volume", "fabric_deviator", "e_oed_v", "e_oed_h")


def _without_radial(scene):
    """The smoke protocol without its radial path (B, C and B' are what is compared)."""
    import dataclasses
    from types import MappingProxyType

    protocol = dataclasses.replace(scene.extensions["protocol"], radial_stress_ratios="")
    return dataclasses.replace(
        scene, extensions=MappingProxyType(dict(scene.extensions, protocol=protocol))
    )


def scenes(stiffness: float, seed: int):
    rigid = load_scene("smoke").replace(scene={"seed": seed})
    bonded = load_scene("smoke_bonded").replace(
        scene={"seed": seed},
        bonds={"normal": stiffness, "shear": stiffness, "bending": stiffness},
    )
    return {"rigid": _without_radial(rigid), "bonded": _without_radial(bonded)}


def run(args) -> None:
    from dem_taichi.protocol.runner import run_protocol

    out = Path(args.out)
    for seed in args.seeds:
        for model, scene in scenes(args.stiffness, seed).items():
            folder = out / f"{model}_seed{seed}"
            if (folder / "summary.json").exists():
                continue
            t0 = time.perf_counter()
            run_protocol(scene, folder, command="benchmarks/bonded_rigid_limit.py", overwrite=True)
            print(f"{model} seed {seed}: {time.perf_counter() - t0:.0f} s", flush=True)


def findings(folder: Path) -> dict[str, dict[str, float]]:
    """The compared findings at B and C of one run
    (:func:`dem_taichi.analysis.findings.state_findings`) and the run's wall time."""
    seconds = json.loads((folder / "summary.json").read_text())["total_seconds"]
    states = state_findings(folder)
    return {
        label: {name: states[label][name] for name in FINDINGS} | {"seconds": seconds}
        for label in ("B", "C")
    }


def _interval(values: np.ndarray) -> float:
    return mean_interval(values)[1]


def summarise(out: Path, stiffness: float | None) -> str:
    runs: dict[str, list[dict[str, dict[str, float]]]] = {"rigid": [], "bonded": []}
    for folder in sorted(out.glob("*_seed*")):
        model = folder.name.split("_seed")[0]
        if (folder / "summary.json").exists() and model in runs:
            runs[model].append(findings(folder))
    lines = [
        "# Bonded rods in the stiff-bond limit against rigid rods (smoke protocol, issue 10)",
        "",
        f"Seeds: rigid {len(runs['rigid'])}, bonded {len(runs['bonded'])}"
        + (f"; bonds {stiffness:g} x (k_n, k_n, k_n d²)" if stiffness else "")
        + ". Mean ± 95 % interval over seeds; Δ = bonded − rigid with its Welch 95 % interval.",
        "",
        "| state | finding | rigid | bonded | Δ | within scatter |",
        "|---|---|---|---|---|---|",
    ]
    for label in ("B", "C"):
        for name in FINDINGS:
            a = np.array([r[label][name] for r in runs["rigid"]])
            b = np.array([r[label][name] for r in runs["bonded"]])
            if len(a) < 2 or len(b) < 2:
                continue
            diff = b.mean() - a.mean()
            welch = stats.ttest_ind(b, a, equal_var=False)
            half = float(
                stats.t.ppf(0.975, max(len(a) + len(b) - 2, 1))
                * np.sqrt(a.var(ddof=1) / len(a) + b.var(ddof=1) / len(b))
            )
            lines.append(
                f"| {label} | {name} | {a.mean():.4g} ± {_interval(a):.2g} | "
                f"{b.mean():.4g} ± {_interval(b):.2g} | {diff:+.3g} ± {half:.2g} | "
                f"{'yes' if abs(diff) <= half else 'no'} (p = {welch.pvalue:.2f}) |"
            )
    for model, rows in runs.items():
        if rows:
            seconds = [r["B"]["seconds"] for r in rows]
            lines.append(f"\n{model}: protocol wall time {np.mean(seconds):.0f} s per seed (mean)")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--stiffness", type=float, default=10.0)
    parser.add_argument("--out", default="runs/bonded_rigid_limit")
    parser.add_argument("--summarise", metavar="DIR")
    args = parser.parse_args()
    if not args.summarise:
        run(args)
    text = summarise(Path(args.summarise or args.out), None if args.summarise else args.stiffness)
    print(text)
    path = RESULTS / "bonded_rigid_limit.md"
    path.write_text(text)
    print(f"written {path}")


if __name__ == "__main__":
    main()
