"""What the data determine: profile likelihoods, parameters at bounds, correlations, replicas.

Profile likelihood (per stage, conditional on the other stages' parameters, like the standard
errors; the compressibility and elastic stages together): for a free parameter θ of a stage,
C_p(θ) = min of the stage's cost C = ½ Σ (residual/scale)² over the stage's other free
parameters, with θ held on a grid that walks away from the optimum θ̂ on each side (from 1.96
standard errors, or a twentieth of |θ̂| or of a tenth of the search range, doubling, at most
``max_steps`` steps or up to the search bound), each refit started from the previous one.
With the residual variance s² = 2 C_min/(m − n) (the scaling of the standard errors),
Δ(θ) = 2 (C_p(θ) − C_min)/s² follows F(1, m − n) (χ²₁ for many residuals), and the ``level``
(95 %) profile interval is where Δ < F⁻¹(level; 1, m − n) (3.84 for m − n → ∞, 4.1 for
m − n = 35); its ends are bracketed by bisection and interpolated in √Δ.

Each parameter gets a status:

* ``determined`` — the interval closes on both sides inside the search range;
* ``bounded below`` / ``bounded above`` — it closes on one side only: the data give a bound;
* ``not determined`` — it closes on neither side (the profile is flat over the range);
* ``fixed`` — not fitted: kept at :attr:`CalibrationOptions.initial` (the study's Table 1 by
  default, the literature value), or p_r (a unit choice);

and a flag when the optimum sits on a search bound (the bound, not the data, sets the value
there: the standard error is then no interval). Correlations |ρ| ≥ 0.95 within a stage's
covariance are listed. :func:`replica_spread` summarises calibrations on replica runs (the
spread the DEM's own scatter gives the parameters).

A side also stays open where the refits fail (the model cannot be evaluated, or fitted, with θ
held there: a limit point of a path, a parameter outside the model's domain). Such a point is
no evidence against θ, only the lack of any: the profile records the nearest failing value
(``failed_lower``/``failed_upper``) and the statement says so. (Counting a failure as Δ = ∞
closed both sides at θ̂ itself: a zero-width "determined" interval for a parameter the data
did not determine, seen on a 300-rod demo calibration whose K0 path reached a limit point.)
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2
from scipy.stats import f as f_dist

from tiv_model.errors import TivModelError
from tiv_model.params import Parameters

from .fit import JointStage, build_stages, fit_stage
from .options import STAGES, CalibrationError
from .result import CalibrationResult

#: xtol/ftol/gtol of the refits along a profile (Δ needs ~3 digits, not 12)
PROFILE_TOLERANCE = 1e-8
#: most residual evaluations of one refit along a profile (each starts from the previous one)
PROFILE_EVALUATIONS = 60
STATUSES = ("determined", "bounded below", "bounded above", "not determined", "fixed")


@dataclass(frozen=True)
class Profile:
    """Profile likelihood of one parameter: grid, Δ(θ), interval and status."""

    symbol: str
    stage: str
    value: float
    values: tuple[float, ...]
    delta: tuple[float, ...]
    lower: float  # interval end; where it does not close, the last point profiled
    upper: float
    closed_lower: bool
    closed_upper: bool
    at_bound: str
    level: float
    #: refits that stopped at PROFILE_EVALUATIONS (their C_p is an upper bound: the interval
    #: may then be too narrow)
    capped_refits: int = 0
    #: the nearest value on each side where the refit failed and left that side open (NaN: none)
    failed_lower: float = math.nan
    failed_upper: float = math.nan

    @property
    def status(self) -> str:
        if self.closed_lower and self.closed_upper:
            return "determined"
        if self.closed_lower:
            return "bounded below"
        if self.closed_upper:
            return "bounded above"
        return "not determined"


@dataclass
class Identifiability:
    """Profiles of every fitted parameter, correlations and what is fixed."""

    profiles: dict[str, Profile]
    fixed: dict[str, float]
    correlations: list[tuple[str, str, float]]
    level: float
    seconds: float
    notes: list[str] = field(default_factory=list)

    def status(self, symbol: str) -> str:
        return "fixed" if symbol in self.fixed else self.profiles[symbol].status

    def determined(self) -> tuple[str, ...]:
        return tuple(s for s, p in self.profiles.items() if p.status == "determined")

    def statement(self) -> str:
        """Plain sentences: what the data determine, what they bound, what is fixed and why."""
        groups: dict[str, list[str]] = {s: [] for s in STATUSES}
        for sym, prof in self.profiles.items():
            groups[prof.status].append(sym)
        lines = []
        pct = f"{100 * self.level:g} %"
        if groups["determined"]:
            lines.append(
                f"Determined by the data ({pct} profile interval closed on both sides): "
                + ", ".join(groups["determined"])
                + "."
            )
        for key in ("bounded below", "bounded above"):
            if groups[key]:
                lines.append(
                    f"Only {key} by the data (the profile rises on one side only): "
                    + ", ".join(groups[key])
                    + "."
                )
        if groups["not determined"]:
            lines.append(
                f"Not determined (the {pct} profile interval closes on neither side: the "
                "profile is flat over the search range, or the model fails beyond the values "
                "given below; the value reported may be one of many that fit as well): "
                + ", ".join(groups["not determined"])
                + "."
            )
        failed = [
            f"{s} ({' and '.join(_failed_sides(p))})"
            for s, p in self.profiles.items()
            if _failed_sides(p)
        ]
        if failed:
            lines.append(
                "The model could not be evaluated or refitted with the parameter held beyond "
                "these values, so the data say nothing there (the side stays open): "
                + ", ".join(failed)
                + "."
            )
        at_bound = [f"{s} ({p.at_bound})" for s, p in self.profiles.items() if p.at_bound]
        if at_bound:
            lines.append("At a search bound: " + ", ".join(at_bound) + ".")
        if self.fixed:
            lines.append(
                "Fixed, not fitted: "
                + ", ".join(f"{s} = {v:g}" for s, v in self.fixed.items())
                + " (p_r is the unit of stress; the others keep the starting values, the "
                "study's Table 1 unless given)."
            )
        if self.correlations:
            lines.append(
                "Strongly correlated within a stage (|ρ| ≥ 0.95): "
                + ", ".join(f"{a}–{b} ({r:+.3f})" for a, b, r in self.correlations)
                + "."
            )
        lines.extend(self.notes)
        return "\n".join(lines)

    def to_dict(self) -> dict:
        def clean(x):
            return float(x) if math.isfinite(float(x)) else None

        return {
            "level": self.level,
            "seconds": self.seconds,
            "profiles": {
                s: {
                    "stage": p.stage,
                    "value": p.value,
                    "lower": clean(p.lower),
                    "upper": clean(p.upper),
                    "status": p.status,
                    "at_bound": p.at_bound,
                    "capped_refits": p.capped_refits,
                    "failed_lower": clean(p.failed_lower),
                    "failed_upper": clean(p.failed_upper),
                    "grid": [clean(v) for v in p.values],
                    "delta": [clean(d) for d in p.delta],
                }
                for s, p in self.profiles.items()
            },
            "fixed": dict(self.fixed),
            "correlations": [[a, b, r] for a, b, r in self.correlations],
            "statement": self.statement(),
        }


def _failed_sides(profile: Profile) -> list[str]:
    """'below X' / 'above Y' for the sides of ``profile`` left open by failed refits."""
    sides = []
    if math.isfinite(profile.failed_lower):
        sides.append(f"below {profile.failed_lower:.4g}")
    if math.isfinite(profile.failed_upper):
        sides.append(f"above {profile.failed_upper:.4g}")
    return sides


def _profile_cost(stage, params: Parameters, symbol: str, value: float, free, options):
    """(C_p, refitted Parameters, whether the refit stopped at the evaluation cap) with
    ``symbol`` held at ``value``."""
    held = params.replace(**{symbol: float(value)})
    others = tuple(s for s in free if s != symbol)
    try:
        fitted, fit = fit_stage(stage, held, others, options)
    except (CalibrationError, TivModelError):
        return math.inf, params, False
    return fit.cost, fitted, not fit.success


def profile_parameter(
    stage, params: Parameters, symbol: str, fit, options, level: float = 0.95,
    max_steps: int = 6, bisections: int = 3,
) -> Profile:  # fmt: skip
    """Profile of ``symbol`` of the fitted stage ``fit`` at ``params`` (module docstring).

    Each side starts 1.96 standard errors away (see the module docstring when the standard
    error is not usable), doubles the step while Δ stays below half the threshold, jumps to the
    quadratic-profile estimate of the crossing once it is above half, and brackets the crossing
    by bisection until Δ there is within 1.5× the threshold; the end of the interval is
    interpolated linearly in √Δ (exact for a quadratic profile). A side whose crossing stays at a
    failed refit (Δ = ∞) after the bisections stays open at the last finite point (module
    docstring).
    """
    free = fit.parameters
    dof = fit.n_data - len(free)
    s2 = 2.0 * fit.cost / dof if dof > 0 and fit.cost > 0 else 1.0
    # s² is estimated from the same residuals: Δ follows F(1, m − n) (lmfit's conf_interval
    # uses the same F test), which is χ²₁ for many residuals
    threshold = float(f_dist.ppf(level, 1, dof)) if dof > 0 else float(chi2.ppf(level, 1))
    value = float(fit.values[symbol])
    lo, hi = fit.bounds.get(symbol, (-math.inf, math.inf))
    se = fit.standard_errors.get(symbol, math.nan)
    span = hi - lo if math.isfinite(hi - lo) else math.inf
    usable = math.isfinite(se) and 0.0 < se < max(abs(value), 0.1 * span)
    # without a usable standard error: a twentieth of |θ̂| or of a tenth of the search range
    first = 1.96 * se if usable else 0.05 * max(abs(value), min(0.1 * span, 1.0), 1e-3)
    grid, delta = [value], [0.0]
    ends, closed, failed = {}, {}, {-1.0: math.nan, 1.0: math.nan}
    capped = 0

    def at(current, target):
        nonlocal capped
        cost, refit, cap = _profile_cost(stage, current, symbol, target, free, options)
        capped += cap
        d = 2.0 * (cost - fit.cost) / s2
        d = d if math.isfinite(d) else math.inf  # a NaN cost is a failed refit too
        grid.append(target)
        delta.append(d)
        return d, refit

    for side in (-1.0, 1.0):
        bound = lo if side < 0 else hi
        current, inside, inside_value = params, 0.0, value
        closed[side], ends[side] = False, bound
        out = None
        step = first
        for _ in range(max_steps):
            if abs(inside_value - bound) <= 1e-12 * max(1.0, abs(bound)):
                break  # the previous point was the bound
            target = inside_value + side * step
            if (target - bound) * side >= 0:
                target = bound
            d, refit = at(current, target)
            if d >= threshold:
                out = (target, d)
                break
            inside_value, inside, current = target, d, refit
            offset = abs(target - value)
            if d >= 0.5 * threshold:  # quadratic estimate of the crossing, a little beyond
                step = max(offset * (1.1 * math.sqrt(threshold / d) - 1.0), 1e-3 * offset)
            else:
                step *= 2.0
        if out is None:  # not closed: the interval reaches at least the last point profiled
            ends[side] = inside_value
            continue
        out_value, out_d = out
        for _ in range(bisections):
            if out_d <= 1.5 * threshold:
                break
            mid = 0.5 * (inside_value + out_value)
            d_m, refit_m = at(current, mid)
            if d_m >= threshold:
                out_value, out_d = mid, d_m
            else:
                inside_value, inside, current = mid, d_m, refit_m
        if not math.isfinite(out_d):  # the model failed, not the data: the side stays open
            ends[side], failed[side] = inside_value, out_value
            continue
        a, b = math.sqrt(max(inside, 0.0)), math.sqrt(out_d)
        frac = (math.sqrt(threshold) - a) / (b - a) if b > a else 1.0
        ends[side] = inside_value + min(max(frac, 0.0), 1.0) * (out_value - inside_value)
        closed[side] = True
    order = np.argsort(grid)
    return Profile(
        symbol=symbol,
        stage=fit.name,
        value=value,
        values=tuple(float(grid[i]) for i in order),
        delta=tuple(float(delta[i]) for i in order),
        lower=float(ends[-1.0]),
        upper=float(ends[1.0]),
        closed_lower=closed[-1.0],
        closed_upper=closed[1.0],
        at_bound=fit.at_bound.get(symbol, ""),
        level=level,
        capped_refits=capped,
        failed_lower=failed[-1.0],
        failed_upper=failed[1.0],
    )


def identifiability(
    result: CalibrationResult,
    series: Mapping,
    probes: Mapping,
    stages: tuple[str, ...] | None = None,
    level: float = 0.95,
    symbols: Sequence[str] | None = None,
) -> Identifiability:
    """Profiles of the fitted parameters of ``result`` (optionally only ``symbols``), the
    correlated pairs and the fixed parameters (module docstring)."""
    import time

    t0 = time.perf_counter()
    options = dataclasses.replace(
        result.options,
        tolerance=PROFILE_TOLERANCE,
        cost_tolerance=max(PROFILE_TOLERANCE, result.options.cost_tolerance),
        max_evaluations=PROFILE_EVALUATIONS,
    )
    names = tuple(st.name for st in result.stages_) if stages is None else stages
    built = build_stages(series, probes, options, tuple(s for s in STAGES if s in names))
    fits = [fit for fit in result.stages_ if fit.name in built and fit.parameters]
    jobs = [(built[fit.name], result.params_, fit) for fit in fits]
    notes = []
    cheap = [fit for fit in fits if fit.name in ("compressibility", "elastic")]
    if len(cheap) == 2:
        # the constraint forces couple the compressibility stage to k, n, r and the elastic law
        # depends on N, λ*: profile both stages' parameters together (cheap model evaluations)
        joint = JointStage([built[fit.name] for fit in cheap])
        free = tuple(p for fit in cheap for p in fit.parameters)
        start, joint_fit = fit_stage(joint, result.params_, free, options)
        jobs = [(joint, start, joint_fit)] + [job for job in jobs if job[2] not in cheap]
        notes.append(
            "The compressibility and elastic parameters are profiled jointly (both stages' "
            "residuals, all their parameters free); the fabric parameters with the others "
            "held at their calibrated values."
        )
    profiles = {}
    correlations = []
    for stage, start, fit in jobs:
        for sym in fit.parameters:
            if symbols is None or sym in symbols:
                profiles[sym] = profile_parameter(stage, start, sym, fit, options, level)
        corr = fit.correlation
        for i, a in enumerate(fit.parameters):
            for j in range(i + 1, len(fit.parameters)):
                r = float(corr[i, j])
                if math.isfinite(r) and abs(r) >= 0.95:
                    correlations.append((a, fit.parameters[j], r))
    fitted = set(result.fitted_parameters)
    fixed = {s: v for s, v in result.params_.as_symbols().items() if s not in fitted}
    notes += [
        f"The profile of {s} has {p.capped_refits} refit(s) stopped at {PROFILE_EVALUATIONS} "
        "evaluations: its interval may be too narrow."
        for s, p in profiles.items()
        if p.capped_refits and p.status == "determined"
    ]
    return Identifiability(profiles, fixed, correlations, level, time.perf_counter() - t0, notes)


def replica_spread(results: Sequence[CalibrationResult]) -> dict[str, dict[str, float]]:
    """Mean, standard deviation, min and max of each parameter over calibrations of replica
    runs (the same scene, other seeds): the scatter the DEM itself gives the parameters."""
    table = {}
    for sym in results[0].params_.as_symbols():
        values = np.array([r.params_.as_symbols()[sym] for r in results])
        table[sym] = {
            "mean": float(values.mean()),
            "std": float(values.std(ddof=1)) if values.size > 1 else math.nan,
            "min": float(values.min()),
            "max": float(values.max()),
            "n": int(values.size),
        }
    return table


__all__ = [
    "PROFILE_TOLERANCE",
    "PROFILE_EVALUATIONS",
    "STATUSES",
    "Profile",
    "Identifiability",
    "profile_parameter",
    "identifiability",
    "replica_spread",
]
