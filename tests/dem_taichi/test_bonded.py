"""Bonded rods (docs/science/dem-model.md §1.7, issue 10): the bond law, a single chain against
the discrete-chain solution, conservation, breakage, resume, execution modes and precision.

- the kernels' bond forces equal the numpy law (:mod:`dem_taichi.physics.bonds`), which is the exact
  gradient of its energy (finite differences) and conserves linear and angular momentum;
- a free chain vibrates at the eigenfrequencies of the discrete chain (its bending and axial
  stiffness, within 1 %), whose static compliances are the closed forms (Castigliano);
- no damping: energy conserved with contacts and long-range forces; with every dashpot on,
  linear momentum conserved to round-off, angular momentum of a free chain too;
- a bond that opens beyond F_b breaks for good and carries nothing after.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dem_taichi.engine.simulation import Simulation
from dem_taichi.engine.state import states_equal
from dem_taichi.physics.bonds import (
    BondParameters,
    bond_forces,
    chain_bonds,
    chain_hessian,
    chain_max_frequency,
    disc_inertia,
)
from dem_taichi.physics.forcelaw import cross
from dem_taichi.response.flexible import BondStiffness, three_point_compliance
from dem_taichi.scene.config import SceneError, scene_from_toml
from dem_taichi.scene.geometry import GasState

CHAIN = """
[scene]
seed = 5
[particles]
n_rods = {n_rods}
n_spheres = {n_spheres}
rod_model = "bonded"
initial_area_fraction = 0.2
initial_speed = 1.0
[bonds]
bending = 0.3
shear = 0.2
damping_ratio = {zeta}
breakage_force = {f_b}
[contact]
k_n = 1.0e4
gamma_n = {gamma_n}
friction = {friction}
[long_range]
enabled = {long_range}
pattern = "acidic"
[integration]
dt_safety = {dt_safety}
local_damping = 0.0
steps_per_call = 200
"""


def chain_scene(n_rods=1, n_spheres=5, zeta=0.0, f_b=0.0, gamma_n=0.0, friction="false",
                long_range="false", dt_safety=0.1):  # fmt: skip
    return scene_from_toml(
        CHAIN.format(
            n_rods=n_rods, n_spheres=n_spheres, zeta=zeta, f_b=f_b, gamma_n=gamma_n,
            friction=friction, long_range=long_range, dt_safety=dt_safety,
        )
    )  # fmt: skip


def free_chain(scene, position, angle, velocity=None, omega=None, cell=40.0):
    """A simulation of the chain's discs (bodies) in a large empty cell."""
    n = len(angle)
    gas = GasState(
        np.array([cell, cell]),
        np.asarray(position, dtype=float),
        np.asarray(angle, dtype=float),
        np.zeros((n, 2)) if velocity is None else np.asarray(velocity, dtype=float),
        np.zeros(n) if omega is None else np.asarray(omega, dtype=float),
    )
    return Simulation(scene, initial=gas)


def straight(n, spacing=1.0, centre=(20.0, 20.0), angle=0.0):
    offsets = (np.arange(n) - (n - 1) / 2.0) * spacing
    axis = np.array([math.cos(angle), math.sin(angle)])
    return np.asarray(centre) + offsets[:, None] * axis, np.full(n, angle)


def deformed_chain(rng, n=5):
    x, theta = straight(n, angle=0.4)
    x = x + rng.normal(0.0, 0.02, x.shape)
    theta = theta + rng.normal(0.0, 0.05, n)
    return x, theta


def test_kernel_bond_forces_equal_the_numpy_law():
    rng = np.random.default_rng(1)
    scene = chain_scene(zeta=0.3)
    x, theta = deformed_chain(rng)
    v, w = rng.normal(0.0, 0.3, (5, 2)), rng.normal(0.0, 0.5, 5)
    sim = free_chain(scene, x, theta, v, w)
    state = sim.get_state()
    bonds = scene.bond_parameters
    ref = bond_forces(x, theta, chain_bonds(1, 5), sim.cell_lengths, bonds, v, w)
    force = np.zeros((5, 2))
    torque = np.zeros(5)
    g = chain_bonds(1, 5)
    np.add.at(force, g + 1, ref.force_h)
    np.add.at(force, g, -ref.force_h)
    np.add.at(torque, g + 1, ref.torque_h)
    np.add.at(torque, g, ref.torque_g)
    scale = np.abs(ref.force_h).max()
    np.testing.assert_allclose(state["force"], force, atol=1e-12 * scale)
    np.testing.assert_allclose(state["torque"], torque, atol=1e-12 * scale)
    assert sim.measure()["bond_energy"] == pytest.approx(ref.energy.sum(), rel=1e-12)


def test_bond_law_is_the_gradient_of_its_energy_and_conserves_momentum():
    rng = np.random.default_rng(2)
    x, theta = deformed_chain(rng, n=3)
    bonds = BondParameters(1e4, 3e3, 2e3, 0.0, 0.0, 0.0, rest_length=1.0)
    g = chain_bonds(1, 3)
    cell = np.array([40.0, 40.0])
    result = bond_forces(x, theta, g, cell, bonds)

    def energy(q):
        return bond_forces(q[:, :2], q[:, 2], g, cell, bonds).energy.sum()

    q = np.column_stack([x, theta])
    generalised = np.zeros_like(q)
    np.add.at(generalised[:, :2], g + 1, result.force_h)
    np.add.at(generalised[:, :2], g, -result.force_h)
    np.add.at(generalised[:, 2], g + 1, result.torque_h)
    np.add.at(generalised[:, 2], g, result.torque_g)
    step = 1e-6
    for index in np.ndindex(q.shape):
        plus, minus = q.copy(), q.copy()
        plus[index] += step
        minus[index] -= step
        fd = -(energy(plus) - energy(minus)) / (2 * step)
        assert generalised[index] == pytest.approx(fd, rel=1e-6, abs=1e-6)
    # with dashpots: forces sum to zero and so do the moments about the origin
    damped = BondParameters(1e4, 3e3, 2e3, 30.0, 20.0, 5.0, rest_length=1.0)
    r = bond_forces(x, theta, g, cell, damped, rng.normal(size=(3, 2)), rng.normal(size=3))
    moment = r.torque_h + r.torque_g + cross(x[g + 1] - x[g], r.force_h)
    np.testing.assert_allclose(moment, 0.0, atol=1e-10)


def test_discrete_chain_compliance_is_the_closed_form():
    """The chain Hessian (dem_taichi.physics.bonds) against Castigliano's three-point and axial
    compliance of the bond law (flexible_response): two independent derivations."""
    for n in (3, 5, 9):
        k_n, k_t, k_b = 1e4, 2e3, 3e3
        hessian = chain_hessian(n, 1.0, k_n, k_t, k_b)
        # three-point load: P at the middle disc, −P/2 at the end discs (self-equilibrated)
        load = np.zeros(3 * n)
        load[3 * (n // 2) + 1] = 1.0
        load[1] = load[3 * (n - 1) + 1] = -0.5
        u = np.linalg.lstsq(hessian, load, rcond=None)[0]
        deflection = u[3 * (n // 2) + 1] - 0.5 * (u[1] + u[3 * (n - 1) + 1])
        expected = three_point_compliance(n, 1.0, BondStiffness(k_n, k_t, k_b))
        assert deflection == pytest.approx(expected, rel=1e-9)
        axial = np.zeros(3 * n)
        axial[0], axial[3 * (n - 1)] = -1.0, 1.0
        u = np.linalg.lstsq(hessian, axial, rcond=None)[0]
        assert u[3 * (n - 1)] - u[0] == pytest.approx((n - 1) / k_n, rel=1e-9)


def _modal_frequency(sim, mode, mass, steps, dt, every=1):
    """Frequency of the modal coordinate of the discs' displacement, from its zero crossings,
    sampled every ``every`` steps (``steps`` a multiple of it)."""
    assert steps % every == 0
    x0 = sim.get_state()["reduced_position"] * sim.cell_lengths
    theta0 = sim.get_state()["angle"].copy()
    series = []

    def record(s, _m):
        state = s.get_state()
        u = np.column_stack([state["reduced_position"] * s.cell_lengths - x0,
                             state["angle"] - theta0]).ravel()  # fmt: skip
        series.append(float(np.sum(mass * mode * u)))

    sim.run(steps, output_every=every, callback=record)
    y = np.asarray(series)
    y = y - y.mean()
    up = np.flatnonzero((y[:-1] < 0.0) & (y[1:] >= 0.0))
    times = (up + (-y[up]) / (y[up + 1] - y[up])) * every * dt  # linear interpolation
    return 2.0 * math.pi * (len(times) - 1) / (times[-1] - times[0])


@pytest.mark.parametrize("which", ["bending", "axial"])
def test_free_chain_vibrates_at_the_discrete_chain_frequencies(which):
    scene = chain_scene(n_spheres=5, dt_safety=0.05)
    b = scene.bond_parameters
    n = 5
    mass = np.tile([1.0, 1.0, disc_inertia(1.0, 1.0)], n)
    hessian = chain_hessian(n, 1.0, b.k_n, b.k_t, b.k_b)
    inv = 1.0 / np.sqrt(mass)
    values, vectors = np.linalg.eigh(hessian * inv[:, None] * inv[None, :])
    modes = vectors * inv[:, None]  # mass-orthogonal displacement modes
    axial_share = np.sum(modes[0::3] ** 2, axis=0) / np.sum(modes**2, axis=0)
    nonzero = values > 1e-6 * values.max()
    pick = nonzero & ((axial_share > 0.99) if which == "axial" else (axial_share < 0.01))
    k = int(np.flatnonzero(pick)[0])  # the lowest of its kind
    mode = modes[:, k] / np.abs(modes[:, k]).max()
    x, theta = straight(n)
    amplitude = 1e-4
    x = x + amplitude * mode.reshape(n, 3)[:, :2]
    theta = theta + amplitude * mode.reshape(n, 3)[:, 2]
    sim = free_chain(scene, x, theta)
    omega = math.sqrt(values[k])
    dt = scene.time_step
    # 12 periods, sampled every 4 steps (≥ 48 samples a period: the interpolated zero
    # crossings are exact far below the 1 % asked; a sample every step cost 4x the time)
    every = 4
    steps = every * int(12 * 2 * math.pi / omega / dt / every)
    measured = _modal_frequency(sim, mode / np.sum(mass * mode * mode), mass, steps, dt, every)
    assert measured == pytest.approx(omega, rel=1e-2)
    assert chain_max_frequency(n, 1.0, 1.0, 1.0, b.k_n, b.k_t, b.k_b) == pytest.approx(
        math.sqrt(values.max()), rel=1e-12
    )


@pytest.mark.parametrize("long_range", ["true", "false"])
def test_energy_is_conserved_without_damping(long_range):
    scene = chain_scene(n_rods=40, long_range=long_range, dt_safety=0.05)
    sim = Simulation(scene)
    e0 = sim.total_energy()
    k0 = sim.measure()["kinetic_energy"]
    worst, contacts = 0.0, 0
    for _ in range(40):
        m = sim.run(250, output_every=10**9)
        worst = max(worst, abs(sim.total_energy() - e0))
        contacts += m["n_contacts"]
    assert contacts > 20
    assert worst <= 2e-3 * k0


def test_momentum_is_conserved_with_every_dashpot_on():
    scene = chain_scene(n_rods=40, zeta=0.5, gamma_n=30.0, friction="true", long_range="true")
    sim = Simulation(scene)
    p0 = sim.get_state()["velocity"].sum(axis=0)
    sim.run(4000)
    p = sim.get_state()["velocity"].sum(axis=0)
    assert np.abs(p - p0).max() <= 1e-10 * math.sqrt(40 * 5)
    # a free spinning, vibrating chain: angular momentum about the origin conserved
    rng = np.random.default_rng(3)
    x, theta = deformed_chain(rng)
    v = rng.normal(0.0, 0.2, (5, 2))
    v -= v.mean(axis=0)
    w = np.full(5, 0.7)
    chain = free_chain(chain_scene(zeta=0.5), x, theta, v, w, cell=60.0)
    inertia = disc_inertia(1.0, 1.0)

    def angular_momentum(s):
        st = s.get_state()
        pos = st["reduced_position"] * s.cell_lengths
        return float(np.sum(cross(pos, st["velocity"])) + inertia * st["angular_velocity"].sum())

    l0 = angular_momentum(chain)
    energy0 = chain.total_energy()
    chain.run(3000)
    # leapfrog: positions and velocities half a step apart; the drift is O(Δt) and bounded
    assert angular_momentum(chain) == pytest.approx(l0, rel=2e-3)
    assert chain.total_energy() < energy0  # the dashpots dissipate


def test_a_bond_that_opens_beyond_its_strength_breaks_and_carries_nothing():
    scene = chain_scene(n_spheres=2, f_b=50.0)
    x, theta = straight(2)
    v = np.array([[-2.0, 0.0], [2.0, 0.0]])  # pulled apart: peak tension ~ v sqrt(k m) >> F_b
    sim = free_chain(scene, x, theta, v)
    assert sim.measure()["n_broken_bonds"] == 0
    sim.run(400)
    m = sim.measure()
    assert m["n_broken_bonds"] == 1 and sim.n_broken_bonds == 1
    assert m["bond_energy"] == 0.0
    state = sim.get_state()
    assert np.all(state["force"] == 0.0) and np.all(state["torque"] == 0.0)
    distance = np.linalg.norm(np.diff(state["reduced_position"] * sim.cell_lengths, axis=0))
    assert distance > 1.5  # the discs fly apart
    # a weaker pull stays bonded and keeps carrying force
    held = free_chain(scene, x, theta, 0.01 * v)
    held.run(50)
    assert held.measure()["n_broken_bonds"] == 0
    assert held.measure()["bond_energy"] > 0.0


def listed_partners(sim, disc: int) -> set[int]:
    """The discs in ``disc``'s half neighbour list."""
    from dem_taichi.kernels.layout import IMAGE_CODES

    state = sim.get_state()
    count = int(state["neighbour_count"][disc])
    return {int(e) // IMAGE_CODES for e in state["neighbours"][disc, :count]}


def test_an_intact_bond_is_not_listed_and_a_broken_one_is_at_the_next_step():
    """The two discs of an intact bond never interact, so the list leaves them out; when the bond
    breaks the list is rebuilt before the next step's forces, so from then on they are a pair
    like any other (within the list radius at once: a bond breaks near its rest length)."""
    scene = chain_scene(n_spheres=2, f_b=50.0)
    x, theta = straight(2)
    v = np.array([[-2.0, 0.0], [2.0, 0.0]])
    sim = free_chain(scene, x, theta, v)
    assert 1 not in listed_partners(sim, 0)
    for _ in range(400):
        sim.run(1)
        if sim.n_broken_bonds:
            break
    assert sim.n_broken_bonds == 1
    gap = np.linalg.norm(np.diff(sim.get_state()["reduced_position"] * sim.cell_lengths, axis=0))
    assert gap < sim.list_radius
    sim.run(1)
    assert 1 in listed_partners(sim, 0)


def test_bonded_checkpoint_resumes_bit_for_bit(tmp_path):
    scene = chain_scene(n_rods=40, zeta=0.2, gamma_n=30.0, friction="true", long_range="true",
                        f_b=200.0)  # fmt: skip
    sim = Simulation(scene)
    sim.run(600)
    path = sim.save_checkpoint(tmp_path / "bonded.npz")
    sim.run(600)
    resumed = Simulation.from_checkpoint(path)
    assert resumed.n_bodies == 200 and resumed.bonded
    resumed.run(600)
    assert states_equal(sim.get_state(), resumed.get_state())


@pytest.mark.parametrize("execution", ["parallel", "gather"])
def test_execution_modes_agree_with_serial(execution):
    scene = chain_scene(n_rods=40, zeta=0.2, gamma_n=30.0, friction="true", long_range="true")
    serial = Simulation(scene, execution="serial")
    other = Simulation(scene, execution=execution)
    serial.run(300)
    other.run(300)
    a, b = serial.get_state(), other.get_state()
    scale = np.abs(a["velocity"]).max()
    np.testing.assert_allclose(b["reduced_position"], a["reduced_position"], atol=1e-9)
    np.testing.assert_allclose(b["velocity"], a["velocity"], atol=1e-7 * scale)


def test_single_precision_follows_double():
    scene = chain_scene(n_rods=40, zeta=0.2, gamma_n=30.0, friction="true", long_range="true")
    m64 = Simulation(scene, precision="f64").run(300)  # (a precision change re-inits Taichi)
    f32 = Simulation(scene, precision="f32")
    m32 = f32.run(300)
    assert f32.get_state()["angle"].dtype == np.float32
    assert m32["kinetic_energy"] == pytest.approx(m64["kinetic_energy"], rel=1e-3)
    assert m32["bond_energy"] == pytest.approx(m64["bond_energy"], rel=5e-2, abs=1e-6)
    Simulation(scene, precision="f64")  # the runtime goes back to f64 for the other tests


def test_bonded_scenes_are_validated_at_load():
    with pytest.raises(SceneError, match="rod_model = 'bonded' needs n_spheres >= 2"):
        scene_from_toml('[particles]\nrod_model = "bonded"\nn_spheres = 1')
    with pytest.raises(SceneError, match=r"\[bonds\] is used only with"):
        scene_from_toml("[bonds]\nbending = 0.5")
    with pytest.raises(SceneError, match="rod_model"):
        scene_from_toml('[particles]\nrod_model = "flexible"')
    with pytest.raises(SceneError, match="bending"):
        scene_from_toml('[particles]\nrod_model = "bonded"\n[bonds]\nbending = -1.0')
    with pytest.raises(SceneError, match="unknown key"):
        scene_from_toml('[particles]\nrod_model = "bonded"\n[bonds]\nstiffness = 1.0')
    with pytest.raises(SceneError, match="stability limit of bonded rods, 0.4"):
        scene_from_toml('[particles]\nrod_model = "bonded"\n[integration]\ndt_safety = 0.45')
    scene_from_toml('[particles]\nrod_model = "bonded"\n[integration]\ndt_safety = 0.4')
    scene_from_toml("[integration]\ndt_safety = 0.45")  # rigid rods: the contact limits


def test_the_time_step_follows_the_stiffest_of_contact_and_bond():
    rigid = scene_from_toml("[particles]\nn_spheres = 5")
    soft = scene_from_toml('[particles]\nrod_model = "bonded"\n[bonds]\nbending = 0.01\n'
                           "normal = 0.3\nshear = 0.1")  # fmt: skip
    stiff = scene_from_toml('[particles]\nrod_model = "bonded"\n[bonds]\nbending = 1.0')
    assert soft.time_step == pytest.approx(rigid.time_step, rel=1e-12)  # contacts rule
    assert stiff.time_step < 0.5 * rigid.time_step
    b = stiff.bond_parameters
    omega = chain_max_frequency(5, 1.0, 1.0, 1.0, b.k_n, b.k_t, b.k_b)
    assert stiff.time_step == pytest.approx(stiff.integration.dt_safety * math.pi / omega)


@pytest.mark.slow
def test_stiff_bonds_tend_to_the_rigid_packing():
    """One rigid smoke packing, relaxed, rebuilt as bonded chains of growing stiffness (s k_n,
    s k_n, s k_n d²) and relaxed again: the same cell and rod fabric, and the linear-response
    moduli approach the rigid ones as s grows (measured: E_oed,v 38 %, 82 %, 93 % of the rigid
    value at s = 1, 10, 100). The protocol-level comparison over seeds is
    benchmarks/bonded_rigid_limit.py (results/bonded_rigid_limit.md)."""
    from dem_taichi.engine.simulation import CellControl
    from dem_taichi.protocol.probing import linear_probe
    from dem_taichi.protocol.quasistatic import relax
    from dem_taichi.scene.config import load_scene

    rigid = Simulation(load_scene("smoke"))
    while rigid.measure()["specific_volume"] > 1.75:
        rigid.run(1000, CellControl.strain_rate(0.02, stage="isotropic_to_A"))
    measures, ok, _ = relax(rigid, "relax", 1e-9, 1e-12, 500, 60_000)
    assert ok
    reference = linear_probe(rigid, "stuck")
    state = rigid.get_state()
    lengths = state["cell"][:2].astype(float)
    gas = GasState(lengths, np.mod(state["reduced_position"], 1.0) * lengths, state["angle"],
                   np.zeros((40, 2)), np.zeros(40))  # fmt: skip
    ratios = []
    for stiffness in (1.0, 10.0, 100.0):
        scene = load_scene("smoke_bonded").replace(
            bonds={"normal": stiffness, "shear": stiffness, "bending": stiffness}
        )
        bonded = Simulation(scene, initial=gas)
        m, _, _ = relax(bonded, "relax", 1e-8, 1e-12, 500, 200_000)
        assert m["specific_volume"] == pytest.approx(measures["specific_volume"], rel=1e-12)
        assert m["fabric_deviator"] == pytest.approx(measures["fabric_deviator"], abs=2e-3)
        ratios.append(linear_probe(bonded, "stuck").e_oed_v / reference.e_oed_v)
    assert ratios[0] < ratios[1] < ratios[2] <= 1.02
    assert ratios[2] > 0.88
