"""Axisymmetric (triaxial) fast path of the implicit integration, in ``math`` scalars.

The general integrator (:mod:`tiv_model.integrate`) works on 3×3 tensors in Mandel form with
vectorised numpy; each numpy call costs ~1–5 µs, so one increment costs milliseconds. On the
element-test paths every tensor stays diag(a, r, r) and the same backward-Euler problem reduces
to five scalar unknowns (ε^e_a, ε^e_r, μ, β, ln v) with closed-form scalar expressions:

  form A: ε̃_a = (1 − 2b/3) ε_a, ε̃_r = (1 + b/3) ε_r, b = ω |β| β
  form B: ε̃_a = ε_a − (4/9) ω β² (ε_a − ε_r), ε̃_r = ε_r + (2/9) ω β² (ε_a − ε_r)
  y = (q − p̂β)² − (M² − β²)[A² − (p̂ − p_c/2)²]
  n_a = 2(q − p̂β) + ι, n_r = −(q − p̂β) + ι, ι = (2/3)(M² − β²)(p̂ − p_c/2) − (2/3)(q − p̂β)β
  ΔD̄ = sqrt(w² + (4/9)(M² − β²)(Δε^p_a − Δε^p_r)²), w = Δε^p_v + (2/3) β (Δε^p_a − Δε^p_r)

(the triaxial reductions of :mod:`tiv_model.energy` and :mod:`tiv_model.dissipation`; the tests
check that both paths give the same states). β here is the signed scalar β_a − β_r.
Used automatically by :func:`tiv_model.integrate.advance` when the state and the control are
axisymmetric (``SolverSettings.triaxial_fast_path``).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from .energy import energy_exponent, log_energy_constant
from .errors import ConvergenceError
from .params import ModelOptions, Parameters, SolverSettings, exponential_bound
from .state import State
from .tensors import triaxial, triaxial_fabric

_TINY_Q = 1e-300
_FD = 1e-7


class TriaxialModel:
    """Scalar residuals and stresses of the axisymmetric backward-Euler increment."""

    def __init__(self, params: Parameters, options: ModelOptions) -> None:
        self.params = params
        self.options = options
        self.a = energy_exponent(params)
        self.ln_c0 = log_energy_constant(params)
        self.lam = params.k * (1.0 - params.n) - 2.0 * params.g / 3.0
        self.g2 = 2.0 * params.g
        self.x = params.energy_exponent
        self.ln_n = math.log(params.N)
        self.form_a = options.anisotropy == "A"
        self.cf = options.constraint_forces
        self.exponential = options.bound_law is exponential_bound
        self.bound_a = params.s / params.M
        self.bound_scale = params.maximum_fabric
        self.c = params.c
        self.m2 = params.M * params.M
        self.p_r = params.p_r
        self.inv_lambda = 1.0 / params.lambda_star
        self.omega = params.omega

    def bound_factor(self, eta: float) -> float:
        """f(η) of the bound law (β_b = f(η) q/p in triaxial terms)."""
        if self.exponential:
            xa = self.bound_a * eta
            if xa < 1e-4:
                return self.bound_scale * self.bound_a * (1 - xa / 2 + xa * xa / 6 - xa**3 / 24)
            return self.bound_scale * -math.expm1(-xa) / eta
        return float(self.options.bound_law(np.array(eta), self.params))

    def stress(self, ea: float, er: float, beta: float, lnv: float):
        """(σ_a, σ_r, σ̃_a, σ̃_r, Q̃, F) at elastic strains (ε_a, ε_r), fabric β, ln v."""
        om = self.omega
        if self.form_a:
            b = om * abs(beta) * beta
            ta = (1.0 - 2.0 * b / 3.0) * ea
            tr = (1.0 + b / 3.0) * er
        else:
            k4 = om * beta * beta
            d = ea - er
            ta = ea - 4.0 / 9.0 * k4 * d
            tr = er + 2.0 / 9.0 * k4 * d
        tv = ta + 2.0 * tr
        quad = max(self.lam * tv * tv + self.g2 * (ta * ta + 2.0 * tr * tr), _TINY_Q)
        factor = math.exp(self.x * (lnv - self.ln_n))
        kp = 2.0 * self.a * factor * math.exp(self.ln_c0 + (self.a - 1.0) * math.log(quad))
        sta = kp * (self.lam * tv + self.g2 * ta)
        st_r = kp * (self.lam * tv + self.g2 * tr)
        if self.form_a:
            sa = (1.0 - 2.0 * b / 3.0) * sta
            sr = (1.0 + b / 3.0) * st_r
        else:
            ds = sta - st_r
            sa = sta - 4.0 / 9.0 * k4 * ds
            sr = st_r + 2.0 / 9.0 * k4 * ds
        return sa, sr, sta, st_r, quad, factor

    def evaluate(self, x, trial_a, trial_r, beta_n, lnv_n):
        """Residuals (5), stresses (σ_a, σ_r) and (p_c, Δε^p_a, Δε^p_r, ΔD̄, w) at x.

        Residuals are None where the point is inadmissible (p ≤ 0, β_s > M, overflow), which
        the Newton line search treats as a rejected step.
        """
        try:
            return self._evaluate(x, trial_a, trial_r, beta_n, lnv_n)
        except (ValueError, OverflowError, ZeroDivisionError):
            return None, math.nan, math.nan, None

    def _evaluate(self, x, trial_a, trial_r, beta_n, lnv_n):
        ea, er, mu, beta, lnv = x
        sa, sr, sta, st_r, quad, factor = self.stress(ea, er, beta, lnv)
        p = (sa + 2.0 * sr) / 3.0
        q = sa - sr
        pc = self.p_r * math.exp(-(lnv - self.ln_n) * self.inv_lambda)
        if not p > 0.0:
            return None, sa, sr, None
        eta = abs(q) / p
        bb = self.bound_factor(eta) * q / p
        if self.cf:
            phi = factor * math.exp(self.ln_c0 + self.a * math.log(quad))
            shift = -self.x * phi
            om = self.omega
            if self.form_a:
                dta = -4.0 / 3.0 * om * abs(beta) * ea
                dtr = 2.0 / 3.0 * om * abs(beta) * er
            else:
                d = ea - er
                dta = -8.0 / 9.0 * om * beta * d
                dtr = 4.0 / 9.0 * om * beta * d
            size = 0.5 * pc + self.c * (sta * dta + 2.0 * st_r * dtr) * (bb - beta)
        else:
            shift = 0.0
            size = 0.5 * pc
        ph = p - shift
        rq = q - ph * beta
        m2 = self.m2 - beta * beta
        y = rq * rq - m2 * (size * size - (ph - 0.5 * pc) ** 2)
        iso = 2.0 / 3.0 * m2 * (ph - 0.5 * pc) - 2.0 / 3.0 * rq * beta
        scale = mu / pc
        dpa = scale * (2.0 * rq + iso)
        dpr = scale * (-rq + iso)
        dd = dpa - dpr
        w = dpa + 2.0 * dpr + 2.0 / 3.0 * beta * dd
        dbar = math.sqrt(w * w + 4.0 / 9.0 * m2 * dd * dd)
        cd = self.c * dbar
        res = (
            ea - trial_a + dpa,
            er - trial_r + dpr,
            y / (pc * pc),
            beta * (1.0 + cd) - beta_n - cd * bb,
            lnv - lnv_n + dpa + 2.0 * dpr,
        )
        return res, sa, sr, (pc, dpa, dpr, dbar, w)


@lru_cache(maxsize=64)
def model_for(params: Parameters, options: ModelOptions) -> TriaxialModel:
    """Cached :class:`TriaxialModel` for a parameter set and options."""
    return TriaxialModel(params, options)


def _solve(matrix: list[list[float]], rhs: list[float]) -> list[float] | None:
    """Gaussian elimination with partial pivoting for the small dense systems of the fast path
    (pure Python: numpy.linalg.solve costs ~20 µs of call overhead for a 5×5)."""
    n = len(rhs)
    a = [row[:] + [rhs[i]] for i, row in enumerate(matrix)]
    for col in range(n):
        piv = max(range(col, n), key=lambda r: abs(a[r][col]))
        if a[piv][col] == 0.0 or not math.isfinite(a[piv][col]):
            return None
        a[col], a[piv] = a[piv], a[col]
        pivot_row = a[col]
        inv = 1.0 / pivot_row[col]
        for r in range(col + 1, n):
            row = a[r]
            factor = row[col] * inv
            if factor != 0.0:
                for k in range(col, n + 1):
                    row[k] -= factor * pivot_row[k]
    out = [0.0] * n
    for r in range(n - 1, -1, -1):
        acc = a[r][n]
        for k in range(r + 1, n):
            acc -= a[r][k] * out[k]
        out[r] = acc / a[r][r]
    return out


def _norm(res, strain_scale):
    return max(
        abs(res[0]) / strain_scale,
        abs(res[1]) / strain_scale,
        abs(res[2]),
        abs(res[3]),
        abs(res[4]) / strain_scale,
    )


def elastic_tangent(model: TriaxialModel, ea: float, er: float, beta: float, lnv: float):
    """2×2 elastic tangent [dσ_a, dσ_r]/[dε_a, dε_r] (radial strain applied to both radial
    directions), by central differences of the closed-form scalar stress (kPa)."""
    tangent = np.empty((2, 2))
    h = _FD * max(abs(ea), abs(er), 1e-12)
    for j, (da, dr) in enumerate(((1.0, 0.0), (0.0, 1.0))):
        sp = model.stress(ea + h * da, er + h * dr, beta, lnv)
        sm = model.stress(ea - h * da, er - h * dr, beta, lnv)
        tangent[0, j] = (sp[0] - sm[0]) / (2 * h)
        tangent[1, j] = (sp[1] - sm[1]) / (2 * h)
    return tangent


def local_solve(model: TriaxialModel, state: State, d_axial: float, d_radial: float,
                settings: SolverSettings, need_tangent: bool = True):  # fmt: skip
    """One axisymmetric backward-Euler increment: (new State, 2×2 tangent dσ/dΔε or None)."""
    par = model.params
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
        tangent = elastic_tangent(model, ta, tr, beta_n, lnv_n) if need_tangent else None
        new = State(
            strain=state.strain + triaxial(d_axial, d_radial),
            elastic_strain=triaxial(ta, tr),
            stress=triaxial(sa, sr),
            specific_volume=state.specific_volume,
            fabric=state.fabric,
            preconsolidation_pressure=aux[0],
            plastic_multiplier=state.plastic_multiplier,
            dissipated_energy=state.dissipated_energy,
            plastic=False,
        )
        return new, tangent

    strain_scale = max(abs(ta), abs(tr), abs(d_axial), abs(d_radial), 1e-14)
    typical = (strain_scale, strain_scale, strain_scale, 1e-2, 1e-2)
    x = x0
    norm = _norm(res, strain_scale)
    converged = False
    jac = [[0.0] * 5 for _ in range(5)]
    dsig = [[0.0] * 5 for _ in range(2)]
    for _ in range(settings.max_iterations):
        for j in range(5):
            h = _FD * max(abs(x[j]), typical[j])
            xp = list(x)
            xp[j] += h
            rp, sap, srp, _ = model.evaluate(xp, ta, tr, beta_n, lnv_n)
            if rp is None:
                raise ConvergenceError("inadmissible point during the local Newton", state)
            for i in range(5):
                jac[i][j] = (rp[i] - res[i]) / h
            dsig[0][j] = (sap - sa) / h
            dsig[1][j] = (srp - sr) / h
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
    ea, er, mu, beta, lnv = x
    if mu < -1e3 * settings.tolerance * strain_scale:
        index = abs(par.energy_exponent) * (1.0 - par.n) * (ea_n + 2.0 * er_n)
        raise ConvergenceError(
            f"negative plastic multiplier μ = {mu:.3g}; softening index |X|(1−n)ε^e_v = "
            f"{index:.3g}" + (" ≥ 1: the parameters are unstable here (X = r/((n−1)λ*) too "
                              "large, e.g. n close to 1)" if index >= 1.0 else ""),
            state,
        )  # fmt: skip
    pc, dpa, dpr, dbar, w = aux
    # algorithmic tangent dσ/dΔε = (∂σ/∂x) J⁻¹ [e_1, e_2] (R_ε = ε^e − ε^e_n − Δε + ...)
    tangent = np.empty((2, 2)) if need_tangent else None
    for k in range(2 if need_tangent else 0):
        col = _solve(jac, [1.0 if i == k else 0.0 for i in range(5)])
        if col is None:
            tangent = np.array([[dsig[0][0], dsig[0][1]], [dsig[1][0], dsig[1][1]]])
            break
        for i in range(2):
            tangent[i, k] = sum(dsig[i][j] * col[j] for j in range(5))
    new = State(
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
    return new, tangent


def is_axisymmetric(state: State, control) -> bool:
    """Whether state and control stay diag(a, r, r) (so the fast path applies)."""
    sc = control.stress_controlled
    if any(sc[3:]) or any(control.strain_increment[3:]) or sc[1] != sc[2]:
        return False
    if sc[1] and control.stress_target[1] != control.stress_target[2]:
        return False
    if not sc[1] and control.strain_increment[1] != control.strain_increment[2]:
        return False
    for vec in (state.stress, state.elastic_strain, state.fabric):
        scale = max(abs(float(vec[0])), abs(float(vec[1])), 1e-300)
        if abs(float(vec[1] - vec[2])) > 1e-13 * scale or max(abs(vec[3:])) > 1e-13 * scale:
            return False
    return True


def mixed_step(
    model: TriaxialModel, state: State, control, settings: SolverSettings, guess=None
) -> State:
    """Axisymmetric increment with axial/radial stress or strain control (outer Newton)."""
    sc = (bool(control.stress_controlled[0]), bool(control.stress_controlled[1]))
    deps = [
        0.0 if sc[0] else float(control.strain_increment[0]),
        0.0 if sc[1] else float(control.strain_increment[1]),
    ]
    if not (sc[0] or sc[1]):
        return local_solve(model, state, deps[0], deps[1], settings, need_tangent=False)[0]
    target = (float(control.stress_target[0]), float(control.stress_target[1]))
    u = [i for i in (0, 1) if sc[i]]
    if guess is not None and all(math.isfinite(float(g)) for g in guess[:2]):
        for i in u:
            deps[i] = float(guess[i])
    else:
        tangent = elastic_tangent(
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
    tol = settings.stress_tolerance * max(
        state.mean_stress, abs(target[0]), abs(target[1]), settings.minimum_pressure
    )
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
            if last_good is None or backtracks > 12:
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
