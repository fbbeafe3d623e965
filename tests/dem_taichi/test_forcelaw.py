"""The numpy reference pair laws against hand formulas, and forces = -∇(potential)."""

import dataclasses

import numpy as np
import pytest

from dem_taichi.physics import forcelaw
from dem_taichi.response.linear import NetworkSnapshot

K_N = 1.0e3
F_EDGE, F_INNER = 10.0, 4.0
K_EDGE, K_INNER = 20.0, 16.0


def two_rod_snapshot(separation, species=(1, 0), charge=(1, -1, 1), shift=(0.0, 0.0), cell=50.0,
                     k_t=0.0, mu=0.5, spring=(0.0, 0.0), vdw=(0.0, 0.0)):  # fmt: skip
    """Two 3-disc rods; rod 0 horizontal at the centre of the cell, rod 1 placed so that its disc
    ``species[1]`` sits at ``x_i - separation - shift`` with x_i disc ``species[0]`` of rod 0.
    Only that disc pair is listed. Species values: disc 0 and 2 edge, disc 1 inner."""
    n_s = 3
    centre = np.array([cell / 2, cell / 2])
    offsets = forcelaw.disc_offsets(n_s, 1.0)
    x_i = centre + np.array([offsets[species[0]], 0.0])
    x_j = x_i - np.asarray(separation, float) - np.asarray(shift, float)
    angle_1 = np.pi / 2  # rod 1 vertical
    position_1 = x_j - offsets[species[1]] * np.array([np.cos(angle_1), np.sin(angle_1)])
    return NetworkSnapshot(
        cell_lengths=[cell, cell],
        rod_position=[centre, position_1],
        rod_angle=[0.0, angle_1],
        n_spheres=n_s,
        spacing=1.0,
        diameter=1.0,
        disc_mass=1.0,
        charge=list(charge),
        f_max=[F_EDGE, F_INNER, F_EDGE],
        k_a=[K_EDGE, K_INNER, K_EDGE],
        k_n=K_N,
        k_t=k_t,
        mu=mu,
        vdw_f_max=vdw[0],
        vdw_k=vdw[1],
        pair_i=[species[0]],
        pair_j=[n_s + species[1]],
        pair_shift=[shift],
        tangential_spring=[spring],
        sliding=[False],
    )


def test_harmonic_mean_mixing():
    assert forcelaw.harmonic_mean(3.0, 3.0) == pytest.approx(3.0)
    assert forcelaw.harmonic_mean(10.0, 4.0) == pytest.approx(2 * 40 / 14)
    assert forcelaw.harmonic_mean(0.0, 0.0) == 0.0
    snap = two_rod_snapshot([1.2, 0.0], species=(0, 1))
    params = forcelaw.pair_parameters(snap)
    f_mix = 2 * F_EDGE * F_INNER / (F_EDGE + F_INNER)
    k_mix = 2 * K_EDGE * K_INNER / (K_EDGE + K_INNER)
    assert params.f_max[0] == pytest.approx(f_mix)
    assert params.k_a[0] == pytest.approx(k_mix)
    assert params.g_max[0] == pytest.approx(f_mix / k_mix)
    assert params.charge_product[0] == -1.0


@pytest.mark.parametrize(
    ("species", "sign"), [((0, 0), 1.0), ((1, 1), 1.0), ((0, 1), -1.0), ((1, 2), -1.0)]
)
@pytest.mark.parametrize("distance", [0.97, 1.0, 1.1, 1.3, 2.5])
def test_every_long_range_branch_and_sign(species, sign, distance):
    """Acidic charges: edge-edge and face-face repel, edge-face attract; contact adds k_n δ."""
    direction = np.array([0.6, 0.8])
    snap = two_rod_snapshot(distance * direction, species=species)
    pairs = forcelaw.pair_forces(snap)
    value = {0: F_EDGE, 1: F_INNER, 2: F_EDGE}
    f_max = 2 * value[species[0]] * value[species[1]] / (value[species[0]] + value[species[1]])
    kv = {0: K_EDGE, 1: K_INNER, 2: K_EDGE}
    k_a = 2 * kv[species[0]] * kv[species[1]] / (kv[species[0]] + kv[species[1]])
    g_max = f_max / k_a
    gap = distance - 1.0
    if gap <= 0:
        expected_long = sign * f_max
    elif gap <= g_max:
        expected_long = sign * f_max * (1 - gap / g_max)
    else:
        expected_long = 0.0
    expected_contact = K_N * (1.0 - distance) if distance < 1.0 else 0.0
    assert pairs.long_range_force[0] == pytest.approx(expected_long, rel=1e-12, abs=1e-12)
    assert pairs.contact_force[0] == pytest.approx(expected_contact, rel=1e-12, abs=1e-12)
    total = expected_long + expected_contact
    np.testing.assert_allclose(pairs.force[0], total * direction, rtol=1e-12, atol=1e-12)


def test_cut_off_is_included_and_beyond_is_zero():
    g_max = F_EDGE / K_EDGE
    for gap, expected in [(g_max * (1 - 1e-9), F_EDGE * 1e-9), (g_max * (1 + 1e-9), 0.0)]:
        f = forcelaw.long_range_force(gap, F_EDGE, K_EDGE, 1.0)
        assert f == pytest.approx(expected, rel=1e-5, abs=1e-14)
    assert forcelaw.long_range_stiffness(g_max, F_EDGE, K_EDGE, -1.0) == -K_EDGE
    assert forcelaw.long_range_stiffness(g_max * 1.01, F_EDGE, K_EDGE, -1.0) == 0.0
    assert forcelaw.long_range_stiffness(-0.01, F_EDGE, K_EDGE, 1.0) == 0.0
    assert forcelaw.long_range_force(0.1, F_EDGE, K_EDGE, 0.0) == 0.0  # neutral


def test_neutral_discs_feel_no_long_range_and_no_vdw():
    snap = two_rod_snapshot([0.0, 1.2], charge=(0, 0, 0), vdw=(2.0, 4.0))
    pairs = forcelaw.pair_forces(snap)
    assert pairs.long_range_force[0] == 0.0 and pairs.van_der_waals_force[0] == 0.0


@pytest.mark.parametrize("charge", [(1, -1, -1), (-1, -1, -1)])
def test_van_der_waals_always_attractive(charge):
    f_w, k_w = 2.0, 8.0  # range 0.25
    for distance, expected in [(0.99, -f_w), (1.1, -f_w * (1 - 0.1 / 0.25)), (1.3, 0.0)]:
        snap = two_rod_snapshot([distance, 0.0], species=(0, 0), charge=charge, vdw=(f_w, k_w))
        pairs = forcelaw.pair_forces(snap)
        assert pairs.van_der_waals_force[0] == pytest.approx(expected, rel=1e-12, abs=1e-12)


def test_across_periodic_boundary_equals_direct():
    """Same pair geometry through an image shift gives the same forces and torques."""
    direct = two_rod_snapshot([0.9, 0.3], species=(0, 1))
    cell = 50.0
    moved = direct.rod_position + np.array([[0.0, 0.0], [cell, -cell]])
    wrapped = dataclasses.replace(direct, rod_position=moved, pair_shift=[[-cell, cell]])
    f_direct, t_direct = forcelaw.rod_forces_and_torques(direct)
    f_wrap, t_wrap = forcelaw.rod_forces_and_torques(wrapped)
    np.testing.assert_allclose(f_wrap, f_direct, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(t_wrap, t_direct, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(
        forcelaw.stress_from_forces(wrapped), forcelaw.stress_from_forces(direct), rtol=1e-10
    )


def test_contact_damping_and_tangential_cap_by_hand():
    assert forcelaw.contact_normal_force(0.01, K_N, normal_velocity=-0.5, gamma_n=3.0) == (
        pytest.approx(K_N * 0.01 + 1.5)
    )
    assert forcelaw.contact_normal_force(-0.01, K_N, normal_velocity=-0.5, gamma_n=3.0) == 0.0
    normal = np.array([1.0, 0.0])
    # below the cap: F_t = -k_t ξ_t (normal part of ξ removed)
    force, sliding = forcelaw.tangential_force([0.3, 1e-3], normal, 500.0, 0.5, 10.0)
    np.testing.assert_allclose(force, [0.0, -0.5])
    assert not sliding
    # above the cap: |F_t| = μ f_c
    force, sliding = forcelaw.tangential_force([0.0, 0.1], normal, 500.0, 0.5, 10.0)
    np.testing.assert_allclose(force, [0.0, -5.0])
    assert sliding


def test_tangential_spring_step_projects_accumulates_and_resets():
    normal = np.array([0.0, 1.0])
    spring, force, sliding = forcelaw.tangential_spring_step(
        [1e-3, 5e-4], normal, [0.2, -7.0], 1e-3, 1000.0, 0.5, 10.0, gamma_t=2.0
    )
    # projected ξ = (1e-3, 0); v_t = (0.2, 0); ξ = 1.2e-3; F = -1.2 - 0.4 = -1.6 (below cap 5)
    np.testing.assert_allclose(spring, [1.2e-3, 0.0])
    np.testing.assert_allclose(force, [-1.6, 0.0])
    assert not sliding
    spring, force, sliding = forcelaw.tangential_spring_step(
        [1e-2, 0.0], normal, [0.2, 0.0], 1e-3, 1000.0, 0.5, 10.0, gamma_t=2.0
    )
    # F = -10.2 - 0.4 -> capped to -5; ξ reset so that -k_t ξ - γ_t v_t = -5
    np.testing.assert_allclose(force, [-5.0, 0.0])
    np.testing.assert_allclose(-1000.0 * spring - 2.0 * np.array([0.2, 0.0]), force)
    assert sliding


def test_tangential_force_acts_at_the_contact_midpoint():
    """Rod 0 horizontal, rod 1 vertical below disc 2 of rod 0; a tangential spring along x."""
    snap = two_rod_snapshot([0.0, 0.98], species=(2, 0), charge=(0, 0, 0), k_t=400.0, mu=10.0,
                            spring=(1e-3, 0.0))  # fmt: skip
    force, torque = forcelaw.rod_forces_and_torques(snap)
    f_n = K_N * 0.02
    f_t = -400.0 * 1e-3  # along t = (-n_y, n_x) = (-1, 0): ξ·t = -1e-3 -> F_t = -k_t ξ
    np.testing.assert_allclose(force[0], [f_t, f_n], rtol=1e-12)
    np.testing.assert_allclose(force[1], [-f_t, -f_n], rtol=1e-12)
    # contact point x_c = x_i - r/2 = (1, -0.49) relative to rod 0's centroid
    assert torque[0] == pytest.approx(1.0 * f_n - (-0.49) * f_t, rel=1e-12)
    # rod 1's centroid is 1 below its disc 0 (vertical rod, disc 0 at offset -1 -> centroid above)
    lever_1 = snap.rod_position[0] + np.array([1.0, -0.49]) - snap.rod_position[1]
    assert torque[1] == pytest.approx(-(lever_1[0] * f_n - lever_1[1] * f_t), rel=1e-12)


@pytest.mark.parametrize("f_max,k_a,sign", [(10.0, 20.0, 1.0), (10.0, 20.0, -1.0), (3.0, 4.0, 1.0)])
def test_scalar_potentials_are_continuous_and_give_the_force(f_max, k_a, sign):
    gaps = np.array([-0.05, -0.001, 0.01, 0.2, 0.4, 0.6, 0.9])
    gaps = gaps[np.abs(gaps - f_max / k_a) > 1e-3]
    h = 1e-7
    numeric = -(
        forcelaw.long_range_potential(gaps + h, f_max, k_a, sign)
        - forcelaw.long_range_potential(gaps - h, f_max, k_a, sign)
    ) / (2 * h)
    np.testing.assert_allclose(
        numeric, forcelaw.long_range_force(gaps, f_max, k_a, sign), rtol=1e-7, atol=1e-7
    )
    for point in (0.0, f_max / k_a):
        left = forcelaw.long_range_potential(point - 1e-12, f_max, k_a, sign)
        right = forcelaw.long_range_potential(point + 1e-12, f_max, k_a, sign)
        assert left == pytest.approx(right, abs=1e-9)
    assert forcelaw.long_range_potential(0.0, f_max, k_a, sign) == pytest.approx(
        sign * 0.5 * k_a * (f_max / k_a) ** 2
    )


def random_network(seed=0, n_rods=14, n_s=4, vdw=(1.0, 5.0)):
    """Random overlapping rods with an acidic pattern; pairs listed from a brute-force search."""
    rng = np.random.default_rng(seed)
    cell = np.array([7.0, 6.0])
    position = rng.uniform(0, 1, (n_rods, 2)) * cell
    angle = rng.uniform(0, np.pi, n_rods)
    discs = forcelaw.disc_positions(position, angle, n_s, 0.9)
    i, j = np.triu_indices(len(discs), 1)
    keep = i // n_s != j // n_s
    i, j = i[keep], j[keep]
    d = discs[i] - discs[j]
    shift = cell * np.round(d / cell)
    close = np.linalg.norm(d - shift, axis=1) < 1.0 + 0.6
    i, j, shift = i[close], j[close], shift[close]
    charge = [1] + [-1] * (n_s - 2) + [1]
    return NetworkSnapshot(
        cell_lengths=cell, rod_position=position, rod_angle=angle, n_spheres=n_s, spacing=0.9,
        diameter=1.0, disc_mass=1.0, charge=charge, f_max=[2.0] + [1.0] * (n_s - 2) + [2.0],
        k_a=[4.0] + [3.0] * (n_s - 2) + [4.0], k_n=K_N, k_t=0.0, mu=0.5, vdw_f_max=vdw[0],
        vdw_k=vdw[1], pair_i=i, pair_j=j, pair_shift=shift,
        tangential_spring=np.zeros((len(i), 2)), sliding=np.zeros(len(i), bool),
    )  # fmt: skip


def test_forces_and_torques_are_minus_energy_gradient():
    snap = random_network()
    force, torque = forcelaw.rod_forces_and_torques(snap)
    assert snap.n_pairs > 20
    h = 1e-7
    for rod in range(snap.n_rods):
        for dof in range(3):
            energies = []
            for sign in (1, -1):
                position = snap.rod_position.copy()
                angle = snap.rod_angle.copy()
                if dof < 2:
                    position[rod, dof] += sign * h
                else:
                    angle[rod] += sign * h
                moved = dataclasses.replace(snap, rod_position=position, rod_angle=angle)
                energies.append(forcelaw.potential_energy(moved).total)
            gradient = (energies[0] - energies[1]) / (2 * h)
            expected = force[rod, dof] if dof < 2 else torque[rod]
            assert -gradient == pytest.approx(expected, rel=1e-5, abs=1e-5 * K_N * 1e-2)
    np.testing.assert_allclose(force.sum(axis=0), 0.0, atol=1e-9)


def test_virial_stress_is_minus_energy_derivative_under_affine_strain():
    """σ_ab A = -∂U/∂G_ab for X -> (I+G)X, shift -> (I+G)shift at fixed angles (any state)."""
    snap = random_network(seed=3)
    area = float(np.prod(snap.cell_lengths))
    stress = forcelaw.stress_from_forces(snap)
    h = 1e-7
    for a in range(2):
        for b in range(2):
            energies = []
            for sign in (1, -1):
                gradient = np.zeros((2, 2))
                gradient[a, b] = sign * h
                deformation = np.eye(2) + gradient
                moved = dataclasses.replace(
                    snap,
                    rod_position=snap.rod_position @ deformation.T,
                    pair_shift=snap.pair_shift @ deformation.T,
                )
                energies.append(forcelaw.potential_energy(moved).total)
            derivative = (energies[0] - energies[1]) / (2 * h)
            assert -derivative / area == pytest.approx(stress[a, b], rel=1e-5, abs=1e-6)


def test_potential_energy_parts_by_hand():
    snap = two_rod_snapshot([0.98, 0.0], species=(0, 1), k_t=400.0, mu=10.0, spring=(0, 2e-3))
    energy = forcelaw.potential_energy(snap)
    f_mix = 2 * F_EDGE * F_INNER / (F_EDGE + F_INNER)
    k_mix = 2 * K_EDGE * K_INNER / (K_EDGE + K_INNER)
    assert energy.contact == pytest.approx(0.5 * K_N * 0.02**2)
    assert energy.tangential == pytest.approx(0.5 * 400.0 * 2e-3**2)
    assert energy.long_range == pytest.approx(-(0.5 * k_mix * (f_mix / k_mix) ** 2 + f_mix * 0.02))
    assert energy.total == pytest.approx(energy.contact + energy.tangential + energy.long_range)


def test_disc_positions_layout():
    x = forcelaw.disc_positions([[1.0, 2.0]], [np.pi / 2], 3, 0.8)
    np.testing.assert_allclose(x, [[1.0, 1.2], [1.0, 2.0], [1.0, 2.8]], atol=1e-15)
