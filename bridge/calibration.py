"""Staged least-squares calibration of the TIV model on DEM series (model.md §3).

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
gives a large constant residual (``penalty``) so the optimiser steps back; a stage that ends
there fails with :class:`CalibrationError` naming the stage and the model's message.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np
import xarray as xr
from scipy.optimize import least_squares

from tiv_model.errors import TivModelError
from tiv_model.integrate import normally_consolidated_preconsolidation
from tiv_model.params import (
    DEFAULT_OPTIONS,
    PARAMETER_INFO,
    SYMBOLS,
    TABLE1,
    ModelOptions,
    Parameters,
)

from .moduli import moduli_at_states
from .runs import k0_run

STAGES = ("compressibility", "elastic", "fabric")
#: Parameters (study symbols) fitted in each stage, before removing the fixed ones.
STAGE_PARAMETERS: Mapping[str, tuple[str, ...]] = MappingProxyType(
    {
        "compressibility": ("N", "lambda_star"),
        "elastic": ("k", "g", "n", "r", "omega"),
        "fabric": ("c", "s", "z", "M"),
    }
)
#: Default search bounds (study symbols).
DEFAULT_BOUNDS: Mapping[str, tuple[float, float]] = MappingProxyType(
    {
        "k": (0.1, 1e5),
        "g": (0.1, 1e5),
        "n": (0.0, 0.95),
        "r": (0.0, 5.0),
        "N": (1.0 + 1e-6, 50.0),
        "lambda_star": (1e-4, 3.0),
        "M": (0.05, 3.0),
        "c": (0.0, 200.0),
        "s": (1e-3, 200.0),
        "z": (1.0 + 1e-6, 200.0),
        "omega": (0.0, 1e3),
    }
)
#: Default residual scales (one standard deviation of the data, in the residual's units).
DEFAULT_SCALES: Mapping[str, float] = MappingProxyType(
    {"ln_specific_volume": 0.01, "ln_modulus": 0.05, "fabric": 0.01, "stress_ratio": 0.02}
)
FABRIC_SERIES = ("fabric", "stress_ratio", "specific_volume")
ELASTIC_MODULI = ("e_oed_v", "e_oed_h", "e_cross")
INITIAL_FABRIC = ("zero", "measured")
_SYMBOL_TO_NAME = {sym: name for name, sym in SYMBOLS.items()}
UNITS = {sym: PARAMETER_INFO[name][1] for name, sym in SYMBOLS.items()}


class CalibrationError(RuntimeError):
    """A calibration stage could not be set up or did not succeed; the message says why."""


@dataclass(frozen=True)
class CalibrationOptions:
    """How to calibrate (defaults follow the study).

    reference_pressure: p_r (kPa), the only dimensional parameter, never fitted.
    model_options: the model's uncertain parts (anisotropy form, constraint forces, bound law).
    initial: starting values; parameters listed in ``fixed`` (study symbols) keep them.
    fit_critical_stress_ratio: fit M in the fabric stage from the K0 stress ratio (else fixed).
    omega_stage: ``"elastic"`` (default) or ``"fabric"`` (the study's grouping), where ω is fitted.
    initial_fabric: the model's fabric at A: ``"zero"`` (default, isotropic as in the model's
        standard start) or ``"measured"`` (the DEM's β at A; p_c from the rotated yield surface,
        :func:`bridge.runs.start_state`).
    fabric_series: K0 series fitted in the fabric stage, among ``FABRIC_SERIES``.
    elastic_moduli: probe moduli fitted in the elastic stage, among ``ELASTIC_MODULI``
        (the cross term is used only where the probes have it).
    elastic_paths: probe paths of the elastic stage.
    compressibility_min_pressure: isotropic points with p below it (kPa) are not fitted.
    max_k0_increments: most increments of a model K0 run (more DEM points are interpolated).
    passes: most repetitions of the coupled stages (stops when no parameter changes by more
        than ``pass_tolerance``, relative, or absolute below 1e-6):
        compressibility and elastic (cheap) are cycled to a fixed point, then fabric runs once;
        with ``omega_stage="fabric"`` all three are cycled.
    scales: residual scales, keys of ``DEFAULT_SCALES``.
    bounds: per-symbol (low, high) overriding ``DEFAULT_BOUNDS``.
    penalty: residual value given to each point when a model run fails.
    method: :func:`scipy.optimize.least_squares` method of every stage: ``"dogbox"``
        (default: bounds as an active set; on the demo's fabric stage, where z sits at its
        bound, a third of the model runs of ``"trf"`` for the same cost) or ``"trf"`` (the
        method before issue 12).
    """

    reference_pressure: float = 100.0
    model_options: ModelOptions = DEFAULT_OPTIONS
    initial: Parameters = TABLE1
    fixed: tuple[str, ...] = ()
    fit_critical_stress_ratio: bool = True
    omega_stage: str = "elastic"
    initial_fabric: str = "zero"
    fabric_series: tuple[str, ...] = ("fabric", "stress_ratio")
    elastic_moduli: tuple[str, ...] = ELASTIC_MODULI
    elastic_paths: tuple[str, ...] = ("isotropic", "unloading")
    compressibility_min_pressure: float = 0.0
    max_k0_increments: int = 12
    passes: int = 12
    pass_tolerance: float = 1e-9
    scales: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_SCALES))
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    penalty: float = 1e3
    method: str = "dogbox"

    def __post_init__(self) -> None:
        if self.method not in ("dogbox", "trf"):
            raise CalibrationError(f"option method = {self.method!r}: use 'dogbox' or 'trf'")
        if not (isinstance(self.reference_pressure, (int, float)) and self.reference_pressure > 0):
            raise CalibrationError(f"reference_pressure = {self.reference_pressure!r} must be > 0")
        allowed = set(SYMBOLS.values()) - {"p_r"}
        for name, values, ok in (
            ("fixed", self.fixed, allowed),
            ("fabric_series", self.fabric_series, set(FABRIC_SERIES)),
            ("elastic_moduli", self.elastic_moduli, set(ELASTIC_MODULI)),
            ("elastic_paths", self.elastic_paths, {"isotropic", "unloading", "k0"}),
            ("scales", tuple(self.scales), set(DEFAULT_SCALES)),
            ("bounds", tuple(self.bounds), allowed),
        ):
            bad = sorted(set(values) - ok)
            if bad:
                raise CalibrationError(
                    f"option {name}: unknown entries {bad}; allowed {sorted(ok)}"
                )
        if self.omega_stage not in ("elastic", "fabric"):
            raise CalibrationError(
                f"option omega_stage = {self.omega_stage!r}: use 'elastic' or 'fabric'"
            )
        if self.initial_fabric not in INITIAL_FABRIC:
            raise CalibrationError(
                f"option initial_fabric = {self.initial_fabric!r}: use one of {INITIAL_FABRIC}"
            )
        if not self.fabric_series:
            raise CalibrationError("option fabric_series must name at least one K0 series")
        for key in ("passes", "max_k0_increments"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise CalibrationError(f"option {key} = {value!r} must be an integer ≥ 1")

    def start(self) -> Parameters:
        return self.initial.replace(p_r=float(self.reference_pressure))

    def bound(self, symbol: str) -> tuple[float, float]:
        return tuple(self.bounds.get(symbol, DEFAULT_BOUNDS[symbol]))  # type: ignore[return-value]

    def scale(self, key: str) -> float:
        return float(self.scales.get(key, DEFAULT_SCALES[key]))

    def free(self, stage: str) -> tuple[str, ...]:
        names = [s for s in STAGE_PARAMETERS[stage] if s not in self.fixed]
        if self.omega_stage == "fabric":
            names = [s for s in names if s != "omega"]
            if stage == "fabric" and "omega" not in self.fixed:
                names.append("omega")
        if stage == "fabric" and not self.fit_critical_stress_ratio:
            names = [s for s in names if s != "M"]
        return tuple(names)


def covariance_from_jacobian(jac: np.ndarray) -> np.ndarray:
    """(JᵀJ)⁻¹ from the SVD of J = U S Vᵀ: V S⁻² Vᵀ, non-negative diagonal by construction.

    Singular values below ``max(S)·max(shape)·eps`` span directions the data do not determine;
    a parameter with a component along such a direction gets an infinite variance (reported as
    not determined) instead of the meaningless, possibly negative, value of a plain inverse.
    """
    n = jac.shape[1]
    if jac.size == 0 or not np.all(np.isfinite(jac)):
        return np.full((n, n), math.inf)
    _, sv, vt = np.linalg.svd(jac, full_matrices=False)
    keep = sv > sv.max() * max(jac.shape) * np.finfo(float).eps
    cov = (vt[keep].T / sv[keep] ** 2) @ vt[keep]
    if sv.size < n or not np.all(keep):
        null = vt[~keep] if sv.size == n else np.vstack([vt[~keep], np.eye(n)])
        weak = np.any(np.abs(null) > 1e-8, axis=0)
        cov[weak, :] = math.inf
        cov[:, weak] = math.inf
    return cov


@dataclass
class StageFit:
    """Outcome of one stage: values, standard errors, covariance, fit quality."""

    name: str
    parameters: tuple[str, ...]
    values: dict[str, float]
    standard_errors: dict[str, float]
    covariance: np.ndarray
    residual_rms: dict[str, float]
    n_data: int
    cost: float
    nfev: int
    success: bool
    message: str
    seconds: float
    fitted: tuple[tuple[str, str], ...]

    @property
    def correlation(self) -> np.ndarray:
        std = np.sqrt(np.diag(self.covariance))
        with np.errstate(all="ignore"):
            return self.covariance / np.outer(std, std)


@dataclass
class CalibrationResult:
    """Calibrated parameters with uncertainty, fit quality and what was fitted (lmfit-like)."""

    params_: Parameters
    initial_: Parameters
    stages_: list[StageFit]
    options: CalibrationOptions
    passes_run: int
    history_: list[dict[str, float]] = field(default_factory=list)
    #: largest relative parameter change in the last pass over coupled stages
    last_change: float = 0.0

    @property
    def standard_errors_(self) -> dict[str, float]:
        out = {}
        for st in self.stages_:
            out.update(st.standard_errors)
        return out

    @property
    def covariance_(self) -> dict[str, np.ndarray]:
        return {st.name: st.covariance for st in self.stages_}

    @property
    def residual_rms_(self) -> dict[str, float]:
        out = {}
        for st in self.stages_:
            out.update(st.residual_rms)
        return out

    @property
    def fitted_(self) -> tuple[tuple[str, str], ...]:
        """(path, variable) pairs that entered a residual."""
        return tuple(pair for st in self.stages_ for pair in st.fitted)

    @property
    def fitted_parameters(self) -> tuple[str, ...]:
        return tuple(p for st in self.stages_ for p in st.parameters)

    def role(self, path: str, variable: str) -> str:
        """``"fitted"`` if (path, variable) entered the calibration, else ``"out_of_sample"``."""
        return "fitted" if (path, variable) in self.fitted_ else "out_of_sample"

    def parameter_table(self) -> list[dict[str, object]]:
        rows = []
        errors = self.standard_errors_
        fitted = set(self.fitted_parameters)
        for sym, value in self.params_.as_symbols().items():
            stage = next((st.name for st in self.stages_ if sym in st.parameters), "fixed")
            rows.append(
                {
                    "symbol": sym,
                    "value": value,
                    "standard_error": errors.get(sym, math.nan),
                    "units": UNITS[sym],
                    "stage": stage if sym in fitted else "fixed",
                    "initial": self.initial_.as_symbols()[sym],
                }
            )
        return rows

    def warnings(self) -> list[str]:
        out = []
        if self.last_change >= self.options.pass_tolerance:
            out.append(
                f"the coupled stages did not settle within {self.options.passes} passes (last "
                f"relative parameter change {self.last_change:.2g} ≥ "
                f"{self.options.pass_tolerance:g})"
            )
        for st in self.stages_:
            if not st.success:
                out.append(f"stage {st.name}: optimiser did not report success ({st.message})")
            for sym in st.parameters:
                err = st.standard_errors.get(sym, math.nan)
                val = st.values[sym]
                if not math.isfinite(err) or (val != 0 and err > abs(val)):
                    out.append(
                        f"{sym} is poorly determined by the data of stage {st.name} "
                        f"(standard error {err:.3g} vs value {val:.4g})"
                    )
        return out

    def report(self) -> str:
        """Plain-text report: parameters ± standard errors, fit quality, what was fitted."""
        lines = ["[[Calibration of the TIV model]]"]
        lines.append(
            f"    passes: {self.passes_run}, model options: {self.options.model_options.describe()}"
        )
        lines.append("[[Parameters]]")
        for row in self.parameter_table():
            err = row["standard_error"]
            err_s = f"+/- {err:.3g}" if isinstance(err, float) and math.isfinite(err) else ""
            lines.append(
                f"    {row['symbol']:<12} = {row['value']:<12.6g} {err_s:<14} [{row['units']}] "
                f"({row['stage']}; init {row['initial']:.4g})"
            )
        for st in self.stages_:
            lines.append(f"[[Stage {st.name}]]")
            lines.append(
                f"    {st.n_data} residuals, cost {st.cost:.4g}, {st.nfev} evaluations, "
                f"{st.seconds:.2f} s, success {st.success}: {st.message}"
            )
            for key, rms in st.residual_rms.items():
                lines.append(f"    RMS {key}: {rms:.4g}")
            lines.append("    fitted: " + ", ".join(f"{p}:{v}" for p, v in st.fitted))
        warnings = self.warnings()
        if warnings:
            lines.append("[[Warnings]]")
            lines.extend(f"    {w}" for w in warnings)
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-serialisable summary."""

        def clean(x):
            return float(x) if math.isfinite(float(x)) else None

        return {
            "parameters": {k: clean(v) for k, v in self.params_.as_symbols().items()},
            "standard_errors": {k: clean(v) for k, v in self.standard_errors_.items()},
            "units": dict(UNITS),
            "model_options": self.options.model_options.describe(),
            "passes": self.passes_run,
            "stages": [
                {
                    "name": st.name,
                    "parameters": list(st.parameters),
                    "residual_rms": {k: clean(v) for k, v in st.residual_rms.items()},
                    "n_data": st.n_data,
                    "cost": clean(st.cost),
                    "nfev": st.nfev,
                    "success": st.success,
                    "message": st.message,
                    "seconds": st.seconds,
                    "fitted": [list(p) for p in st.fitted],
                    "correlation": [[clean(c) for c in row] for row in st.correlation],
                }
                for st in self.stages_
            ],
            "fitted": [list(p) for p in self.fitted_],
            "warnings": self.warnings(),
        }


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
            out[f"{path}:ln_{name}"] = np.log(cache[path][name][good]) - ln_e
        return out

    def scales(self):
        return self._scales


class _Fabric(_Stage):
    name = "fabric"

    def __init__(self, series: xr.Dataset, options: CalibrationOptions):
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

    def pieces(self, params):
        run = k0_run(
            self.axial,
            self.p_start,
            params,
            self.model_options,
            self.max_increments,
            start_fabric=self.start_fabric,
        )
        out = {}
        for name, data in self.data.items():
            model = run[name][1:]
            if name == "specific_volume":
                out["k0:ln_specific_volume"] = np.log(model) - np.log(data)
            else:
                out[f"k0:{name}"] = model - data
        return out

    def scales(self):
        return self._scales


# ---------------------------------------------------------------------------------------------
# the optimiser
# ---------------------------------------------------------------------------------------------
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
        raise CalibrationError(
            f"stage {stage.name}: the model fails at the starting parameters "
            f"{params.as_symbols()}: {exc}"
        ) from exc
    sizes = {k: v.size for k, v in base.items()}
    n_data = sum(sizes.values())
    if not free:
        values = {}
        fit = StageFit(
            stage.name,
            (),
            values,
            {},
            np.zeros((0, 0)),
            {k: float(np.sqrt(np.mean(v**2))) for k, v in base.items()},
            n_data,
            0.0,
            0,
            True,
            "no free parameter",
            0.0,
            stage.fitted,
        )
        return params, fit
    failures = []

    def make(x) -> Parameters:
        return params.replace(**dict(zip(free, (float(v) for v in x), strict=True)))

    def residuals(x):
        try:
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
    sol = least_squares(
        residuals,
        x0,
        bounds=(lo, hi),
        x_scale="jac",
        method=options.method,
        diff_step=diff_step,
        xtol=1e-12,
        ftol=1e-12,
        gtol=1e-12,
        max_nfev=200 * (len(free) + 1),
    )
    final = residuals(sol.x)
    if np.all(final == options.penalty):
        raise CalibrationError(
            f"stage {stage.name}: the model fails at the best parameters found "
            f"({dict(zip(free, sol.x.tolist(), strict=True))}): {failures[-1] if failures else '?'}"
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
    )
    return fitted_params, fit


def calibrate(
    series: Mapping[str, xr.Dataset],
    probes: Mapping[str, xr.Dataset],
    options: CalibrationOptions | None = None,
    stages: tuple[str, ...] = STAGES,
) -> CalibrationResult:
    """Calibrate the TIV model on DEM series (:mod:`bridge.series`), staged (module docstring).

    ``series``: path series with at least ``"isotropic"`` and ``"k0"`` (for the stages run);
    ``probes``: probe series by path (``"isotropic"``, ``"unloading"``...).
    ``stages``: the stages to run, in order (a subset of ``STAGES``).
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
    built: dict[str, _Stage] = {}
    for stage in stages:
        if stage == "compressibility":
            built[stage] = _Compressibility(series["isotropic"], options)
        elif stage == "elastic":
            built[stage] = _Elastic(probes, options)
        else:
            built[stage] = _Fabric(series["k0"], options)
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
    for group in groups:
        if not group:
            continue
        rounds = options.passes if (coupled or group == cheap) else 1
        for _ in range(rounds):
            passes += 1
            before = np.array(list(params.as_symbols().values()))
            for stage in group:
                params, fits[stage] = _fit_stage(built[stage], params, options.free(stage), options)
            history.append(params.as_symbols())
            after = np.array(list(params.as_symbols().values()))
            # relative change; parameters at a zero bound (r = 0...) count in absolute terms
            if rounds == 1:  # a stage nothing else depends on: no fixed point to reach
                break
            change = float(np.max(np.abs(after - before) / np.maximum(np.abs(before), 1e-6)))
            if change < options.pass_tolerance:
                break
    return CalibrationResult(
        params, initial, [fits[s] for s in stages], options, passes, history, change
    )


def _check_identifiable(built: Mapping[str, _Stage], options: CalibrationOptions) -> None:
    """Fail early, with advice, where the data cannot fix a free parameter."""
    elastic = built.get("elastic")
    if elastic is None:
        return
    free = options.free("elastic")
    names = {n for _, n, *_ in elastic.data}  # type: ignore[attr-defined]
    paths = {p for p, *_ in elastic.data}  # type: ignore[attr-defined]
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
