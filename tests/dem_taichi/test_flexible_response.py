"""Flexible (bonded-rod) linear response: bond blocks against finite differences of an
independent bond energy, the three-point compliance of a chain against its closed form, the
rigid limit against the rigid-rod response, and the stiffness variants at fixed forces."""

import dataclasses

import numpy as np
import pytest

from dem_taichi.physics import forcelaw
from dem_taichi.response.flexible import (
    BondStiffness,
    bond_jacobians,
    bond_pre_forces,
    chain_stiffness,
    disc_forces_and_torques,
    flexible_response,
    three_point_compliance,
)
from dem_taichi.response.linear import StiffnessVariant, linear_response
from tests.dem_taichi.test_linear_response import (
    build_friction_network,
    build_frictionless_network,
    on_the_cap,
)

BONDS = BondStiffness(normal=1.3e3, shear=4.1e2, bending=70.0)


@pytest.fixture(scope="module")
def frictionless_network():
    return build_frictionless_network()


@pytest.fixture(scope="module")
def friction_network(frictionless_network):
    return build_friction_network(frictionless_network)


def bond_energy(x_g, theta_g, x_h, theta_h, rest, lam, bonds):
    """U_b = λ·e + ½ Σ k e² with the objective bond measures, written out from
    docs/science/dem-model.md §1.7."""
    d = np.asarray(x_h) - np.asarray(x_g)
    mid = 0.5 * (theta_g + theta_h)
    a = np.array([np.cos(mid), np.sin(mid)])
    t = np.array([-np.sin(mid), np.cos(mid)])
    e = np.array([d @ a - rest, d @ t, theta_h - theta_g])
    k = np.array([bonds.normal, bonds.shear, bonds.bending])
    return float(lam @ e + 0.5 * np.sum(k * e * e))


@pytest.mark.parametrize("angle", [0.0, 0.7, 2.9])
@pytest.mark.parametrize("geometric", [True, False])
def test_bond_blocks_match_finite_differences(angle, geometric):
    """K = d(F_h, τ_h, F_g, τ_g)/d(d, φ_h, φ_g) equals minus the FD Hessian of the bond energy."""
    spacing = 0.9
    lam = np.array([3.0, -2.0, 0.7]) if geometric else np.zeros(3)
    axis = np.array([[np.cos(angle), np.sin(angle)]])
    tangent = np.array([[-np.sin(angle), np.cos(angle)]])
    separation = spacing * axis
    k, _, force_h = bond_jacobians(axis, tangent, separation, lam[None], BONDS, True)

    def forces(z):  # z = (d_x, d_y, θ_h, θ_g) about the reference; generalised forces R
        def energy(y):
            return bond_energy([0.0, 0.0], angle + y[3], separation[0] + y[:2], angle + y[2],
                               spacing, lam, BONDS)  # fmt: skip

        grad = np.empty(4)
        for c in range(4):
            step = np.zeros(4)
            step[c] = 1e-6
            grad[c] = (energy(z + step) - energy(z - step)) / 2e-6
        return np.array([-grad[0], -grad[1], -grad[2], grad[0], grad[1], -grad[3]])

    np.testing.assert_allclose(forces(np.zeros(4))[:2], force_h[0], atol=1e-6)
    fd = np.empty((6, 4))
    for c in range(4):
        step = np.zeros(4)
        step[c] = 1e-4
        fd[:, c] = (forces(step) - forces(-step)) / 2e-4
    np.testing.assert_allclose(k[0], fd, rtol=1e-5, atol=1e-4 * np.abs(fd).max())


@pytest.mark.parametrize("n_spheres", [3, 5, 9])
@pytest.mark.parametrize("angle", [0.0, 1.1])
def test_three_point_and_axial_compliance_of_a_free_chain(n_spheres, angle):
    """A free chain loaded P at the middle disc and −P/2 at the ends (transverse), or ±P along
    its axis at the ends: the deflection per load matches the closed forms."""
    spacing = 0.95
    h = chain_stiffness(n_spheres, spacing, angle, BONDS)
    axis = np.array([np.cos(angle), np.sin(angle)])
    normal = np.array([-axis[1], axis[0]])
    assert np.allclose(h, h.T)

    def solve(load):  # free-free: minimum-norm solution of a self-equilibrated load
        return np.linalg.lstsq(h, load, rcond=1e-12)[0].reshape(n_spheres, 3)

    mid, end = n_spheres // 2, n_spheres - 1
    load = np.zeros((n_spheres, 3))
    load[mid, :2] = normal
    load[0, :2] = load[end, :2] = -0.5 * normal
    u = solve(load.ravel())
    deflection = (u[mid, :2] - 0.5 * (u[0, :2] + u[end, :2])) @ normal
    assert deflection == pytest.approx(three_point_compliance(n_spheres, spacing, BONDS),
                                       rel=1e-9)  # fmt: skip
    load = np.zeros((n_spheres, 3))
    load[end, :2] = axis
    load[0, :2] = -axis
    u = solve(load.ravel())
    stretch = (u[end, :2] - u[0, :2]) @ axis
    assert stretch == pytest.approx((n_spheres - 1) / BONDS.normal, rel=1e-9)


def test_pre_forces_put_every_disc_in_equilibrium(friction_network):
    """λ from the chain recursion balance every disc but the last; what is left on the last
    disc is the rod's unbalanced force (equilibrium network: ~0)."""
    snap = friction_network
    pairs = forcelaw.pair_forces(snap)
    lam, residual = bond_pre_forces(snap, pairs)
    rod_force, _ = forcelaw.rod_forces_and_torques(snap)
    np.testing.assert_allclose(residual[:, :2], rod_force, atol=1e-12 * np.abs(pairs.force).max())
    scale = np.abs(pairs.force).max()
    assert np.abs(residual).max() < 1e-9 * scale
    assert np.abs(lam).max() > 1e-3 * scale  # the rods do carry internal forces
    force, torque = disc_forces_and_torques(snap, pairs)
    np.testing.assert_allclose(force.reshape(snap.n_rods, -1, 2).sum(axis=1), rod_force,
                               atol=1e-12 * scale)  # fmt: skip


def rigid_limit_error(snap, mode):
    """Richardson extrapolation of the flexible tangent to infinitely stiff bonds (error
    O(k_n/k_b)) against the rigid tangent; also the first-order convergence ratio."""
    rigid = linear_response(snap, mode)

    def tangent(factor):
        bonds = BondStiffness.relative(snap.k_n, 1.0, factor, factor, factor)
        return flexible_response(snap, bonds, mode).tangent

    t1, t2 = tangent(1e4), tangent(2e4)
    scale = np.abs(rigid.tangent).max()
    extrapolated = 2.0 * t2 - t1
    e1 = np.abs(t1 - rigid.tangent).max() / scale
    e2 = np.abs(t2 - rigid.tangent).max() / scale
    return np.abs(extrapolated - rigid.tangent).max() / scale, e1 / e2


@pytest.mark.parametrize("mode", ["free", "stuck"])
def test_rigid_limit_equals_rigid_response(frictionless_network, friction_network, mode):
    for snap in (frictionless_network, friction_network):
        error, ratio = rigid_limit_error(snap, mode)
        assert error < 1e-6
        assert ratio == pytest.approx(2.0, rel=0.05)  # first order in 1/k_b


def test_rigid_limit_with_sliding_contacts(friction_network):
    snap = on_the_cap(friction_network)
    error, _ = rigid_limit_error(snap, "free")
    assert error < 1e-6


def test_bending_softens_and_pre_forces_matter(friction_network):
    snap = friction_network
    rigid = linear_response(snap, "stuck")
    moduli = []
    for bending in (1.0, 0.1, 0.01):
        flex = flexible_response(snap, BondStiffness.relative(snap.k_n, 1.0, 1.0, 1.0, bending))
        assert flex.solver.residual < 1e-8 and not flex.solver.regularised
        moduli.append(flex.e_oed_v)
    assert rigid.e_oed_v > moduli[0] > moduli[1] > moduli[2] > 0.0
    stiff = BondStiffness.relative(snap.k_n, 1.0, 1e4, 1e4, 1e4)
    with_pre = flexible_response(snap, stiff).tangent
    without = flexible_response(snap, dataclasses.replace(stiff, pre_force="none")).tangent
    assert not np.allclose(with_pre, without, rtol=1e-6)


def test_stiffness_variants(frictionless_network):
    """The default variant is the engine's linearisation; each knob moves what it should."""
    snap = dataclasses.replace(frictionless_network, k_t=300.0)
    base = linear_response(snap, "stuck")
    same = linear_response(snap, "stuck", variant=StiffnessVariant(tangential_stiffness=300.0))
    np.testing.assert_array_equal(base.tangent, same.tangent)
    same = linear_response(snap, "stuck", variant=StiffnessVariant(long_range_factor=1.0))
    np.testing.assert_array_equal(base.tangent, same.tangent)
    stiffer = linear_response(snap, "stuck", variant=StiffnessVariant(tangential_stiffness=1e3))
    assert stiffer.voigt_shear_modulus > base.voigt_shear_modulus
    long_range = linear_response(snap, "stuck", variant=StiffnessVariant(long_range_factor=1e3))
    assert not np.allclose(long_range.tangent, base.tangent, rtol=1e-3)
    rolling = linear_response(snap, "stuck", variant=StiffnessVariant(rolling_stiffness=50.0))
    assert rolling.voigt_shear_modulus > base.voigt_shear_modulus
    # rolling springs act between discs in the flexible model too, and agree in the rigid limit
    bonds = BondStiffness.relative(snap.k_n, 1.0, 1e5, 1e5, 1e5)
    flex = flexible_response(snap, bonds, variant=StiffnessVariant(rolling_stiffness=50.0))
    assert flex.voigt_shear_modulus == pytest.approx(rolling.voigt_shear_modulus, rel=1e-3)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"normal": 0.0, "shear": 1.0, "bending": 1.0}, "normal"),
        ({"normal": 1.0, "shear": np.inf, "bending": 1.0}, "shear"),
        ({"normal": 1.0, "shear": 1.0, "bending": -1.0}, "bending"),
        ({"normal": 1.0, "shear": 1.0, "bending": 1.0, "pre_force": "rigid"}, "pre_force"),
    ],
)
def test_bond_stiffness_rejects_invalid_values(kwargs, message):
    with pytest.raises(ValueError, match=message):
        BondStiffness(**kwargs)


def test_variant_rejects_invalid_values():
    with pytest.raises(ValueError, match="tangential_stiffness"):
        StiffnessVariant(tangential_stiffness=-1.0)
    with pytest.raises(ValueError, match="rolling_stiffness"):
        StiffnessVariant(rolling_stiffness=np.nan)


def test_negative_modes_count_the_inertia(frictionless_network):
    """The symmetric-mode LU counts negative eigenvalues (against numpy on a dense matrix); the
    relaxed frictionless network is stable, and pre-stressed rods with very soft bonds are not."""
    import scipy.sparse as sparse

    from dem_taichi.response.linear import negative_modes

    rng = np.random.default_rng(4)
    q, _ = np.linalg.qr(rng.normal(size=(30, 30)))
    eigenvalues = np.concatenate([-rng.uniform(0.1, 2.0, 4), rng.uniform(0.1, 2.0, 26)])
    matrix = sparse.csc_matrix(q @ np.diag(eigenvalues) @ q.T)
    assert negative_modes(matrix) == 4
    assert linear_response(frictionless_network, stability=True).solver.n_negative_modes == 0
    assert linear_response(frictionless_network).solver.n_negative_modes == -1
