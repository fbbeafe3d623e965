"""The engine on a GPU (not a test): steps/s against the number of rods, the serial against the
parallel neighbour-list build, several replicas sharing one device, and the device's own CPU.

Large packings are made by *tiling* a jammed periodic packing of the paper size (1520 rods of 5
discs, acidic long-range forces, p = 10, made by ``prepare`` with the protocol's building blocks,
:func:`bench_dem.prepared_state`): k × k copies side by side are a periodic packing of k² × 1520
rods with the same local structure (contacts, coordination, list length), so the rates at every
size are measured on the same material. Each case is timed during a slow strain-controlled
compression (ε̇ = 1e-4, so the lists are rebuilt as on a loading path), in its own process, for
``--steps`` steps or ``--seconds`` seconds, whichever comes first, after a warm-up call that
compiles the kernels.

Usage::

    # here (CPU): the jammed 1520-rod packing the cases tile
    .venv/bin/python benchmarks/bench_gpu.py prepare --out gpu_state.npz
    # one case, one JSON line on stdout
    python benchmarks/bench_gpu.py case --state gpu_state.npz --arch gpu --tiles 64
    # the measurement of benchmarks/results/gpu_bench.md (each case in its own process, rows
    # appended to OUT/cases.jsonl as they come; a time budget skips what does not fit)
    python benchmarks/bench_gpu.py suite --state gpu_state.npz --out OUT --budget 420
    # a table of the rows
    .venv/bin/python benchmarks/bench_gpu.py table OUT/cases.jsonl
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

RATE = 1e-4  # the timed compression's strain rate (1/time), as bench_dem.py


def prepare(args: argparse.Namespace) -> None:
    """The jammed paper-size packing (CPU), saved as a gas: cell lengths, centroids, angles and
    velocities."""
    from bench_dem import prepared_state

    from dem_taichi.kernels import layout
    from dem_taichi.scene.config import load_scene

    scene = load_scene("paper").replace(integration={"steps_per_call": 500})
    state, m = prepared_state(scene, "cpu", args.pressure)
    lengths = state["cell"][[layout.C_LX, layout.C_LY]]
    np.savez(
        args.out,
        cell_lengths=lengths,
        position=(state["reduced_position"] % 1.0) * lengths,
        angle=state["angle"],
        velocity=state["velocity"],
        angular_velocity=state["angular_velocity"],
        pressure=args.pressure,
        coordination=m["coordination_number"],
        specific_volume=m["specific_volume"],
    )
    print(f"saved {args.out}: p = {m['mean_stress']:.3g}, Z = {m['coordination_number']:.2f}")


def tiled_gas(path: str, tiles: int):
    """``tiles`` × ``tiles`` copies of the saved packing side by side (a periodic packing)."""
    from dem_taichi.scene.geometry import GasState

    data = np.load(path)
    lengths = np.asarray(data["cell_lengths"], dtype=float)
    shifts = np.array([(ix, iy) for ix in range(tiles) for iy in range(tiles)], dtype=float)
    position = (data["position"][None, :, :] + (shifts * lengths)[:, None, :]).reshape(-1, 2)

    def repeat(name: str) -> np.ndarray:
        a = data[name]
        return np.concatenate([a] * tiles**2)

    return GasState(
        lengths * tiles,
        position,
        repeat("angle"),
        repeat("velocity"),
        repeat("angular_velocity"),
    )


def case(args: argparse.Namespace) -> None:
    """One timed case; prints one JSON line."""
    from dem_taichi.engine.simulation import CellControl, Simulation
    from dem_taichi.kernels import layout
    from dem_taichi.scene.config import load_scene

    gas = tiled_gas(args.state, args.tiles)
    n_rods = len(gas.angle)
    scene = load_scene("paper").replace(
        particles={"n_rods": n_rods}, integration={"steps_per_call": args.chunk}
    )
    t0 = time.perf_counter()
    sim = Simulation(
        scene,
        arch=args.arch,
        precision=args.precision,
        execution=args.execution,
        list_build=args.list_build,
        initial=gas,
    )
    t_init = time.perf_counter() - t0
    control = CellControl.strain_rate(RATE)
    t0 = time.perf_counter()
    sim.run(args.chunk, control=control, output_every=10**12)
    t_warm = time.perf_counter() - t0
    if args.start_at:  # concurrent replicas: start the timed window together
        time.sleep(max(0.0, args.start_at - time.time()))
    started = time.time()
    rebuilds0 = int(sim.a["flags"].to_numpy()[layout.F_REBUILDS])
    steps = 0
    t0 = time.perf_counter()
    while steps < args.steps and time.perf_counter() - t0 < args.seconds:
        sim.run(args.chunk, control=control, output_every=10**12)
        steps += args.chunk
    wall = time.perf_counter() - t0
    rebuilds = int(sim.a["flags"].to_numpy()[layout.F_REBUILDS]) - rebuilds0
    build_s = build_seconds(sim, layout)
    measure_times = []
    for _ in range(3):
        t1 = time.perf_counter()
        m = sim.measure()
        measure_times.append(time.perf_counter() - t1)
    row = {
        "arch": args.arch,
        "precision": args.precision,
        "execution": sim.execution,
        "list_build": sim.list_build if sim.execution != "serial" else "serial (fused)",
        "threads": os.environ.get("DEM_TAICHI_CPU_THREADS", "") if args.arch == "cpu" else "",
        "tiles": args.tiles,
        "n_rods": n_rods,
        "n_discs": sim.n_discs,
        "steps": steps,
        "wall_s": round(wall, 3),
        "steps_per_s": round(steps / wall, 1),
        "disc_steps_per_s": round(steps * sim.n_discs / wall),
        "rebuild_every_steps": round(steps / max(rebuilds, 1), 1),
        "build_ms": round(build_s * 1e3, 3),
        # sim.measure() (the protocol's servo measures every servo_check_steps = 100 steps, and
        # so does every run call of the timed window)
        "measure_ms": round(float(np.median(measure_times)) * 1e3, 2),
        # a loading path rebuilds every ~10²–10³ steps; the slow timed compression rarely does
        "steps_per_s_build_every_100": round(1.0 / (wall / steps + build_s / 100), 1),
        "init_s": round(t_init, 2),
        "warm_s": round(t_warm, 2),
        "coordination": round(m["coordination_number"], 3),
        "mean_stress": round(m["mean_stress"], 4),
        "started": round(started, 2),
        "ended": round(time.time(), 2),
        "label": args.label,
    }
    print(json.dumps(row), flush=True)


def build_seconds(sim, layout, repeats: int = 5) -> float:
    """The cost of one list build: the median time of a step with a forced build less that of
    a step without (each one step, synchronised by the host's read of the flags)."""

    def step_time(force: bool) -> float:
        times = []
        for _ in range(repeats):
            if force:
                flags = sim.a["flags"].to_numpy()
                flags[layout.F_FORCE_REBUILD] = 1
                sim.a["flags"].from_numpy(flags)
            t0 = time.perf_counter()
            sim._advance(1)
            times.append(time.perf_counter() - t0)
        return float(np.median(times))

    step_time(True)  # compile anything the forced build needs
    return max(step_time(True) - step_time(False), 0.0)


def _case_command(args: argparse.Namespace, **options) -> list[str]:
    command = [sys.executable, __file__, "case", "--state", args.state]
    for key, value in options.items():
        command += [f"--{key.replace('_', '-')}", str(value)]
    return command


def _record(out: Path, row: dict) -> None:
    with (out / "cases.jsonl").open("a") as stream:
        stream.write(json.dumps(row) + "\n")
    print(json.dumps(row), flush=True)


def _run_case(args, out: Path, timeout: float, env=None, **options) -> None:
    command = _case_command(args, **options)
    t0 = time.perf_counter()
    try:
        done = subprocess.run(
            command, capture_output=True, text=True, timeout=timeout, env=env, check=False
        )
    except subprocess.TimeoutExpired:
        _record(out, {**options, "error": f"timed out after {timeout:.0f} s"})
        return
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode != 0 or not lines:
        tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
        _record(out, {**options, "error": f"rc {done.returncode}: {' | '.join(tail)}"})
        return
    row = json.loads(lines[-1])
    row["process_s"] = round(time.perf_counter() - t0, 1)
    _record(out, row)


def _concurrent(args, out: Path, processes: int, arch: str, seconds: float, lead: float) -> None:
    """``processes`` replicas of the 1520-rod case at once, timed over the same window."""
    import shutil

    # each process reads its own copy of the kernel cache (filled by the earlier cases): Taichi
    # processes sharing one cache folder can read a kernel another is writing (tests/conftest.py)
    default_cache = Path.home() / ".cache/taichi/ticache"
    cache = Path(os.environ.get("TI_OFFLINE_CACHE_FILE_PATH", default_cache))
    envs = []
    for k in range(processes):
        env = {**os.environ}
        if arch == "cpu":
            env["DEM_TAICHI_CPU_THREADS"] = "1"
        copy = Path(f"/tmp/bench_gpu_cache/{arch}{k}")
        if cache.is_dir() and not copy.exists():
            shutil.copytree(cache, copy)
        env["TI_OFFLINE_CACHE_FILE_PATH"] = str(copy)
        envs.append(env)
    start_at = time.time() + lead
    options = dict(arch=arch, tiles=1, steps=10**9, seconds=seconds, start_at=start_at)
    options["label"] = f"concurrent {processes}"
    procs = [
        subprocess.Popen(
            _case_command(args, **options),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=envs[k],
        )  # fmt: skip
        for k in range(processes)
    ]
    rows, errors = [], []
    for proc in procs:
        try:
            stdout, stderr = proc.communicate(timeout=lead + seconds + 120)
        except subprocess.TimeoutExpired:
            proc.kill()
            errors.append("timed out")
            continue
        lines = [line for line in stdout.splitlines() if line.startswith("{")]
        if lines:
            rows.append(json.loads(lines[-1]))
        else:
            errors.append(" | ".join(stderr.strip().splitlines()[-2:]))
    late = sum(1 for r in rows if r["started"] > start_at + 1.0)
    summary = {
        "label": f"concurrent {processes}",
        "arch": arch,
        "processes": processes,
        "finished": len(rows),
        "late_starts": late,
        "steps_per_s_each": [r["steps_per_s"] for r in rows],
        "steps_per_s_total": round(sum(r["steps_per_s"] for r in rows), 1),
        "n_rods": 1520,
        "error": errors[0] if errors else "",
    }
    _record(out, summary)


def suite(args: argparse.Namespace) -> None:
    """The measurement of gpu_bench.md, in order of priority, within ``--budget`` seconds."""
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()

    def left() -> float:
        return args.budget - (time.perf_counter() - t_start)

    gpu: dict[str, Any] = dict(arch=args.arch, steps=args.steps, seconds=args.seconds)
    # a case's options (one process), or "concurrent N arch" (N replicas at once)
    plan: list[dict[str, Any] | str] = [
        # the serial against the parallel list build, by size (k × k tiles of 1520 rods)
        dict(gpu, tiles=1, list_build="parallel"),
        dict(gpu, tiles=1, list_build="serial"),
        dict(gpu, tiles=2, list_build="parallel"),
        dict(gpu, tiles=4, list_build="parallel"),
        dict(gpu, tiles=4, list_build="serial"),
        dict(gpu, tiles=9, list_build="parallel"),
        # the device's own CPU: the fused serial step at the paper size (one thread)
        dict(arch="cpu", tiles=1, steps=args.steps, seconds=args.seconds),
        "concurrent 8 gpu",
        "concurrent 14 cpu",
        # precision and determinism at ≥ 10⁵ rods; larger and intermediate packings
        dict(gpu, tiles=9, list_build="parallel", precision="f32"),
        dict(gpu, tiles=9, list_build="parallel", execution="gather"),
        dict(gpu, tiles=18, list_build="parallel"),
        dict(gpu, tiles=2, list_build="serial"),
        dict(gpu, tiles=8, list_build="parallel"),
        "concurrent 4 gpu",
        dict(gpu, tiles=9, list_build="serial"),
    ]
    if args.plan == "rerun":  # the parallel path after a kernel change, by size
        plan = [dict(gpu, tiles=k, list_build="parallel") for k in (1, 2, 4, 8, 9, 18)]
        plan += [
            dict(gpu, tiles=9, list_build="parallel", execution="gather"),
            dict(gpu, tiles=9, list_build="parallel", precision="f32"),
            "concurrent 8 gpu",
            dict(gpu, tiles=36, list_build="parallel"),
        ]
    for options in plan:
        if isinstance(options, str):
            _, processes, arch = options.split()
            if left() < args.seconds + 60:
                _record(out, {"label": options, "error": "skipped: out of the time budget"})
                continue
            arch = args.arch if arch == "gpu" else arch
            _concurrent(args, out, int(processes), arch, args.seconds, lead=35.0)
            continue
        timeout = min(args.case_timeout, left())
        if timeout < 30:
            _record(out, {**options, "error": "skipped: out of the time budget"})
            continue
        _run_case(args, out, timeout, **options)


def table(args: argparse.Namespace) -> None:
    """The rows of a ``cases.jsonl`` as a markdown table."""
    keys = ["label", "arch", "precision", "execution", "list_build", "n_rods", "steps",
            "steps_per_s", "disc_steps_per_s", "rebuild_every_steps", "build_ms", "measure_ms",
            "steps_per_s_build_every_100", "init_s", "warm_s", "coordination", "processes",
            "steps_per_s_total", "error"]  # fmt: skip
    rows = [json.loads(line) for line in Path(args.file).read_text().splitlines() if line]
    used = [k for k in keys if any(k in r for r in rows)]
    print("| " + " | ".join(used) + " |")
    print("|" + "---|" * len(used))
    for r in rows:
        print("| " + " | ".join(str(r.get(k, "")) for k in used) + " |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("prepare", help="the jammed paper-size packing (CPU)")
    p.add_argument("--out", required=True)
    p.add_argument("--pressure", type=float, default=10.0)
    p = sub.add_parser("case", help="one timed case (one JSON line)")
    p.add_argument("--state", required=True)
    p.add_argument("--arch", default="gpu", choices=("cpu", "gpu"))
    p.add_argument("--precision", default="f64", choices=("f64", "f32"))
    p.add_argument("--execution", default="auto", choices=("auto", "serial", "parallel", "gather"))
    p.add_argument("--list-build", default=None, choices=("serial", "parallel"))
    p.add_argument("--tiles", type=int, default=1, help="k: k × k copies of the packing")
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--chunk", type=int, default=100, help="steps per run call")
    p.add_argument("--start-at", type=float, default=0.0, help="epoch of the timed window")
    p.add_argument("--label", default="")
    p = sub.add_parser("suite", help="the measurement of gpu_bench.md")
    p.add_argument("--state", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--budget", type=float, default=420.0, help="seconds for the whole suite")
    p.add_argument("--arch", default="gpu", choices=("cpu", "gpu"), help="cpu: a dry run")
    p.add_argument("--plan", default="full", choices=("full", "rerun"))
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--case-timeout", type=float, default=75.0)
    p = sub.add_parser("table", help="a markdown table of a cases.jsonl")
    p.add_argument("file")
    args = parser.parse_args()
    {"prepare": prepare, "case": case, "suite": suite, "table": table}[args.command](args)


if __name__ == "__main__":
    main()
