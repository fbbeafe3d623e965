"""The ageing of a bonded scene's gas as rigid rods: ``[protocol] aggregation_rod_model =
"rigid"`` (issue 20).

The aggregation stage (:mod:`dem_taichi.protocol.aggregation`) is most of a bonded run's steps
(60 % of the bonded study cell's, ``benchmarks/results/study_clay_bonded_stiffness.md``): it is a
long hold of a dilute gas at the bonded scene's Δt, which the bonds' own period sets (at k_n 3e5:
Δt 2.8e-4, against 6.2e-4 for the contacts alone), with n_s bodies per rod. With this key the
compression of the gas and its ageing run instead on a *rigid twin*: the same rods, discs,
contacts, attraction, thermostat and seed, integrated as rigid bodies at the rigid scene's Δt
(:attr:`dem_taichi.scene.config.Scene.time_step`) with one body per rod. The thermostat's check
interval is kept in time (``relax_check_steps`` steps of the *bonded* Δt), and the ``"rods"``
thermostat draws exactly the rod motions on both (:mod:`dem_taichi.protocol.rod_thermostat`).

At the end of the ageing the rods are handed back (:func:`hand_over`): each becomes a straight
bonded chain moving as its rigid rod did (:func:`dem_taichi.scene.geometry.bodies_from_rods`),
at the twin's step and time. The discs are numbered alike (rod-major) and sit where they sat,
so each contact keeps its geometry: its tangential and rolling springs are carried over
(``[protocol] aggregation_springs = "kept"``, the default) or set to zero ("reset", what the
first measurements used); the normal forces are recomputed from the same overlaps.
The compression to A and every path after it run on bonded rods. What the ageing gives up is the
rods' bending while they age: in the gas the thermostat leaves the bonds without kinetic energy
at every draw, so they bend only under contact and attraction forces.

Measured (``benchmarks/results/ageing_rigid_rods.md``, the bonded study cell KB300 at 300 rods,
three seeds): the ageing takes 0.14 of its bonded time and the isotropic run 0.31, but the
material differs: K0 at C higher on every seed (+0.12 ± 0.16), λ* on the mapped window −0.013 ±
0.044; Z at the end of the ageing −0.07 ± 0.09 (springs reset). With the springs kept, from the
same gels (``ageing_rigid_springs.md``): λ* higher on every seed (+0.021 ± 0.024 against the
reset), K0 at C scattered (0.47–0.77 against the bonded ageing's 0.54–0.59). A rigid-aged bonded
run is a preparation of its own, not a cheaper way to the bonded one.

Pure set-up and hand-over; the stage itself is :func:`dem_taichi.protocol.aggregation.aggregate`.
"""

from __future__ import annotations

from typing import Any

from dem_taichi.engine.simulation import Simulation
from dem_taichi.physics.bonds import unwrapped_chains
from dem_taichi.scene.geometry import GasState, rods_from_bodies

__all__ = ["rigid_twin", "hand_over"]


def rigid_twin(sim: Simulation) -> Simulation:
    """A simulation of ``sim``'s rods as rigid rods: the scene with ``[particles] rod_model =
    "rigid"``, its rods the rigid-body fit of ``sim``'s chains (:func:`~dem_taichi.scene.
    geometry.rods_from_bodies`), at ``sim``'s step, time and strain reference, on the same
    architecture, precision and execution, adding its work to ``sim``'s ledger."""
    if not sim.bonded:
        raise ValueError("a rigid twin is made of bonded rods; this simulation's are rigid")
    scene = sim.scene.replace(particles={"rod_model": "rigid"})
    state = sim.get_state()
    discs = unwrapped_chains(sim.body_positions(), sim.geometry.n_spheres, sim.cell_lengths)
    gas = rods_from_bodies(
        discs, state["velocity"], state["angular_velocity"], sim.geometry, sim.cell_lengths
    )
    twin = Simulation(
        scene,
        arch=sim.arch,
        precision=sim.precision,
        deterministic=sim.deterministic,
        execution=sim.execution,
        initial=gas,
    )
    twin.step = sim.step
    twin.reference_lengths = sim.reference_lengths.copy()
    twin.state_io.set_time(sim.time)
    twin.work = sim.work
    return twin


def hand_over(twin: Simulation, sim: Simulation, springs: str = "kept") -> dict[str, Any]:
    """Load the twin's rods into the bonded ``sim`` as straight chains (module docstring) and add
    the twin's timings to ``sim``'s; returns what the hand-over found (the mean stress and the
    coordination before, on the rigid rods, and after). ``springs``: "kept" carries the
    tangential and rolling springs of the twin's contacts to the same disc pairs (the twin's
    discs are numbered as the chains' bodies, rod-major, and sit where they sat); "reset" starts
    them from zero (``[protocol] aggregation_springs``)."""
    if springs not in ("kept", "reset"):
        raise ValueError(f"springs = {springs!r}: allowed values are kept | reset")
    state = twin.get_state()
    before = twin.measure()
    gas = GasState(
        twin.cell_lengths.astype(float),
        twin.rod_positions().astype(float),
        twin.rod_angles().astype(float),
        state["velocity"].astype(float),
        state["angular_velocity"].astype(float),
    )
    sim.load_gas(gas, twin.step, twin.time, contacts=state if springs == "kept" else None)
    after = sim.measure()
    for key, seconds in twin.timings.items():
        sim.timings[key] = sim.timings.get(key, 0.0) + seconds
    sim.n_rebuild_calls += twin.n_rebuild_calls
    return {
        "handover_step": int(twin.step),
        "handover_mean_stress_rigid": float(before["mean_stress"]),
        "handover_mean_stress": float(after["mean_stress"]),
        "handover_coordination_number_rigid": float(before["coordination_number"]),
        "handover_coordination_number": float(after["coordination_number"]),
        "handover_springs": springs,
    }
