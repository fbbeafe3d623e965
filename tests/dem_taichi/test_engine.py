"""Engine behaviour: measures, stress, fabric, control, state/checkpoint, determinism, failures."""

import math

import numpy as np
import pytest

from dem_taichi.engine.simulation import AxisControl, BlowUpError, CellControl, Simulation
from dem_taichi.engine.state import states_equal
from dem_taichi.io.schema import HISTORY
from dem_taichi.kernels import layout
from dem_taichi.scene.config import load_scene, scene_from_toml
from dem_taichi.scene.geometry import GasState


@pytest.fixture(scope="module")
def smoke():
    return load_scene("smoke")


@pytest.fixture(scope="module")
def packed_state(smoke):
    """A smoke-scene packing compressed into contact (state dict + scene)."""
    sim = Simulation(smoke)
    sim.run(4000, control=CellControl.strain_rate(0.12, stage="isotropic_to_A"))
    return sim.get_state()


def test_measure_names_are_the_history_schema(smoke):
    sim = Simulation(smoke)
    m = sim.measure()
    assert set(m) <= set(HISTORY)
    assert set(HISTORY) - set(m) == set()
    assert m["specific_volume"] == pytest.approx(1.0 / smoke.particles.initial_area_fraction)
    assert m["strain_xx"] == 0.0
    assert math.isnan(m["inertial_number"])  # p = 0 in the gas


def test_measures_record_declares_every_history_variable_with_its_type(smoke):
    """Measures (the typed dict of measure()) has exactly the history variables; the engine
    fills each with a value of the declared type."""
    import typing

    from dem_taichi.engine.measures import BondedMeasures, Measures
    from dem_taichi.io.history_schema import BONDED_HISTORY_VARIABLES

    hints = typing.get_type_hints(BondedMeasures)
    bonded = {var.name for var in BONDED_HISTORY_VARIABLES}
    assert set(typing.get_type_hints(Measures)) == set(HISTORY)
    assert set(BondedMeasures.__optional_keys__) == bonded
    m = Simulation(smoke).run(10, CellControl.strain_rate(0.1))
    assert set(m) == set(HISTORY)
    scene = smoke.replace(particles={"rod_model": "bonded"})
    mb = Simulation(scene).run(10, CellControl.strain_rate(0.1))
    assert set(mb) == set(HISTORY) | bonded
    for name, kind in hints.items():
        assert type(mb[name]) is kind, (name, type(mb[name]))
        if name in m:
            assert type(m[name]) is kind, (name, type(m[name]))


def test_strain_control_follows_the_prescribed_logarithmic_strain(smoke):
    sim = Simulation(smoke)
    m = sim.run(1000, control=CellControl.strain_rate(0.05, 0.1))
    t = 1000 * smoke.time_step
    assert m["strain_xx"] == pytest.approx(0.05 * t, rel=1e-9)
    assert m["strain_yy"] == pytest.approx(0.1 * t, rel=1e-9)
    assert m["strain_rate_yy"] == 0.1
    assert m["time"] == pytest.approx(t, rel=1e-12)


def test_fabric_of_a_known_orientation_set_is_exact():
    scene = scene_from_toml("[particles]\nn_rods = 4\nn_spheres = 3")
    angles = np.array([0.0, math.pi / 2, math.pi / 6, math.pi / 3])
    positions = np.array([[5.0, 5.0], [15.0, 5.0], [5.0, 15.0], [15.0, 15.0]])
    gas = GasState(np.array([20.0, 20.0]), positions, angles, np.zeros((4, 2)), np.zeros(4))
    m = Simulation(scene, initial=gas).measure()
    c, s = np.cos(angles), np.sin(angles)
    assert m["fabric_xx"] == pytest.approx(np.mean(c * c), abs=1e-15)
    assert m["fabric_yy"] == pytest.approx(np.mean(s * s), abs=1e-15)
    assert m["fabric_xy"] == pytest.approx(np.mean(c * s), abs=1e-15)
    # 0, 90, 30, 60 degrees: cos² = 1, 0, 3/4, 1/4 -> β_xx = 1/2 exactly, deviator 0
    assert m["fabric_xx"] + m["fabric_yy"] == pytest.approx(1.0, abs=1e-15)
    assert m["fabric_deviator"] == pytest.approx(0.0, abs=1e-15)


def static_energy(scene, lengths, position, angle):
    gas = GasState(np.asarray(lengths, float), position % lengths, angle, 0 * position, 0 * angle)
    m = Simulation(scene, initial=gas).measure()
    return m["contact_energy"] + m["long_range_energy"]


@pytest.mark.parametrize("long_range", [False, True])
def test_stress_from_forces_equals_the_virtual_work_stress(smoke, packed_state, long_range):
    """σ_aa = −(L_a/A) ∂U/∂L_a under an affine stretch of the centroids (angles fixed)."""
    scene = smoke.replace(
        contact={"friction": False}, long_range={"enabled": long_range, "pattern": "acidic"}
    )
    lengths = packed_state["cell"][[layout.C_LX, layout.C_LY]]
    position = (packed_state["reduced_position"] % 1.0) * lengths
    angle = packed_state["angle"]
    gas = GasState(lengths, position, angle, 0 * position, 0 * angle)
    sim = Simulation(scene, initial=gas)
    assert sim.measure()["n_contacts"] > 10
    stress = sim.stress()
    h = 1e-6
    for axis in (0, 1):
        scale = np.ones(2)
        scale[axis] = 1 + h
        up = static_energy(scene, lengths * scale, position * scale, angle)
        scale[axis] = 1 - h
        down = static_energy(scene, lengths * scale, position * scale, angle)
        d_energy = (up - down) / (2 * h * lengths[axis])
        virtual_work = -lengths[axis] * d_energy / np.prod(lengths)
        assert stress[axis, axis] == pytest.approx(virtual_work, rel=1e-5)


def test_the_engine_controls_strain_rates_only():
    """The engine's own stress servo is gone (issue 9): stresses are held by the protocol's
    (tested on the engine in test_protocol.py::test_protocol_servo_holds_targets_on_the_engine)."""
    assert not hasattr(CellControl, "stress")
    with pytest.raises(ValueError, match="StressServo"):
        AxisControl("stress", 30.0)
    assert CellControl.strain_rate(0.1, 0.2).rates.tolist() == [0.1, 0.2]


def test_checkpoint_resume_is_exact(tmp_path, smoke, packed_state):
    sim = Simulation(smoke)
    sim.set_state(packed_state)
    control = CellControl.strain_rate(0.02)
    sim.run(300, control=control)
    path = sim.save_checkpoint(tmp_path / "checkpoint_000000000300.npz")
    sim.run(700, control=control)
    resumed = Simulation.from_checkpoint(path)
    assert resumed.step == 300 + packed_state["step"]
    resumed.run(700, control=control)
    assert states_equal(sim.get_state(), resumed.get_state())


def test_get_state_set_state_replays_bit_for_bit(smoke, packed_state):
    sim = Simulation(smoke)
    sim.set_state(packed_state)
    sim.run(500)
    first = sim.get_state()
    sim.set_state(packed_state)
    sim.run(500)
    assert states_equal(first, sim.get_state())


def test_deterministic_mode_is_bitwise_reproducible(smoke):
    states = []
    for _ in range(2):
        sim = Simulation(smoke, deterministic=True)
        sim.run(1500, control=CellControl.strain_rate(0.1))
        states.append(sim.get_state())
    assert states_equal(*states)


def test_parallel_gather_mode_is_bitwise_reproducible(smoke, packed_state):
    states = []
    for _ in range(2):
        sim = Simulation(smoke, execution="gather")
        assert sim.full_list
        sim.set_state(packed_state)  # a half-list state: converted to the full list
        sim.run(300, control=CellControl.strain_rate(0.05))
        states.append(sim.get_state())
    assert states_equal(*states)
    back = Simulation(smoke)
    back.set_state(states[0])  # and back to the half list
    assert back.measure()["n_contacts"] == sim.measure()["n_contacts"]


@pytest.mark.parametrize("execution", ["parallel", "gather"])
def test_parallel_execution_agrees_with_serial(smoke, packed_state, execution):
    lengths = packed_state["cell"][[layout.C_LX, layout.C_LY]]
    gas = GasState(lengths, (packed_state["reduced_position"] % 1) * lengths,
                   packed_state["angle"], packed_state["velocity"],
                   packed_state["angular_velocity"])  # fmt: skip
    results = {}
    for mode in ("serial", execution):
        sim = Simulation(smoke, execution=mode, initial=gas)
        sim.run(200, control=CellControl.strain_rate(0.01))
        results[mode] = (sim.get_state(), sim.measure())
    a, b = results["serial"][0], results[execution][0]
    ma, mb = results["serial"][1], results[execution][1]
    assert mb["n_contacts"] == ma["n_contacts"]
    assert mb["mean_stress"] == pytest.approx(ma["mean_stress"], rel=1e-6, abs=1e-9)
    assert mb["contact_energy"] == pytest.approx(ma["contact_energy"], rel=1e-6, abs=1e-12)
    scale = np.abs(a["force"]).max()
    # forces summed in another order: round-off differences only over 200 steps
    np.testing.assert_allclose(a["reduced_position"], b["reduced_position"], atol=1e-9)
    np.testing.assert_allclose(a["force"], b["force"], atol=1e-6 * scale)


def test_capacity_grows_without_dropping_pairs(smoke, packed_state):
    sim = Simulation(smoke)
    sim.set_state(packed_state)
    sim.run(200)
    lengths = packed_state["cell"][[layout.C_LX, layout.C_LY]]
    gas = GasState(lengths, (packed_state["reduced_position"] % 1) * lengths,
                   packed_state["angle"], packed_state["velocity"],
                   packed_state["angular_velocity"])  # fmt: skip
    small = Simulation(smoke, initial=gas, neighbour_capacity=1)
    assert small.capacity > 1
    big = Simulation(smoke, initial=gas, neighbour_capacity=64)
    small.run(300)
    big.run(300)
    a, b = small.get_state(), big.get_state()
    for key in ("reduced_position", "angle", "velocity", "force"):
        assert np.array_equal(a[key], b[key]), key


def test_snapshot_lists_every_interacting_pair_once(smoke, packed_state):
    sim = Simulation(smoke)
    sim.set_state(packed_state)
    snap = sim.snapshot()
    m = sim.measure()
    pairs = set(zip(snap.pair_i.tolist(), snap.pair_j.tolist(), strict=True))
    assert len(pairs) == snap.n_pairs
    assert snap.n_pairs >= m["n_contacts"]
    assert np.all(snap.rod_position >= 0) and np.all(snap.rod_position < snap.cell_lengths)
    # the minimum-image pair vector is recovered from the wrapped positions and the shift
    x = (
        snap.rod_position[:, None, :]
        + sim.geometry.offsets[None, :, None]
        * np.stack([np.cos(snap.rod_angle), np.sin(snap.rod_angle)], axis=1)[:, None, :]
    )
    x = x.reshape(-1, 2)
    r = x[snap.pair_i] - x[snap.pair_j] - snap.pair_shift
    assert np.linalg.norm(r, axis=1).max() < sim.cutoff + 1e-9


def test_non_finite_state_is_reported_with_the_fix(smoke):
    sim = Simulation(smoke)
    state = sim.get_state()
    state["velocity"][3, 0] = np.nan
    sim.set_state(state)
    with pytest.raises(
        BlowUpError, match=r"non-finite .* rod 3 .*reduce \[integration\] dt_safety"
    ):
        sim.run(10)


def test_overlap_blow_up_is_reported_with_the_fix(smoke, packed_state):
    # k_t within the leapfrog bound of the soft k_n (the default 2e4 is refused with k_n 300)
    scene = smoke.replace(contact={"k_n": 300.0, "k_t": 60.0, "e_n": 0.5})
    sim = Simulation(scene)
    sim.set_state(packed_state)
    sim.set_parameters(k_n=300.0)
    with pytest.raises(BlowUpError, match=r"overlap beyond the bound .*dt_safety from 0.15 to <="):
        sim.run(20000, control=CellControl.strain_rate(0.5))


def test_runaway_kinetic_energy_is_reported(smoke):
    scene = smoke.replace(integration={"max_kinetic_energy_per_rod": 1e-6})
    sim = Simulation(scene)
    with pytest.raises(BlowUpError, match="runaway kinetic energy"):
        sim.run(100)


def test_runtime_parameters_do_not_need_a_new_simulation(smoke, packed_state):
    sim = Simulation(smoke)
    sim.set_state(packed_state)
    sim.set_parameters(mu=0.1, local_damping=0.5)
    assert sim.get_parameter("mu") == 0.1
    sim.run(100)
    with pytest.raises(ValueError, match="unknown parameter"):
        sim.set_parameters(stiffness=1.0)


def test_runtime_parameters_are_the_one_source_for_snapshot_and_time_step(smoke, packed_state):
    """The snapshot (linear-response probes) and the protocol's Δt read the parameters the
    kernels integrate with, not the scene (issue 9: k_n came from the parameters but μ from the
    scene; Δt from the scene in the protocol)."""
    from dem_taichi.protocol.quasistatic import apply_strain

    sim = Simulation(smoke)
    sim.set_state(packed_state)
    assert sim.time_step == smoke.time_step and sim.snapshot().mu == smoke.contact.mu
    sim.set_parameters(mu=0.1, k_n=2.0e5, time_step=0.5 * smoke.time_step)
    snap = sim.snapshot()
    assert (snap.mu, snap.k_n) == (0.1, 2.0e5)
    assert sim.time_step == 0.5 * smoke.time_step
    before = sim.step
    apply_strain(sim, (1e-4, 0.0), "other", max_rate=1e-2, min_steps=1)
    assert sim.step - before == math.ceil(1e-4 / (1e-2 * sim.time_step))
