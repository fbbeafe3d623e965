"""Two-body tests of every pair-force branch against the formulas (docs/science/dem-model.md §1.2).

Each test places two bodies (single discs, or 3-disc rods whose only interacting pair is chosen by
the geometry) and compares the engine's rod forces with the closed-form law, including across the
periodic boundary. The numpy reference ``dem_taichi.physics.forcelaw`` (written independently) is
used for the long-range branches.
"""

import math

import numpy as np
import pytest

from dem_taichi.engine.simulation import Simulation
from dem_taichi.kernels import layout
from dem_taichi.physics import forcelaw
from dem_taichi.physics.restitution import restitution_by_phase
from dem_taichi.scene.config import gamma_from_restitution, scene_from_toml
from dem_taichi.scene.geometry import GasState

L_CELL = 12.0


def disc_scene(friction=False, e_n=None, extra="", restitution_model="discrete"):
    damping = f"e_n = {e_n}" if e_n is not None else "gamma_n = 0.0"
    damping += f'\nrestitution_model = "{restitution_model}"'
    return scene_from_toml(
        f"""
[particles]
n_rods = 2
n_spheres = 1
[contact]
k_n = 1.0e5
{damping}
k_t = 4.0e4
mu = 0.4
friction = {"true" if friction else "false"}
[integration]
local_damping = 0.0
steps_per_call = 50
dt_safety = 0.02
{extra}
"""
    )


def two(positions, velocities=((0, 0), (0, 0)), angles=(0.0, 0.0), omega=(0.0, 0.0), L=L_CELL):
    return GasState(
        np.array([L, L], dtype=float),
        np.array(positions, dtype=float) % L,
        np.array(angles, dtype=float),
        np.array(velocities, dtype=float),
        np.array(omega, dtype=float),
    )


@pytest.mark.parametrize("x0", [5.0, L_CELL - 0.45])  # second: the pair straddles the boundary
def test_static_contact_force_is_k_n_overlap(x0):
    delta = 0.01
    sim = Simulation(disc_scene(), initial=two([[x0, 3.0], [x0 + 1.0 - delta, 3.0]]))
    force = sim.get_state()["force"]
    assert force[0] == pytest.approx([-1.0e5 * delta, 0.0], rel=1e-9, abs=1e-9)
    assert force[1] == pytest.approx([1.0e5 * delta, 0.0], rel=1e-9, abs=1e-9)
    m = sim.measure()
    assert m["n_contacts"] == 1
    assert m["contact_energy"] == pytest.approx(0.5 * 1.0e5 * delta**2, rel=1e-9)


def test_contact_damping_uses_the_normal_relative_velocity():
    scene = disc_scene(e_n=0.5, restitution_model="continuous")
    gamma = gamma_from_restitution(0.5, 1.0e5, 1.0)
    delta, v = 0.004, 0.3
    # diagonal contact normal, across the corner of the periodic cell
    n = np.array([1.0, 1.0]) / math.sqrt(2.0)
    x1 = np.array([L_CELL - 0.2, L_CELL - 0.3])
    x2 = x1 + (1.0 - delta) * n
    sim = Simulation(scene, initial=two([x1, x2], velocities=[v * n, [0.0, 0.0]]))
    # disc 1 approaches disc 2: v_n = (v_1 - v_2)·(x_1 - x_2)/|..| = -v
    expected = (1.0e5 * delta + gamma * v) * (-n)
    assert sim.get_state()["force"][0] == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize("e_n", [0.3, 0.7, 1.0])
def test_restitution_of_a_real_collision_matches_e_n(e_n):
    scene = disc_scene(e_n=e_n) if e_n < 1 else disc_scene()
    scene = scene.replace(integration={"dt_safety": 0.005})
    sim = Simulation(scene, initial=two([[4.0, 5.0], [5.5, 5.0]], velocities=[[1, 0], [-1, 0]]))
    sim.run(int(0.6 / scene.time_step), output_every=10**9)
    v = sim.get_state()["velocity"][:, 0]
    # the dashpot sees the half-step velocity: an O(Δt/t_c) error in e_n, measured ~4 % at
    # Δt = 0.02 t_c for e_n = 0.3 and < 0.4 % at Δt = 0.005 t_c (here)
    assert (v[1] - v[0]) / 2.0 == pytest.approx(e_n, rel=0.01)
    assert v[0] + v[1] == pytest.approx(0.0, abs=1e-12)


N_PHASES = 64  # pairs per collision run, one per contact phase (i + ½)/N_PHASES


def collide_pairs_at_all_phases(scene, speed=1.0, approach_steps=3):
    """Run N_PHASES head-on disc pairs, far apart in one cell, whose first overlap after
    ``approach_steps`` steps is φ·speed·Δt for the midpoint phases φ; return (φ, restitution)."""
    dt = scene.time_step
    phases = (np.arange(N_PHASES) + 0.5) / N_PHASES
    side = math.ceil(math.sqrt(N_PHASES))
    positions, velocities = [], []
    for i, phase in enumerate(phases):
        x0, y0 = 4.0 * (i % side) + 1.0, 4.0 * (i // side) + 2.0
        gap = (approach_steps - phase) * speed * dt
        positions += [[x0, y0], [x0 + 1.0 + gap, y0]]
        velocities += [[0.5 * speed, 0.0], [-0.5 * speed, 0.0]]
    n = 2 * N_PHASES
    cell = 4.0 * side
    gas = GasState(np.array([cell, cell]), np.array(positions), np.zeros(n),
                   np.array(velocities), np.zeros(n))  # fmt: skip
    sim = Simulation(scene, initial=gas)
    steps = approach_steps + int(3.0 * scene.contact_duration / dt) + 5
    sim.run(steps, output_every=10**9)
    v = sim.get_state()["velocity"][:, 0].reshape(N_PHASES, 2)
    assert np.abs(sim.get_state()["velocity"][:, 1]).max() == 0.0
    return phases, (v[:, 1] - v[:, 0]) / speed


def collision_scene(e_n, dt_safety, restitution_model):
    return disc_scene(e_n=e_n, restitution_model=restitution_model).replace(
        particles={"n_rods": 2 * N_PHASES}, integration={"dt_safety": dt_safety}
    )


@pytest.mark.parametrize("dt_safety", [0.05, 0.15])
@pytest.mark.parametrize("e_n", [0.3, 0.5, 0.9])
def test_discrete_restitution_model_gives_e_n_in_real_collisions(e_n, dt_safety):
    """Default model: γ_n calibrated on the discrete collision; the engine's collisions averaged
    over the contact phase give e_n within 1 %, and each collision is the replica's."""
    scene = collision_scene(e_n, dt_safety, "discrete")
    phases, restitution = collide_pairs_at_all_phases(scene)
    assert restitution.mean() == pytest.approx(e_n, rel=0.01)
    # the host replica reproduces each engine collision (phase-by-phase); a phase lying on a
    # discontinuity of e(φ) may fall either side by rounding, hence the median
    replica = restitution_by_phase(scene.gamma_n, 1.0e5, 1.0, scene.time_step, phases)
    assert np.median(np.abs(restitution - replica)) < 1e-9
    assert np.mean(np.abs(restitution - replica) < 1e-9) > 0.9


def test_continuous_restitution_model_keeps_the_closed_form_gamma_and_its_error():
    """'continuous': γ_n from e_n = exp(−γ_n t_c/m) exactly as before; the engine then realises
    a restitution 13 % low for e_n = 0.3 at dt_safety 0.15 (measured; the replica agrees)."""
    scene = collision_scene(0.3, 0.15, "continuous")
    assert scene.gamma_n == gamma_from_restitution(0.3, 1.0e5, 1.0)
    phases, restitution = collide_pairs_at_all_phases(scene)
    replica = restitution_by_phase(scene.gamma_n, 1.0e5, 1.0, scene.time_step, phases)
    assert np.median(np.abs(restitution - replica)) < 1e-9
    assert restitution.mean() == pytest.approx(0.3 * (1 - 0.132), rel=0.01)
    # both models share the time step (continuous-model t_c); only γ_n differs
    discrete = collision_scene(0.3, 0.15, "discrete")
    assert discrete.time_step == scene.time_step
    assert discrete.gamma_n == pytest.approx(0.923 * scene.gamma_n, rel=1e-3)


def test_tangential_force_below_and_at_the_coulomb_cap():
    delta = 0.01
    sim = Simulation(disc_scene(friction=True), initial=two([[3.0, 3.0], [3.0 + 1.0 - delta, 3.0]]))
    state = sim.get_state()
    slot = 0
    assert state["neighbour_count"][0] == 1
    f_c = 1.0e5 * delta
    for xi, expect in ((1.0e-5, -4.0e4 * 1.0e-5), (1.0, -0.4 * f_c), (-1.0, 0.4 * f_c)):
        state["tangential_spring"][0, slot] = xi
        sim.set_state(state)
        sim.recompute_forces()
        # t = (-n_y, n_x) with n = (x_0 - x_1)/|..| = (-1, 0): t = (0, -1)
        force = sim.get_state()["force"][0]
        assert force[1] == pytest.approx(-expect, rel=1e-9)
        torque = sim.get_state()["torque"]
        # F_t acts at the contact point, half a centre distance from each disc centre
        lever = 0.5 * (1.0 - delta)
        assert torque[0] == pytest.approx(-lever * expect, rel=1e-9)
        assert torque[1] == pytest.approx(-lever * expect, rel=1e-9)


def test_sliding_contact_resets_the_spring_to_the_cap():
    delta = 0.01
    gas = two([[3.0, 3.0], [3.0 + 1.0 - delta, 3.0]], velocities=[[0.0, 0.5], [0.0, -0.5]])
    sim = Simulation(disc_scene(friction=True), initial=gas)
    state = sim.get_state()
    state["tangential_spring"][0, 0] = 1.0  # far beyond the cap
    sim.set_state(state)
    sim.run(1, output_every=10**9)
    snap = sim.snapshot()
    xi = np.linalg.norm(snap.tangential_spring[0])
    pos = sim.get_state()["reduced_position"] * L_CELL
    overlap = 1.0 - np.linalg.norm(pos[0] - pos[1])
    assert snap.sliding[0]
    assert 4.0e4 * xi == pytest.approx(0.4 * 1.0e5 * overlap, rel=1e-9)


def rods_scene(pattern="acidic", vdw=False):
    return scene_from_toml(
        f"""
[particles]
n_rods = 2
n_spheres = 3
[contact]
k_n = 1.0e5
gamma_n = 0.0
friction = false
[long_range]
enabled = true
pattern = "{pattern}"
f_max_edge = 10.0
f_max_inner = 30.0
k_a_edge = 50.0
k_a_inner = 150.0
[van_der_waals]
enabled = {"true" if vdw else "false"}
f_max = 2.0
k = 10.0
[integration]
local_damping = 0.0
skin = 0.2
"""
    )


def facing_rods(gap, face, x0=3.0):
    """Rod A along x centred at (x0, 5); its edge disc 2 at x0+1 faces, at surface gap ``gap``,
    rod B's edge disc (``face="edge"``: B collinear) or middle disc (``face="inner"``: B
    vertical). Returns the gas and the species pair (s_i, s_j)."""
    xb = x0 + 1.0 + 1.0 + gap
    if face == "edge":
        return two([[x0, 5.0], [xb + 1.0, 5.0]]), (2, 0)
    return two([[x0, 5.0], [xb, 5.0]], angles=[0.0, math.pi / 2]), (2, 1)


@pytest.mark.parametrize("pattern", ["acidic", "basic"])
@pytest.mark.parametrize("face", ["edge", "inner"])
@pytest.mark.parametrize("gap", [-0.01, 0.0, 0.05, 0.15, 0.2 - 1e-9, 0.2 + 1e-6, 0.35])
def test_long_range_branches_signs_and_cut_off(pattern, face, gap):
    scene = rods_scene(pattern)
    gas, (si, sj) = facing_rods(gap, face)
    sim = Simulation(scene, initial=gas)
    charge = {"acidic": np.array([1, -1, 1]), "basic": np.array([-1, -1, -1])}[pattern]
    f_max = np.array([10.0, 30.0, 10.0])
    k_a = np.array([50.0, 150.0, 50.0])
    f_pair = forcelaw.harmonic_mean(f_max[si], f_max[sj])
    k_pair = forcelaw.harmonic_mean(k_a[si], k_a[sj])
    s = charge[si] * charge[sj]
    expected_lr = float(forcelaw.long_range_force(gap, f_pair, k_pair, s))
    contact = 1.0e5 * max(-gap, 0.0)
    f = expected_lr + contact  # repulsive positive, along n = (x_A - x_B)/|..| = (-1, 0)
    force_a = sim.get_state()["force"][0]
    assert force_a[0] == pytest.approx(-f, rel=1e-9, abs=1e-9)
    assert force_a[1] == pytest.approx(0.0, abs=1e-9)
    m = sim.measure()
    assert m["n_long_range_pairs"] == (1 if expected_lr != 0.0 else 0)
    u = float(forcelaw.long_range_potential(gap, f_pair, k_pair, s))
    assert m["long_range_energy"] == pytest.approx(u, rel=1e-9, abs=1e-12)
    # the sign: edge-edge and face-face repel, edge-face attract (acidic); all repel (basic)
    if -1e-12 < gap < 0.2:
        assert np.sign(expected_lr) == s


def test_harmonic_mean_range_and_values():
    # edge-inner pair: F = 2*10*30/40 = 15, k = 75, g_max = 0.2; half range: f = 7.5 attraction
    gas, _ = facing_rods(0.1, "inner")
    sim = Simulation(rods_scene("acidic"), initial=gas)
    assert sim.get_state()["force"][0][0] == pytest.approx(7.5, rel=1e-9)


def test_van_der_waals_is_attractive_for_any_charges():
    gas, _ = facing_rods(0.05, "edge")
    with_vdw = Simulation(rods_scene("basic", vdw=True), initial=gas).get_state()["force"][0][0]
    without = Simulation(rods_scene("basic", vdw=False), initial=gas).get_state()["force"][0][0]
    # vdW: F_w = 2, k_w = 10, range 0.2: f = -2 (1 - 0.05/0.2) = -1.5 (attractive: +x on rod A)
    assert with_vdw - without == pytest.approx(1.5, rel=1e-9)


def test_intra_rod_pairs_never_interact():
    scene = scene_from_toml(
        "[particles]\nn_rods = 1\nn_spheres = 5\nspacing = 0.5\n[long_range]\nenabled = true\n"
        "pattern = 'basic'\n[integration]\nlocal_damping = 0.0"
    )
    gas = GasState(np.array([15.0, 15.0]), np.array([[7.0, 7.0]]), np.array([0.3]),
                   np.zeros((1, 2)), np.zeros(1))  # fmt: skip
    sim = Simulation(scene, initial=gas)
    state = sim.get_state()
    assert state["neighbour_count"].sum() == 0
    assert np.all(state["force"] == 0.0)


#: a jammed acidic packing (30 rods of 5 discs, friction springs, periodic images): see
#: :func:`jammed_network`
DENSE_NETWORK = """
[scene]
seed = 5
[particles]
n_rods = 30
n_spheres = 5
initial_area_fraction = 0.2
[contact]
e_n = 0.5
[long_range]
enabled = true
[integration]
steps_per_call = 100
[control]
inertial_number_max = 0.01
"""


def jammed_network(scene) -> Simulation:
    """``scene`` compressed 4000 steps at a strain rate of 0.1 into a jammed packing, then made
    a static network (velocities and the affine flow zeroed, the forces recomputed)."""
    from dem_taichi.engine.simulation import CellControl

    sim = Simulation(scene)
    sim.run(4000, control=CellControl.strain_rate(0.1), output_every=10**9)
    make_static(sim)
    return sim


def make_static(sim: Simulation) -> None:
    """``sim`` made a static network: velocities and the affine flow zeroed, the forces
    recomputed."""
    state = sim.get_state()
    state["velocity"][:] = 0.0
    state["angular_velocity"][:] = 0.0
    state["params"][[layout.P_RATE_X, layout.P_RATE_Y]] = 0.0  # no affine flow: a static network
    sim.set_state(state)
    sim.recompute_forces()


def test_engine_forces_match_the_numpy_reference_on_a_dense_network():
    """Forces and torques of a jammed acidic packing (with friction springs and periodic
    images) agree with dem_taichi.physics.forcelaw evaluated on the engine's snapshot."""
    sim = jammed_network(scene_from_toml(DENSE_NETWORK))
    snap = sim.snapshot()
    assert snap.n_pairs > 20
    assert sim.measure()["n_contacts"] > 5
    assert_engine_matches_reference(sim, snap)


def assert_engine_matches_reference(sim: Simulation, snap) -> None:
    """The rigid rods' forces, torques and stress of ``sim`` equal the numpy force law on its
    snapshot ``snap``, to 1e-9 of the largest force."""
    force, torque = forcelaw.rod_forces_and_torques(snap)
    state = sim.get_state()
    scale = np.abs(force).max()
    np.testing.assert_allclose(state["force"], force, atol=1e-9 * scale)
    np.testing.assert_allclose(state["torque"], torque, atol=1e-9 * scale)
    np.testing.assert_allclose(sim.stress(), forcelaw.stress_from_forces(snap), atol=1e-9 * scale)


@pytest.mark.parametrize("face", ["edge", "inner"])
def test_long_range_force_across_the_periodic_boundary(face):
    """The same pair placed straddling the cell boundary gives the same force."""
    forces = []
    for x0 in (3.0, L_CELL - 1.6, L_CELL - 2.7):
        gas, _ = facing_rods(0.08, face, x0=x0)
        forces.append(Simulation(rods_scene("acidic"), initial=gas).get_state()["force"][0])
    np.testing.assert_allclose(forces[1], forces[0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(forces[2], forces[0], rtol=1e-9, atol=1e-12)
    assert abs(forces[0][0]) > 1.0
