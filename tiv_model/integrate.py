"""Implicit (backward-Euler) integration of the TIV model (docs/science/tiv-model.md §2.4).

One increment, strain-controlled:
1. elastic trial ε^e_tr = ε^e_n + Δε with v and β frozen; accepted if y(ε^e_tr) ≤ 0 (exactly
   path-independent inside the yield surface);
2. otherwise Newton with line search on x = (ε^e, μ, β, ln v), residuals
     R_ε = ε^e − ε^e_tr + μ n/p_c          (Δε^p = Δλ n, μ = Δλ p_c, dimensionless)
     R_y = y / p_c²
     R_β = β (1 + c ΔD̄) − β_n − c ΔD̄ β_b   (implicit fabric update, never overshoots β_b)
     R_v = ln v − ln v_n + tr Δε^p           (v_{n+1} = v_n exp(−Δε^p_v))
   all evaluated at the end of the increment (:class:`tiv_model.local_problem.LocalProblem`).
   The Jacobian is exact (``LocalProblem.evaluate_jacobian``); with
   ``SolverSettings(jacobian="finite_difference")`` it is the forward difference used before
   issue 12, all columns in one batched call. The line search evaluates eight step lengths in
   one batched call.
Mixed control (some stress components prescribed) is solved by an outer Newton on the unknown
strain components with the algorithmic tangent dσ/dΔε = (∂σ/∂x) J⁻¹ [I; 0] on this general
path; axisymmetric increments go to :mod:`tiv_model.triaxial_solver` (one Newton for both).
An increment that does not converge is split in two halves (recursively, up to
``SolverSettings.max_halvings``).
Failures raise typed errors naming the state; no NaN is ever returned.

Symbols: see :mod:`tiv_model.dissipation` and :mod:`tiv_model.energy`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import triaxial as triaxial_path
from . import triaxial_solver
from .dissipation import (
    YieldEvaluation,
    dissipation_rate,
    preconsolidation_pressure,
)
from .energy import (
    CONVEXITY_LIMIT,
    EnergyEvaluation,
    check_convexity,
    constraint_pressure,
    convexity_measure,
    elastic_strain_for_stress,
    isotropic_elastic_volumetric_strain,
    stiffness,
)
from .errors import ConvergenceError, ParameterError, SpecificVolumeBelowOneError, TivModelError
from .local_problem import LNV, MU, SIZE, B, E, LocalProblem
from .params import (
    DEFAULT_OPTIONS,
    DEFAULT_SETTINGS,
    TABLE1,
    ModelOptions,
    Parameters,
    SolverSettings,
)
from .state import State
from .tensors import IDENTITY_MANDEL, trace

_E, _MU, _B, _LNV, _SIZE = E, MU, B, LNV, SIZE
_LINE_SEARCH_STEPS = 0.5 ** np.arange(8)


# ---------------------------------------------------------------------------------------------
# initial states
# ---------------------------------------------------------------------------------------------
def state_from_stress(
    stress_m,
    specific_volume: float,
    fabric_m=None,
    params: Parameters = TABLE1,
    options: ModelOptions = DEFAULT_OPTIONS,
) -> State:
    """A state with the given stress (kPa), model specific volume and fabric; zero total strain."""
    fabric_m = np.zeros(6) if fabric_m is None else np.asarray(fabric_m, dtype=float)
    if abs(float(trace(fabric_m))) > 1e-12:
        raise ParameterError(f"fabric must be deviatoric, got trace {float(trace(fabric_m)):g}")
    if not specific_volume >= 1.0:
        raise ParameterError(f"specific volume {specific_volume!r} must be ≥ 1")
    eps = elastic_strain_for_stress(stress_m, specific_volume, fabric_m, params, options)
    ev = EnergyEvaluation(eps, specific_volume, fabric_m, params, options)
    return State(
        strain=np.zeros(6),
        elastic_strain=eps,
        stress=ev.stress,
        specific_volume=specific_volume,
        fabric=fabric_m,
        preconsolidation_pressure=float(preconsolidation_pressure(specific_volume, params)),
    )


def normally_consolidated_preconsolidation(
    mean_stress: float, params: Parameters = TABLE1, options: ModelOptions = DEFAULT_OPTIONS
) -> float:
    """p_c of the isotropic, isotropic-fabric state that lies on the yield surface at p (kPa).

    Without constraint forces p_c = p. With them the isotropic yield point is p̂ = p − Λ_K = p_c,
    Λ_K = −X φ = −X p ε^e_v (1 − n)/(2 − n), ε^e_v = (p/p_r)^(1−n) (p_c/p_r)^(−r) / (k(1 − n)),
    i.e. p_c solves p_c = p [1 + X (p/p_r)^(1−n) (p_c/p_r)^(−r) / (k(2 − n))] (root near p).
    """
    if not (mean_stress > 0.0 and math.isfinite(mean_stress)):
        raise ParameterError(f"mean stress p = {mean_stress!r} kPa must be > 0")
    if not options.constraint_forces:
        return float(mean_stress)
    p, pr = float(mean_stress), params.p_r
    coef = params.energy_exponent * (p / pr) ** (1.0 - params.n) / (params.k * (2.0 - params.n))

    def g(pc):
        return pc - p * (1.0 + coef * (pc / pr) ** (-params.r))

    def dg(pc):
        return 1.0 + p * coef * params.r * (pc / pr) ** (-params.r) / pc

    pc = p
    for _ in range(100):
        step = g(pc) / dg(pc)
        new = pc - step
        if not new > 0.0:
            new = 0.5 * pc
        pc = new
        if abs(step) <= 1e-15 * pc:
            break
    if not (pc > 0.0 and abs(g(pc)) <= 1e-12 * p and dg(pc) > 0.0):
        raise ParameterError(
            f"no normally consolidated state at p = {p:g} kPa with constraint forces: "
            "the constraint force Λ_K exceeds p (stiffness too low for this pressure)"
        )
    return pc


def initial_state(
    mean_stress: float = 5.0,
    params: Parameters = TABLE1,
    options: ModelOptions = DEFAULT_OPTIONS,
    overconsolidation_ratio: float = 1.0,
) -> State:
    """Isotropic stress p (kPa), isotropic fabric, on the yield surface (×OCR in p_c).

    The default is the study's starting state: normally consolidated at p0 = 5 kPa.
    """
    if not overconsolidation_ratio >= 1.0:
        raise ParameterError(f"overconsolidation_ratio = {overconsolidation_ratio!r} must be ≥ 1")
    pc = normally_consolidated_preconsolidation(mean_stress, params, options)
    pc *= overconsolidation_ratio
    v = params.N * (pc / params.p_r) ** (-params.lambda_star)
    if v < 1.0:
        raise SpecificVolumeBelowOneError(
            f"initial state at p = {mean_stress:g} kPa would have v = {v:.6g} < 1: "
            f"{_volume_limit_text(params)}"
        )
    eps_v = float(isotropic_elastic_volumetric_strain(mean_stress, v, params))
    eps = eps_v / 3.0 * IDENTITY_MANDEL
    ev = EnergyEvaluation(eps, v, np.zeros(6), params, options)
    return State(
        strain=np.zeros(6),
        elastic_strain=eps,
        stress=ev.stress,
        specific_volume=v,
        fabric=np.zeros(6),
        preconsolidation_pressure=pc,
    )


def _volume_limit_text(params: Parameters) -> str:
    pc_limit = params.p_r * params.N ** (1.0 / params.lambda_star)
    return (
        f"with N = {params.N:g}, λ* = {params.lambda_star:g} the normal compression line "
        f"reaches v = 1 at p_c = p_r N^(1/λ*) = {pc_limit:.4g} kPa; beyond it the void ratio "
        "would be negative and the model is unphysical"
    )


# ---------------------------------------------------------------------------------------------
# loading control
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Control:
    """Loading of one increment, per Mandel component: a strain increment or a stress target.

    stress_controlled: six booleans; strain_increment (1) is used on the strain-controlled
    components, stress_target (kPa, total stress at the end of the increment) on the others.
    """

    stress_controlled: tuple[bool, ...]
    strain_increment: tuple[float, ...]
    stress_target: tuple[float, ...]

    @classmethod
    def triaxial(
        cls,
        axial_strain_increment: float | None = None,
        axial_stress: float | None = None,
        radial_strain_increment: float | None = None,
        radial_stress: float | None = None,
    ) -> Control:
        """Axisymmetric control: give exactly one of (strain increment, stress) per direction."""
        if (axial_strain_increment is None) == (axial_stress is None):
            raise ParameterError("give exactly one of axial_strain_increment, axial_stress")
        if (radial_strain_increment is None) == (radial_stress is None):
            raise ParameterError("give exactly one of radial_strain_increment, radial_stress")
        a_s = axial_stress is not None
        r_s = radial_stress is not None
        de_a = 0.0 if axial_strain_increment is None else float(axial_strain_increment)
        de_r = 0.0 if radial_strain_increment is None else float(radial_strain_increment)
        sa = 0.0 if axial_stress is None else float(axial_stress)
        sr = 0.0 if radial_stress is None else float(radial_stress)
        return cls(
            stress_controlled=(a_s, r_s, r_s, False, False, False),
            strain_increment=(de_a, de_r, de_r, 0.0, 0.0, 0.0),
            stress_target=(sa, sr, sr, 0.0, 0.0, 0.0),
        )

    @classmethod
    def strain(cls, strain_increment_m) -> Control:
        """Fully strain-controlled increment (Mandel strain increment)."""
        return cls((False,) * 6, tuple(float(x) for x in strain_increment_m), (0.0,) * 6)

    def split(self, state: State) -> tuple[Control, Control]:
        """Two half increments: half the strain, stress target halfway, then the rest."""
        half = tuple(0.5 * x for x in self.strain_increment)
        mid = tuple(
            0.5 * (float(s) + t) if c else 0.0
            for s, t, c in zip(
                state.stress, self.stress_target, self.stress_controlled, strict=True
            )
        )
        return (
            Control(self.stress_controlled, half, mid),
            Control(self.stress_controlled, half, self.stress_target),
        )


# ---------------------------------------------------------------------------------------------
# local implicit solve (strain-controlled)
# ---------------------------------------------------------------------------------------------
def _finite_difference_steps(x: np.ndarray, strain_scale: float) -> np.ndarray:
    typical = np.empty(_SIZE)
    typical[_E] = strain_scale
    typical[_MU] = strain_scale
    typical[_B] = 1e-2
    typical[_LNV] = 1e-2
    return 1e-7 * np.maximum(np.abs(x), typical)


def _local_solve(state: State, strain_increment, params, options, settings, need_tangent=True):
    """One backward-Euler increment; returns (new state, algorithmic tangent 6×6 or None)."""
    deps = np.asarray(strain_increment, dtype=float)
    trial = state.elastic_strain + deps
    v_n = state.specific_volume
    with np.errstate(all="ignore"):
        ye = YieldEvaluation(trial, v_n, state.fabric, params, options)
    p_trial = float(trace(ye.stress)) / 3.0
    if not (np.all(np.isfinite(ye.stress)) and p_trial >= settings.minimum_pressure):
        raise ConvergenceError(
            f"elastic trial mean stress {p_trial:.4g} kPa below p_min = "
            f"{settings.minimum_pressure:g} kPa",
            state,
        )
    pc = float(ye.preconsolidation)
    if float(ye.value) <= 1e-12 * pc * pc:
        new = State(
            strain=state.strain + deps,
            elastic_strain=trial,
            stress=ye.stress,
            specific_volume=v_n,
            fabric=state.fabric,
            preconsolidation_pressure=pc,
            plastic_multiplier=state.plastic_multiplier,
            dissipated_energy=state.dissipated_energy,
            plastic=False,
        )
        tangent = stiffness(trial, v_n, state.fabric, params, options) if need_tangent else None
        return new, tangent

    strain_scale = max(float(np.max(np.abs(trial))), float(np.max(np.abs(deps))), 1e-14)
    problem = LocalProblem(trial, state.fabric, math.log(v_n), params, options, strain_scale)
    analytic = settings.jacobian == "analytic"
    x = np.concatenate([trial, [0.0], state.fabric, [math.log(v_n)]])
    with np.errstate(all="ignore"):
        res, sig, _ = problem.evaluate(x[None])
    res, sig = res[0], sig[0]
    norm = float(problem.norm(res))
    jac = None
    dsig = None
    converged = False
    for _ in range(settings.max_iterations):
        with np.errstate(all="ignore"):
            if analytic:
                out = problem.evaluate_jacobian(x[None])
                jac, dsig = out[3][0], out[4][0][:, :]
            else:
                h = _finite_difference_steps(x, strain_scale)
                batch = np.repeat(x[None], _SIZE, axis=0)
                batch[np.arange(_SIZE), np.arange(_SIZE)] += h
                res_b, sig_b, _ = problem.evaluate(batch)
                jac = (res_b - res[None]).T / h[None, :]
                dsig = (sig_b - sig[None]).T / h[None, :]
        if not np.all(np.isfinite(jac)):
            break
        try:
            step = np.linalg.solve(jac, -res)
        except np.linalg.LinAlgError:
            break
        trials = x[None] + _LINE_SEARCH_STEPS[:, None] * step[None]
        with np.errstate(all="ignore"):
            res_t, sig_t, _ = problem.evaluate(trials)
        norms = problem.norm(res_t)
        ok = np.isfinite(norms) & (norms < (1.0 - 1e-4 * _LINE_SEARCH_STEPS) * norm)
        if not np.any(ok):
            # stagnation at round-off level (ill-conditioned, e.g. ω β_s² → 3/2): accept when
            # within 1000 × tolerance, otherwise fail
            converged = norm < 1e3 * settings.tolerance
            break
        i = int(np.argmax(ok))
        x, res, sig, norm = trials[i], res_t[i], sig_t[i], float(norms[i])
        if norm < settings.tolerance:
            converged = True
            break
    if not converged or jac is None:
        raise ConvergenceError(
            f"local Newton did not converge (scaled residual {norm:.3g} > "
            f"{settings.tolerance:g}) for a strain increment of size {np.max(np.abs(deps)):.3g}",
            state,
        )
    mu = float(x[_MU])
    if mu < -1e3 * settings.tolerance * strain_scale:
        # plastic compaction raises F(v) = (v/N)^X; if |X| (1−n) ε^e_v > 1 it raises the stress
        # faster than the elastic unloading relieves it and no solution with Δλ ≥ 0 exists
        index = abs(params.energy_exponent) * (1.0 - params.n) * float(trace(state.elastic_strain))
        raise ConvergenceError(
            f"negative plastic multiplier μ = {mu:.3g}; softening index |X|(1−n)ε^e_v = "
            f"{index:.3g}"
            + (
                " ≥ 1: the parameters are unstable here (X = r/((n−1)λ*) too "
                "large, e.g. n close to 1)"
                if index >= 1.0
                else ""
            ),
            state,
        )
    eps, beta, v = x[_E], x[_B], math.exp(float(x[_LNV]))
    with np.errstate(all="ignore"):
        ye = YieldEvaluation(eps, v, beta, params, options)
    pc = float(ye.preconsolidation)
    dep = (mu / pc) * ye.flow
    d_inc = float(dissipation_rate(dep, beta, pc, params))
    tangent = None
    if need_tangent and analytic:  # the exact Jacobian at the converged point
        with np.errstate(all="ignore"):
            out = problem.evaluate_jacobian(x[None])
        jac, dsig = out[3][0], out[4][0]
    if need_tangent:
        try:
            tangent = dsig @ np.linalg.solve(jac, np.eye(_SIZE)[:, :6])
        except np.linalg.LinAlgError:
            tangent = stiffness(eps, v, beta, params, options)
    new = State(
        strain=state.strain + deps,
        elastic_strain=eps,
        stress=ye.stress,
        specific_volume=v,
        fabric=beta,
        preconsolidation_pressure=pc,
        plastic_multiplier=state.plastic_multiplier + mu / pc,
        dissipated_energy=state.dissipated_energy + d_inc,
        plastic=True,
    )
    return new, tangent


def _mixed_step(state: State, control: Control, params, options, settings, guess=None) -> State:
    if settings.triaxial_fast_path and triaxial_path.is_axisymmetric(state, control):
        model = triaxial_path.model_for(params, options)
        return triaxial_solver.mixed_step(model, state, control, settings, guess)
    mask = np.array(control.stress_controlled, dtype=bool)
    deps = np.where(mask, 0.0, np.asarray(control.strain_increment, dtype=float))
    if not np.any(mask):
        # halving is done by ``advance``; nesting it here too would cost 2^(2k) solves
        return _local_solve(state, deps, params, options, settings, need_tangent=False)[0]
    target = np.asarray(control.stress_target, dtype=float)
    u = np.flatnonzero(mask)
    kn = np.flatnonzero(~mask)
    if guess is not None and np.all(np.isfinite(guess)):
        deps[u] = np.asarray(guess, dtype=float)[u]
    else:
        d = stiffness(state.elastic_strain, state.specific_volume, state.fabric, params, options)
        rhs = target[u] - state.stress[u] - d[np.ix_(u, kn)] @ deps[kn]
        deps[u] = np.linalg.solve(d[np.ix_(u, u)], rhs)
    scale = settings.stress_tolerance * max(
        state.mean_stress, float(np.max(np.abs(target))), settings.minimum_pressure
    )
    best = math.inf
    last_good = None
    correction = np.zeros(len(u))
    backtracks = 0
    last_tangent = None
    local_error = ""
    for _ in range(settings.max_outer_iterations):
        try:
            # no substepping inside the outer iteration: a failed trial is backtracked here and
            # the whole increment is halved by ``advance`` (nesting both would cost 2^k solves)
            new, tangent = _local_solve(state, deps, params, options, settings)
            res = new.stress[u] - target[u]
            rnorm = float(np.max(np.abs(res)))
            failed = not math.isfinite(rnorm)
        except ConvergenceError as exc:
            failed = True
            local_error = exc.args[0]
        if failed or (last_good is not None and rnorm > best):
            backtracks += 1
            if last_good is None or backtracks > 12:
                break
            # backtrack: halve the last correction
            correction *= 0.5
            deps[u] = last_good + correction
            if np.max(np.abs(correction)) < 1e-16:
                break
            continue
        if rnorm <= scale:
            return new
        best = rnorm
        last_good = deps[u].copy()
        last_tangent = tangent
        try:
            correction = -np.linalg.solve(tangent[np.ix_(u, u)], res)
        except np.linalg.LinAlgError:
            break
        deps[u] = last_good + correction
    hint = ""
    if last_tangent is not None:
        sub = last_tangent[np.ix_(u, u)]
        if np.min(np.linalg.eigvals(0.5 * (sub + sub.T)).real) <= 0.0:
            hint = (
                "; the tangent under this control is not positive (limit point): use strain control"
            )
    raise ConvergenceError(
        "mixed stress/strain control did not converge (the prescribed stress may be beyond "
        "what the material can carry, e.g. a stress ratio at or above the critical one"
        f"{hint})" + (f"; last local failure: {local_error}" if local_error else ""),
        state,
    )


def _check_admissible(new: State, params: Parameters) -> None:
    if new.specific_volume < 1.0:
        raise SpecificVolumeBelowOneError(
            f"specific volume v = {new.specific_volume:.6g} < 1 at p = {new.mean_stress:.5g} "
            f"kPa: {_volume_limit_text(params)}",
            new,
        )
    b = new.fabric.tolist()
    mean = (b[0] + b[1] + b[2]) / 3.0
    dev2 = (b[0] - mean) ** 2 + (b[1] - mean) ** 2 + (b[2] - mean) ** 2 + b[3] ** 2 + b[4] ** 2
    # ω β_s² with β_s² = 3/2 dev β : dev β (pure Python: this runs after every increment)
    if params.omega * 1.5 * (dev2 + b[5] ** 2) >= 0.999 * CONVEXITY_LIMIT:
        if float(convexity_measure(new.fabric, params)) >= CONVEXITY_LIMIT:
            check_convexity(new.fabric, params, new)
    values = new.stress.tolist() + new.elastic_strain.tolist() + [new.specific_volume]
    if not all(map(math.isfinite, values)):
        raise ConvergenceError("non-finite state after an increment", new)


def advance(
    state: State,
    control: Control,
    params: Parameters = TABLE1,
    options: ModelOptions = DEFAULT_OPTIONS,
    settings: SolverSettings = DEFAULT_SETTINGS,
    guess=None,
    _depth: int = 0,
) -> State:
    """Integrate one loading increment (mixed control), halving it on failure.

    ``guess`` is an optional Mandel strain increment used as the starting value of the
    stress-controlled components (e.g. the previous increment scaled); by default the elastic
    stiffness gives it.

    Raises :class:`ConvergenceError`, :class:`SpecificVolumeBelowOneError` or
    :class:`NonConvexEnergyError` with the state at which it happened.
    """
    try:
        new = _mixed_step(state, control, params, options, settings, guess)
    except ConvergenceError as exc:
        if _depth >= settings.max_halvings:
            raise ConvergenceError(
                f"increment failed after {_depth} halvings ({exc.args[0]})", state
            ) from exc
        first, second = control.split(state)
        mid = advance(state, first, params, options, settings, None, _depth + 1)
        return advance(mid, second, params, options, settings, None, _depth + 1)
    _check_admissible(new, params)
    return new


def strain_increment(
    state: State,
    strain_increment_m,
    params: Parameters = TABLE1,
    options: ModelOptions = DEFAULT_OPTIONS,
    settings: SolverSettings = DEFAULT_SETTINGS,
) -> State:
    """Integrate a fully strain-controlled increment (Mandel strain increment)."""
    return advance(state, Control.strain(strain_increment_m), params, options, settings)


def algorithmic_tangent(
    state: State,
    strain_increment_m,
    params: Parameters = TABLE1,
    options: ModelOptions = DEFAULT_OPTIONS,
    settings: SolverSettings = DEFAULT_SETTINGS,
) -> tuple[State, np.ndarray]:
    """New state and dσ_{n+1}/dΔε (Mandel 6×6, kPa) of one strain increment (no substepping)."""
    return _local_solve(state, np.asarray(strain_increment_m, float), params, options, settings)


def constraint_force(state: State, params: Parameters, options: ModelOptions) -> float:
    """Λ_K = −X φ at a state (kPa); zero when constraint forces are off."""
    if not options.constraint_forces:
        return 0.0
    ev = EnergyEvaluation(
        state.elastic_strain, state.specific_volume, state.fabric, params, options
    )
    return float(constraint_pressure(ev.energy, params))


__all__ = [
    "Control",
    "TivModelError",
    "advance",
    "algorithmic_tangent",
    "constraint_force",
    "initial_state",
    "normally_consolidated_preconsolidation",
    "state_from_stress",
    "strain_increment",
]
