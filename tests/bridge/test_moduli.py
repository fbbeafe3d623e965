"""Model moduli at measured states: closed form on the isotropic axis, agreement with tiv_model."""

import numpy as np
import pytest

from bridge.moduli import ModuliError, moduli_at_states, triaxial_elastic_strain
from tiv_model.errors import NonConvexEnergyError
from tiv_model.params import TABLE1


def test_isotropic_axis_closed_form():
    p = np.array([2.0, 10.0, 50.0, 300.0])
    v = np.array([2.2, 1.8, 1.5, 1.2])
    mod = moduli_at_states(p, p, v, 0.0, TABLE1)
    pc = TABLE1.p_r * (v / TABLE1.N) ** (-1.0 / TABLE1.lambda_star)
    factor = TABLE1.p_r * (p / TABLE1.p_r) ** TABLE1.n * (pc / TABLE1.p_r) ** TABLE1.r
    bulk, shear = TABLE1.k * factor, TABLE1.g * factor
    np.testing.assert_allclose(mod["e_oed_v"], bulk + 4 * shear / 3, rtol=1e-10)
    np.testing.assert_allclose(mod["e_oed_h"], bulk + 4 * shear / 3, rtol=1e-10)
    np.testing.assert_allclose(mod["e_cross"], bulk - 2 * shear / 3, rtol=1e-10)


def test_inversion_reproduces_the_stress_at_anisotropic_states():
    from tiv_model.energy import stress
    from tiv_model.tensors import TRIAXIAL_DIRECTION_MANDEL

    sa = np.array([30.0, 120.0, 80.0])
    sr = np.array([20.0, 75.0, 80.0])
    v = np.array([1.6, 1.35, 1.4])
    beta = np.array([0.1, 0.15, -0.05])
    eps = triaxial_elastic_strain(sa, sr, v, beta, TABLE1)
    sig = stress(eps, v, beta[:, None] * TRIAXIAL_DIRECTION_MANDEL, TABLE1)
    np.testing.assert_allclose(sig[:, 0], sa, rtol=1e-11)
    np.testing.assert_allclose(sig[:, 1], sr, rtol=1e-11)
    np.testing.assert_allclose(sig[:, 2], sr, rtol=1e-11)


def test_agrees_with_the_drivers_along_k0(synthetic):
    from .conftest import TRUTH

    k0 = synthetic.model["k0"]
    mod = moduli_at_states(
        k0["axial_stress"], k0["radial_stress"], k0["specific_volume"], k0["fabric"], TRUTH
    )
    np.testing.assert_allclose(mod["e_oed_v"], k0["e_oed_v"].values, rtol=1e-9)
    np.testing.assert_allclose(mod["stiffness_ratio"], k0["stiffness_ratio"].values, rtol=1e-9)
    assert mod["stiffness_ratio"][-1] > 1.2  # rods lying down: stiffer horizontally


def test_clear_errors():
    with pytest.raises(ModuliError, match="p ≤ 0"):
        moduli_at_states([1.0], [-5.0], [1.5], [0.0], TABLE1)
    with pytest.raises(NonConvexEnergyError, match="ω β_s²"):
        moduli_at_states([10.0], [8.0], [1.5], [0.3], TABLE1)
