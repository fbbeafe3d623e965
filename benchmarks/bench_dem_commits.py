"""Serial throughput of the DEM engine at several commits, on the same packings (not a test).

Each commit is a checkout of the repository (``git worktree add /tmp/pre9 <commit>``). The
packings of the paper scene (1520 rods of 5 discs, contact only and acidic, p = ``--pressure``)
are prepared once, by ``bench_dem.prepared_state`` of the first checkout; then every checkout's
own ``bench_dem.time_case`` (serial execution: the fused multi-step kernel, slow strain-
controlled compression) and ``bench_dem.profile_serial`` time them, in a fresh process per
checkout and round, one process at a time. Rounds are interleaved (A B C, A B C, ...) so that a
change of the machine's load hits every commit alike. The serial engine is deterministic: a
commit that integrates the same physics ends the timed run on the same state, bit for bit
(column ``same_state``).

Rates: ``steps_per_cpu_s`` (steps per CPU-second of the process: the single-threaded serial
kernel's rate on an idle core; the least sensitive to other processes on a shared machine),
``steps_per_s`` (wall clock), ``steps_per_s_best_window`` (best of 12 short windows).

Usage::

    git worktree add /tmp/pre9 71db25e
    .venv/bin/python benchmarks/bench_dem_commits.py . /tmp/pre9 --labels head pre9 \\
        --steps 4000 --rounds 2

Writes ``benchmarks/results/dem_bench_commits.csv`` (every run) and ``.md`` (the table).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
CASES = (("off", False), ("acidic", True))
N_RODS = 1520
MARK = "BENCH_RESULT "


def _scene(long_range: bool):
    from dem_taichi.scene.config import load_scene

    paper = load_scene("paper").replace(integration={"steps_per_call": 500})
    return paper.replace(particles={"n_rods": N_RODS}, long_range={"enabled": long_range})


def _bench_module(tree: Path):
    sys.path.insert(0, str(tree / "benchmarks"))
    import bench_dem  # the checkout's own benchmark (it puts its checkout on sys.path)

    return bench_dem


def prepare(tree: Path, states: Path, pressure: float) -> None:
    """In a worker process: prepare and save the packings with ``tree``'s benchmark."""
    bench = _bench_module(tree)
    for name, long_range in CASES:
        t0 = time.perf_counter()
        state, m = bench.prepared_state(_scene(long_range), "cpu", pressure)
        np.savez(states / f"state_{name}.npz", **state)
        print(
            f"prepared {name}: {time.perf_counter() - t0:.0f} s, p = {m['mean_stress']:.4g}, "
            f"v = {m['specific_volume']:.4f}, Z = {m['coordination_number']:.2f}",
            flush=True,
        )


def time_tree(tree: Path, states: Path, steps: int) -> None:
    """In a worker process: time the saved packings with ``tree``'s benchmark."""
    bench = _bench_module(tree)
    from dem_taichi.kernels import layout

    for name, long_range in CASES:
        state = dict(np.load(states / f"state_{name}.npz"))
        if state["params"].shape[0] > layout.N_PARAMS:  # a newer state on an older engine
            state["params"] = state["params"][: layout.N_PARAMS]  # (the extra slots are 0)
        r = bench.time_case(_scene(long_range), "cpu", "serial", False, state, steps)
        force, rebuild = bench.profile_serial(r["sim"])
        final = r["sim"].get_state()
        row = {
            "case": name,
            "steps_per_s": r["steps_per_s"],
            "steps_per_cpu_s": r["steps_per_cpu_s"],
            "steps_per_s_best_window": r["steps_per_s_best_window"],
            "load_average_1min": r["load_average"],
            "rebuild_every_steps": r["rebuild_every"],
            "n_contacts": int(r["n_contacts"]),
            "n_long_range_pairs": int(r["n_long_range_pairs"]),
            "force_us_per_step": force * 1e6,
            "rebuild_us_each": rebuild * 1e6,
            "final_angle_sum": repr(float(np.sum(final["angle"]))),
            "final_cell": repr([float(x) for x in final["cell"][:2]]),
        }
        print(MARK + json.dumps(row), flush=True)


def _worker(tree: Path, *args: str) -> list[dict]:
    env = dict(os.environ, PYTHONPATH=str(tree))
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", str(tree), *args]
    done = subprocess.run(cmd, env=env, cwd=tree, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"worker on {tree} failed:\n{done.stdout[-3000:]}{done.stderr[-3000:]}")
    for line in done.stdout.splitlines():
        if not line.startswith(MARK):
            print("   ", line, flush=True)
    lines = done.stdout.splitlines()
    return [json.loads(line[len(MARK) :]) for line in lines if line.startswith(MARK)]


def _commit(tree: Path) -> str:
    out = subprocess.run(
        ["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    )
    return out.stdout.strip() or "?"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("trees", nargs="*", help="checkouts to time; the first prepares")
    parser.add_argument("--labels", nargs="*", help="a name per checkout (default: commit)")
    parser.add_argument("--steps", type=int, default=4000)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--pressure", type=float, default=10.0)
    parser.add_argument(
        "--states",
        default=str(Path(tempfile.gettempdir()) / "dem_bench_commits_states"),
        help="folder of the prepared packings (reused when there)",
    )
    parser.add_argument("--out", default=str(RESULTS / "dem_bench_commits.csv"))
    parser.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--prepare", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker is not None:
        states = Path(args.states)
        if args.prepare:
            prepare(Path(args.worker), states, args.pressure)
        else:
            time_tree(Path(args.worker), states, args.steps)
        return
    trees = [Path(t).resolve() for t in args.trees]
    labels = args.labels or [_commit(t) for t in trees]
    if len(labels) != len(trees):
        parser.error("give one label per checkout")
    states = Path(args.states)
    states.mkdir(parents=True, exist_ok=True)
    if not all((states / f"state_{name}.npz").exists() for name, _ in CASES):
        print(f"preparing the packings with {labels[0]} ({trees[0]})", flush=True)
        _worker(trees[0], "--prepare", "--states", str(states), "--pressure", str(args.pressure))
    rows = []
    for round_ in range(1, args.rounds + 1):
        for tree, label in zip(trees, labels, strict=True):
            t0 = time.perf_counter()
            for row in _worker(tree, "--states", str(states), "--steps", str(args.steps)):
                row = {"label": label, "commit": _commit(tree), "round": round_, **row}
                rows.append(row)
                print(
                    f"round {round_} {label:>6} {row['case']:>6}: "
                    f"{row['steps_per_cpu_s']:.0f} steps/cpu-s, {row['steps_per_s']:.0f} "
                    f"steps/s (best window {row['steps_per_s_best_window']:.0f}), load "
                    f"{row['load_average_1min']:.2f}",
                    flush=True,
                )
            print(f"  ({time.perf_counter() - t0:.0f} s)", flush=True)
    out = Path(args.out)
    with out.open("w", newline="") as stream:
        stream.write(
            f"# bench_dem_commits.py on {platform.node()} ({os.cpu_count()} cpus), "
            f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}: paper scene, {N_RODS} rods, "
            f"p = {args.pressure}, serial, {args.steps} steps per run, {args.rounds} rounds\n"
        )
        writer = csv.DictWriter(stream, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    table = summary(rows, labels, args)
    out.with_suffix(".md").write_text(table)
    print(f"\nwritten {out} and {out.with_suffix('.md')}\n\n{table}")


def summary(rows: list[dict], labels: list[str], args) -> str:
    """Median over rounds per commit and case, with the ratio to the last checkout."""
    reference = labels[-1]
    lines = [
        f"Serial DEM throughput, paper scene ({N_RODS} rods of 5 discs, p = {args.pressure:g}), "
        f"{args.steps} steps per run, median of {args.rounds} interleaved rounds "
        f"(`benchmarks/bench_dem_commits.py`); ratio to `{reference}` in steps per CPU-second.",
        "",
        "| long range | commit | steps/CPU-s | ratio | steps/s (wall) | best window | "
        "force µs/step | rebuild µs | load (1 min) | same final state |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, _ in CASES:
        ref_rows = [r for r in rows if r["case"] == name and r["label"] == reference]
        ref_rate = statistics.median(r["steps_per_cpu_s"] for r in ref_rows)
        ref_state = (ref_rows[0]["final_angle_sum"], ref_rows[0]["final_cell"])
        for label in labels:
            mine = [r for r in rows if r["case"] == name and r["label"] == label]

            def med(key, mine=mine):
                return statistics.median(r[key] for r in mine)

            same = all((r["final_angle_sum"], r["final_cell"]) == ref_state for r in mine)
            lines.append(
                f"| {name} | {label} ({mine[0]['commit']}) | {med('steps_per_cpu_s'):.0f} | "
                f"{med('steps_per_cpu_s') / ref_rate:.3f} | {med('steps_per_s'):.0f} | "
                f"{med('steps_per_s_best_window'):.0f} | {med('force_us_per_step'):.0f} | "
                f"{med('rebuild_us_each'):.0f} | {med('load_average_1min'):.2f} | "
                f"{'yes' if same else 'no'} |"
            )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
