"""The rods' rigid-body thermostat of the aggregation stage, ``[protocol] aggregation_thermostat =
"rods"`` (:mod:`dem_taichi.protocol.rod_thermostat`).

The pure numpy functions on made-up rods (the rigid-body field, zero momentum, equipartition over
20,000 rods); on the ``smoke_bonded`` scene (40 rods of 5 discs, every disc a body): one draw
leaves every bond with zero stretch, shear and bending rates and gives the rods the drawn
centre-of-mass motions; the stage is deterministic and a run resumed from a checkpoint draws what
the uninterrupted one drew; on rigid rods "rods" is "resample" bit for bit; the scene loader
accepts the value and names it among the allowed ones.
"""

from __future__ import annotations

import dataclasses
from types import MappingProxyType

import numpy as np
import pytest

from dem_taichi.protocol.rod_thermostat import draw_rod_motion, rigid_disc_velocities, rod_frames
from dem_taichi.scene.config import SceneError, load_scene, scene_from_toml
from dem_taichi.scene.probing_sections import ProbingConfig
from dem_taichi.scene.protocol_sections import protocol_settings
from tests.dem_taichi.test_aggregation import attractive_scene, run_stage

#: resample_speed's stream tag, which "rods" shares
STREAM = 0x41474754


def bent_rods(n_rods: int, chain: int, rng: np.random.Generator) -> np.ndarray:
    """Contiguous disc centres (n_rods, chain, 2) of randomly placed, turned and bent rods (each
    bond of length ~1 turned a little from the last)."""
    start = rng.uniform(0.0, 50.0, size=(n_rods, 1, 2))
    heading = rng.uniform(-np.pi, np.pi, size=(n_rods, 1)) + np.cumsum(
        rng.normal(0.0, 0.2, size=(n_rods, chain - 1)), axis=1
    )
    length = rng.normal(1.0, 0.02, size=(n_rods, chain - 1))
    steps = length[..., None] * np.stack([np.cos(heading), np.sin(heading)], axis=-1)
    return np.concatenate([start, start + np.cumsum(steps, axis=1)], axis=1)


def bonded_scene(**protocol):
    """The smoke_bonded scene with the given ``[protocol]`` keys (no probes)."""
    base = load_scene("smoke_bonded")
    config = dataclasses.replace(protocol_settings(base), **protocol)
    extensions = {"protocol": config, "probing": ProbingConfig(enabled=False)}
    return dataclasses.replace(base, extensions=MappingProxyType(extensions), source_text="")


# -- the pure functions -------------------------------------------------------------------------
def test_discs_get_the_rigid_body_field_of_their_rod():
    """v_i = V + Ω × (x_i − X) = V + Ω (−(y_i − Y), x_i − X) written out disc by disc, ω_i = Ω;
    the rod's mean disc velocity is V (X the mean of the discs); every pair of discs of a rod
    has zero relative velocity along the line joining them (a rigid motion stretches nothing)."""
    rng = np.random.default_rng(5)
    discs = bent_rods(7, 5, rng)
    centre, inertia = rod_frames(discs, 1.0, 0.125)
    velocity = rng.normal(size=(7, 2))
    omega = rng.normal(size=7)
    v, w = rigid_disc_velocities(discs, centre, velocity, omega)
    assert v.shape == (35, 2) and w.shape == (35,)
    for r in range(7):
        for s in range(5):
            dx, dy = discs[r, s] - centre[r]
            want = velocity[r] + omega[r] * np.array([-dy, dx])
            np.testing.assert_allclose(v[5 * r + s], want, rtol=0, atol=1e-14)
            assert w[5 * r + s] == omega[r]
    np.testing.assert_allclose(v.reshape(7, 5, 2).mean(axis=1), velocity, atol=1e-14)
    np.testing.assert_allclose(centre, discs.mean(axis=1), atol=0)
    rel_v = v.reshape(7, 5, 1, 2) - v.reshape(7, 1, 5, 2)
    rel_x = discs[:, :, None, :] - discs[:, None, :, :]
    assert np.abs(np.sum(rel_v * rel_x, axis=-1)).max() < 1e-13
    # I = Σ m |x − X|² + n_s I_disc: a straight rod of 5 unit discs at spacing 1 has the rigid
    # rod's (4 + 1 + 0 + 1 + 4) + 5/8
    straight = np.stack([np.arange(5.0), np.zeros(5)], axis=-1)[None]
    assert rod_frames(straight, 1.0, 0.125)[1][0] == pytest.approx(10.625, rel=1e-15)


def test_draw_has_zero_momentum_and_equipartition_over_many_rods():
    """20,000 bent rods of 5 discs at speed 0.3: the discs' total momentum is zero; per rod
    <½ M V_x²>, <½ M V_y²> and <½ I Ω²> are ½ M s² within 3 standard errors (a wrong spin
    scale, e.g. speed² without M/I, is ~4 standard errors per per cent off); the discs'
    kinetic energy is the rods' ½ M V² + ½ I Ω², nothing in the rods' insides."""
    n, chain, m, i_disc, speed = 20_000, 5, 1.0, 0.125, 0.3
    rng = np.random.default_rng(17)
    discs = bent_rods(n, chain, rng)
    centre, inertia = rod_frames(discs, m, i_disc)
    mass = chain * m
    velocity, omega = draw_rod_motion(np.random.default_rng(23), n, speed, mass, inertia)
    v, w = rigid_disc_velocities(discs, centre, velocity, omega)
    np.testing.assert_allclose((m * v).sum(axis=0), 0.0, atol=1e-9)
    np.testing.assert_allclose(velocity.sum(axis=0), 0.0, atol=1e-10)
    target = 0.5 * mass * speed**2
    for energy in (
        0.5 * mass * velocity[:, 0] ** 2,
        0.5 * mass * velocity[:, 1] ** 2,
        0.5 * inertia * omega**2,
    ):
        error = energy.std(ddof=1) / np.sqrt(n)
        assert abs(energy.mean() - target) < 3 * error, (energy.mean(), target, error)
    discs_energy = 0.5 * m * np.sum(v * v) + 0.5 * i_disc * np.sum(w * w)
    rods_energy = 0.5 * mass * np.sum(velocity**2) + 0.5 * np.sum(inertia * omega**2)
    assert discs_energy == pytest.approx(rods_energy, rel=1e-12)


def test_draw_is_resample_speeds_order_and_scale():
    """V ~ N(0, s²) with the mean removed, then Ω ~ N(0, s² M/I): the numbers of one
    generator in resample_speed's order (so a rigid rod's draw is resample_speed's)."""
    inertia = np.array([10.0, 12.0, 9.0])
    velocity, omega = draw_rod_motion(np.random.default_rng(4), 3, 0.5, 5.0, inertia)
    rng = np.random.default_rng(4)
    want = rng.normal(0.0, 0.5, size=(3, 2))
    want -= want.mean(axis=0, keepdims=True)
    np.testing.assert_array_equal(velocity, want)
    np.testing.assert_array_equal(omega, rng.normal(0.0, 0.5 * np.sqrt(5.0 / inertia), size=3))


# -- on bonded rods -----------------------------------------------------------------------------
def test_one_draw_on_bonded_rods_moves_every_rod_rigidly():
    """smoke_bonded after a disc-by-disc draw and 300 steps (the rods bent, their bonds
    vibrating): one draw of "rods" leaves every bond with zero stretch, shear and bending rates
    (the dashpots of the bond law exert nothing) and the rods' centres of mass the motion drawn
    with PCG64 (seed, resample's tag, step) — also across the cell's edges (unwrapped chains);
    the momentum is zero."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.physics.bonds import bond_forces, chain_bonds, unwrapped_chains
    from dem_taichi.protocol.quasistatic import hold, resample_speed
    from dem_taichi.protocol.rod_thermostat import rod_speed

    sim = Simulation(load_scene("smoke_bonded"))
    resample_speed(sim, 0.3, 3)  # every disc on its own: the bonds heated
    hold(sim, "other", 300)
    lengths = sim.cell_lengths
    positions = sim.body_positions()
    g = chain_bonds(sim.n_rods, 5)
    before = sim.get_state()
    bond = sim.scene.bond_parameters  # the scene's bond law, dashpots included
    damped = bond_forces(
        positions, before["angle"], g, lengths, bond, before["velocity"],
        before["angular_velocity"],
    )  # fmt: skip
    elastic = bond_forces(positions, before["angle"], g, lengths, bond)
    assert np.abs(damped.force_h - elastic.force_h).max() > 1e-3  # the bonds vibrated
    crossing = np.abs(np.diff(positions.reshape(-1, 5, 2), axis=1)).max(axis=(1, 2)) > 2.0
    assert crossing.any()  # some rod lies across the cell's edge

    rms = rod_speed(sim, 0.3, 7)
    after = sim.get_state()
    assert rms == pytest.approx(np.sqrt(np.mean(before["velocity"] ** 2)), rel=1e-12)
    v, w = after["velocity"], after["angular_velocity"]
    d = positions[g + 1] - positions[g]
    d -= np.round(d / lengths) * lengths
    stretch_rate = np.sum((v[g + 1] - v[g]) * d, axis=1) / np.linalg.norm(d, axis=1)
    assert np.abs(stretch_rate).max() < 1e-13
    assert np.abs(w[g + 1] - w[g]).max() == 0.0  # bending rate
    damped = bond_forces(positions, after["angle"], g, lengths, bond, v, w)
    np.testing.assert_allclose(damped.force_h, elastic.force_h, rtol=0, atol=1e-9)
    np.testing.assert_allclose(damped.torque_h, elastic.torque_h, rtol=0, atol=1e-9)
    # the rods' motions are the draw written out
    discs = unwrapped_chains(positions, 5, lengths)
    centre = discs.mean(axis=1)
    arm = discs - centre[:, None, :]
    inertia = np.sum(arm * arm, axis=(1, 2)) + 5 * sim.body.inertia
    rng = np.random.Generator(np.random.PCG64([7, STREAM, sim.step]))
    drawn = rng.normal(0.0, 0.3, size=(sim.n_rods, 2))
    drawn -= drawn.mean(axis=0, keepdims=True)
    spin = rng.normal(0.0, 0.3 * np.sqrt(5.0 / inertia), size=sim.n_rods)
    np.testing.assert_allclose(v.reshape(-1, 5, 2).mean(axis=1), drawn, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(w.reshape(-1, 5), np.repeat(spin[:, None], 5, axis=1))
    np.testing.assert_allclose(v.sum(axis=0), 0.0, atol=1e-12)


def test_stage_with_rods_on_bonded_rods_is_deterministic_and_thermostatted(monkeypatch):
    """The ageing of smoke_bonded with "rods" (0.6 time units, 3 checks): two runs end in the
    same state bit for bit with the same records; the thermostat is called at the start and
    after every check but the last; the stage records it."""
    import dem_taichi.protocol.aggregation as stage_module
    from dem_taichi.engine.state import states_equal

    calls: list[int] = []
    original = stage_module.rod_speed

    def counting(sim, speed, seed):
        calls.append(sim.step)
        return original(sim, speed, seed)

    monkeypatch.setattr(stage_module, "rod_speed", counting)
    scene = bonded_scene(
        aggregation="time", aggregation_time=0.6, aggregation_speed=0.2,
        aggregation_thermostat="rods", relax_check_steps=400,
    )  # fmt: skip
    first, details_1, records_1 = run_stage(scene)
    assert details_1["thermostat"] == "rods"
    checks = -(-details_1["aging_steps"] // 400)
    assert calls == [400 * k for k in range(checks)] and checks >= 3
    second, details_2, records_2 = run_stage(scene)
    assert states_equal(first.sim.get_state(), second.sim.get_state())
    assert details_1 == details_2
    assert [r["kinetic_energy"] for r in records_1] == [r["kinetic_energy"] for r in records_2]


def test_a_run_resumed_from_a_checkpoint_draws_what_the_uninterrupted_one_drew(tmp_path):
    """smoke_bonded: thermostat, 200 steps, checkpoint, thermostat, 200 steps, thermostat;
    the same from the checkpoint in a new simulation ends in the same state bit for bit (the
    draw is seeded by the seed and the step, and reads only the state)."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.engine.state import states_equal
    from dem_taichi.protocol.quasistatic import hold
    from dem_taichi.protocol.rod_thermostat import rod_speed

    def rest(sim):
        rod_speed(sim, 0.2, 1)
        hold(sim, "aggregation", 200)
        rod_speed(sim, 0.2, 1)
        return sim.get_state()

    sim = Simulation(load_scene("smoke_bonded"))
    rod_speed(sim, 0.2, 1)
    hold(sim, "aggregation", 200)
    path = sim.save_checkpoint(tmp_path / "mid.npz")
    uninterrupted = rest(sim)
    resumed = rest(Simulation.from_checkpoint(path))
    assert states_equal(uninterrupted, resumed)


# -- on rigid rods: "resample" itself -----------------------------------------------------------
def test_rods_on_rigid_rods_is_resample_bit_for_bit():
    """On rigid rods rod_speed is resample_speed (same numbers), and the ageing stage with
    "rods" ends in the state, with the records, of the stage with "resample"."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.engine.state import states_equal
    from dem_taichi.protocol.quasistatic import resample_speed
    from dem_taichi.protocol.rod_thermostat import rod_speed

    sim = Simulation(attractive_scene())
    start = sim.get_state()
    assert rod_speed(sim, 0.3, 7) == resample_speed(Simulation(attractive_scene()), 0.3, 7)
    by_rods = sim.get_state()
    sim.set_state(start)
    resample_speed(sim, 0.3, 7)
    assert states_equal(by_rods, sim.get_state())
    keys = {"aggregation": "time", "aggregation_time": 3.0, "aggregation_speed": 0.25}
    rods, details_rods, records_rods = run_stage(
        attractive_scene(aggregation_thermostat="rods", **keys)
    )
    resample, details_resample, records_resample = run_stage(
        attractive_scene(aggregation_thermostat="resample", **keys)
    )
    assert states_equal(rods.sim.get_state(), resample.sim.get_state())
    assert details_rods.pop("thermostat") == "rods"
    assert details_resample.pop("thermostat") == "resample"
    assert details_rods == details_resample
    assert [r["kinetic_energy"] for r in records_rods] == [
        r["kinetic_energy"] for r in records_resample
    ]


# -- the key ------------------------------------------------------------------------------------
@pytest.mark.parametrize("model", ["rigid", "bonded"])
def test_the_scene_loader_accepts_rods_for_either_rod_model(model):
    scene = scene_from_toml(
        f'[particles]\nrod_model = "{model}"\n[protocol]\naggregation = "time"\n'
        'aggregation_time = 1.0\naggregation_speed = 0.2\naggregation_thermostat = "rods"\n'
    )
    assert protocol_settings(scene).aggregation_thermostat == "rods"


def test_a_bad_thermostat_names_the_key_and_every_allowed_value():
    with pytest.raises(SceneError) as info:
        scene_from_toml(
            '[protocol]\naggregation = "time"\naggregation_time = 1.0\n'
            'aggregation_speed = 0.1\naggregation_thermostat = "rod"\n'
        )
    message = str(info.value)
    assert "\n" not in message and "aggregation_thermostat" in message
    assert "resample | rescale | langevin | clusters | rods" in message
