"""Free energy, stress, closed-form stiffness: exact values and finite-difference checks."""

import numpy as np
import pytest

from tiv_model.energy import (
    check_convexity,
    elastic_strain_for_stress,
    fabric_derivative,
    free_energy,
    isotropic_elastic_volumetric_strain,
    mapping_matrix,
    stiffness,
    stress,
)
from tiv_model.errors import NonConvexEnergyError
from tiv_model.params import TABLE1, ModelOptions
from tiv_model.tensors import (
    IDENTITY_MANDEL,
    deviator,
    from_mandel,
    mandel_to_tensor4,
    tensor4_to_mandel,
    to_mandel,
    triaxial_fabric,
)

from .conftest import random_elastic_state


def central_difference(fun, x, h):
    cols = []
    for j in range(x.size):
        e = np.zeros_like(x)
        e[j] = h
        cols.append((fun(x + e) - fun(x - e)) / (2 * h))
    return np.array(cols).T


@pytest.mark.parametrize("seed", range(6))
def test_stress_is_gradient_of_energy_and_stiffness_is_its_jacobian(form, seed):
    rng = np.random.default_rng(seed)
    opts = ModelOptions(anisotropy=form)
    eps, v, beta = random_elastic_state(rng)
    h = 1e-6 * np.max(np.abs(eps))
    sig = stress(eps, v, beta, TABLE1, opts)
    grad = central_difference(
        lambda e: np.atleast_1d(free_energy(e, v, beta, TABLE1, opts)), eps, h
    )
    np.testing.assert_allclose(grad.ravel(), sig, rtol=0, atol=1e-7 * np.max(np.abs(sig)))
    d = stiffness(eps, v, beta, TABLE1, opts)
    d_fd = central_difference(lambda e: stress(e, v, beta, TABLE1, opts), eps, h)
    np.testing.assert_allclose(d, d_fd, rtol=0, atol=1e-7 * np.max(np.abs(d)))
    np.testing.assert_allclose(d, d.T, atol=1e-10 * np.max(np.abs(d)))
    assert np.all(np.linalg.eigvalsh(d) > 0.0)


@pytest.mark.parametrize("seed", range(4))
def test_fabric_derivative_matches_finite_differences(form, seed):
    rng = np.random.default_rng(100 + seed)
    opts = ModelOptions(anisotropy=form)
    eps, v, beta = random_elastic_state(rng)
    h = 1e-6
    phi_beta = fabric_derivative(eps, v, beta, TABLE1, opts)
    grad = central_difference(
        lambda b: np.atleast_1d(free_energy(eps, v, b, TABLE1, opts)), beta, h
    ).ravel()
    np.testing.assert_allclose(phi_beta, deviator(grad), atol=1e-6 * np.max(np.abs(phi_beta)))


def test_isotropic_axis_moduli_are_exact():
    """K = k p_r (p/p_r)^n (p_c/p_r)^r and G = g p_r (...) to 1e-10 for β = 0."""
    p_r, k, g, n, r = TABLE1.p_r, TABLE1.k, TABLE1.g, TABLE1.n, TABLE1.r
    for p in (1e-3, 0.1, 5.0, 100.0, 1e4):
        for pc in (p, 3.0 * p, 50.0):
            v = TABLE1.N * (pc / p_r) ** (-TABLE1.lambda_star)
            eps_v = float(isotropic_elastic_volumetric_strain(p, v, TABLE1))
            eps = eps_v / 3.0 * IDENTITY_MANDEL
            sig = stress(eps, v, np.zeros(6), TABLE1)
            assert np.allclose(sig, p * IDENTITY_MANDEL, rtol=1e-12, atol=0)
            d = stiffness(eps, v, np.zeros(6), TABLE1)
            bulk = IDENTITY_MANDEL @ d @ IDENTITY_MANDEL / 9.0
            shear = d[3, 3] / 2.0
            expect = p_r * (p / p_r) ** n * (pc / p_r) ** r
            assert bulk == pytest.approx(k * expect, rel=1e-10)
            assert shear == pytest.approx(g * expect, rel=1e-10)
            # isotropic structure of D
            assert d[0, 0] == pytest.approx((k + 4 * g / 3) * expect, rel=1e-10)
            assert d[0, 1] == pytest.approx((k - 2 * g / 3) * expect, rel=1e-10)


def test_triaxial_mapping_of_form_a():
    """ε̃_a = (1 − 2x/3) ε_a, ε̃_r = (1 + x/3) ε_r with x = ω β² (docs/science/tiv-model.md §2.1)."""
    beta = 0.13
    x = TABLE1.omega * beta**2
    pmat = mapping_matrix(triaxial_fabric(beta), TABLE1, ModelOptions(anisotropy="A"))
    assert np.allclose(np.diag(pmat)[:3], [1 - 2 * x / 3, 1 + x / 3, 1 + x / 3], rtol=1e-14)
    pmat_b = mapping_matrix(triaxial_fabric(beta), TABLE1, ModelOptions(anisotropy="B"))
    bm = triaxial_fabric(beta)
    assert np.allclose(pmat_b, np.eye(6) - TABLE1.omega * np.outer(bm, bm))


def test_general_tensor_matches_fourth_order_and_is_frame_indifferent(form):
    rng = np.random.default_rng(7)
    opts = ModelOptions(anisotropy=form)
    eps, v, beta = random_elastic_state(rng)
    q, _ = np.linalg.qr(rng.standard_normal((3, 3)))

    def rotate(m):
        return to_mandel(q @ from_mandel(m) @ q.T)

    sig = stress(eps, v, beta, TABLE1, opts)
    np.testing.assert_allclose(
        stress(rotate(eps), v, rotate(beta), TABLE1, opts), rotate(sig), atol=1e-10 * abs(sig).max()
    )
    assert free_energy(rotate(eps), v, rotate(beta), TABLE1, opts) == pytest.approx(
        free_energy(eps, v, beta, TABLE1, opts), rel=1e-12
    )
    d = stiffness(eps, v, beta, TABLE1, opts)
    d4 = mandel_to_tensor4(d)
    np.testing.assert_allclose(tensor4_to_mandel(d4), d, atol=1e-9 * abs(d).max())
    sig4 = np.einsum("ijkl,kl->ij", d4, from_mandel(eps))
    np.testing.assert_allclose(to_mandel(sig4), d @ eps, atol=1e-9 * abs(d).max())


def test_batched_evaluation_equals_pointwise(form):
    rng = np.random.default_rng(3)
    opts = ModelOptions(anisotropy=form)
    states = [random_elastic_state(rng) for _ in range(5)]
    eps = np.array([s[0] for s in states])
    v = np.array([s[1] for s in states])
    beta = np.array([s[2] for s in states])
    d = stiffness(eps, v, beta, TABLE1, opts)
    for i in range(5):
        np.testing.assert_allclose(d[i], stiffness(eps[i], v[i], beta[i], TABLE1, opts), rtol=1e-13)


def test_elastic_law_inversion_round_trip(form):
    rng = np.random.default_rng(11)
    opts = ModelOptions(anisotropy=form)
    for _ in range(5):
        eps, v, beta = random_elastic_state(rng)
        sig = stress(eps, v, beta, TABLE1, opts)
        back = elastic_strain_for_stress(sig, v, beta, TABLE1, opts)
        np.testing.assert_allclose(back, eps, atol=1e-10 * np.max(np.abs(eps)))


def test_convexity_limit_raises_a_typed_error():
    limit = np.sqrt(1.5 / TABLE1.omega)
    check_convexity(triaxial_fabric(0.999 * limit), TABLE1)
    with pytest.raises(NonConvexEnergyError, match="3/2"):
        check_convexity(triaxial_fabric(1.0001 * limit), TABLE1)
    with pytest.raises(NonConvexEnergyError):
        check_convexity(triaxial_fabric(-1.0001 * limit), TABLE1)


def test_stiffness_loses_positive_definiteness_exactly_at_the_limit(form):
    """Near ω β_s² = 3/2 the smallest eigenvalue of P(β) → 0 (the reason for the check)."""
    opts = ModelOptions(anisotropy=form)
    limit = np.sqrt(1.5 / TABLE1.omega)
    eig = [np.linalg.eigvalsh(mapping_matrix(triaxial_fabric(f * limit), TABLE1, opts)).min()
           for f in (0.9, 0.99, 0.999)]  # fmt: skip
    assert eig[0] > eig[1] > eig[2] > 0.0
    assert eig[2] < 3e-3
