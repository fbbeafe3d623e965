"""Exact Jacobians of the implicit update against finite differences, and the new solvers
against the scheme before issue 12 (finite-difference Jacobian, nested mixed control)."""

import itertools
import math

import numpy as np
import pytest

from tiv_model import drivers
from tiv_model.params import BOUND_LAWS, TABLE1, ModelOptions, SolverSettings
from tiv_model.triaxial import TriaxialModel, elastic_tangent, finite_difference_elastic_tangent

from .conftest import ALL_OPTIONS, option_id

BEFORE = SolverSettings(jacobian="finite_difference", mixed_control="nested")
LAWS = sorted(BOUND_LAWS)


def central_difference(fun, x, steps):
    cols = []
    for j, h in enumerate(steps):
        xp, xm = list(x), list(x)
        xp[j] += h
        xm[j] -= h
        cols.append((np.asarray(fun(xp)) - np.asarray(fun(xm))) / (2 * h))
    return np.array(cols).T


def random_point(rng):
    ea = rng.uniform(0.005, 0.03)
    er = ea * rng.uniform(0.3, 1.2)
    beta = rng.uniform(-0.15, 0.2)
    lnv = math.log(rng.uniform(1.2, 1.8))
    mu = rng.uniform(1e-5, 1e-3)
    return [ea, er, mu, beta, lnv]


@pytest.mark.parametrize(
    ("options", "law"),
    list(itertools.product(ALL_OPTIONS, LAWS)),
    ids=[f"{option_id(o)}-{law}" for o, law in itertools.product(ALL_OPTIONS, LAWS)],
)
def test_triaxial_jacobian_matches_central_differences(options, law):
    model = TriaxialModel(TABLE1, ModelOptions(options.anisotropy, options.constraint_forces,
                                               BOUND_LAWS[law]))  # fmt: skip
    rng = np.random.default_rng(7)
    for _ in range(12):
        x = random_point(rng)
        args = (x[0] * 1.01, x[1] * 0.99, x[3] * 0.9, x[4] + 1e-3)
        res, sa, sr, _, jac, dsig = model.evaluate_jacobian(x, *args)
        assert res is not None
        ref_res, ref_sa, ref_sr, _ = model.evaluate(x, *args)
        np.testing.assert_allclose(res, ref_res, rtol=1e-14, atol=1e-18)
        np.testing.assert_allclose((sa, sr), (ref_sa, ref_sr), rtol=1e-14)
        steps = [1e-6 * max(abs(v), 1e-4) for v in x]
        fd = central_difference(lambda y, a=args: model.evaluate(y, *a)[0], x, steps)
        fd_sig = central_difference(lambda y, a=args: model.evaluate(y, *a)[1:3], x, steps)
        scale = np.maximum(np.abs(fd).max(axis=1, keepdims=True), 1e-300)
        np.testing.assert_allclose(np.array(jac) / scale, fd / scale, atol=2e-6)
        np.testing.assert_allclose(dsig, fd_sig, atol=2e-6 * np.abs(fd_sig).max())


@pytest.mark.parametrize("form", ["A", "B"])
def test_triaxial_jacobian_at_zero_multiplier_is_the_forward_derivative(form):
    """ΔD̄ = |μ| D̄₁: at μ = 0 the Jacobian is the derivative for μ > 0 (the Newton's start)."""
    model = TriaxialModel(TABLE1, ModelOptions(anisotropy=form))
    x = [0.02, 0.015, 0.0, 0.08, math.log(1.5)]
    args = (0.021, 0.015, 0.07, math.log(1.5))
    jac = np.array(model.evaluate_jacobian(x, *args)[4])
    h = 1e-9
    xp = list(x)
    xp[2] = h
    forward = (np.array(model.evaluate(xp, *args)[0]) - model.evaluate(x, *args)[0]) / h
    np.testing.assert_allclose(jac[:, 2], forward, rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize("form", ["A", "B"])
def test_triaxial_elastic_tangent_is_exact(form):
    model = TriaxialModel(TABLE1, ModelOptions(anisotropy=form))
    for beta in (0.0, 0.11, -0.07):
        exact = elastic_tangent(model, 0.02, 0.012, beta, math.log(1.4))
        fd = finite_difference_elastic_tangent(model, 0.02, 0.012, beta, math.log(1.4))
        np.testing.assert_allclose(exact, fd, rtol=1e-7)


PATH_VARIABLES = (
    "axial_stress", "radial_stress", "specific_volume", "fabric", "e_oed_h", "dissipated_energy",
    "plastic_multiplier", "axial_strain", "radial_strain",
)  # fmt: skip


def assert_same_path(new, old, rtol=1e-9):
    assert new.attrs["termination"] == old.attrs["termination"] == "completed"
    np.testing.assert_array_equal(new.plastic.values, old.plastic.values)
    for name in PATH_VARIABLES:
        # floors for variables that are zero up to round-off on some paths (β on the isotropic)
        floor = 1e-3 if name in ("fabric", "axial_strain", "radial_strain") else 0.0
        scale = max(float(np.max(np.abs(old[name].values))), floor)
        np.testing.assert_allclose(new[name].values, old[name].values, atol=rtol * scale,
                                   err_msg=name)  # fmt: skip


@pytest.mark.parametrize("options", ALL_OPTIONS, ids=option_id)
def test_new_solvers_equal_the_scheme_before_on_every_element_test(options):
    """Exact Jacobian + monolithic mixed control = finite differences + nested control."""
    kw = {"options": options}
    for run in (
        lambda s: drivers.k0_then_unload(150.0, increments=40, unload_increments=8, settings=s,
                                         **kw),
        lambda s: drivers.isotropic(200.0, increments=15, settings=s, **kw),
        lambda s: drivers.radial(0.6, p_max=120.0, increments=15, settings=s, **kw),
        lambda s: drivers.radial(-0.4, p_max=80.0, increments=10, settings=s, **kw),
        lambda s: drivers.drained_triaxial(0.05, p0=20.0, increments=20, settings=s, **kw),
    ):  # fmt: skip
        assert_same_path(run(SolverSettings()), run(BEFORE))


def test_new_solvers_equal_the_scheme_before_on_a_long_k0_path():
    new = drivers.k0(250.0, increments=2000)
    old = drivers.k0(250.0, increments=2000, settings=BEFORE)
    assert_same_path(new, old, rtol=1e-9)


def test_solver_setting_names_are_checked():
    with pytest.raises(ValueError, match="jacobian"):
        SolverSettings(jacobian="exact")
    with pytest.raises(ValueError, match="mixed_control"):
        SolverSettings(mixed_control="joint")


def random_mandel_point(rng):
    from tiv_model.tensors import deviator

    ev = rng.uniform(0.01, 0.03)
    eps = ev / 3 * np.array([1.0, 1, 1, 0, 0, 0]) + 0.2 * ev * rng.standard_normal(6)
    beta = deviator(rng.standard_normal(6))
    beta *= rng.uniform(0.02, 0.15) / np.sqrt(1.5 * beta @ beta)
    lnv = math.log(rng.uniform(1.2, 1.8))
    return np.concatenate([eps, [rng.uniform(1e-5, 1e-3)], beta, [lnv]])


@pytest.mark.parametrize(
    ("options", "law"),
    list(itertools.product(ALL_OPTIONS, LAWS)),
    ids=[f"{option_id(o)}-{law}" for o, law in itertools.product(ALL_OPTIONS, LAWS)],
)
def test_general_jacobian_matches_central_differences(options, law):
    from tiv_model.local_problem import LocalProblem

    options = ModelOptions(options.anisotropy, options.constraint_forces, BOUND_LAWS[law])
    rng = np.random.default_rng(11)
    points = np.array([random_mandel_point(rng) for _ in range(4)])
    problem = LocalProblem(points[:, :6] * 1.01, points[:, 7:13] * 0.9, points[:, 13] + 1e-3,
                           TABLE1, options, np.full(4, 0.02))  # fmt: skip
    res, sig, dep, jac, dsig = problem.evaluate_jacobian(points)
    ref_res, ref_sig, ref_dep = problem.evaluate(points)
    np.testing.assert_allclose(res, ref_res, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(sig, ref_sig, rtol=1e-12)
    np.testing.assert_allclose(dep, ref_dep, rtol=1e-12, atol=1e-18)
    for i, x in enumerate(points):
        steps = 1e-6 * np.maximum(np.abs(x), 1e-4)
        fd = np.empty((14, 14))
        fd_sig = np.empty((6, 14))
        for j in range(14):
            xp, xm = x.copy(), x.copy()
            xp[j] += steps[j]
            xm[j] -= steps[j]
            rp, sp, _ = problem.evaluate(xp[None], rows=[i])
            rm, sm, _ = problem.evaluate(xm[None], rows=[i])
            fd[:, j] = (rp[0] - rm[0]) / (2 * steps[j])
            fd_sig[:, j] = (sp[0] - sm[0]) / (2 * steps[j])
        scale = np.maximum(np.abs(fd).max(axis=1, keepdims=True), 1e-300)
        np.testing.assert_allclose(jac[i] / scale, fd / scale, atol=1e-6)
        np.testing.assert_allclose(dsig[i], fd_sig, atol=1e-6 * np.abs(fd_sig).max())


GENERAL = SolverSettings(triaxial_fast_path=False)
GENERAL_BEFORE = SolverSettings(triaxial_fast_path=False, jacobian="finite_difference")


@pytest.mark.parametrize("options", ALL_OPTIONS, ids=option_id)
def test_general_path_with_the_exact_jacobian_equals_the_finite_difference_one(options):
    from tiv_model.integrate import Control, advance, initial_state

    new = drivers.k0_then_unload(100.0, increments=8, unload_increments=2, options=options,
                                 settings=GENERAL)  # fmt: skip
    old = drivers.k0_then_unload(100.0, increments=8, unload_increments=2, options=options,
                                 settings=GENERAL_BEFORE)  # fmt: skip
    assert_same_path(new, old)
    # a non-axisymmetric strain path (shear components): only the general path applies
    state_new = state_old = initial_state(20.0, TABLE1, options)
    for k in range(6):
        deps = 1e-3 * np.array([2.0, -0.3, 0.1 * k, 0.4, -0.2, 0.3])
        control = Control.strain(deps)
        state_new = advance(state_new, control, TABLE1, options, GENERAL)
        state_old = advance(state_old, control, TABLE1, options, GENERAL_BEFORE)
        scale = np.abs(state_old.stress).max()
        np.testing.assert_allclose(state_new.stress, state_old.stress, atol=1e-9 * scale)
        np.testing.assert_allclose(state_new.fabric, state_old.fabric, atol=1e-11)
        assert state_new.specific_volume == pytest.approx(state_old.specific_volume, rel=1e-12)
