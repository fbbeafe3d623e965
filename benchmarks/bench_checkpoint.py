"""Steps per second of the engine from a saved state, with a hash of the state reached (not a
test): a kernel change is measured on the states a protocol really visits, and the hash says
whether it left the trajectory bit for bit the same.

Loads a checkpoint (a run's ``state_A.npz``, ``state_B.npz``, ``resume/*.npz``; any file of
:func:`dem_taichi.io.checkpoint.save_checkpoint`) with the scene stored in it, runs ``--steps``
steps (after 100 to compile) at the strain rate ``--rate`` on both axes (0: the cell fixed), in
five windows, and prints the mean and best steps per second and per CPU-second and the SHA-256
(first 16 hex digits) of every array of the final state. Run it from two trees on the same
file to compare them: the same hash means the same state bit for bit (``--ignore-key KEY`` leaves
out a state key the other tree does not have). ``--set
section.key=value`` changes the stored scene (e.g. ``integration.execution=gather``) and
``--threads N`` caps Taichi's CPU threads, to compare execution layouts on one state.

Usage::

    .venv/bin/python benchmarks/bench_checkpoint.py RUN/state_B.npz --steps 2000 --rate 1e-4
    PYTHONPATH=/path/to/other/tree python /path/to/other/tree/benchmarks/bench_checkpoint.py ...
"""

from __future__ import annotations

import argparse
import hashlib
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dem_taichi.engine.control import AxisControl, CellControl  # noqa: E402
from dem_taichi.engine.simulation import Simulation  # noqa: E402
from dem_taichi.io.checkpoint import load_checkpoint  # noqa: E402
from dem_taichi.scene.config import scene_from_toml, scene_with_overrides  # noqa: E402


def state_hash(state: dict, ignore: tuple[str, ...] = ()) -> str:
    """SHA-256 (16 hex digits) over every array of a state dict, in key order, but the keys in
    ``ignore`` (to compare with a tree whose state has no such key)."""
    digest = hashlib.sha256()
    for key in sorted(state):
        if key in ignore:
            continue
        value = state[key]
        if isinstance(value, np.ndarray):
            digest.update(key.encode())
            digest.update(np.ascontiguousarray(value).tobytes())
    return digest.hexdigest()[:16]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoint", type=Path)
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--rate", type=float, default=1e-4, help="strain rate of both axes")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    parser.add_argument("--threads", type=int, default=None, help="Taichi's CPU threads")
    parser.add_argument(
        "--ignore-key",
        action="append",
        default=[],
        metavar="KEY",
        help="leave this state key out of the hash (a key the other tree's state lacks)",
    )
    args = parser.parse_args()
    state, meta = load_checkpoint(args.checkpoint)
    scene = scene_with_overrides(scene_from_toml(meta["scene_toml"]), args.set)
    if args.threads:  # read when the engine initialises Taichi
        os.environ["DEM_TAICHI_CPU_THREADS"] = str(args.threads)
    sim = Simulation(scene)
    sim.set_state(state)
    rate = AxisControl("strain_rate", args.rate)
    control = CellControl(rate, rate, "other")
    sim.run(100, control=control, output_every=100)  # compile
    window = max(args.steps // 5, 1)
    best = 0.0
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(5):
        start = time.perf_counter()
        sim.run(window, control=control, output_every=window)
        best = max(best, window / (time.perf_counter() - start))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    n = 5 * window
    reached = state_hash(sim.get_state(), tuple(args.ignore_key))
    print(
        f"{args.checkpoint} {' '.join(args.set)}: {sim.n_bodies} bodies, {n} steps: "
        f"{n / wall:.0f} steps/s "
        f"(best window {best:.0f}, {n / cpu:.0f} per CPU-s); state {reached}"
    )


if __name__ == "__main__":
    main()
