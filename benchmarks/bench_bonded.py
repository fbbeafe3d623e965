"""Bonded against rigid rods (issue 10, not a test): cost per step, time step, and stability.

Both models run on the *same* packing: the paper scene (1520 rods of 5 discs, acidic long range)
jammed at p = ``--pressure`` by the protocol's building blocks with rigid rods
(``bench_dem.prepared_state``); the bonded simulation starts from the same rods, each disc a body
(straight chains in their reference state), and is relaxed briefly at fixed cell. Each is then
timed during a slow strain-controlled compression (ε̇ = 1e-4, as in bench_dem), serial.

Rows: rigid, bonded, and each with rolling resistance at the contacts (``+rolling``: the
study's clay drivers' MercuryDPM values, k_r = 2/5 k_n and μ_r = μ, ``ROLLING``; the rolling
springs start unloaded on the same packing).

Columns: steps/s and disc-steps/s; the time step Δt each model allows (dt_safety × the stiffest
of the contact duration and the chain's bond period, ``Scene.time_step``); simulated time per
CPU-second (what a protocol pays: the cost of the bonded model relative to the rigid one is the
ratio of that column; CPU time of the single-threaded serial process, so that other jobs on the
machine change it less than the wall time). ``--stability``: the largest stable dt_safety of
the bonded model (300 rods, jammed, 20 000 steps at fixed cell per value; as
``bench_dem.py --stability``); ``--rolling``: the same with rolling resistance.

Usage::

    .venv/bin/python benchmarks/bench_bonded.py              # paper size, serial
    .venv/bin/python benchmarks/bench_bonded.py --stability  # dt_safety limit of bonded rods
    .venv/bin/python benchmarks/bench_bonded.py --stability --rolling  # ... with rolling resistance

Writes benchmarks/results/bonded_bench.csv (or bonded_stability.csv) and prints the table.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_dem import prepared_state, time_case  # noqa: E402

from dem_taichi.engine.simulation import BlowUpError, CellControl, Simulation  # noqa: E402
from dem_taichi.scene.config import load_scene  # noqa: E402
from dem_taichi.scene.geometry import GasState  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"


def rolling(scene):
    """The scene with rolling resistance: k_r = 2/5 k_n, μ_r = μ (MercuryDPM's clay drivers,
    ClayParticlesArianna.cpp)."""
    c = scene.contact
    return scene.replace(contact={"rolling_stiffness": 0.4 * c.k_n, "rolling_friction": c.mu})


def bonded_state(scene, rigid_state, arch, relax_steps=4000):
    """The bonded simulation's state on the rigid packing ``rigid_state``: every rod's discs as
    bodies at rest, relaxed ``relax_steps`` at fixed cell (the chains give way where the rigid
    rods carried moments: p falls, e.g. 10 -> 3.6 on the 300-rod packing)."""
    lengths = rigid_state["cell"][:2].astype(float)
    reduced = rigid_state["reduced_position"].astype(float)
    n = reduced.shape[0]
    gas = GasState(lengths, np.mod(reduced, 1.0) * lengths, rigid_state["angle"].astype(float),
                   np.zeros((n, 2)), np.zeros(n))  # fmt: skip
    sim = Simulation(scene, arch=arch, initial=gas)
    sim.run(relax_steps, control=CellControl.fixed(), output_every=relax_steps)
    return sim.get_state(), sim.measure()


def speed(args):
    rigid_scene = load_scene("paper")
    bonded_scene = load_scene("paper_bonded")
    state, measures = prepared_state(rigid_scene, args.arch, args.pressure)
    print(f"prepared: p = {measures['mean_stress']:.4g}, v = {measures['specific_volume']:.4f}")
    b_state, b_measures = bonded_state(bonded_scene, state, args.arch)
    print(f"bonded start: p = {b_measures['mean_stress']:.4g}, UFR = "
          f"{b_measures['unbalanced_force_ratio']:.3g}")  # fmt: skip
    rows = []
    cases = (
        ("rigid", rigid_scene, state),
        ("bonded", bonded_scene, b_state),
        ("rigid+rolling", rolling(rigid_scene), state),
        ("bonded+rolling", rolling(bonded_scene), b_state),
    )
    for name, scene, start in cases:
        case = time_case(scene, args.arch, "serial", False, start, args.steps)
        dt = scene.time_step
        rows.append(
            {
                "rod_model": name,
                "bodies": case["sim"].n_bodies,
                "discs": case["sim"].n_discs,
                "dt": dt,
                "dt_over_t_c": dt / scene.contact_duration,
                "steps_per_s": round(case["steps_per_s"], 1),
                "steps_per_s_best_window": round(case["steps_per_s_best_window"], 1),
                "steps_per_cpu_s": round(case["steps_per_cpu_s"], 1),
                "disc_steps_per_s": round(case["disc_steps_per_s"]),
                "simulated_time_per_cpu_s": case["steps_per_cpu_s"] * dt,
                "n_contacts": case["n_contacts"],
                "load_average": round(case["load_average"], 2),
            }
        )
        print(rows[-1], flush=True)
    rigid, bonded = rows[:2]
    for row in rows:
        # per CPU-second of the single-threaded serial process: robust to other jobs' load
        row["cost_per_step_vs_rigid"] = round(rigid["steps_per_cpu_s"] / row["steps_per_cpu_s"], 3)
        row["cost_per_time_vs_rigid"] = round(
            rigid["simulated_time_per_cpu_s"] / row["simulated_time_per_cpu_s"], 3
        )
    header = (
        f"# bench_bonded.py: paper scene (1520 rods x 5 discs, acidic), jammed at p = "
        f"{args.pressure}, {args.steps} steps at strain rate 1e-4, serial, {args.arch}"
    )
    _write(RESULTS / "bonded_bench.csv", rows, header)
    for row in rows[1:]:
        print(f"{row['rod_model']} costs {row['cost_per_step_vs_rigid']}x rigid per step, "
              f"{row['cost_per_time_vs_rigid']}x per simulated time")  # fmt: skip


def stability(args):
    """Largest stable dt_safety of bonded rods: jammed packings at p = pressure, 20 000 steps at
    fixed cell per value (dt_safety relative to the stiffest of t_c and the bond period)."""
    rows = []
    rigid_scene = load_scene("paper").replace(particles={"n_rods": 300})
    state, _ = prepared_state(rigid_scene, args.arch, args.pressure)
    for bending in (0.3, 1.0):
        scene = load_scene("paper_bonded").replace(
            particles={"n_rods": 300}, bonds={"bending": bending}
        )
        if args.rolling:
            scene = rolling(scene)
        start, start_measures = bonded_state(scene, state, args.arch)
        p_start = start_measures["mean_stress"]
        base = min(scene.contact_duration, scene.bond_period, scene.rolling_period)
        for safety in (0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5):
            sim = Simulation(scene, arch=args.arch)
            sim.set_state(start)
            sim.set_parameters(time_step=safety * base)
            outcome = "stable"
            t0 = time.perf_counter()
            try:
                m = sim.run(20_000, control=CellControl.fixed(), output_every=20_000)
                if abs(m["mean_stress"] / p_start - 1) > 0.1:
                    outcome = f"drifted p = {m['mean_stress']:.3g} from {p_start:.3g}"
            except BlowUpError as error:
                outcome = "blow-up: " + str(error).split(":")[0]
            wall = round(time.perf_counter() - t0, 1)
            rows.append({"bending": bending, "dt_safety": safety, "outcome": outcome,
                         "p_start": round(p_start, 4), "wall_s": wall})  # fmt: skip
            print(rows[-1], flush=True)
    suffix = "_rolling" if args.rolling else ""
    with_rolling = " with rolling resistance (k_r = 2/5 k_n, μ_r = μ)" if args.rolling else ""
    _write(RESULTS / f"bonded_stability{suffix}.csv", rows,
           f"# bench_bonded.py --stability: 300 bonded rods of 5 discs (acidic){with_rolling}, "
           f"jammed at p = {args.pressure}, 20000 steps at fixed cell per dt_safety")  # fmt: skip


def _write(path, rows, header):
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as stream:
        stream.write(header + "\n")
        writer = csv.DictWriter(stream, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print(f"written {path}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--arch", default="cpu", choices=("cpu", "gpu"))
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--pressure", type=float, default=10.0)
    parser.add_argument("--stability", action="store_true", help="measure the dt_safety limit")
    parser.add_argument("--rolling", action="store_true", help="with --stability: rolling on")
    args = parser.parse_args()
    if args.stability:
        stability(args)
    else:
        speed(args)


if __name__ == "__main__":
    main()
