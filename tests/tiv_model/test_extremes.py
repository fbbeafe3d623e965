"""Stability at the extremes: each case ends with a result or a clear, typed error (no NaN)."""

import numpy as np
import pytest

from tiv_model import drivers
from tiv_model.drivers import elastic_probe
from tiv_model.errors import (
    ConvergenceError,
    NonConvexEnergyError,
    ParameterError,
    SpecificVolumeBelowOneError,
)
from tiv_model.integrate import Control, advance, initial_state, state_from_stress
from tiv_model.params import TABLE1, ModelOptions, SolverSettings
from tiv_model.tensors import triaxial, triaxial_fabric

FAST_FAIL = SolverSettings(max_halvings=3)
NO_CF = ModelOptions(constraint_forces=False)


def assert_finite(ds):
    for name in ds.data_vars:
        assert np.all(np.isfinite(ds[name].values)), name


@pytest.mark.parametrize("options", [ModelOptions(), NO_CF], ids=["cf", "nocf"])
def test_very_low_pressure_start(options):
    ds = drivers.k0(0.05, p0=1e-3, increments=6, options=options)
    assert ds.attrs["termination"] == "completed"
    assert_finite(ds)
    assert ds.axial_stress.values[-1] == pytest.approx(0.05, rel=1e-9)
    ds = drivers.isotropic(0.1, p0=1e-3, increments=4, options=options)
    p, pc = ds.mean_stress.values, ds.preconsolidation_pressure.values
    expect = TABLE1.k * TABLE1.p_r * (p / TABLE1.p_r) ** TABLE1.n * (pc / TABLE1.p_r) ** TABLE1.r
    np.testing.assert_allclose(ds.bulk_modulus.values, expect, rtol=1e-10)


def test_very_high_pressure_is_refused_clearly():
    with pytest.raises(SpecificVolumeBelowOneError, match="285.6 kPa"):
        initial_state(1e4)
    # an elastic (heavily overconsolidated) state at 1e4 kPa can still be probed
    state = state_from_stress(triaxial(1e4, 1e4), 1.0, np.zeros(6))
    moduli = elastic_probe(state)
    pc = TABLE1.p_r * TABLE1.N ** (1 / TABLE1.lambda_star)
    expect = TABLE1.k * TABLE1.p_r * (1e4 / TABLE1.p_r) ** TABLE1.n * (pc / TABLE1.p_r) ** TABLE1.r
    assert moduli.bulk_modulus == pytest.approx(expect, rel=1e-10)


def test_specific_volume_reaching_one_stops_with_a_clear_error():
    with pytest.raises(SpecificVolumeBelowOneError) as info:
        drivers.isotropic(1e4, increments=6)
    text = str(info.value)
    assert "285.6 kPa" in text and "v = " in text and "p = " in text
    assert info.value.state.specific_volume < 1.0


@pytest.mark.parametrize("n", [0.9, 0.99])
def test_n_near_one_with_the_energy_exponent_kept(n):
    """n → 1 with r scaled so that X = r/((n−1)λ*) stays at its Table 1 value: exact results."""
    r = TABLE1.energy_exponent * (n - 1.0) * TABLE1.lambda_star
    params = TABLE1.replace(n=n, r=r)
    for options in (ModelOptions(), NO_CF):
        ds = drivers.isotropic(50.0, increments=4, params=params, options=options)
        assert_finite(ds)
        p, pc = ds.mean_stress.values, ds.preconsolidation_pressure.values
        v_exact = TABLE1.N * (pc / TABLE1.p_r) ** (-TABLE1.lambda_star)
        np.testing.assert_allclose(ds.specific_volume.values, v_exact, rtol=1e-10)
        expect = params.k * params.p_r * (p / params.p_r) ** n * (pc / params.p_r) ** r
        np.testing.assert_allclose(ds.bulk_modulus.values, expect, rtol=1e-9)
    with pytest.raises(ParameterError, match="n < 1"):
        TABLE1.replace(n=1.0)


def test_n_near_one_with_table1_r_is_refused_clearly():
    """With r = 0.63, X = r/((n−1)λ*) → −∞: no NC state with constraint forces, and without
    them plastic compaction stiffens faster than it unloads (no Δλ ≥ 0 solution)."""
    params = TABLE1.replace(n=0.9)
    with pytest.raises(ParameterError, match="constraint force"):
        initial_state(5.0, params)
    with pytest.raises(ConvergenceError, match="unstable"):
        drivers.isotropic(50.0, increments=2, params=params, options=NO_CF, settings=FAST_FAIL)


def _fabric_state(beta0, eta, params, options=NO_CF, p=40.0):
    """A state on the yield surface (no constraint forces) at stress ratio η, fabric β0."""
    sigma = triaxial(p * (1 + 2 * eta / 3), p * (1 - eta / 3))
    m2 = params.M**2 - beta0**2
    pc = p * (1 + (eta - beta0) ** 2 / m2)
    v = params.N * (pc / params.p_r) ** (-params.lambda_star)
    return state_from_stress(sigma, v, triaxial_fabric(beta0), params, options)


def _eta_for_bound(beta, params):
    return -params.M / params.s * np.log(1 - beta / params.maximum_fabric)


def test_fabric_energy_close_to_the_convexity_limit():
    """ω β² = 1.499: elastic increments give finite results with an SPD stiffness of huge
    anisotropy; a plastic increment ends with a result or a typed error naming the state."""
    beta0 = 0.15
    params = TABLE1.replace(omega=1.499 / beta0**2)
    start = _fabric_state(beta0, _eta_for_bound(beta0, params), params)
    state = start
    for _ in range(3):
        state = advance(state, Control.strain(triaxial(-1e-4, 0.0)), params, NO_CF)
    assert not state.plastic and np.all(np.isfinite(state.stress))
    moduli = elastic_probe(state, params, NO_CF)
    assert np.linalg.eigvalsh(moduli.stiffness).min() > 0
    assert moduli.stiffness_ratio > 1e5  # (1 + x/3)² / (1 − 2x/3)² with x → 3/2
    try:
        loaded = advance(start, Control.strain(triaxial(1e-4, 1e-4)), params, NO_CF, FAST_FAIL)
    except (ConvergenceError, NonConvexEnergyError) as exc:
        assert "state:" in str(exc)
    else:
        assert np.all(np.isfinite(loaded.stress))
        assert params.omega * loaded.fabric_scalar**2 < 1.5


def test_fabric_energy_beyond_the_convexity_limit_raises():
    """Loading at a higher η drives β towards β_b > sqrt(1.5/ω): a typed error, never NaN."""
    beta0 = 0.15
    params = TABLE1.replace(omega=1.45 / beta0**2)
    state = _fabric_state(beta0, 0.8, params)
    with pytest.raises((NonConvexEnergyError, ConvergenceError)) as info:
        for _ in range(30):
            state = advance(state, Control.strain(triaxial(2e-3, -1e-3)), params, NO_CF,
                            FAST_FAIL)  # fmt: skip
            assert np.all(np.isfinite(state.stress))
    assert "state:" in str(info.value)


def test_fabric_at_its_bound_stays_there():
    eta, p = 0.6, 40.0
    sigma = triaxial(p * (1 + 2 * eta / 3), p * (1 - eta / 3))
    bound = TABLE1.maximum_fabric * -np.expm1(-TABLE1.s * eta / TABLE1.M)
    beta = triaxial_fabric(bound)
    m2 = TABLE1.M**2 - bound**2
    pc = p * (1 + (eta - bound) ** 2 / m2)  # on the yield surface without constraint forces
    v = TABLE1.N * (pc / TABLE1.p_r) ** (-TABLE1.lambda_star)
    start = state_from_stress(sigma, v, beta, TABLE1, NO_CF)
    ds = drivers.radial(eta, p_max=80.0, increments=5, approach_increments=1, state=start,
                        options=NO_CF)  # fmt: skip
    assert np.all(ds.plastic.values[2:] == 1)
    np.testing.assert_allclose(ds.fabric.values, bound, rtol=1e-9)
    np.testing.assert_allclose(ds.bounding_fabric.values, bound, rtol=1e-9)


def test_stress_ratio_towards_m_under_strain_control():
    """Drained triaxial (axial strain control): η rises towards the critical state, below M."""
    ds = drivers.drained_triaxial(0.6, p0=20.0, increments=20)
    assert ds.attrs["termination"] == "completed"
    assert_finite(ds)
    eta = ds.stress_ratio.values
    assert np.all(np.diff(eta) > 0)
    assert 0.95 < eta[-1] < TABLE1.M


def test_stress_ratio_beyond_m_under_stress_control_raises():
    with pytest.raises(ConvergenceError) as info:
        drivers.radial(1.2 * TABLE1.M, p_max=20.0, increments=4, approach_increments=4,
                       settings=FAST_FAIL)  # fmt: skip
    assert "stress ratio" in str(info.value) and "q = " in str(info.value)
    ok = drivers.radial(0.5 * TABLE1.M, p_max=20.0, increments=4, approach_increments=4)
    assert ok.stress_ratio.values[-1] == pytest.approx(0.5 * TABLE1.M, rel=1e-8)


def test_tension_is_refused_without_nan():
    with pytest.raises(ConvergenceError, match="p_min|converge"):
        advance(initial_state(), Control.strain(triaxial(-0.2, -0.2)), settings=FAST_FAIL)
