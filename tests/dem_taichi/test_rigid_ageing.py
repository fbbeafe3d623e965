"""A bonded scene's gas aged as rigid rods: ``[protocol] aggregation_rod_model = "rigid"``
(:mod:`dem_taichi.protocol.rigid_ageing`, issue 20).

The rigid-body fit of chains (:func:`dem_taichi.scene.geometry.rods_from_bodies`) against
:func:`~dem_taichi.scene.geometry.bodies_from_rods` and against momentum conservation; the
hand-over of rigid rods to bonded chains (:meth:`Simulation.load_gas`); the stage on the smoke
scene made attractive and bonded (tests/dem_taichi/test_aggregation.py's scene): its steps at
the rigid Δt, its thermostat at the same times as on bonded rods, a straight, contact-keeping
hand-over, determinism, the compression to A after it; the keys' checks and the cost estimate.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from dem_taichi.physics.bonds import unwrapped_chains
from dem_taichi.scene.config import SceneError, scene_from_toml
from dem_taichi.scene.geometry import GasState, bodies_from_rods, rod_geometry, rods_from_bodies
from tests.dem_taichi.test_aggregation import attractive_scene, run_stage

AGEING = dict(
    aggregation="time",
    aggregation_time=3.0,
    aggregation_area_fraction=0.2,
    aggregation_speed=0.2,
    aggregation_thermostat="rods",
)


def bonded(scene):
    """``scene`` with bonded rods."""
    return dataclasses.replace(
        scene, particles=dataclasses.replace(scene.particles, rod_model="bonded")
    )


def random_rods(n: int, lengths: np.ndarray, seed: int = 3) -> GasState:
    rng = np.random.default_rng(seed)
    return GasState(
        lengths,
        rng.uniform(0.0, 1.0, (n, 2)) * lengths,
        rng.uniform(-math.pi, math.pi, n),
        rng.normal(0.0, 1.0, (n, 2)),
        rng.normal(0.0, 1.0, n),
    )


# -- the rigid-body fit -----------------------------------------------------------------------
def test_rods_from_bodies_inverts_bodies_from_rods_across_the_periodic_cell():
    """Rods at random places (many crossing the cell's edges), angles and motions: their discs
    (bodies_from_rods, wrapped into the cell) fitted back give the same rods to rounding."""
    geometry = rod_geometry(attractive_scene())
    lengths = np.array([9.0, 7.5])
    rods = random_rods(200, lengths)
    discs = bodies_from_rods(rods, geometry)
    chain = geometry.n_spheres
    back = rods_from_bodies(
        unwrapped_chains(discs.position, chain, lengths),
        discs.velocity,
        discs.angular_velocity,
        geometry,
        lengths,
    )
    crossing = np.ptp(discs.position.reshape(-1, chain, 2)[..., 0], axis=1) > 0.5 * lengths[0]
    assert crossing.sum() > 5  # the test does cross the edges
    gap = np.mod(back.position - rods.position + 0.5 * lengths, lengths) - 0.5 * lengths
    np.testing.assert_allclose(gap, 0.0, atol=1e-12)
    turn = np.mod(back.angle - rods.angle + math.pi, 2 * math.pi) - math.pi
    np.testing.assert_allclose(turn, 0.0, atol=1e-12)
    np.testing.assert_allclose(back.velocity, rods.velocity, atol=1e-12)
    np.testing.assert_allclose(back.angular_velocity, rods.angular_velocity, atol=1e-12)
    assert np.all((back.position >= 0.0) & (back.position < lengths))


def test_rods_from_bodies_keeps_the_momentum_and_angular_momentum_of_bent_chains():
    """Bent chains with arbitrary disc motions: the fitted rods carry the chains' momentum
    (M V = Σ m v_i) and angular momentum about their centre (I Ω = Σ m (x_i − X) × v_i +
    I_d Σ ω_i, with I the bent chain's own)."""
    geometry = rod_geometry(attractive_scene())
    n, chain, m = 30, geometry.n_spheres, geometry.disc_mass
    rng = np.random.default_rng(8)
    straight = bodies_from_rods(random_rods(n, np.array([50.0, 50.0])), geometry)
    discs = straight.position.reshape(n, chain, 2) + rng.normal(0.0, 0.05, (n, chain, 2))
    velocity = rng.normal(0.0, 1.0, (n * chain, 2))
    spin = rng.normal(0.0, 1.0, n * chain)
    rods = rods_from_bodies(discs, velocity, spin, geometry, np.array([50.0, 50.0]))
    v = velocity.reshape(n, chain, 2)
    np.testing.assert_allclose(chain * m * rods.velocity, m * v.sum(axis=1), rtol=1e-12)
    centre = discs.mean(axis=1)
    arm = discs - centre[:, None, :]
    disc_inertia = m * geometry.diameter**2 / 8
    momentum = m * np.sum(arm[..., 0] * v[..., 1] - arm[..., 1] * v[..., 0], axis=1)
    momentum += disc_inertia * spin.reshape(n, chain).sum(axis=1)
    inertia = m * np.sum(arm**2, axis=(1, 2)) + chain * disc_inertia
    np.testing.assert_allclose(inertia * rods.angular_velocity, momentum, rtol=1e-10)


def test_rods_from_bodies_refuses_chains_of_another_length():
    geometry = rod_geometry(attractive_scene())
    with pytest.raises(ValueError, match="chains of 3 discs do not fit rods of"):
        rods_from_bodies(np.zeros((2, 3, 2)), np.zeros((6, 2)), np.zeros(6), geometry, [9, 9])


# -- the hand-over ----------------------------------------------------------------------------
def test_load_gas_puts_rigid_rods_into_a_bonded_simulation_as_straight_chains():
    """A rigid simulation's aged rods loaded into a bonded one (:meth:`Simulation.load_gas`):
    the same disc centres and contacts, straight bonds at rest, its step and time, the bonded
    Δt and strain reference kept, the tangential springs at zero ("reset")."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.protocol.rigid_ageing import hand_over

    scene = attractive_scene(**AGEING)
    rigid, _, _ = run_stage(scene)
    twin = rigid.sim
    sim = Simulation(bonded(scene))
    dt, reference = sim.time_step, sim.reference_lengths.copy()
    found = hand_over(twin, sim, springs="reset")
    assert found["handover_springs"] == "reset"
    np.testing.assert_allclose(
        sim.disc_positions() % sim.cell_lengths, twin.disc_positions() % twin.cell_lengths,
        atol=1e-12,
    )  # fmt: skip
    after = sim.measure()
    assert after["coordination_number"] == found["handover_coordination_number"]
    assert found["handover_coordination_number"] == twin.measure()["coordination_number"] > 0
    assert after["bond_energy"] < 1e-20
    assert sim.step == twin.step and sim.time == pytest.approx(twin.time, rel=1e-15)
    assert sim.time_step == dt and np.array_equal(sim.reference_lengths, reference)
    assert not np.any(sim.get_state()["tangential_spring"])
    np.testing.assert_allclose(sim.cell_lengths, twin.cell_lengths, rtol=1e-15)


def springs_by_pair(state: dict) -> dict[tuple[int, int], tuple[float, float]]:
    """(i, j) → (ξ, ψ) of every list entry of a state dict whose springs are not both zero."""
    from dem_taichi.kernels.layout import IMAGE_CODES

    out = {}
    for i, count in enumerate(state["neighbour_count"]):
        for k in range(count):
            xi = float(state["tangential_spring"][i, k])
            rolling = state["rolling_spring"]
            psi = float(rolling[i, k]) if rolling.shape[0] > 1 else 0.0
            if xi != 0.0 or psi != 0.0:
                out[(i, int(state["neighbours"][i, k]) // IMAGE_CODES)] = (xi, psi)
    return out


def test_the_hand_over_keeps_every_contact_spring_on_its_disc_pair():
    """With the springs kept (the default), each contact of the aged twin has, after the
    hand-over, its tangential and rolling springs on the same disc pair of the bonded chains,
    bit for bit, whatever image and list slot it sits in; and the first steps after it follow."""
    from dem_taichi.engine.control import CellControl
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.protocol.rigid_ageing import hand_over

    scene = attractive_scene(**AGEING).replace(
        contact={"rolling_stiffness": 2.0e3, "rolling_friction": 0.5}
    )
    rigid, _, _ = run_stage(scene)
    twin = rigid.sim
    before = springs_by_pair(twin.get_state())
    assert len(before) >= 3  # the aged gel has loaded contacts ...
    assert any(psi != 0.0 for _, psi in before.values())  # ... rolling springs among them
    sim = Simulation(bonded(scene))
    found = hand_over(twin, sim)
    assert found["handover_springs"] == "kept"
    after = springs_by_pair(sim.get_state())
    assert after == before
    assert found["handover_coordination_number"] == found["handover_coordination_number_rigid"]
    sim.run(50, control=CellControl.fixed())  # the carried list is a working list


def test_load_gas_refuses_contacts_of_another_size():
    from dem_taichi.engine.simulation import Simulation

    sim = Simulation(bonded(attractive_scene()))
    state = sim.get_state()
    gas = GasState(
        sim.cell_lengths, sim.body_positions(), state["angle"], state["velocity"],
        state["angular_velocity"],
    )  # fmt: skip
    lists = ("neighbour", "tangential", "rolling")
    contacts = {k: v[:-1] for k, v in state.items() if k.startswith(lists)}
    with pytest.raises(ValueError, match="contacts of .* discs do not fit this simulation"):
        sim.load_gas(gas, 0, 0.0, contacts=contacts)


def test_load_gas_refuses_a_gas_of_another_size():
    from dem_taichi.engine.simulation import Simulation

    sim = Simulation(bonded(attractive_scene()))
    gas = random_rods(3, sim.cell_lengths)
    with pytest.raises(ValueError, match="gas of 3 bodies does not fit this scene"):
        sim.load_gas(gas, 0, 0.0)


# -- the stage --------------------------------------------------------------------------------
def test_the_stage_ages_a_rigid_twin_at_its_time_step_with_the_thermostat_at_the_same_times():
    """Bonded rods aged as rigid: the ageing covers the same time in the rigid Δt's steps, the
    thermostat draws at the same times as on bonded rods (its interval kept in time), and the
    simulation left is the bonded one at the bonded Δt, its chains straight and its contacts
    those of the twin."""
    import dem_taichi.protocol.aggregation as stage_module

    scene = bonded(attractive_scene(**AGEING))
    twin_scene = bonded(attractive_scene(**AGEING, aggregation_rod_model="rigid"))
    draws: list[float] = []
    original = stage_module.rod_speed

    def counting(sim, speed, seed):
        draws.append(sim.time)
        return original(sim, speed, seed)

    stage_module.rod_speed = counting
    try:
        plain, details_1, _ = run_stage(scene)
        n_plain = len(draws)
        aged, details_2, records = run_stage(twin_scene)
        times_2 = draws[n_plain:]
    finally:
        stage_module.rod_speed = original
    dt_bonded = plain.sim.time_step
    dt_rigid = dataclasses.replace(
        twin_scene, particles=dataclasses.replace(twin_scene.particles, rod_model="rigid")
    ).time_step
    assert dt_rigid > 1.5 * dt_bonded  # the lever: the bonds' period sets the bonded Δt
    assert details_2["rod_model"] == "rigid" and "rod_model" not in details_1
    assert details_2["time_step_ratio"] == pytest.approx(dt_rigid / dt_bonded, rel=1e-12)
    assert details_2["aging_steps"] == math.ceil(3.0 / dt_rigid - 1e-9)
    assert details_1["aging_steps"] == math.ceil(3.0 / dt_bonded - 1e-9)
    assert abs(len(times_2) - n_plain) <= 1  # as many draws ...
    np.testing.assert_allclose(times_2[1:5], draws[1:5], atol=2 * dt_rigid)  # ... at the times
    assert aged.sim.bonded and aged.sim.time_step == dt_bonded
    assert aged.sim.step == details_2["handover_step"] == details_2["step"]
    assert details_2["handover_coordination_number"] == details_2["coordination_number"]
    assert aged.sim.measure()["bond_energy"] < 1e-20
    assert all("bond_energy" not in r or np.isnan(r["bond_energy"]) for r in records)


def test_the_stage_with_a_rigid_twin_is_deterministic_and_reaches_a():
    """Two runs of the stage on the rigid twin end in the same bonded state bit for bit (the
    springs kept, the key's default, given explicitly); the compression to A then runs on the
    bonded rods and finds A. With the springs reset the stage ends with none loaded."""
    from dem_taichi.engine.state import states_equal

    scene = bonded(attractive_scene(**AGEING, aggregation_rod_model="rigid"))
    kept = bonded(
        attractive_scene(**AGEING, aggregation_rod_model="rigid", aggregation_springs="kept")
    )
    first, details_1, _ = run_stage(scene)
    second, details_2, _ = run_stage(kept)
    assert states_equal(first.sim.get_state(), second.sim.get_state())
    assert details_1 == details_2 and details_1["handover_springs"] == "kept"
    assert np.any(first.sim.get_state()["tangential_spring"])
    reset = bonded(
        attractive_scene(**AGEING, aggregation_rod_model="rigid", aggregation_springs="reset")
    )
    third, details_3, _ = run_stage(reset)
    assert details_3["handover_springs"] == "reset"
    assert details_3["handover_coordination_number"] == details_1["handover_coordination_number"]
    assert not np.any(third.sim.get_state()["tangential_spring"])
    state_a = first.compress_to_transition()
    assert state_a.label == "A" and state_a.measures["mean_stress"] > 0
    assert first.sim.bonded and first.aggregation_details is details_1


def test_an_ageing_on_a_rigid_twin_is_saved_once_aged_with_the_bonded_state(monkeypatch):
    """The resume points of the stage (``runner.save_point``, even asked at every check): on a
    rigid twin none inside the ageing (the protocol's simulation is not the one ageing), one
    when the stage is done, holding the bonded rods after the hand-over and the details."""
    import dem_taichi.protocol.aggregation as stage_module
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.engine.state import states_equal
    from dem_taichi.protocol.paths import ProtocolRunner
    from dem_taichi.scene.probing_sections import ProbingConfig
    from dem_taichi.scene.protocol_sections import protocol_settings

    monkeypatch.setattr(stage_module, "AGEING_SAVE_SECONDS", 0.0)
    scene = bonded(attractive_scene(**AGEING, aggregation_rod_model="rigid"))
    runner = ProtocolRunner(Simulation(scene), protocol_settings(scene), ProbingConfig())
    saves: list[tuple[dict, dict]] = []
    runner.save_point = lambda progress: saves.append((progress, runner.sim.get_state()))
    details = runner.aggregate()
    assert [progress["phase"] for progress, _ in saves] == ["aged"]
    progress, state = saves[0]
    assert progress["details"] == details and progress["done"] == details["aging_steps"]
    assert states_equal(state, runner.sim.get_state()) and runner.sim.bonded


def test_rigid_on_rigid_rods_is_their_own_model():
    """``aggregation_rod_model = "rigid"`` on rigid rods changes nothing: the same state."""
    from dem_taichi.engine.state import states_equal

    plain, details_1, _ = run_stage(attractive_scene(**AGEING))
    same, details_2, _ = run_stage(attractive_scene(**AGEING, aggregation_rod_model="rigid"))
    assert states_equal(plain.sim.get_state(), same.sim.get_state())
    assert details_1 == details_2


# -- keys and cost ----------------------------------------------------------------------------
def test_the_cluster_thermostat_is_allowed_on_bonded_rods_aged_as_rigid():
    text = (
        '[particles]\nrod_model = "bonded"\n[protocol]\naggregation = "time"\n'
        'aggregation_time = 1.0\naggregation_speed = 0.1\naggregation_thermostat = "clusters"\n'
    )
    with pytest.raises(SceneError, match="aggregation_rod_model = 'rigid'"):
        scene_from_toml(text)
    scene = scene_from_toml(text + 'aggregation_rod_model = "rigid"\n')
    assert scene.extensions["protocol"].ages_rigid(scene)


def test_the_key_unset_leaves_the_scene_toml_as_before():
    from dem_taichi.scene.config import load_scene, scene_to_toml

    text = scene_to_toml(load_scene("study_demo"))
    assert "aggregation_rod_model" not in text
    key = '[protocol]\naggregation_rod_model = "rigid"\n'
    aged = scene_from_toml(text.replace("[protocol]\n", key))
    assert aged.extensions["protocol"].aggregation_rod_model == "rigid"
    again = scene_from_toml(scene_to_toml(aged))
    assert again.extensions["protocol"].aggregation_rod_model == "rigid"


def test_the_cost_estimate_counts_the_ageing_at_the_rigid_time_step_and_cost():
    """The estimate counts T/Δt_rigid ageing steps instead of T/Δt_bonded, at the rigid cost
    per step."""
    from dem_taichi.protocol.cost import estimate_cost

    keys = dict(aggregation="time", aggregation_time=50.0)
    plain = bonded(attractive_scene(**keys))
    twin = bonded(attractive_scene(**keys, aggregation_rod_model="rigid"))
    rigid_dt = dataclasses.replace(
        twin, particles=dataclasses.replace(twin.particles, rod_model="rigid")
    ).time_step
    fewer = estimate_cost(plain, "protocol").steps - estimate_cost(twin, "protocol").steps
    assert fewer == pytest.approx(50.0 / plain.time_step - 50.0 / rigid_dt, rel=1e-9)
    cheaper = estimate_cost(twin, "protocol").cpu_seconds
    assert cheaper < estimate_cost(plain, "protocol").cpu_seconds
