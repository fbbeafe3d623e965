"""Staged least-squares calibration of the TIV model on DEM series (docs/science/tiv-model.md §3).

Stages (each :func:`scipy.optimize.least_squares`, trust-region reflective, with bounds):

1. ``compressibility`` — λ*, N from v–ln p on the isotropic path A→B. Closed form: on the
   normally consolidated isotropic path β = 0 and v = N (p_c/p_r)^(−λ*), with p_c the
   isotropic yield point at p (:func:`tiv_model.integrate.normally_consolidated_preconsolidation`,
   p_c = p without constraint forces). Residual (ln v_model − ln v_DEM)/σ_lnv.
2. ``elastic`` — k, g, n, r (and ω, see below) from the probes: the model's elastic
   stiffness D at each probed state (σ_a, σ_r, v, β measured,
   :func:`bridge.moduli.moduli_at_states`) against E_oed,v, E_oed,h and, when the
   linear-response tensor is there, the cross term C_xxyy; probes of the isotropic path
   (k, g, n: K = k p_r (p/p_r)^n (p_c/p_r)^r) and of the constant-p unloading path (r: same p,
   different v; ω: E_h ≠ E_v at the anisotropic fabric left by K0).
   Residual (ln E_model − ln E_DEM)/σ_lnE.
3. ``fabric`` — c, s, z (and M unless fixed) from model runs along the DEM's K0 path
   (:func:`bridge.runs.k0_run`, ε_r = 0 at the DEM's σ_a): fabric β, and by default the K0
   stress ratio η (this is what fixes M) and optionally v. Residuals (model − DEM)/σ.

Where ω is fitted is an option (``omega_stage``). The study lists it with the fabric
parameters; here the default is the elastic stage, because ω is a parameter of the elastic
energy and the unloading probes, taken at measured anisotropic fabric, fix it directly. Measured
with exact synthetic data (tests/bridge): with ω in the fabric stage the alternating stages
settle on a wrong fixed point (ω 26 instead of 20, n 0.43 instead of 0.2: the elastic stage
trades n against ω on the unloading probes), with ω in the elastic stage all parameters come
back to 1e-6. E_h/E_v along K0 stays out of sample either way (K0 probes are not fitted).

The stages depend on each other weakly (constraint forces couple 1 to k, n, r; the elastic law
depends on N, λ*, ω), so the three stages are repeated (``passes``) until the parameters stop
changing. Uncertainty: per stage, covariance = s² (JᵀJ)⁻¹ from the Jacobian of the scaled
residuals at the solution, s² = 2·cost/(m − n) (lmfit's scaling); these standard errors are
conditional on the parameters of the other stages. Parameters that the data cannot fix show as
huge or infinite standard errors and a warning in :meth:`CalibrationResult.report`.

A failed model run inside a stage (tiv_model error: no convergence, v < 1, non-convex energy)
gives a large constant residual (``penalty``) so the optimiser steps back; so does a trial point
where a residual is not finite, e.g. a model modulus ≤ 0 in the elastic stage (the cross term
D_ra = K − 2G/3 < 0 where g is large against k: no logarithm). A stage that ends there fails
with :class:`CalibrationError` naming the stage and the model's message.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping

import numpy as np
import xarray as xr
from scipy.optimize import least_squares

from tiv_model.errors import TivModelError
from tiv_model.integrate import normally_consolidated_preconsolidation
from tiv_model.params import ModelOptions, Parameters

from ..moduli import moduli_at_states
from ..runs import WarmStart, k0_run, start_state, stress_path_run
from .options import (
    DEFAULT_BOUNDS,
    DEFAULT_SCALES,
    ELASTIC_MODULI,
    FABRIC_SERIES,
    INITIAL_FABRIC,
    STAGE_PARAMETERS,
    STAGES,
    UNITS,
    CalibrationError,
    CalibrationOptions,
    ModelFailureError,
)
from .result import CalibrationResult, StageFit, covariance_from_jacobian


# ---------------------------------------------------------------------------------------------
# residual models of the stages
# ---------------------------------------------------------------------------------------------
def isotropic_specific_volume(mean_stress, params: Parameters, options: ModelOptions) -> np.ndarray:
    """Model v on the normally consolidated isotropic path: v = N (p_c(p)/p_r)^(−λ*)."""
    p = np.atleast_1d(np.asarray(mean_stress, dtype=float))
    pc = np.array([normally_consolidated_preconsolidation(x, params, options) for x in p])
    return params.N * (pc / params.p_r) ** (-params.lambda_star)


class _Stage:
    """Residual function of one stage: ``residuals(params)`` (scaled) and per-series pieces."""

    name = ""

    def pieces(self, params: Parameters) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def scales(self) -> dict[str, float]:
        raise NotImplementedError

    fitted: tuple[tuple[str, str], ...] = ()

    def upper_bounds(self) -> dict[str, float]:
        """Stage-specific upper bounds (e.g. convexity of the energy at the measured fabric)."""
        return {}


class JointStage(_Stage):
    """Several stages as one residual (their pieces side by side), e.g. for profiles that let
    the parameters of coupled stages move together."""

    def __init__(self, stages: list[_Stage]):
        self.parts = list(stages)
        self.name = "+".join(st.name for st in self.parts)
        self.fitted = tuple(pair for st in self.parts for pair in st.fitted)

    def pieces(self, params):
        out = {}
        for st in self.parts:
            out.update(st.pieces(params))
        return out

    def scales(self):
        out = {}
        for st in self.parts:
            out.update(st.scales())
        return out

    def upper_bounds(self):
        out: dict[str, float] = {}
        for st in self.parts:
            for key, value in st.upper_bounds().items():
                out[key] = min(value, out.get(key, math.inf))
        return out


class _Compressibility(_Stage):
    name = "compressibility"

    def __init__(self, series: xr.Dataset, options: CalibrationOptions):
        keep = series["mean_stress"].values >= options.compressibility_min_pressure
        if keep.sum() < 2:
            raise CalibrationError(
                "stage compressibility needs ≥ 2 isotropic points with p ≥ "
                f"{options.compressibility_min_pressure:g} kPa, found {int(keep.sum())}"
            )
        self.p = series["mean_stress"].values[keep]
        self.lnv = np.log(series["specific_volume"].values[keep])
        self.model_options = options.model_options
        self._scales = {"isotropic:ln_specific_volume": options.scale("ln_specific_volume")}
        self.fitted = (("isotropic", "specific_volume"),)

    def pieces(self, params):
        v = isotropic_specific_volume(self.p, params, self.model_options)
        return {"isotropic:ln_specific_volume": np.log(v) - self.lnv}

    def scales(self):
        return self._scales


class _Elastic(_Stage):
    name = "elastic"

    def __init__(self, probes: Mapping[str, xr.Dataset], options: CalibrationOptions):
        self.model_options = options.model_options
        self.data = []
        fitted = []
        for path in options.elastic_paths:
            if path not in probes:
                continue
            ds = probes[path]
            for name in options.elastic_moduli:
                if name not in ds:
                    continue
                values = ds[name].values
                good = np.isfinite(values) & (values > 0)
                if not np.any(good):
                    continue
                self.data.append((path, name, ds, good, np.log(values[good])))
                fitted.append((path, name))
        if not self.data:
            raise CalibrationError(
                f"stage elastic: no probe moduli {list(options.elastic_moduli)} on the paths "
                f"{list(options.elastic_paths)}; probe paths given: {sorted(probes)}"
            )
        self.fitted = tuple(fitted)
        betas = np.concatenate([np.abs(ds["fabric"].values) for _, _, ds, *_ in self.data])
        self.max_fabric = float(np.max(betas)) if betas.size else 0.0
        self._scales = {f"{p}:ln_{n}": options.scale("ln_modulus") for p, n, *_ in self.data}

    def upper_bounds(self):
        # strict convexity of φ at every measured fabric: ω β² < 3/2 (tiv_model.energy)
        if self.max_fabric <= 0:
            return {}
        return {"omega": 0.999 * 1.5 / self.max_fabric**2}

    def pieces(self, params):
        out = {}
        cache = {}
        for path, name, ds, good, ln_e in self.data:
            if path not in cache:
                cache[path] = moduli_at_states(
                    ds["axial_stress"].values,
                    ds["radial_stress"].values,
                    ds["specific_volume"].values,
                    ds["fabric"].values,
                    params,
                    self.model_options,
                )
            # A trial point may give a model modulus <= 0: the cross term D_ra = K - 2G/3 is
            # negative where g is large against k. It has no logarithm: its residual is NaN
            # (-inf at 0), without numpy's warning, and the optimiser's residual function gives
            # the point the penalty, as a failed model run (module docstring).
            with np.errstate(invalid="ignore", divide="ignore"):
                out[f"{path}:ln_{name}"] = np.log(cache[path][name][good]) - ln_e
        return out

    def scales(self):
        return self._scales


class _Fabric(_Stage):
    name = "fabric"

    def __init__(self, series: xr.Dataset, options: CalibrationOptions, radial=None):
        if series.sizes["point"] < 2:
            raise CalibrationError("stage fabric needs the K0 path with ≥ 2 points (A and C)")
        self.axial = series["axial_stress"].values
        self.p_start = float(series["mean_stress"].values[0])
        measured = options.initial_fabric == "measured"
        self.start_fabric = float(series["fabric"].values[0]) if measured else 0.0
        self.data = {name: series[name].values[1:] for name in options.fabric_series}
        self.model_options = options.model_options
        self.max_increments = options.max_k0_increments
        key = {
            "fabric": "fabric",
            "stress_ratio": "stress_ratio",
            "specific_volume": "ln_specific_volume",
        }
        self._scales = {f"k0:{key[n]}": options.scale(key[n]) for n in options.fabric_series}
        self.fitted = tuple(("k0", n) for n in options.fabric_series)
        # the last run's increments start the next run's Newton (nearby parameters)
        self.warm = WarmStart()
        # radial paths (from A along the DEM's stresses): fabric, and v when asked for
        self.radial = {}
        for name, ds in (radial or {}).items():
            if ds.sizes["point"] < 2:
                continue
            wanted = [n for n in ("fabric", "specific_volume") if n in options.fabric_series]
            self.radial[name] = (ds, {n: ds[n].values[1:] for n in wanted}, WarmStart())
            for n in wanted:
                series_name = "ln_specific_volume" if n == "specific_volume" else n
                self._scales[f"{name}:{series_name}"] = options.scale(series_name)
            self.fitted += tuple((name, n) for n in wanted)

    def pieces(self, params):
        run = k0_run(
            self.axial,
            self.p_start,
            params,
            self.model_options,
            self.max_increments,
            start_fabric=self.start_fabric,
            warm=self.warm,
        )
        out = {}
        for name, data in self.data.items():
            model = run[name][1:]
            if name == "specific_volume":
                out["k0:ln_specific_volume"] = np.log(model) - np.log(data)
            else:
                out[f"k0:{name}"] = model - data
        for path, (ds, radial_data, warm) in self.radial.items():
            sa = ds["axial_stress"].values.copy()
            sr = ds["radial_stress"].values.copy()
            sa[0] = sr[0] = self.p_start  # from the model's state A, as the K0 run
            start = start_state(self.p_start, params, self.model_options, self.start_fabric)
            run = stress_path_run(sa, sr, params, self.model_options, start, self.max_increments,
                                  warm=warm)  # fmt: skip
            for name, values in radial_data.items():
                if name == "specific_volume":
                    out[f"{path}:ln_specific_volume"] = np.log(run[name][1:]) - np.log(values)
                else:
                    out[f"{path}:{name}"] = run[name][1:] - values
        return out

    def scales(self):
        return self._scales


# ---------------------------------------------------------------------------------------------
# the optimiser
# ---------------------------------------------------------------------------------------------
#: evaluations after which a dogbox fit that has not converged continues with trf
SWITCH_EVALUATIONS = 60


def _fit_stage(
    stage: _Stage, params: Parameters, free: tuple[str, ...], options: CalibrationOptions
) -> tuple[Parameters, StageFit]:
    t0 = time.perf_counter()
    scales = stage.scales()
    lo = np.array([options.bound(s)[0] for s in free])
    hi = np.array([min(options.bound(s)[1], stage.upper_bounds().get(s, np.inf)) for s in free])
    if np.any(hi <= lo):
        bad = [s for s, a, b in zip(free, lo, hi, strict=True) if b <= a]
        raise CalibrationError(f"stage {stage.name}: empty search range for {bad}")
    # start inside the bounds (e.g. ω below the convexity limit at the measured fabric)
    x0 = np.clip([params.as_symbols()[s] for s in free], lo, hi)
    params = params.replace(**dict(zip(free, (float(v) for v in x0), strict=True)))
    try:
        base = stage.pieces(params)
    except TivModelError as exc:
        raise ModelFailureError(
            stage.name,
            f"stage {stage.name}: the model fails at the starting parameters "
            f"{params.as_symbols()}: {exc}",
        ) from exc
    sizes = {k: v.size for k, v in base.items()}
    n_data = sum(sizes.values())
    if not free:
        cost = 0.5 * float(sum(np.sum((v / scales[k]) ** 2) for k, v in base.items()))
        fit = StageFit(
            stage.name,
            (),
            {},
            {},
            np.zeros((0, 0)),
            {k: float(np.sqrt(np.mean(v**2))) for k, v in base.items()},
            n_data,
            cost,
            1,
            True,
            "no free parameter",
            time.perf_counter() - t0,
            stage.fitted,
        )
        return params, fit
    failures = []

    def make(x) -> Parameters:
        return params.replace(**dict(zip(free, (float(v) for v in x), strict=True)))

    def residuals(x):
        try:
            # a trial point far from the data can overflow inside the model's local solve: the
            # model then rejects the step or fails (TivModelError), and a non-finite or failed
            # trial gets the penalty below, so numpy's warnings say nothing the fit does not handle
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                pieces = stage.pieces(make(x))
        except (TivModelError, ValueError, FloatingPointError, np.linalg.LinAlgError) as exc:
            failures.append(f"{type(exc).__name__}: {exc}")
            return np.full(n_data, options.penalty)
        res = np.concatenate([pieces[k] / scales[k] for k in sizes])
        if not np.all(np.isfinite(res)):
            failures.append("non-finite residuals")
            return np.full(n_data, options.penalty)
        return res

    diff_step = 1e-6 if stage.name == "fabric" else None
    budget = options.max_evaluations or 200 * (len(free) + 1)

    def solve(start, method, max_nfev):
        return least_squares(
            residuals,
            start,
            bounds=(lo, hi),
            x_scale="jac",
            method=method,
            diff_step=diff_step,
            xtol=options.tolerance,
            ftol=options.cost_tolerance,
            gtol=options.tolerance,
            max_nfev=max_nfev,
        )

    if options.method == "dogbox" and budget > SWITCH_EVALUATIONS:
        # dogbox reaches a bound in few steps (the demo's z = 1) but can creep along a flat
        # valley (the paper scene's c–s–z); trf, the other way round: when dogbox has not
        # converged after SWITCH_EVALUATIONS, trf continues from where it is
        sol = solve(x0, "dogbox", SWITCH_EVALUATIONS)
        if sol.status == 0:
            first = sol
            sol = solve(np.clip(sol.x, lo, hi), "trf", budget - SWITCH_EVALUATIONS)
            sol.nfev += first.nfev
            if first.cost < sol.cost:  # keep the better of the two
                sol = first
    else:
        sol = solve(x0, options.method, budget)
    final = residuals(sol.x)
    if np.all(final == options.penalty):
        raise ModelFailureError(
            stage.name,
            f"stage {stage.name}: the model fails at the best parameters found "
            f"({dict(zip(free, sol.x.tolist(), strict=True))}): "
            f"{failures[-1] if failures else '?'}",
        )
    jac = np.asarray(sol.jac, dtype=float)
    dof = n_data - len(free)
    s2 = 2.0 * float(sol.cost) / dof if dof > 0 else math.nan
    cov = covariance_from_jacobian(jac) * s2
    std = np.sqrt(np.diag(cov))
    fitted_params = make(sol.x)
    pieces = stage.pieces(fitted_params)
    rms = {k: float(np.sqrt(np.mean(v**2))) for k, v in pieces.items()}
    fit = StageFit(
        name=stage.name,
        parameters=free,
        values={s: float(v) for s, v in zip(free, sol.x, strict=True)},
        standard_errors={s: float(e) for s, e in zip(free, std, strict=True)},
        covariance=cov,
        residual_rms=rms,
        n_data=n_data,
        cost=float(sol.cost),
        nfev=int(sol.nfev),
        success=bool(sol.success),
        message=str(sol.message),
        seconds=time.perf_counter() - t0,
        fitted=stage.fitted,
        bounds={s: (float(a), float(b)) for s, a, b in zip(free, lo, hi, strict=True)},
        at_bound=_at_bound(free, sol.x, lo, hi),
    )
    return fitted_params, fit


def _at_bound(free, x, lo, hi) -> dict[str, str]:
    """Which free parameters ended on (within 1e-6 relative of) a bound: "lower" or "upper"."""
    out = {}
    for sym, value, a, b in zip(free, x, lo, hi, strict=True):
        if abs(value - a) <= 1e-6 * max(1.0, abs(a)):
            out[sym] = "lower"
        elif math.isfinite(b) and abs(value - b) <= 1e-6 * max(1.0, abs(b)):
            out[sym] = "upper"
    return out


def build_stages(
    series: Mapping[str, xr.Dataset],
    probes: Mapping[str, xr.Dataset],
    options: CalibrationOptions,
    stages: tuple[str, ...] = STAGES,
) -> dict[str, _Stage]:
    """The residual models of the stages, by name (what :func:`calibrate` fits)."""
    built: dict[str, _Stage] = {}
    for stage in stages:
        if stage == "compressibility":
            built[stage] = _Compressibility(series["isotropic"], options)
        elif stage == "elastic":
            built[stage] = _Elastic(probes, options)
        else:
            radial = {k: v for k, v in series.items() if k.startswith("radial_")}
            use = radial if "radial" in options.fabric_paths else {}
            built[stage] = _Fabric(series["k0"], options, use)
    return built


def fit_stage(stage, params: Parameters, free: tuple[str, ...], options: CalibrationOptions):
    """Fit one stage's ``free`` parameters from ``params``: (fitted Parameters, StageFit)."""
    return _fit_stage(stage, params, free, options)


def calibrate(
    series: Mapping[str, xr.Dataset],
    probes: Mapping[str, xr.Dataset],
    options: CalibrationOptions | None = None,
    stages: tuple[str, ...] = STAGES,
    keep_cheap_stages: bool = False,
) -> CalibrationResult:
    """Calibrate the TIV model on DEM series (:mod:`bridge.series`), staged (module docstring).

    ``series``: path series with at least ``"isotropic"`` and ``"k0"`` (for the stages run);
    ``probes``: probe series by path (``"isotropic"``, ``"unloading"``...).
    ``stages``: the stages to run, in order (a subset of ``STAGES``).
    ``keep_cheap_stages``: where the fabric stage runs after the cheap ones (ω in the elastic
    stage, the default) and its model fails at every parameter set the fit tries
    (:class:`ModelFailureError`), return the cheap stages' result with the failure in
    :attr:`CalibrationResult.not_fitted` and the fabric parameters at their starting values,
    instead of raising. A fabric stage coupled to the others (``omega_stage = "fabric"``)
    raises either way: its failure leaves no cheap result of its own.
    """
    options = options or CalibrationOptions()
    bad = sorted(set(stages) - set(STAGES))
    if bad or not stages:
        raise CalibrationError(f"unknown stage(s) {bad}; allowed {STAGES}")
    needs = {"compressibility": "isotropic", "fabric": "k0"}
    for stage in stages:
        if stage in needs and needs[stage] not in series:
            raise CalibrationError(
                f"stage {stage} needs the {needs[stage]!r} path series; given: {sorted(series)}"
            )
    built = build_stages(series, probes, options, stages)
    _check_identifiable(built, options)
    params = options.start()
    initial = params
    history = [params.as_symbols()]
    fits: dict[str, StageFit] = {}
    # The fabric stage (model runs, costly) changes nothing the other stages use unless ω is
    # fitted there: then the cheap stages are iterated to a fixed point first and the fabric
    # stage runs once; otherwise all stages are cycled ``passes`` times.
    cheap = tuple(s for s in stages if s != "fabric")
    coupled = options.omega_stage == "fabric" and "fabric" in stages
    groups = [stages] if coupled else [cheap, tuple(s for s in stages if s == "fabric")]
    passes = 0
    change = 0.0
    not_fitted: dict[str, str] = {}
    for group in groups:
        if not group:
            continue
        rounds = options.passes if (coupled or group == cheap) else 1
        for _ in range(rounds):
            passes += 1
            before = np.array(list(params.as_symbols().values()))
            for stage in group:
                try:
                    params, fits[stage] = _fit_stage(
                        built[stage], params, options.free(stage), options
                    )
                except ModelFailureError as error:
                    if not (keep_cheap_stages and stage == "fabric" and not coupled):
                        raise
                    not_fitted[stage] = str(error)
            history.append(params.as_symbols())
            after = np.array(list(params.as_symbols().values()))
            # relative change; parameters at a zero bound (r = 0...) count in absolute terms
            if rounds == 1:  # a stage nothing else depends on: no fixed point to reach
                break
            change = float(np.max(np.abs(after - before) / np.maximum(np.abs(before), 1e-6)))
            if change < options.pass_tolerance:
                break
    return CalibrationResult(
        params,
        initial,
        [fits[s] for s in stages if s in fits],
        options,
        passes,
        history,
        change,
        not_fitted,
    )


def _check_identifiable(built: Mapping[str, _Stage], options: CalibrationOptions) -> None:
    """Fail early, with advice, where the data cannot fix a free parameter."""
    elastic = built.get("elastic")
    if not isinstance(elastic, _Elastic):  # None: no elastic stage
        return
    free = options.free("elastic")
    names = {n for _, n, *_ in elastic.data}
    paths = {p for p, *_ in elastic.data}
    if "k" in free and "g" in free and "e_cross" not in names:
        raise CalibrationError(
            "stage elastic: with only constrained moduli E_oed = K + 4G/3 the data cannot "
            "separate k and g; use linear-response probes (cross term C_xxyy) or fix one, "
            "e.g. CalibrationOptions(fixed=('g',))"
        )
    if "r" in free and paths == {"isotropic"}:
        raise CalibrationError(
            "stage elastic: r needs probes at the same p with different v (the constant-p "
            "unloading path); none given, so fix r, e.g. CalibrationOptions(fixed=('r',))"
        )


__all__ = [
    "DEFAULT_BOUNDS",
    "DEFAULT_SCALES",
    "ELASTIC_MODULI",
    "FABRIC_SERIES",
    "INITIAL_FABRIC",
    "STAGES",
    "STAGE_PARAMETERS",
    "UNITS",
    "CalibrationError",
    "CalibrationOptions",
    "CalibrationResult",
    "JointStage",
    "StageFit",
    "build_stages",
    "calibrate",
    "fit_stage",
    "covariance_from_jacobian",
]
