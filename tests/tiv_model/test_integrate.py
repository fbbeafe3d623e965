"""Implicit integration: exact isotropic solutions, thermodynamic checks, admissibility."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

from tiv_model import checks, drivers
from tiv_model.drivers import elastic_probe, run_path
from tiv_model.integrate import (
    Control,
    advance,
    algorithmic_tangent,
    initial_state,
    state_from_stress,
)
from tiv_model.params import TABLE1, ModelOptions, SolverSettings
from tiv_model.tensors import triaxial

from .conftest import ALL_OPTIONS, option_id


def exact_ncl_preconsolidation(p, params, constraint_forces):
    """p_c on the isotropic NCL, solved independently of the package.

    Without constraint forces the yield surface passes through (p_c, 0): p_c = p. With them it
    passes through p̂ = p − Λ_K = p_c, Λ_K = −X φ, φ = p ε^e_v (1−n)/(2−n) on the isotropic axis
    and ε^e_v = (p/p_r)^(1−n) (p_c/p_r)^(−r) / (k(1−n)).
    """
    if not constraint_forces:
        return p
    pr, k, n, r = params.p_r, params.k, params.n, params.r
    x = r / ((n - 1.0) * params.lambda_star)

    def g(pc):
        eps_v = (p / pr) ** (1 - n) * (pc / pr) ** (-r) / (k * (1 - n))
        return pc - (p + x * p * eps_v * (1 - n) / (2 - n))

    return brentq(g, 0.5 * p, p, xtol=1e-15 * p, rtol=1e-15)


@pytest.mark.parametrize("options", ALL_OPTIONS[:2] + ALL_OPTIONS[3:], ids=option_id)
@pytest.mark.parametrize("increments", [3, 40])
def test_normal_compression_line_is_exact_whatever_the_increments(options, increments):
    """v = N (p_c/p_r)^(−λ*) with p_c from the exact isotropic yield condition, at every step."""
    ds = drivers.isotropic(250.0, p0=5.0, increments=increments, options=options)
    assert ds.attrs["termination"] == "completed"
    for p, v in zip(ds.mean_stress.values, ds.specific_volume.values, strict=True):
        pc = exact_ncl_preconsolidation(p, TABLE1, options.constraint_forces)
        v_exact = TABLE1.N * (pc / TABLE1.p_r) ** (-TABLE1.lambda_star)
        assert v == pytest.approx(v_exact, rel=1e-10)
    assert np.allclose(ds.fabric.values, 0.0, atol=1e-9)  # roundoff of the stress control
    assert ds.mean_stress.values[-1] == pytest.approx(250.0, rel=1e-9)


def test_isotropic_moduli_along_the_path_are_exact():
    ds = drivers.isotropic(200.0, p0=5.0, increments=12)
    p, pc = ds.mean_stress.values, ds.preconsolidation_pressure.values
    expect = TABLE1.p_r * (p / TABLE1.p_r) ** TABLE1.n * (pc / TABLE1.p_r) ** TABLE1.r
    np.testing.assert_allclose(ds.bulk_modulus.values, TABLE1.k * expect, rtol=1e-10)
    np.testing.assert_allclose(ds.shear_modulus.values, TABLE1.g * expect, rtol=1e-10)
    np.testing.assert_allclose(ds.e_oed_v.values, ds.e_oed_h.values, rtol=1e-10)


def test_algorithmic_tangent_matches_finite_differences():
    state = run_path(
        initial_state(),
        [Control.triaxial(axial_stress=s, radial_strain_increment=0.0) for s in (8.0, 15.0, 30.0)],
    )[0][-1]
    deps = triaxial(2e-3, 0.0) + np.array([0, 1e-4, -2e-4, 1e-4, 0, 5e-5])
    _, tangent = algorithmic_tangent(state, deps)
    h = 1e-7
    fd = np.array(
        [
            (algorithmic_tangent(state, deps + h * e)[0].stress
             - algorithmic_tangent(state, deps - h * e)[0].stress) / (2 * h)
            for e in np.eye(6)
        ]
    ).T  # fmt: skip
    np.testing.assert_allclose(tangent, fd, atol=2e-5 * np.abs(fd).max())


def _k0_states(options, sigma_max=60.0, increments=12):
    targets = np.geomspace(5.0, sigma_max, increments + 1)[1:]
    controls = [Control.triaxial(axial_stress=s, radial_strain_increment=0.0) for s in targets]
    return run_path(initial_state(5.0, TABLE1, options), controls, TABLE1, options)[0]


@pytest.mark.parametrize("form", ["A", "B"])
def test_closed_elastic_loop_gives_zero_net_work_and_returns_the_state(form):
    options = ModelOptions(anisotropy=form)
    start = _k0_states(options)[-1]
    # unload a little first so that the loop stays inside the yield surface
    inside = advance(start, Control.strain(triaxial(-2e-3, 0.0)), TABLE1, options)
    assert checks.yield_value(inside, TABLE1, options) < 0
    angles = np.linspace(0, 2 * np.pi, 401)
    path = 3e-4 * np.stack(
        [np.cos(angles) - 1, np.sin(angles), 0.5 * np.sin(2 * angles), 0 * angles,
         0.3 * np.sin(angles), 0.2 * (np.cos(angles) - 1)], axis=1
    )  # fmt: skip
    steps = np.diff(path, axis=0)
    net, gross, end = checks.closed_loop_work(inside, steps, TABLE1, options)
    assert abs(net) < 1e-5 * gross
    np.testing.assert_allclose(end.stress, inside.stress, atol=1e-10 * np.abs(inside.stress).max())
    assert end.specific_volume == inside.specific_volume
    np.testing.assert_array_equal(end.fabric, inside.fabric)


@pytest.mark.parametrize("options", ALL_OPTIONS, ids=option_id)
def test_thermodynamic_identity_on_k0(options):
    """σ:Δε^p − vφ_v Δln v − φ_β:Δβ equals d ≥ 0 with constraint forces (not without)."""
    states = _k0_states(options)
    pairs = list(zip(states[:-1], states[1:], strict=True))
    values = np.array([checks.mechanical_dissipation(a, b, TABLE1, options) for a, b in pairs])
    assert np.all(values[:, 1] > 0)
    if options.constraint_forces:
        np.testing.assert_allclose(values[:, 0], values[:, 1], rtol=1e-8)
    else:
        assert np.max(np.abs(values[:, 0] / values[:, 1] - 1)) > 1e-3
    for a, b in pairs:
        assert checks.fabric_within_bounds(a, b, TABLE1, options) < 1e-12
        assert abs(checks.yield_value(b, TABLE1, options)) < 1e-9


increment = st.tuples(
    st.floats(-1.0, 3.0), st.floats(-1.0, 1.5), st.floats(-1.0, 1.5),
    st.floats(-0.5, 0.5), st.floats(-0.5, 0.5), st.floats(-0.5, 0.5),
)  # fmt: skip


@settings(max_examples=12, deadline=None)
@given(st.lists(increment, min_size=3, max_size=6), st.sampled_from(["A", "B"]))
def test_random_admissible_paths_dissipate(path, form):
    """Random strain paths (compression dominated): d ≥ 0, identity holds, β between β_n, β_b."""
    options = ModelOptions(anisotropy=form)
    state = initial_state(20.0, TABLE1, options)
    for raw in path:
        deps = 2e-3 * np.array(raw)
        new = advance(state, Control.strain(deps), TABLE1, options)
        work, d = checks.mechanical_dissipation(state, new, TABLE1, options)
        assert d >= -1e-14 * state.mean_stress
        assert work == pytest.approx(d, rel=1e-7, abs=1e-10 * state.mean_stress)
        assert checks.fabric_within_bounds(state, new, TABLE1, options) < 1e-12
        assert checks.yield_value(new, TABLE1, options) < 1e-9
        assert new.dissipated_energy >= state.dissipated_energy
        state = new


def test_constant_p_unloading_from_k0_is_elastic():
    options = ModelOptions()
    top = _k0_states(options, sigma_max=100.0, increments=20)[-1]
    ds = drivers.constant_p_unloading(top, increments=8)
    assert ds.attrs["termination"] == "completed"
    assert np.all(ds.plastic.values[1:] == 0)
    np.testing.assert_allclose(ds.mean_stress.values, top.mean_stress, rtol=1e-9)
    assert ds.deviatoric_stress.values[-1] == pytest.approx(0.0, abs=1e-7)
    assert np.all(ds.specific_volume.values == top.specific_volume)
    assert np.all(ds.fabric.values == ds.fabric.values[0])


def test_state_from_stress_round_trip_and_probe_leaves_state_unchanged():
    fabric = np.array([0.08, -0.04, -0.04, 0.0, 0.01, 0.0])
    state = state_from_stress(triaxial(90.0, 55.0), 1.6, fabric)
    np.testing.assert_allclose(state.stress, triaxial(90.0, 55.0), rtol=1e-12, atol=1e-10)
    before = (state.stress.copy(), state.elastic_strain.copy(), state.specific_volume)
    moduli = elastic_probe(state)
    assert moduli.e_oed_h > moduli.e_oed_v > 0
    np.testing.assert_array_equal(state.stress, before[0])
    np.testing.assert_array_equal(state.elastic_strain, before[1])
    assert state.specific_volume == before[2]


def test_solver_settings_are_respected():
    with pytest.raises(Exception, match="Newton|halvings|converge"):
        advance(
            initial_state(),
            Control.strain(triaxial(0.05, -0.02)),
            settings=SolverSettings(max_iterations=1, max_halvings=0),
        )


GENERAL = SolverSettings(triaxial_fast_path=False)


@pytest.mark.parametrize("options", ALL_OPTIONS, ids=option_id)
def test_triaxial_fast_path_equals_general_tensor_path(options):
    """The scalar axisymmetric solver and the 3×3 Mandel solver give the same states."""
    fast = drivers.k0_then_unload(120.0, increments=10, unload_increments=3, options=options)
    general = drivers.k0_then_unload(
        120.0, increments=10, unload_increments=3, options=options, settings=GENERAL
    )
    for name in ("axial_stress", "radial_stress", "specific_volume", "fabric", "e_oed_h",
                 "dissipated_energy", "plastic_multiplier"):  # fmt: skip
        scale = float(np.max(np.abs(general[name].values)))
        np.testing.assert_allclose(fast[name].values, general[name].values, atol=1e-9 * scale)


def test_general_path_reproduces_the_ncl():
    options = ModelOptions()
    ds = drivers.isotropic(150.0, increments=5, options=options, settings=GENERAL)
    for p, v in zip(ds.mean_stress.values, ds.specific_volume.values, strict=True):
        pc = exact_ncl_preconsolidation(p, TABLE1, True)
        assert v == pytest.approx(TABLE1.N * (pc / TABLE1.p_r) ** (-TABLE1.lambda_star), rel=1e-10)


def test_fast_path_is_used_only_for_axisymmetric_controls():
    from tiv_model.triaxial import is_axisymmetric

    state = initial_state()
    assert is_axisymmetric(state, Control.triaxial(axial_stress=10.0, radial_strain_increment=0))
    assert not is_axisymmetric(state, Control.strain([1e-3, 0, 1e-4, 0, 0, 0]))
    assert not is_axisymmetric(state, Control.strain([1e-3, 0, 0, 1e-4, 0, 0]))
