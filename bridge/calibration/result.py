"""Results of the staged calibration: per-stage fits, covariance, report (lmfit-like)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from tiv_model.params import Parameters

from .options import UNITS, CalibrationOptions


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
    #: search bounds (low, high) of the free parameters
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)
    #: "lower"/"upper" for the parameters that ended on a search bound
    at_bound: dict[str, str] = field(default_factory=dict)

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
    #: stages asked for but not fitted, and why (``calibrate(..., keep_cheap_stages=True)``)
    not_fitted: dict[str, str] = field(default_factory=dict)

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
            for sym, side in st.at_bound.items():
                lo, hi = st.bounds.get(sym, (math.nan, math.nan))
                out.append(
                    f"{sym} = {st.values[sym]:.6g} is at the {side} search bound "
                    f"{lo if side == 'lower' else hi:g} of stage {st.name}: the data push it "
                    "there, its standard error is not an interval"
                )
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
        for stage, why in self.not_fitted.items():
            lines.append(f"[[Stage {stage}: not fitted]]")
            lines.append(f"    {why}")
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
            "stages_not_fitted": dict(self.not_fitted),
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
                    "at_bound": dict(st.at_bound),
                    "bounds": {k: [clean(a), clean(b)] for k, (a, b) in st.bounds.items()},
                    "correlation": [[clean(c) for c in row] for row in st.correlation],
                }
                for st in self.stages_
            ],
            "fitted": [list(p) for p in self.fitted_],
            "warnings": self.warnings(),
        }


__all__ = [
    "covariance_from_jacobian",
    "StageFit",
    "CalibrationResult",
]
