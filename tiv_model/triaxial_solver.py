"""Newton solvers of the axisymmetric backward-Euler increment (:mod:`tiv_model.triaxial`).

- :func:`local_solve`: strain-controlled increment (Δε_a, Δε_r given), Newton with line search
  on x = (ε^e_a, ε^e_r, μ, β, ln v), and the algorithmic tangent dσ/dΔε = (∂σ/∂x) J⁻¹ [e₁, e₂];
- :func:`mixed_step`: axial and/or radial stress control. Default (``SolverSettings
  .mixed_control = "monolithic"``): one Newton on the same five unknowns in which the strain
  residual of each stress-controlled direction is replaced by its stress residual σ_i − σ_i*
  (the strain increment Δε_i = ε^e_i − ε^e_i,n + Δε^p_i follows); an elastic predictor first
  solves σ_u(ε^e) = σ_u* at frozen β, v and the increment is elastic if y ≤ 0 there. If that
  Newton fails the nested scheme is tried before the caller halves the increment;
- :func:`nested_mixed_step`: the scheme used before issue 12, an outer Newton on the unknown
  strain increments around :func:`local_solve` with the algorithmic tangent.

Both schemes solve the same equations (tested equal to 1e-9 and better); the monolithic one
needs one Newton instead of two or three. The Jacobian is exact by default
(``SolverSettings.jacobian = "analytic"``); ``"finite_difference"`` gives the forward
differences of before (the reference the tests compare with).
"""

from __future__ import annotations

import math

import numpy as np

from .errors import ConvergenceError
from .params import SolverSettings
from .state import IncrementGuess, State
from .tensors import triaxial, triaxial_fabric
from .triaxial import TriaxialModel, elastic_tangent, finite_difference_elastic_tangent


def _solve(matrix: list[list[float]], rhs: list[float]) -> list[float] | None:
    """Gaussian elimination with partial pivoting for the small dense systems of the fast path
    (pure Python: numpy.linalg.solve costs ~20 µs of call overhead for a 5×5); None when the
    matrix is singular or not finite."""
    n = len(rhs)
    a = [list(row) for row in matrix]
    b = list(rhs)
    for col in range(n):
        piv, big = col, abs(a[col][col])
        for r in range(col + 1, n):
            v = abs(a[r][col])
            if v > big:
                piv, big = r, v
        if not (0.0 < big < math.inf):
            return None
        if piv != col:
            a[col], a[piv] = a[piv], a[col]
            b[col], b[piv] = b[piv], b[col]
        prow = a[col]
        inv = 1.0 / prow[col]
        bc = b[col]
        for r in range(col + 1, n):
            row = a[r]
            f = row[col] * inv
            if f != 0.0:
                for k in range(col + 1, n):
                    row[k] -= f * prow[k]
                b[r] -= f * bc
    out = [0.0] * n
    for r in range(n - 1, -1, -1):
        row = a[r]
        acc = b[r]
        for k in range(r + 1, n):
            acc -= row[k] * out[k]
        out[r] = acc / row[r]
    return out


def _norm(res, strain_scale):
    return max(
        abs(res[0]) / strain_scale,
        abs(res[1]) / strain_scale,
        abs(res[2]),
        abs(res[3]),
        abs(res[4]) / strain_scale,
    )


def _tangent_for(settings: SolverSettings):
    return elastic_tangent if settings.jacobian == "analytic" else finite_difference_elastic_tangent


def _linearise(model: TriaxialModel, x, ta, tr, beta_n, lnv_n, strain_scale, base, settings):
    """(jac, dsig) at x: exact, or forward differences around ``base`` = (res, σ_a, σ_r)."""
    if settings.jacobian == "analytic":
        out = model.evaluate_jacobian(x, ta, tr, beta_n, lnv_n)
        return out[4], out[5]
    return model.finite_difference_jacobian(x, ta, tr, beta_n, lnv_n, strain_scale, base)


def softening_index(model: TriaxialModel, state: State) -> float:
    """|X|(1−n)ε^e_v: at or above 1 plastic compaction raises F(v) faster than the elastic
    unloading relieves the stress (the parameters are unstable there)."""
    par = model.params
    eps_v = float(state.elastic_strain[0]) + 2.0 * float(state.elastic_strain[1])
    return abs(par.energy_exponent) * (1.0 - par.n) * eps_v


def _negative_multiplier(mu, strain_scale, state, settings, par, ea_n, er_n):
    if mu < -1e3 * settings.tolerance * strain_scale:
        index = abs(par.energy_exponent) * (1.0 - par.n) * (ea_n + 2.0 * er_n)
        raise ConvergenceError(
            f"negative plastic multiplier μ = {mu:.3g}; softening index |X|(1−n)ε^e_v = "
            f"{index:.3g}" + (" ≥ 1: the parameters are unstable here (X = r/((n−1)λ*) too "
                              "large, e.g. n close to 1)" if index >= 1.0 else ""),
            state,
        )  # fmt: skip


def _elastic_state(state, d_axial, d_radial, ta, tr, sa, sr, pc) -> State:
    return State._from_fresh(
        strain=state.strain + triaxial(d_axial, d_radial),
        elastic_strain=triaxial(ta, tr),
        stress=triaxial(sa, sr),
        specific_volume=state.specific_volume,
        fabric=state.fabric.copy(),
        preconsolidation_pressure=pc,
        plastic_multiplier=state.plastic_multiplier,
        dissipated_energy=state.dissipated_energy,
        plastic=False,
    )


def _plastic_state(state, d_axial, d_radial, x, sa, sr, aux) -> State:
    ea, er, mu, beta, lnv = x
    pc, _, _, dbar, w = aux
    return State._from_fresh(
        strain=state.strain + triaxial(d_axial, d_radial),
        elastic_strain=triaxial(ea, er),
        stress=triaxial(sa, sr),
        specific_volume=math.exp(lnv),
        fabric=triaxial_fabric(beta),
        preconsolidation_pressure=pc,
        plastic_multiplier=state.plastic_multiplier + mu / pc,
        dissipated_energy=state.dissipated_energy + 0.5 * pc * (dbar + w),
        plastic=True,
    )


def local_solve(model: TriaxialModel, state: State, d_axial: float, d_radial: float,
                settings: SolverSettings, need_tangent: bool = True):  # fmt: skip
    """One axisymmetric backward-Euler increment: (new State, 2×2 tangent dσ/dΔε or None)."""
    ea_n, er_n = float(state.elastic_strain[0]), float(state.elastic_strain[1])
    beta_n = float(state.fabric[0] - state.fabric[1])
    lnv_n = math.log(state.specific_volume)
    ta, tr = ea_n + d_axial, er_n + d_radial
    x0 = [ta, tr, 0.0, beta_n, lnv_n]
    res, sa, sr, aux = model.evaluate(x0, ta, tr, beta_n, lnv_n)
    p_trial = (sa + 2.0 * sr) / 3.0
    if res is None:
        p_trial = math.nan
    if not (math.isfinite(p_trial) and p_trial >= settings.minimum_pressure):
        raise ConvergenceError(
            f"elastic trial mean stress {p_trial:.4g} kPa below p_min = "
            f"{settings.minimum_pressure:g} kPa",
            state,
        )
    if res[2] <= 1e-12:
        tangent = _tangent_for(settings)(model, ta, tr, beta_n, lnv_n) if need_tangent else None
        return _elastic_state(state, d_axial, d_radial, ta, tr, sa, sr, aux[0]), tangent

    strain_scale = max(abs(ta), abs(tr), abs(d_axial), abs(d_radial), 1e-14)
    x = x0
    norm = _norm(res, strain_scale)
    converged = False
    jac = dsig = None
    for _ in range(settings.max_iterations):
        jac, dsig = _linearise(model, x, ta, tr, beta_n, lnv_n, strain_scale, (res, sa, sr),
                               settings)  # fmt: skip
        if jac is None:
            raise ConvergenceError("inadmissible point during the local Newton", state)
        step = _solve(jac, [-r for r in res])
        if step is None or not all(math.isfinite(v) for v in step):
            break
        alpha = 1.0
        accepted = False
        for _ in range(10):
            xt = [x[i] + alpha * step[i] for i in range(5)]
            rt, sat, srt, auxt = model.evaluate(xt, ta, tr, beta_n, lnv_n)
            if rt is not None:
                nt = _norm(rt, strain_scale)
                if math.isfinite(nt) and nt < (1.0 - 1e-4 * alpha) * norm:
                    accepted = True
                    break
            alpha *= 0.5
        if not accepted:
            converged = norm < 1e3 * settings.tolerance
            break
        x, res, sa, sr, aux, norm = xt, rt, sat, srt, auxt, nt
        if norm < settings.tolerance:
            converged = True
            break
    if not converged:
        raise ConvergenceError(
            f"local Newton (triaxial) did not converge (scaled residual {norm:.3g} > "
            f"{settings.tolerance:g}) for strain increments ({d_axial:.3g}, {d_radial:.3g})",
            state,
        )
    _negative_multiplier(x[2], strain_scale, state, settings, model.params, ea_n, er_n)
    tangent = None
    if need_tangent:
        if settings.jacobian == "analytic":  # the Jacobian at the converged point
            jac, dsig = _linearise(model, x, ta, tr, beta_n, lnv_n, strain_scale, None, settings)
        if jac is None or dsig is None:  # as inside the loop (a TypeError in _solve before)
            raise ConvergenceError("inadmissible point during the local Newton", state)
        # algorithmic tangent dσ/dΔε = (∂σ/∂x) J⁻¹ [e_1, e_2] (R_ε = ε^e − ε^e_n − Δε + ...)
        tangent = np.empty((2, 2))
        for k in range(2):
            col = _solve(jac, [1.0 if i == k else 0.0 for i in range(5)])
            if col is None:
                tangent = np.array([[dsig[0][0], dsig[0][1]], [dsig[1][0], dsig[1][1]]])
                break
            for i in range(2):
                tangent[i, k] = sum(dsig[i][j] * col[j] for j in range(5))
    return _plastic_state(state, d_axial, d_radial, x, sa, sr, aux), tangent


def _controls(control):
    sc = (bool(control.stress_controlled[0]), bool(control.stress_controlled[1]))
    deps = [
        0.0 if sc[0] else float(control.strain_increment[0]),
        0.0 if sc[1] else float(control.strain_increment[1]),
    ]
    target = (float(control.stress_target[0]), float(control.stress_target[1]))
    return sc, deps, target


def _start_increments(model, state, sc, deps, target, settings, guess):
    """Starting strain increments of the stress-controlled directions: ``guess`` if given,
    else the elastic tangent at the start of the increment."""
    u = [i for i in (0, 1) if sc[i]]
    deps = list(deps)
    if isinstance(guess, IncrementGuess):
        guess = guess.strain
    if guess is not None and all(math.isfinite(float(g)) for g in guess[:2]):
        for i in u:
            deps[i] = float(guess[i])
        return deps
    tangent = _tangent_for(settings)(
        model,
        float(state.elastic_strain[0]),
        float(state.elastic_strain[1]),
        float(state.fabric[0] - state.fabric[1]),
        math.log(state.specific_volume),
    )
    known = [i for i in (0, 1) if not sc[i]]
    rhs = np.array([target[i] - float(state.stress[i]) for i in u])
    for row, i in enumerate(u):
        for k in known:
            rhs[row] -= tangent[i, k] * deps[k]
    sol = np.linalg.solve(tangent[np.ix_(u, u)], rhs)
    for i, val in zip(u, sol, strict=True):
        deps[i] = float(val)
    return deps


def _stress_scale(state, target, settings):
    return max(state.mean_stress, abs(target[0]), abs(target[1]), settings.minimum_pressure)


def mixed_step(
    model: TriaxialModel, state: State, control, settings: SolverSettings, guess=None
) -> State:
    """Axisymmetric increment with axial/radial stress or strain control (module docstring)."""
    sc, deps, target = _controls(control)
    if not (sc[0] or sc[1]):
        return local_solve(model, state, deps[0], deps[1], settings, need_tangent=False)[0]
    if settings.mixed_control == "nested" or softening_index(model, state) >= 1.0:
        # past the softening limit the equations have several roots; the nested scheme refuses
        # them (negative multiplier of the strain-controlled problem), as it always did
        return nested_mixed_step(model, state, control, settings, guess)
    try:
        return monolithic_step(model, state, control, settings, guess)
    except ConvergenceError:
        return nested_mixed_step(model, state, control, settings, guess)


def _elastic_predictor(model, state, sc, deps, target, settings, guess):
    """ε^e of the elastic increment meeting the stress targets at frozen β, v (Newton on the
    stress-controlled components with the exact elastic tangent): (ε^e_a, ε^e_r) or None."""
    beta_n = float(state.fabric[0] - state.fabric[1])
    lnv_n = math.log(state.specific_volume)
    d = _start_increments(model, state, sc, deps, target, settings, guess)
    e = [float(state.elastic_strain[0]) + d[0], float(state.elastic_strain[1]) + d[1]]
    u = [i for i in (0, 1) if sc[i]]
    scale = _stress_scale(state, target, settings)
    best, e_best = math.inf, None
    for _ in range(settings.max_iterations):
        try:
            sa, sr, sa_g, sr_g, _ = model.stress_gradient(e[0], e[1], beta_n, lnv_n)
        except (ValueError, OverflowError, ZeroDivisionError):
            break
        r = (sa - target[0], sr - target[1])
        rnorm = max(abs(r[i]) for i in u) / scale
        if not rnorm < best:
            break  # converged to round-off, or diverging: keep the best point
        best, e_best = rnorm, list(e)
        if rnorm < 1e-15:
            break
        if len(u) == 1:
            i = u[0]
            e[i] -= r[i] / (sa_g, sr_g)[i][i]
        else:
            det = sa_g[0] * sr_g[1] - sa_g[1] * sr_g[0]
            e[0] -= (sr_g[1] * r[0] - sa_g[1] * r[1]) / det
            e[1] -= (-sr_g[0] * r[0] + sa_g[0] * r[1]) / det
    return e_best if best <= 1e-2 * settings.stress_tolerance else None


def monolithic_step(
    model: TriaxialModel, state: State, control, settings: SolverSettings, guess=None
) -> State:
    """Mixed-control increment by one Newton (module docstring); ConvergenceError on failure.

    After a plastic increment, or when ``guess`` predicts a plastic one, the plastic Newton is
    tried first, from ``guess`` (the likely case on a loading path); a solution with μ ≥ 0 is
    the increment's. When it fails or gives μ < 0 the elastic predictor decides, as it does
    after an elastic one.
    """
    sc, deps, target = _controls(control)
    ea_n, er_n = float(state.elastic_strain[0]), float(state.elastic_strain[1])
    predicted = isinstance(guess, IncrementGuess) and guess.plastic_multiplier > 0.0
    if state.plastic or predicted:
        try:
            if isinstance(guess, IncrementGuess):
                start = _predicted_start(model, state, guess)
            else:
                d = _start_increments(model, state, sc, deps, target, settings, guess)
                start = (ea_n + d[0], er_n + d[1], 0.0, float(state.fabric[0] - state.fabric[1]),
                         math.log(state.specific_volume))  # fmt: skip
            return _plastic_newton(model, state, sc, deps, target, settings, start)
        except ConvergenceError:
            pass
    start = _elastic_predictor(model, state, sc, deps, target, settings, guess)
    if start is None:
        raise ConvergenceError("elastic predictor of the mixed control did not converge", state)
    beta_n = float(state.fabric[0] - state.fabric[1])
    lnv_n = math.log(state.specific_volume)
    x = [start[0], start[1], 0.0, beta_n, lnv_n]
    raw, sa, sr, aux = model.evaluate(x, start[0], start[1], beta_n, lnv_n)
    p_trial = (sa + 2.0 * sr) / 3.0 if raw is not None else math.nan
    if not (math.isfinite(p_trial) and p_trial >= settings.minimum_pressure):
        raise ConvergenceError(
            f"elastic trial mean stress {p_trial:.4g} kPa below p_min = "
            f"{settings.minimum_pressure:g} kPa",
            state,
        )
    if raw[2] <= 1e-12:
        return _elastic_state(state, start[0] - ea_n, start[1] - er_n, start[0], start[1], sa,
                              sr, aux[0])  # fmt: skip
    return _plastic_newton(model, state, sc, deps, target, settings, x)


def _predicted_start(model: TriaxialModel, state: State, guess: IncrementGuess):
    """x = (ε^e_a, ε^e_r, μ, β, ln v) of the state moved by the guessed increment."""
    lnv = math.log(state.specific_volume) + guess.log_specific_volume
    pc = model.p_r * math.exp(-(lnv - model.ln_n) * model.inv_lambda)
    de, db = guess.elastic_strain, guess.fabric
    return (
        float(state.elastic_strain[0] + de[0]),
        float(state.elastic_strain[1] + de[1]),
        guess.plastic_multiplier * pc,
        float(state.fabric[0] - state.fabric[1] + db[0] - db[1]),
        lnv,
    )


def _plastic_newton(model, state, sc, deps, target, settings, start) -> State:
    """Newton with line search on x = (ε^e_a, ε^e_r, μ, β, ln v) from ``start`` with the
    stress rows of the stress-controlled directions; ConvergenceError on failure."""
    ea_n, er_n = float(state.elastic_strain[0]), float(state.elastic_strain[1])
    beta_n = float(state.fabric[0] - state.fabric[1])
    lnv_n = math.log(state.specific_volume)
    # trial strains of the strain-controlled directions; ε^e_n for the stress-controlled ones,
    # so that their strain residual is the strain increment Δε_i = ε^e_i − ε^e_i,n + Δε^p_i
    ta = ea_n if sc[0] else ea_n + deps[0]
    tr = er_n if sc[1] else er_n + deps[1]
    x = list(start)
    sscale = _stress_scale(state, target, settings)
    strain_scale = max(abs(start[0]), abs(start[1]), abs(start[0] - ea_n),
                       abs(start[1] - er_n), 1e-14)  # fmt: skip
    weight = settings.tolerance / settings.stress_tolerance / sscale

    def rows(raw, sa, sr):
        """Residuals with the stress rows in place of the stress-controlled strain rows."""
        out = list(raw)
        if sc[0]:
            out[0] = (sa - target[0]) / sscale
        if sc[1]:
            out[1] = (sr - target[1]) / sscale
        return out

    def norm(raw, sa, sr):
        ra = abs(sa - target[0]) * weight if sc[0] else abs(raw[0]) / strain_scale
        rr = abs(sr - target[1]) * weight if sc[1] else abs(raw[1]) / strain_scale
        return max(ra, rr, abs(raw[2]), abs(raw[3]), abs(raw[4]) / strain_scale)

    raw, sa, sr, aux = model.evaluate(x, ta, tr, beta_n, lnv_n)
    if raw is None:
        raise ConvergenceError("inadmissible start of the mixed-control Newton", state)
    res = rows(raw, sa, sr)
    nrm = norm(raw, sa, sr)
    converged = False
    for _ in range(settings.max_iterations):
        jac, dsig = _linearise(model, x, ta, tr, beta_n, lnv_n, strain_scale, (raw, sa, sr),
                               settings)  # fmt: skip
        if jac is None:
            break
        jac = list(jac)
        for i in (0, 1):
            if sc[i]:
                jac[i] = [v / sscale for v in dsig[i]]
        step = _solve(jac, [-r for r in res])
        if step is None or not all(math.isfinite(v) for v in step):
            break
        alpha = 1.0
        accepted = False
        for _ in range(10):
            xt = [x[i] + alpha * step[i] for i in range(5)]
            rt, sat, srt, auxt = model.evaluate(xt, ta, tr, beta_n, lnv_n)
            if rt is not None:
                nt = norm(rt, sat, srt)
                if math.isfinite(nt) and nt < (1.0 - 1e-4 * alpha) * nrm:
                    accepted = True
                    break
            alpha *= 0.5
        if not accepted:
            converged = nrm < 1e3 * settings.tolerance
            break
        x, raw, sa, sr, aux, nrm = xt, rt, sat, srt, auxt, nt
        res = rows(raw, sa, sr)
        if nrm < settings.tolerance:
            converged = True
            break
    if not converged:
        raise ConvergenceError(
            f"monolithic mixed-control Newton did not converge (scaled residual {nrm:.3g})", state
        )
    _negative_multiplier(x[2], strain_scale, state, settings, model.params, ea_n, er_n)
    d_axial = raw[0] if sc[0] else deps[0]
    d_radial = raw[1] if sc[1] else deps[1]
    return _plastic_state(state, d_axial, d_radial, x, sa, sr, aux)


def nested_mixed_step(
    model: TriaxialModel, state: State, control, settings: SolverSettings, guess=None
) -> State:
    """Outer Newton on the stress-controlled strain increments around :func:`local_solve`."""
    sc, deps, target = _controls(control)
    u = [i for i in (0, 1) if sc[i]]
    deps = _start_increments(model, state, sc, deps, target, settings, guess)
    tol = settings.stress_tolerance * _stress_scale(state, target, settings)
    best = math.inf
    last_good = None
    correction = None
    backtracks = 0
    local_error = ""
    last_tangent = None
    for _ in range(settings.max_outer_iterations):
        try:
            new, tangent = local_solve(model, state, deps[0], deps[1], settings)
            res = np.array([float(new.stress[0]) - target[0] if i == 0 else
                            float(new.stress[1]) - target[1] for i in u])  # fmt: skip
            rnorm = float(np.max(np.abs(res)))
            failed = not math.isfinite(rnorm)
        except ConvergenceError as exc:
            failed = True
            local_error = exc.args[0]
        if failed or (last_good is not None and rnorm > best):
            backtracks += 1
            if last_good is None or correction is None or backtracks > 12:
                break
            correction = 0.5 * correction
            for k, i in enumerate(u):
                deps[i] = last_good[k] + correction[k]
            continue
        if rnorm <= tol:
            return new
        best = rnorm
        last_good = [deps[i] for i in u]
        last_tangent = tangent
        try:
            correction = -np.linalg.solve(tangent[np.ix_(u, u)], res)
        except np.linalg.LinAlgError:
            break
        for k, i in enumerate(u):
            deps[i] = last_good[k] + float(correction[k])
    hint = ""
    if last_tangent is not None:
        sub = last_tangent[np.ix_(u, u)]
        if np.min(np.linalg.eigvals(0.5 * (sub + sub.T)).real) <= 0.0:
            hint = (
                "; the tangent under this control is not positive (limit point): use strain control"
            )
    raise ConvergenceError(
        "mixed stress/strain control did not converge (the prescribed stress may be beyond "
        f"what the material can carry, e.g. a stress ratio at or above the critical one{hint})"
        + (f"; last local failure: {local_error}" if local_error else ""),
        state,
    )
