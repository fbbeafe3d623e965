"""Dissipation, yield function, flow rule and bounding fabric."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tiv_model.checks import legendre_consistency
from tiv_model.dissipation import (
    bounding_fabric,
    dissipation_rate,
    dissipative_stress,
    flow_direction,
    preconsolidation_pressure,
    specific_volume_for_preconsolidation,
    yield_function,
)
from tiv_model.params import TABLE1, ModelOptions, hyperbolic_tangent_bound
from tiv_model.tensors import deviator, triaxial, triaxial_fabric


def test_preconsolidation_and_ncl_are_inverse():
    for pc in (1e-3, 5.0, 100.0, 285.6, 1e4):
        v = specific_volume_for_preconsolidation(pc, TABLE1)
        assert preconsolidation_pressure(v, TABLE1) == pytest.approx(pc, rel=1e-13)
    assert specific_volume_for_preconsolidation(TABLE1.p_r, TABLE1) == pytest.approx(TABLE1.N)


def test_triaxial_yield_function_without_constraint_forces():
    """(q − pβ)² = (M² − β²) p (p_c − p) on the surface (docs/science/tiv-model.md §2.2)."""
    rng = np.random.default_rng(0)
    for _ in range(20):
        p, q, pc, beta = rng.uniform(1, 100), rng.uniform(-80, 80), rng.uniform(50, 200), 0.15
        sig = triaxial(p + 2 * q / 3, p - q / 3)
        y = yield_function(sig, triaxial_fabric(beta), pc, TABLE1)
        expect = (q - p * beta) ** 2 - (TABLE1.M**2 - beta**2) * p * (pc - p)
        assert y == pytest.approx(expect, rel=1e-12, abs=1e-9)


def test_flow_direction_is_gradient_of_yield_function():
    rng = np.random.default_rng(1)
    sig = triaxial(120.0, 70.0) + deviator(rng.standard_normal(6))
    beta = triaxial_fabric(0.1) + 0.02 * deviator(rng.standard_normal(6))
    pc, shift, size = 150.0, 3.0, 80.0
    n = flow_direction(sig, beta, pc, TABLE1, shift)
    h = 1e-5
    fd = np.array(
        [
            (
                yield_function(sig + h * e, beta, pc, TABLE1, size, shift)
                - yield_function(sig - h * e, beta, pc, TABLE1, size, shift)
            )
            / (2 * h)
            for e in np.eye(6)
        ]
    )
    np.testing.assert_allclose(n, fd, rtol=1e-8, atol=1e-8 * np.abs(n).max())


rates = st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6).filter(
    lambda x: np.linalg.norm(x) > 1e-3
)
fabrics = st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6)


@settings(max_examples=60, deadline=None)
@given(rates, fabrics, st.floats(0.0, 1.0), st.floats(1.0, 500.0), st.floats(-0.3, 0.3),
       st.floats(-5.0, 5.0))  # fmt: skip
def test_legendre_consistency_random(rate, fabric, size_fraction, pc, size_offset, shift):
    """χ = ∂d/∂ε̇^p lies on y = 0 and the flow ∂y/∂χ is parallel to ε̇^p (any A, Λ_K)."""
    beta = deviator(np.array(fabric))
    norm = np.sqrt(1.5 * beta @ beta)
    if norm > 0:
        beta *= size_fraction * TABLE1.maximum_fabric / norm
    size = pc * (0.5 + size_offset)
    y, angle = legendre_consistency(np.array(rate), beta, pc, TABLE1, size, shift)
    assert y < 1e-10
    assert angle < 1e-10


@settings(max_examples=60, deadline=None)
@given(rates, fabrics, st.floats(0.0, 1.0), st.floats(1e-3, 1e4))
def test_dissipation_is_non_negative_and_homogeneous(rate, fabric, size_fraction, pc):
    beta = deviator(np.array(fabric))
    norm = np.sqrt(1.5 * beta @ beta)
    if norm > 0:
        beta *= size_fraction * TABLE1.maximum_fabric / norm
    d = float(dissipation_rate(np.array(rate), beta, pc, TABLE1))
    assert d >= -1e-12 * pc
    assert float(dissipation_rate(3.0 * np.array(rate), beta, pc, TABLE1)) == pytest.approx(3 * d)
    # χ:ε̇^p = d (first-order homogeneity, Euler)
    chi = dissipative_stress(np.array(rate), beta, pc, TABLE1)
    assert float(chi @ np.array(rate)) == pytest.approx(d, rel=1e-9, abs=1e-12 * pc)


@pytest.mark.parametrize("law", ["exponential", "tanh"])
def test_bounding_fabric_triaxial_limits(law):
    options = ModelOptions(bound_law=hyperbolic_tangent_bound) if law == "tanh" else ModelOptions()
    iso = bounding_fabric(triaxial(50.0, 50.0), TABLE1, options)
    assert np.allclose(iso, 0.0)
    big = bounding_fabric(triaxial(300.0, 10.0), TABLE1, options)
    np.testing.assert_allclose(big, triaxial_fabric(TABLE1.M / TABLE1.z), rtol=1e-6)
    ext = bounding_fabric(triaxial(10.0, 300.0), TABLE1, options)
    assert ext[0] - ext[1] < 0  # signed like q
    p, q = 100.0, 60.0
    bb = bounding_fabric(triaxial(p + 2 * q / 3, p - q / 3), TABLE1)
    expect = TABLE1.M / TABLE1.z * (1 - np.exp(-TABLE1.s * (q / p) / TABLE1.M))
    assert bb[0] - bb[1] == pytest.approx(expect, rel=1e-13)
