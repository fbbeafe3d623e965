"""Relax a saved state at a multiple of its time step and watch for a period-two oscillation.

Usage::

    python benchmarks/period_two_relax.py CHECKPOINT.npz [--factor 2] [--steps 400000]

Loads the checkpoint (any ``save_checkpoint`` file: a run's ``state_<label>.npz``, a pairing's
``seedN.state_A.npz``), sets Δt to ``--factor`` × the checkpoint's, relaxes at fixed cell (the
scene's relaxation, as ``quasistatic.relax`` does, without its stop) and prints, every 10,000
steps, the unbalanced-force ratio, the kinetic energy per rod (full-step velocities, blind to a
period-two mode) and the bodies caught in a period-two oscillation with their share of the
unbalanced force (:func:`dem_taichi.engine.failures.period_two_bodies`). It stops once UFR < 1e-4.
Results: ``benchmarks/results/period_two.md``.
"""

from __future__ import annotations

import argparse
import time


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoint")
    parser.add_argument("--factor", type=float, default=1.0)
    parser.add_argument("--steps", type=int, default=400_000)
    parser.add_argument("--every", type=int, default=10_000)
    args = parser.parse_args(argv)

    from dem_taichi.engine.simulation import CellControl, Simulation

    sim = Simulation.from_checkpoint(args.checkpoint)
    sim.set_parameters(time_step=sim.time_step * args.factor)
    control = CellControl.relaxation("relax")
    start, steps = time.perf_counter(), 0
    print("steps  time  UFR  KE/rod  period-two bodies  their share of sum|F|  seconds")
    while steps < args.steps:
        measures = sim.run(args.every, control, output_every=args.every)
        steps += args.every
        ufr = measures["unbalanced_force_ratio"]
        found = sim.period_two()
        print(
            f"{steps} {steps * sim.time_step:.1f} {ufr:.3g} "
            f"{measures['kinetic_energy'] / sim.n_rods:.3g} {found.bodies.size} "
            f"{found.share:.4f} {time.perf_counter() - start:.0f}",
            flush=True,
        )
        if ufr < 1e-4:
            break
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
