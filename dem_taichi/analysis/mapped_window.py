"""The study's findings on the mapped stress window: the DEM stress scale measured from the
stiffness, λ* and the moduli exponents fitted over a window in kPa, N under two definitions of
the specific volume, and the densification sensitivity (issue 19, scope item 3).

numpy only (no Taichi, no file input): :func:`dem_taichi.analysis.findings.run_findings` reads a run
folder and calls these functions.

The DEM has one dimensional choice: which DEM stress stands for 100 kPa. The study (the
continuum model's Table 1, docs/science/tiv-model.md §2) has E_v/p ≈ 125 at p = 100 kPa,
λ* = 0.25 (slope of ln v against ln p), moduli ∝ p^0.8 (n + r = 0.8), N = 1.30 (v at 100 kPa)
and, from Table 1, a densification sensitivity ln(E_B′/E_B)/ln(v_B′/v_B) ≈ −r/λ* ≈ −2.5. E_v/p is
dimensionless, so the DEM stress p* at which the DEM's E_v/p equals 125 is the DEM's 100 kPa: the
measured stress scale is 100/p* kPa per DEM stress unit (force/length in 2D).

Symbols: p mean stress (σ_xx + σ_yy)/2; v specific volume; E_v = E_oed,v = ∂σ_yy/∂ε_yy and
E_h = E_oed,h = ∂σ_xx/∂ε_xx constrained moduli (linear response, same units as p); N_rods rods
of n_s discs of diameter d at centre spacing s_p; rod length L = (n_s − 1) s_p + d.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dem_taichi.scene.geometry import lens_area

__all__ = [
    "STUDY_EV_OVER_P",
    "STUDY_REFERENCE_KPA",
    "STUDY_WINDOW_KPA",
    "STATE_STRESS_TOLERANCE",
    "StressScale",
    "WindowFit",
    "stress_scale_from_stiffness",
    "windowed_compressibility",
    "local_compressibility",
    "moduli_exponent",
    "rod_disc_union_area",
    "rod_rectangle_area",
    "specific_volume_rectangle",
    "specific_volume_at",
    "densification_sensitivity",
]

#: E_v/p at p = 100 kPa in the study (Table 1 of the continuum model).
STUDY_EV_OVER_P = 125.0
#: The study's reference stress (kPa): N is v there, E_v/p = 125 there.
STUDY_REFERENCE_KPA = 100.0
#: The stress window (kPa) of the windowed fits, both ends included.
STUDY_WINDOW_KPA = (1.0, 200.0)
#: Relative distance of a relaxed state's p from a reference stress within which the state
#: counts as at it: twice the servo's default tolerance (``[protocol] stress_tolerance`` 1e-3).
STATE_STRESS_TOLERANCE = 2e-3

_NAN = float("nan")


@dataclass(frozen=True)
class StressScale:
    """A measured stress scale: ``kpa_per_unit`` = reference_kpa / ``p_star`` (kPa per DEM
    stress unit), ``p_star`` the DEM stress at which E_v/p = target, ``method``
    ("interpolated", "extrapolated" or "none") and ``reason`` (why NaN; "" when found)."""

    kpa_per_unit: float
    p_star: float
    method: str
    reason: str = ""


@dataclass(frozen=True)
class WindowFit:
    """Least-squares line y = a + b x over the points in a window: ``slope`` b, its standard
    error ``se`` (s/√Sxx, s² = residual sum of squares/(n − 2)), ``intercept`` a and ``n``."""

    slope: float
    se: float
    intercept: float
    n: int


def _positive_pairs(x, y) -> tuple[np.ndarray, np.ndarray]:
    """The (x, y) pairs with both finite and > 0, ordered by x (stable)."""
    x = np.asarray(x, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    if x.shape != y.shape:
        raise ValueError(f"need arrays of one length, got {x.size} and {y.size}")
    ok = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
    order = np.argsort(x[ok], kind="stable")
    return x[ok][order], y[ok][order]


def _falling_log_crossing(x: np.ndarray, y: np.ndarray, target: float) -> float:
    """x at which a falling y passes target: on the last pair (the highest x, x rising) with
    y ≥ target at the first and y ≤ target at the second state (not both equal), interpolated
    linearly in (ln x, ln y); NaN when no pair falls through the target."""
    ly, lt, lx = np.log(y), math.log(target), np.log(x)
    for k in range(len(x) - 2, -1, -1):
        a, b = ly[k] - lt, ly[k + 1] - lt
        if a >= 0.0 >= b and a != b:
            if b == 0.0 or a == 0.0:  # a state exactly at the target
                return float(x[k + 1] if b == 0.0 else x[k])
            t = a / (a - b)
            return float(math.exp(lx[k] + t * (lx[k + 1] - lx[k])))
    return _NAN


def stress_scale_from_stiffness(
    p,
    e_v,
    target_ratio: float = STUDY_EV_OVER_P,
    reference_kpa: float = STUDY_REFERENCE_KPA,
    allow_extrapolation: bool = False,
) -> StressScale:
    """The stress scale (kPa per DEM stress unit) at which the DEM's stiffness matches the study.

    ``p`` (DEM stress) and ``e_v`` (E_oed,v, DEM stress) at the probed states of the isotropic
    path A→B (state A included). E_v/p is dimensionless, so the DEM stress p* at which
    E_v/p = ``target_ratio`` (the study: 125 at 100 kPa, Table 1) stands for ``reference_kpa``:
    the scale is reference_kpa/p*. p* is found on the last pair of states (ordered by p) on which
    E_v/p falls through the target (E_v/p ≥ target at the lower p, ≤ at the higher): the
    material's stiffness grows more slowly than p (the study's E ∝ p^0.8), whereas near A,
    where the gel is still forming, E_v/p may rise through the target at a few DEM units (120 →
    221 between p = 3.4 and 7.9 on a 300-rod loose gel), which says nothing of the loaded
    material. Interpolated linearly in ln(E_v/p) against ln p (exact for a power law E_v ∝ p^n).
    Without such a pair p* is NaN (``reason`` says why) unless ``allow_extrapolation``: then the
    least-squares line of ln(E_v/p) on ln p over all states (at least 2, non-zero slope) is
    solved for the target.
    """
    x, y = _positive_pairs(p, e_v)
    ratio = y / x
    if x.size == 0:
        return StressScale(_NAN, _NAN, "none", "no state with finite positive p and E_v")
    p_star = _falling_log_crossing(x, ratio, target_ratio) if x.size > 1 else _NAN
    if np.isfinite(p_star):
        return StressScale(reference_kpa / p_star, p_star, "interpolated")
    span = f"E_v/p from {ratio.min():.4g} to {ratio.max():.4g} over {x.size} states"
    if not allow_extrapolation:
        return StressScale(
            _NAN,
            _NAN,
            "none",
            f"E_v/p does not fall through {target_ratio:g} between two states ({span})",
        )
    if x.size < 2 or np.ptp(np.log(x)) == 0.0:
        return StressScale(_NAN, _NAN, "none", f"too few distinct states to extrapolate ({span})")
    if np.ptp(np.log(ratio)) == 0.0:
        return StressScale(_NAN, _NAN, "none", f"E_v/p does not vary with p ({span})")
    slope, intercept = np.polyfit(np.log(x), np.log(ratio), 1)
    log_p_star = (math.log(target_ratio) - intercept) / slope
    if not abs(log_p_star) < 700.0:  # exp would overflow: the line (nearly) never reaches it
        return StressScale(_NAN, _NAN, "none", f"the log-log line misses the target ({span})")
    p_star = math.exp(log_p_star)
    return StressScale(reference_kpa / p_star, p_star, "extrapolated")


def _window_fit(x, y, window: tuple[float, float]) -> WindowFit:
    """Least-squares ln y = a + b ln x over the points with window[0] ≤ x ≤ window[1] (both
    finite and > 0); NaN with fewer than 3 points (no standard error from 2)."""
    x, y = _positive_pairs(x, y)
    lo, hi = window
    inside = (x >= lo) & (x <= hi)
    n = int(inside.sum())
    if n < 3:
        return WindowFit(_NAN, _NAN, _NAN, n)
    lx, ly = np.log(x[inside]), np.log(y[inside])
    dx = lx - lx.mean()
    sxx = float(dx @ dx)
    if sxx == 0.0:
        return WindowFit(_NAN, _NAN, _NAN, n)
    slope = float(dx @ (ly - ly.mean())) / sxx
    intercept = float(ly.mean() - slope * lx.mean())
    residual = ly - (intercept + slope * lx)
    se = math.sqrt(float(residual @ residual) / (n - 2) / sxx)
    return WindowFit(slope, se, intercept, n)


def windowed_compressibility(p_kpa, v, window: tuple[float, float] = STUDY_WINDOW_KPA) -> WindowFit:
    """λ* on the mapped window: minus the least-squares slope of ln v on ln p over the relaxed
    states with window[0] ≤ p ≤ window[1] (p in kPa, after the stress scale; both ends included).

    The study's λ* (Table 1: 0.25) is the slope of the normal compression line ln v = ln N −
    λ* ln(p/p_ref). Returned as a :class:`WindowFit` whose ``slope`` is λ* (sign turned, so
    positive for compression) and ``intercept`` ln v at 1 kPa; ``se`` the standard error of
    λ*, ``n`` the points in the window; NaN with fewer than 3 points.
    """
    fit = _window_fit(p_kpa, v, window)
    return WindowFit(-fit.slope, fit.se, fit.intercept, fit.n)


def local_compressibility(p, v) -> tuple[np.ndarray, np.ndarray]:
    """The local compressibility −d ln v/d ln p along a path, from consecutive relaxed states.

    For states k, k + 1 (in path order): λ_k+½ = −(ln v_k+1 − ln v_k)/(ln p_k+1 − ln p_k), the
    central difference at the mid-point in ln p, p_k+½ = √(p_k p_k+1). Pairs with a state of
    non-positive or non-finite p or v, or equal p, are left out. Returns (p_mid, λ_local), in the
    units of ``p``.
    """
    p = np.asarray(p, dtype=float).ravel()
    v = np.asarray(v, dtype=float).ravel()
    if p.shape != v.shape:
        raise ValueError(f"need arrays of one length, got {p.size} and {v.size}")
    ok = np.isfinite(p) & np.isfinite(v) & (p > 0) & (v > 0)
    lp = np.log(np.where(ok, p, 1.0))
    lv = np.log(np.where(ok, v, 1.0))
    dlp, dlv = np.diff(lp), np.diff(lv)
    keep = ok[:-1] & ok[1:] & (dlp != 0.0)
    return np.exp(0.5 * (lp[:-1] + lp[1:]))[keep], -(dlv[keep] / dlp[keep])


def moduli_exponent(p_kpa, e, window: tuple[float, float] = STUDY_WINDOW_KPA) -> WindowFit:
    """The exponent n of E ∝ p^n on the mapped window: the least-squares slope of ln E on ln p
    over the probed states with window[0] ≤ p ≤ window[1] (p in kPa; E = E_oed,v or E_oed,h in
    any one unit). The study: n + r = 0.8 (Table 1). ``slope`` is n; NaN below 3 points."""
    return _window_fit(p_kpa, e, window)


def rod_disc_union_area(n_spheres: int, spacing: float, diameter: float) -> float:
    """Area of one rod as the DEM counts it (:func:`dem_taichi.scene.geometry.rod_geometry`,
    ``solid_area``): the union of n_s discs of diameter d at centre spacing s_p,
    n_s π d²/4 − (n_s − 1) A_lens(d/2, s_p) (the lens overlap of neighbours when s_p < d)."""
    return n_spheres * math.pi * diameter * diameter / 4.0 - (n_spheres - 1) * lens_area(
        diameter / 2.0, spacing
    )


def rod_rectangle_area(n_spheres: int, spacing: float, diameter: float) -> float:
    """Area of one rod as a rectangle L × d, L = (n_s − 1) s_p + d the tip-to-tip length
    (:class:`dem_taichi.scene.geometry.RodGeometry` ``length``)."""
    return ((n_spheres - 1) * spacing + diameter) * diameter


def specific_volume_rectangle(v_disc, n_spheres: int, spacing: float, diameter: float):
    """The specific volume with the rod counted as its rectangle L × d.

    The DEM's v = A_cell/(N_rods A_disc-union) (:mod:`dem_taichi.engine.measures`); with the rod's
    solid area taken as L × d instead, v_rect = A_cell/(N_rods L d) = v_disc · A_disc-union/(L d).
    The rectangle is larger (it fills the notches between discs and the rounded tips), so
    v_rect < v_disc: for 5 discs with s_p = d, the ratio is (5π/4)/5 = π/4.
    """
    ratio = rod_disc_union_area(n_spheres, spacing, diameter) / rod_rectangle_area(
        n_spheres, spacing, diameter
    )
    return np.asarray(v_disc, dtype=float) * ratio if np.ndim(v_disc) else float(v_disc) * ratio


def specific_volume_at(
    p_kpa, v, p_ref: float = STUDY_REFERENCE_KPA, rel_tol: float = STATE_STRESS_TOLERANCE
) -> float:
    """v at the stress ``p_ref`` (kPa) along a path: the study's N when p_ref = 100 kPa.

    Interpolated linearly in (ln p, ln v) (exact on a normal compression line v ∝ p^−λ*) on the
    first pair of states (ordered by p) whose p brackets p_ref; NaN when none does (no
    extrapolation). An end state within ``rel_tol`` (relative) of p_ref counts as reaching it: the
    servo stops each relaxed state within its stress tolerance (``[protocol] stress_tolerance``,
    1e-3 by default), so a path whose last state B is at p = 99.95 for 100 still gives N, as v of
    that state (an error in v of ≈ λ* × rel_tol, ≤ 5e-4 relative at λ* ≤ 0.25)."""
    x, y = _positive_pairs(p_kpa, v)
    if x.size == 0:
        return _NAN
    if x[-1] < p_ref <= x[-1] * (1.0 + rel_tol):
        return float(y[-1])
    if x[0] * (1.0 - rel_tol) <= p_ref < x[0]:
        return float(y[0])
    if not x[0] <= p_ref <= x[-1]:
        return _NAN
    k = int(np.searchsorted(x, p_ref, side="left"))
    if x[k] == p_ref:
        return float(y[k])
    t = (math.log(p_ref) - math.log(x[k - 1])) / (math.log(x[k]) - math.log(x[k - 1]))
    return float(math.exp(math.log(y[k - 1]) + t * (math.log(y[k]) - math.log(y[k - 1]))))


def densification_sensitivity(e_b: float, e_b_prime: float, v_b: float, v_b_prime: float) -> float:
    """ln(E_B′/E_B)/ln(v_B′/v_B): how the modulus at one stress changes with density.

    B and B′ share p (B′ is reached from C by unloading at constant p to q = 0), so the ratio
    isolates the density dependence of the modulus; the study's Table 1 implies ≈ −r/λ* ≈ −2.5
    (issue 19). Any one unit of E, v dimensionless. NaN when a value is non-positive or not
    finite, or v_B′ = v_B.
    """
    values = (e_b, e_b_prime, v_b, v_b_prime)
    if not all(math.isfinite(x) and x > 0 for x in values) or v_b_prime == v_b:
        return _NAN
    return math.log(e_b_prime / e_b) / math.log(v_b_prime / v_b)
