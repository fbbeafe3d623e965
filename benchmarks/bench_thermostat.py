"""The ageing thermostat's cost per check (issue 20, not a test): the velocities written alone
(:meth:`Simulation.set_velocities`, since 2026-12-05) against the full state round trip the
thermostats made before (``get_state``, the velocities replaced, ``set_state``).

An ageing of ``--checks`` checks of ``--steps`` steps each (the scenes' ``relax_check_steps``
is 500), each followed by the resampling thermostat's draw, is run twice from the same gas: once
as shipped, once with the draws written through a full restore. The script prints the seconds
per draw of each, the seconds of the whole ageing, and whether the two states reached are the
same bit for bit (they must be: the change only removes copies).

Usage::

    .venv/bin/python benchmarks/bench_thermostat.py [--scene study] [--checks 40] [--steps 500]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/ is not a package
from bench_checkpoint import state_hash  # noqa: E402

from dem_taichi import Simulation  # noqa: E402
from dem_taichi.protocol.aggregation import hold  # noqa: E402
from dem_taichi.protocol.quasistatic import resample_speed  # noqa: E402


def _full_restore(sim, velocity, angular_velocity) -> None:
    state = sim.get_state()
    state["velocity"], state["angular_velocity"] = velocity, angular_velocity
    sim.set_state(state)


def age(scene: str, checks: int, steps: int, full_restore: bool) -> tuple[str, float, float]:
    """(state hash, seconds of the ageing, seconds of the draws) of one ageing from the gas."""
    sim = Simulation(scene)
    if full_restore:
        sim.set_velocities = lambda v, w: _full_restore(sim, v, w)
    sim.run(1000)
    draws = 0.0
    start = time.perf_counter()
    for _ in range(checks):
        hold(sim, "aggregation", steps)
        t0 = time.perf_counter()
        resample_speed(sim, 0.5, sim.scene.scene.seed)
        draws += time.perf_counter() - t0
    return state_hash(sim.get_state()), time.perf_counter() - start, draws


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="study", help="scene name (default study)")
    parser.add_argument("--checks", type=int, default=40, help="checks (default 40)")
    parser.add_argument("--steps", type=int, default=500, help="steps per check (default 500)")
    args = parser.parse_args(argv)
    rows = {}
    for name, full in (("full state round trip (before)", True), ("velocities alone", False)):
        rows[name] = age(args.scene, args.checks, args.steps, full)
        digest, wall, draws = rows[name]
        print(
            f"{name}: {1e3 * draws / args.checks:.2f} ms per draw, ageing {wall:.2f} s "
            f"({args.checks} checks of {args.steps} steps), state {digest}"
        )
    same = len({digest for digest, _, _ in rows.values()}) == 1
    print(f"the same state bit for bit: {same}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
