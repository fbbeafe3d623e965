"""Rolling resistance at inter-rod contacts (:mod:`dem_taichi.physics.rolling`, issue 10).

- scene keys validated at load, written only when set (scenes without them keep their TOML);
  the time step follows the rolling period when that is the shortest;
- two discs: the engine's couple is −κ_r ψ with ψ the integrated relative rotation, capped at
  μ_r d_eff k_n δ, and the numpy law gives the same (sign, reset on slip);
- no damping and no cap: energy conserved, rigid and bonded rods; with every dashpot on, linear
  momentum conserved and, for two free discs, angular momentum;
- the springs survive list rebuilds, the half/full list conversion (ψ changes sign), checkpoints
  (bit for bit), the parallel and gather modes and f32;
- the linearisation (stuck springs, and couples at the cap) equals finite differences of the
  reference force law. The engine's linear response against its dynamic probe, with rolling
  resistance, rigid and bonded: ``test_probing.py`` (the "+rolling" packings).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from dem_taichi.engine.simulation import Simulation
from dem_taichi.engine.state import convert_neighbour_list, states_equal
from dem_taichi.physics import forcelaw
from dem_taichi.physics.rolling import RollingParameters, rolling_moment, rolling_spring_step
from dem_taichi.response.linear import network_matrices
from dem_taichi.scene.config import SceneError, load_scene, scene_from_toml, scene_to_toml
from dem_taichi.scene.geometry import GasState

from .test_linear_response import (
    UNIT_GRADIENTS,
    build_frictionless_network,
    deform,
    generalised_forces,
)

SCENE = """
[scene]
seed = 3
[particles]
n_rods = {n_rods}
n_spheres = {n_spheres}
rod_model = "{model}"
initial_area_fraction = 0.3
initial_speed = 1.0
[contact]
k_n = 1.0e4
gamma_n = {gamma_n}
friction = {friction}
rolling_stiffness = {k_r}
rolling_friction = {mu_r}
rolling_damping = {gamma_r}
[long_range]
enabled = false
[integration]
dt_safety = {dt_safety}
local_damping = 0.0
steps_per_call = 100
"""


def rolling_scene(n_rods=40, n_spheres=3, model="rigid", gamma_n=0.0, friction="false", k_r=2e3,
                  mu_r=1e6, gamma_r=0.0, dt_safety=0.05):  # fmt: skip
    return scene_from_toml(
        SCENE.format(
            n_rods=n_rods, n_spheres=n_spheres, model=model, gamma_n=gamma_n, friction=friction,
            k_r=k_r, mu_r=mu_r, gamma_r=gamma_r, dt_safety=dt_safety,
        )
    )  # fmt: skip


def two_discs(scene, omega=(3.0, -1.0), overlap=0.02, cell=20.0):
    """Two single-disc rods (bodies) touching along x in a large empty cell."""
    x = np.array([[10.0, 10.0], [11.0 - overlap, 10.0]])
    gas = GasState(np.array([cell, cell]), x, np.zeros(2), np.zeros((2, 2)), np.array(omega))
    return Simulation(scene, initial=gas)


BOUND = """
[long_range]
enabled = true
pattern = "basic"
f_max_edge = 1.0
f_max_inner = 1.0
k_a_edge = 2.0
k_a_inner = 2.0
[van_der_waals]
enabled = true
f_max = 50.0
k = 100.0
"""


def bound_pair(model, mu_r=1e6, dt_safety=0.05, gamma_n=0.0, gamma_r=0.0):
    """Two rods held in contact by a van der Waals attraction (net −49 at contact: they never
    part), spinning against each other: single discs (rigid), or two 2-disc bonded rods side
    by side (two contacts, stuck by friction μ = 0.5 without slip)."""
    n_spheres = 1 if model == "rigid" else 2
    friction = "false" if model == "rigid" else "true"  # (else the bonded rods slide apart)
    text = SCENE.format(
        n_rods=2, n_spheres=n_spheres, model=model, gamma_n=gamma_n, friction=friction, k_r=2e3,
        mu_r=mu_r, gamma_r=gamma_r, dt_safety=dt_safety,
    ).replace("[long_range]\nenabled = false\n", BOUND)  # fmt: skip
    if model == "bonded":
        text += "[bonds]\ndamping_ratio = 0.0\n"
    scene = scene_from_toml(text)
    if model == "rigid":
        return two_discs(scene, omega=(3.0, -1.0), overlap=0.005)
    x = np.array([[10.0, 10.0], [11.0, 10.0], [10.0, 10.995], [11.0, 10.995]])
    omega = np.array([0.3, 0.3, -0.3, -0.3])  # counter-rolling: loads ψ, not ξ
    gas = GasState(np.array([20.0, 20.0]), x, np.zeros(4), np.zeros((4, 2)), omega)
    return Simulation(scene, initial=gas)


# --------------------------------------------------------------------------------------------
# scene keys, time step
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("contact", "message"),
    [
        ("rolling_stiffness = 1.0e3", "rolling_friction"),
        ("rolling_friction = 0.3", "rolling_stiffness"),
        ("rolling_damping = 1.0", "rolling_stiffness"),
        ("rolling_stiffness = -1.0", "rolling_stiffness"),
        ("rolling_stiffness = 1.0e3\nrolling_friction = -0.1", "rolling_friction"),
        ("rolling_stiffnes = 1.0", "allowed keys"),
    ],
)
def test_bad_rolling_keys_fail_at_load_naming_the_key(contact, message):
    with pytest.raises(SceneError, match=message):
        scene_from_toml(f"[contact]\n{contact}\n")


def test_rolling_keys_are_written_only_when_set_and_round_trip():
    smoke = load_scene("smoke")
    assert "rolling" not in scene_to_toml(smoke)
    assert not smoke.rolling_parameters.enabled and math.isinf(smoke.rolling_period)
    rolling = smoke.replace(contact={"rolling_stiffness": 2e4, "rolling_friction": 0.3})
    text = scene_to_toml(rolling)
    assert "rolling_stiffness = 20000.0" in text and "rolling_friction = 0.3" in text
    assert scene_from_toml(text) == rolling
    roll = rolling.rolling_parameters
    # MercuryDPM: d_eff = r = d/2; κ_r = k_r d_eff², cap μ_r d_eff per unit contact force
    assert roll == RollingParameters(stiffness=2e4 * 0.25, damping=0.0, cap=0.15)


def test_the_time_step_follows_the_rolling_period_when_it_is_shortest():
    soft = rolling_scene(model="bonded", k_r=1e3)
    stiff = rolling_scene(model="bonded", k_r=1e6)
    assert soft.rolling_period > min(soft.contact_duration, soft.bond_period)
    assert soft.time_step == pytest.approx(0.05 * min(soft.contact_duration, soft.bond_period))
    # two free discs, I = m d²/8: ω² = 2 κ_r / I = 2 (k_r/4) 8 = 4 k_r
    assert stiff.rolling_period == pytest.approx(math.pi / math.sqrt(4e6))
    assert stiff.time_step == pytest.approx(0.05 * stiff.rolling_period)
    assert stiff.time_step < soft.time_step


# --------------------------------------------------------------------------------------------
# the law: numpy and the two-disc engine run
# --------------------------------------------------------------------------------------------


def test_numpy_law_caps_the_couple_and_resets_the_spring():
    moment, spring, sliding = rolling_moment(0.01, 0.0, 100.0, 0.0, 0.5, 10.0)
    assert moment == pytest.approx(-1.0) and spring == 0.01 and not sliding
    moment, spring, sliding = rolling_moment(-0.2, 0.0, 100.0, 0.0, 0.5, 10.0)
    assert moment == pytest.approx(5.0) and sliding  # cap 0.5 × 10
    assert spring == pytest.approx(-0.05)  # reset to −M/κ
    spring, moment, _ = rolling_spring_step(0.0, 2.0, 0.1, 100.0, 1.0, 1e9, 1.0)
    assert spring == pytest.approx(0.2) and moment == pytest.approx(-20.0 - 2.0)


@pytest.mark.parametrize("mu_r", [1e6, 2e-3])
def test_two_discs_carry_the_couple_of_their_relative_rotation(mu_r):
    """Each step: ψ += (ω_1 − ω_2) Δt with the engine's half-step ω, couple −κψ on disc 1 and
    +κψ on disc 2 (no force: the normal force alone is along x), capped at μ_r d_eff k_n δ
    (the discs held together by a van der Waals attraction)."""
    sim = bound_pair("rigid", mu_r=mu_r)
    roll = sim.scene.rolling_parameters
    dt = sim.time_step
    psi = sim.get_state()["rolling_spring"][0, 0]
    assert psi == 0.0
    capped = 0
    for _ in range(60):
        sim.run(1)
        state = sim.get_state()
        omega = state["angular_velocity"].astype(float)
        x = state["reduced_position"] * sim.cell_lengths
        overlap = 1.0 - np.linalg.norm(x[1] - x[0])
        spring, moment, sliding = rolling_spring_step(
            psi, omega[0] - omega[1], dt, roll.stiffness, 0.0, roll.cap, 1e4 * overlap
        )
        psi = float(spring)
        assert state["rolling_spring"][0, 0] == pytest.approx(psi, rel=1e-9, abs=1e-15)
        assert state["torque"][0] == pytest.approx(float(moment), rel=1e-9, abs=1e-12)
        assert state["torque"][1] == pytest.approx(-float(moment), rel=1e-9, abs=1e-12)
        assert abs(state["force"][0, 1]) < 1e-9 * abs(state["force"][0, 0])
        capped += int(sliding)
    if mu_r < 1.0:
        assert capped > 10  # the cap is reached and the spring follows it
    else:
        assert capped == 0


# --------------------------------------------------------------------------------------------
# conservation
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("model", ["rigid", "bonded"])
def test_energy_is_conserved_without_damping(model):
    """Contacts that never open (a contact that opens drops its spring's energy, as the
    tangential spring's: history springs are not conservative across contact changes): the
    kinetic, contact (with ½ κ_r ψ²), long-range and bond energies sum to a constant."""
    errors = []
    for dt_safety, every in ((0.05, 100), (0.025, 200)):
        sim = bound_pair(model, dt_safety=dt_safety)
        e0 = sim.total_energy()
        k0 = sim.measure()["kinetic_energy"]
        contacts = np.count_nonzero(forcelaw.pair_forces(sim.snapshot()).in_contact)
        worst, rolling = 0.0, 0.0
        for _ in range(40):
            sim.run(every, output_every=10**9)
            worst = max(worst, abs(sim.total_energy() - e0))
            snap = sim.snapshot()
            rolling = max(rolling, forcelaw.potential_energy(snap).rolling)
            assert np.count_nonzero(forcelaw.pair_forces(snap).in_contact) == contacts
        assert rolling > 0.1 * k0  # the rolling springs store a good part of the energy
        errors.append(worst / k0)
    # a bounded leapfrog error, second order in Δt (no drift)
    assert errors[0] <= 5e-3
    assert errors[1] <= errors[0] / 3.0


def test_momentum_is_conserved_with_every_dashpot_on():
    scene = rolling_scene(gamma_n=20.0, friction="true", mu_r=0.2, gamma_r=5.0)
    sim = Simulation(scene)
    p0 = sim.get_state()["velocity"].sum(axis=0)
    sim.run(3000)
    assert np.abs(sim.get_state()["velocity"].sum(axis=0) - p0).max() <= 1e-10
    # two free discs: the couple is internal, the angular momentum is conserved
    pair = bound_pair("rigid", mu_r=2e-3, gamma_n=20.0, gamma_r=5.0)
    inertia = 1.0 / 8.0

    def angular_momentum(s):
        st = s.get_state()
        x = st["reduced_position"] * s.cell_lengths
        return float(
            np.sum(forcelaw.cross(x, st["velocity"])) + inertia * st["angular_velocity"].sum()
        )

    l0 = angular_momentum(pair)
    pair.run(200)
    assert np.count_nonzero(pair.get_state()["rolling_spring"]) == 1
    assert angular_momentum(pair) == pytest.approx(l0, rel=1e-9)


# --------------------------------------------------------------------------------------------
# state: rebuilds, list forms, checkpoints, execution modes, precision
# --------------------------------------------------------------------------------------------


def loaded_scene(**changes):
    return rolling_scene(gamma_n=20.0, friction="true", mu_r=0.2, gamma_r=5.0, **changes)


def used_springs(state):
    """Sorted ψ of the list entries in use (slots past a disc's count keep stale values)."""
    count = state["neighbour_count"]
    used = np.arange(state["rolling_spring"].shape[1])[None, :] < count[:, None]
    return np.sort(state["rolling_spring"][used])


def compress(sim, min_contacts=40):
    """Compress isotropically (fast) until the packing has ``min_contacts`` contacts."""
    from dem_taichi.engine.simulation import CellControl

    for _ in range(40):
        m = sim.run(200, CellControl.strain_rate(0.5, stage="isotropic_to_A"))
        if m["n_contacts"] >= min_contacts:
            return sim
    raise AssertionError("the packing did not form")


@pytest.fixture(scope="module", params=["rigid", "bonded"])
def dense(request):
    """(scene, state) of a compressed packing with rolling springs on about 40 contacts."""
    scene = loaded_scene(model=request.param)
    state = compress(Simulation(scene)).get_state()
    assert np.count_nonzero(state["rolling_spring"]) >= 30
    return scene, state


def test_springs_survive_list_rebuilds(dense):
    """A list rebuilt at every step carries the springs of the pairs that stay: the run is the
    same as with the usual rebuilds (to round-off; the entries' order may change)."""
    from dem_taichi.kernels import layout as L

    scene, state = dense
    usual = Simulation(scene)
    usual.set_state(state)
    usual.run(300)
    forced = Simulation(scene)
    forced.set_state(state)
    for _ in range(300):
        now = forced.get_state()
        now["flags"][L.F_FORCE_REBUILD] = 1
        forced.set_state(now)
        forced.run(1)
    a, b = usual.get_state(), forced.get_state()
    assert b["flags"][L.F_REBUILDS] - state["flags"][L.F_REBUILDS] == 300
    np.testing.assert_allclose(b["reduced_position"], a["reduced_position"], atol=1e-12)
    np.testing.assert_allclose(b["angular_velocity"], a["angular_velocity"], atol=1e-9)
    psi_a, psi_b = used_springs(a), used_springs(b)
    psi_a, psi_b = psi_a[psi_a != 0.0], psi_b[psi_b != 0.0]  # the contacts' springs
    assert psi_a.shape == psi_b.shape and psi_a.size >= 30
    np.testing.assert_allclose(psi_b, psi_a, atol=1e-12)


def test_half_and_full_lists_convert_with_the_spring_sign_flipped(dense):
    scene, half = dense
    full = convert_neighbour_list(half, True, half["neighbours"].shape[1])
    # every spring appears twice, with opposite signs
    values = used_springs(full)
    values = values[values != 0.0]
    assert values.size == 2 * np.count_nonzero(used_springs(half))
    np.testing.assert_array_equal(values, -values[::-1])
    back = convert_neighbour_list(full, False, half["neighbours"].shape[1])
    count = half["neighbour_count"]
    np.testing.assert_array_equal(back["neighbour_count"], count)
    for key in ("rolling_spring", "tangential_spring"):  # the same springs, entry by entry
        for i in range(len(count)):
            entries = slice(0, count[i])
            a = dict(zip(half["neighbours"][i, entries], half[key][i, entries], strict=True))
            b = dict(zip(back["neighbours"][i, entries], back[key][i, entries], strict=True))
            assert a == b


def test_checkpoint_resumes_bit_for_bit(dense, tmp_path):
    scene, state = dense
    sim = Simulation(scene)
    sim.set_state(state)
    sim.run(300)
    path = sim.save_checkpoint(tmp_path / "rolling.npz")
    sim.run(300)
    resumed = Simulation.from_checkpoint(path)
    assert resumed.physics.rolling
    resumed.run(300)
    assert states_equal(sim.get_state(), resumed.get_state())


@pytest.mark.parametrize("execution", ["parallel", "gather"])
def test_execution_modes_agree_with_serial(dense, execution):
    scene, state = dense
    serial = Simulation(scene, execution="serial")
    other = Simulation(scene, execution=execution)
    serial.set_state(state)
    other.set_state(state)  # the half list converted to the full one for "gather"
    serial.run(300)
    other.run(300)
    a, b = serial.get_state(), other.get_state()
    np.testing.assert_allclose(b["reduced_position"], a["reduced_position"], atol=1e-9)
    np.testing.assert_allclose(b["angular_velocity"], a["angular_velocity"], atol=1e-6)
    # back to the serial mode: the same springs (as a set: the entries' order may differ)
    serial.set_state(b)
    psi_a, psi_b = used_springs(a), used_springs(serial.get_state())
    psi_a, psi_b = psi_a[psi_a != 0.0], psi_b[psi_b != 0.0]
    np.testing.assert_allclose(psi_b, psi_a, rtol=1e-6, atol=1e-12)


def test_single_precision_follows_double():
    scene = loaded_scene()
    m64 = compress(Simulation(scene, precision="f64"), 20).measure()
    f32 = compress(Simulation(scene, precision="f32"), 20)  # (a precision change re-inits)
    m32 = f32.measure()
    assert f32.get_state()["rolling_spring"].dtype == np.float32
    assert np.count_nonzero(f32.get_state()["rolling_spring"]) >= 10
    assert m32["specific_volume"] == pytest.approx(m64["specific_volume"], rel=1e-4)
    assert m32["mean_stress"] == pytest.approx(m64["mean_stress"], rel=0.1)


def test_scenes_without_rolling_pay_no_memory_and_refuse_rolling_states():
    plain = Simulation(rolling_scene(k_r=0.0, mu_r=0.0))
    assert not plain.physics.rolling
    assert plain.get_state()["rolling_spring"].shape == (1, plain.capacity)
    rolling = compress(Simulation(loaded_scene()), 10)
    state = rolling.get_state()
    with pytest.raises(ValueError, match="rolling springs"):
        plain.set_state(state)
    # a state of a scene without rolling (or written before it) restores with ψ = 0, and the
    # rolling parameters it lacks are the simulation's own (rolling stays on)
    from dem_taichi.kernels import layout as L

    kappa = rolling.get_state()["params"][L.P_ROLL_K]
    assert kappa > 0.0
    old = {k: v for k, v in plain.get_state().items() if k != "rolling_spring"}
    old["params"] = old["params"][: L.P_ROLL_K]
    rolling.set_state(old)
    assert not np.any(rolling.get_state()["rolling_spring"])
    assert rolling.get_state()["params"][L.P_ROLL_K] == kappa


# --------------------------------------------------------------------------------------------
# the linearisation against finite differences
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def rolling_network():
    """The frictionless test network with rolling springs loaded at random (κ_r = 50, cap
    μ_r d_eff = 0.05) on its contacts."""
    snap = build_frictionless_network()
    pairs = forcelaw.pair_forces(snap)
    rng = np.random.default_rng(4)
    # |κ_r ψ| up to 0.6 of the cap: loaded, none on it
    psi = rng.uniform(-0.6, 0.6, snap.n_pairs) * 0.05 * pairs.contact_force / 50.0
    psi = np.where(pairs.in_contact, psi, 0.0)
    return dataclasses.replace(snap, rolling_spring=psi, rolling_stiffness=50.0, rolling_cap=0.05)


def advance_rolling(old, new, capped):
    """``new`` with ψ += Δθ_P − Δθ_Q (the engine's update); pairs ``capped`` stay on the cap."""
    rod_i, rod_j = old.pair_i // old.n_spheres, old.pair_j // old.n_spheres
    spin = new.rod_angle - old.rod_angle
    psi = old.pair_rolling_spring + spin[rod_i] - spin[rod_j]
    pairs = forcelaw.pair_forces(new)
    on_cap = np.sign(old.pair_rolling_spring) * old.rolling_cap * pairs.contact_force
    psi = np.where(capped, on_cap / old.rolling_stiffness, psi)
    return dataclasses.replace(new, rolling_spring=np.where(pairs.in_contact, psi, 0.0))


@pytest.mark.parametrize("sliding", ["stuck", "free"])
def test_linearisation_matches_finite_differences(rolling_network, sliding):
    snap = rolling_network
    pairs = forcelaw.pair_forces(snap)
    assert np.count_nonzero(pairs.rolling_moment) > 5
    capped = np.zeros(snap.n_pairs, bool)
    if sliding == "free":  # put the three most loaded couples exactly on the cap
        ratio = np.abs(pairs.rolling_moment) / np.maximum(pairs.contact_force, 1e-300)
        capped = ratio >= np.sort(ratio)[-3]
        psi = np.where(
            capped,
            np.sign(snap.rolling_spring) * snap.rolling_cap * pairs.contact_force / 50.0,
            snap.rolling_spring,
        )
        snap = dataclasses.replace(snap, rolling_spring=psi)
        assert np.count_nonzero(forcelaw.pair_forces(snap).rolling_sliding) == 3
    matrices = network_matrices(snap, sliding, include_geometric=True, prune_rattlers=False)
    rng = np.random.default_rng(7)
    h = 1e-7
    for _ in range(3):
        direction = rng.normal(size=3 * snap.n_rods)
        values = []
        for sign in (1.0, -1.0):
            step = sign * h * direction.reshape(-1, 3)
            moved = dataclasses.replace(
                snap, rod_position=snap.rod_position + step[:, :2],
                rod_angle=snap.rod_angle + step[:, 2],
            )  # fmt: skip
            values.append(generalised_forces(advance_rolling(snap, moved, capped)))
        numeric = (values[0] - values[1]) / (2 * h)
        analytic = -(matrices.hessian @ direction)
        np.testing.assert_allclose(analytic, numeric, rtol=0, atol=1e-6 * np.abs(analytic).max())
    for c, gradient in enumerate(UNIT_GRADIENTS):  # the strain coupling Γ (the cap follows δ)
        values = [
            generalised_forces(advance_rolling(snap, deform(snap, sign * h * gradient), capped))
            for sign in (1.0, -1.0)
        ]
        numeric = (values[0] - values[1]) / (2 * h)
        analytic = matrices.strain_coupling[:, c]
        np.testing.assert_allclose(analytic, numeric, rtol=0, atol=1e-6 * np.abs(analytic).max())
    # the rolling springs change the matrices (stuck: κ_r on the rotations)
    bare = network_matrices(
        dataclasses.replace(snap, rolling_stiffness=0.0), sliding, prune_rattlers=False
    )
    assert abs(matrices.hessian - bare.hessian).max() > 1.0


def test_springs_restart_when_the_contact_opens_without_long_range_forces():
    """Two spinning discs pushed apart (no long-range forces: the interaction cut-off is the
    diameter) keep their list entry, and both springs restart at zero once they part."""
    scene = rolling_scene(n_rods=2, n_spheres=1, friction="true", mu_r=0.3)
    sim = two_discs(scene, omega=(3.0, 1.0), overlap=0.02)
    sim.run(3)
    loaded = sim.get_state()
    assert loaded["tangential_spring"][0, 0] != 0.0 and loaded["rolling_spring"][0, 0] != 0.0
    sim.run(30)
    apart = sim.get_state()
    x = apart["reduced_position"] * sim.cell_lengths
    assert 1.0 < np.linalg.norm(x[1] - x[0]) < sim.list_radius
    assert apart["neighbour_count"][0] == 1  # still listed
    assert apart["tangential_spring"][0, 0] == 0.0 and apart["rolling_spring"][0, 0] == 0.0
