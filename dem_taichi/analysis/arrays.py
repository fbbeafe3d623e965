"""Numpy-only analysis of DEM results: transition detection, elastic plateaus, fabric statistics,
and the study's findings over the arrays of a run's relaxed states and probes.

Nothing here imports Taichi, so results can be analysed on a machine without it. The findings
(λ* and its fit, the moduli's p-exponent, E_oed,h/E_oed,v, K0, the fabric and its isotropy
within the sampling noise, E_oed,v/p, the agreement of the probing methods) are written once
here, against :class:`PathArrays` and :class:`ProbeArrays`; the report of a run in memory
(:func:`dem_taichi.protocol.report.findings`) and the reader of a run folder
(:func:`dem_taichi.analysis.findings.run_findings`) build those arrays and call the same functions.

Symbols
-------
p        mean stress (σ_xx + σ_yy)/2, DEM stress units (force/length), compression positive
Z_m      mechanical coordination number: contacts per rod counted over non-rattler rods (the exact
         definition is the ``definition`` attribute of ``mechanical_coordination_number``)
E(Δε)    secant constrained modulus of a dynamic strain probe of amplitude Δε
N        number of rods
β_yy − β_xx  rod fabric deviator; sampling noise sqrt(0.5/N) for random orientations
v        specific volume; λ* = −d ln v/d ln p (compressibility index)
E_oed,v  ∂σ_yy/∂ε_yy, E_oed,h = ∂σ_xx/∂ε_xx constrained moduli (DEM stress units)
K0       σ_xx/σ_yy at C (end of the K0 path)
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike


@dataclass(frozen=True)
class Transition:
    """The fluid–solid transition (state A) found in a sequence of relaxed states.

    Attributes
    ----------
    index : position of state A in the relaxed-state sequence, or -1 if not found
    pressure : relaxed static pressure at A (DEM units), NaN if not found
    coordination : mechanical coordination number at A, NaN if not found
    coordination_jump : Z_m(A) − Z_m(previous relaxed state)
    rule : the rule that was applied, in words (stored in results for provenance)
    """

    index: int
    pressure: float
    coordination: float
    coordination_jump: float
    rule: str

    @property
    def found(self) -> bool:
        return self.index >= 0


def detect_transition(
    pressure: np.ndarray,
    mechanical_coordination: np.ndarray,
    pressure_tolerance: float,
    coordination_min: float,
) -> Transition:
    """Find state A: the first relaxed state that carries load through a percolating network.

    docs/science/dem-model.md §1.6, step 2: "the first relaxed state in which the static
    pressure stays positive (p > tolerance) and the contact network percolates (mechanical
    coordination jumps)".
    Rule applied, in order of the relaxed states i = 0, 1, …:
    A is the first i with p_i > ``pressure_tolerance`` and Z_m,i ≥ ``coordination_min`` such that
    every later relaxed state also has p > ``pressure_tolerance`` (the pressure *stays* positive;
    a transient positive pressure that relaxes away is not a solid).

    Parameters
    ----------
    pressure : (n,) relaxed static mean stress at each relaxed state (DEM units)
    mechanical_coordination : (n,) Z_m at each relaxed state
    pressure_tolerance : p threshold (DEM units), > 0
    coordination_min : Z_m threshold; for rigid 2D bodies with friction ~3 (isostatic d+1), 6
        without friction
    """
    p = np.asarray(pressure, dtype=float)
    z = np.asarray(mechanical_coordination, dtype=float)
    if p.shape != z.shape or p.ndim != 1:
        raise ValueError(
            f"pressure and mechanical_coordination must be 1-D of equal length, got {p.shape}, "
            f"{z.shape}"
        )
    if not pressure_tolerance > 0:
        raise ValueError(f"pressure_tolerance must be > 0, got {pressure_tolerance}")
    rule = (
        f"first relaxed state with p > {pressure_tolerance:g} and Z_m >= {coordination_min:g}, "
        "after which p stays above the tolerance"
    )
    loaded = p > pressure_tolerance
    # stays_loaded[i]: every state from i on is loaded (reverse cumulative AND).
    stays_loaded = np.logical_and.accumulate(loaded[::-1])[::-1]
    candidates = np.flatnonzero(stays_loaded & (z >= coordination_min))
    if candidates.size == 0:
        return Transition(-1, float("nan"), float("nan"), float("nan"), rule)
    i = int(candidates[0])
    jump = float(z[i] - z[i - 1]) if i > 0 else float(z[i])
    return Transition(i, float(p[i]), float(z[i]), jump, rule)


@dataclass(frozen=True)
class Plateau:
    """Elastic plateau of a stiffness-degradation curve E(Δε).

    Attributes
    ----------
    modulus : mean of E over the plateau amplitudes (the elastic modulus)
    elastic_limit : largest amplitude still on the plateau
    n_points : number of amplitudes on the plateau
    rule : the rule that was applied, in words
    """

    modulus: float
    elastic_limit: float
    n_points: int
    rule: str


def elastic_plateau(
    amplitudes: np.ndarray, moduli: np.ndarray, relative_tolerance: float = 0.02
) -> Plateau:
    """Pick the elastic plateau of a degradation curve, as the study did with its strain probes.

    Rule: sort by amplitude; the reference is the modulus at the smallest amplitude; the plateau
    is the longest run of increasing amplitudes, starting at the smallest, whose moduli all lie
    within ``relative_tolerance`` of the running mean of the run. The plateau modulus is the mean
    over that run.

    Raises ``ValueError`` on non-finite moduli or fewer than one amplitude.
    """
    a = np.asarray(amplitudes, dtype=float)
    e = np.asarray(moduli, dtype=float)
    if a.shape != e.shape or a.ndim != 1 or a.size == 0:
        raise ValueError(f"amplitudes and moduli must be 1-D of equal non-zero length: {a.shape}")
    if not np.all(np.isfinite(e)) or not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise ValueError("amplitudes must be finite and > 0, moduli finite")
    order = np.argsort(a)
    a, e = a[order], e[order]
    n = 1
    while n < a.size:
        trial = e[: n + 1]
        mean = trial.mean()
        if np.max(np.abs(trial - mean)) > relative_tolerance * abs(mean):
            break
        n += 1
    rule = (
        f"longest run from the smallest amplitude with all moduli within {relative_tolerance:g} "
        "(relative) of the run mean"
    )
    return Plateau(float(e[:n].mean()), float(a[n - 1]), n, rule)


def fabric_tensor(rod_angle: np.ndarray) -> np.ndarray:
    """Rod-orientation fabric β = (1/N) Σ a ⊗ a, a = (cos θ, sin θ) (study Eq. 1); tr β = 1."""
    theta = np.asarray(rod_angle, dtype=float)
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[np.mean(c * c), np.mean(c * s)], [np.mean(c * s), np.mean(s * s)]])


def fabric_sampling_noise(n_rods: int) -> float:
    """Standard deviation of β_yy − β_xx for N uniformly random orientations: sqrt(0.5/N).

    β_yy − β_xx = −mean(cos 2θ); var(cos 2θ) = 1/2 for uniform θ.
    """
    if n_rods < 1:
        raise ValueError(f"n_rods must be >= 1, got {n_rods}")
    return float(np.sqrt(0.5 / n_rods))


# --- the study's findings over arrays -----------------------------------------------------------
# One implementation of each finding, written against arrays of the relaxed states and probes
# of a run. Two readers build these arrays: dem_taichi.protocol.report from a ProtocolResult in
# memory (report.md) and dem_taichi.analysis.findings from a run folder's files (summaries, sweeps,
# benchmarks); both then call the functions below, so the two cannot disagree. The row of a run
# folder (run_findings) is assembled from the arrays by findings.findings_from_arrays, which a run
# in memory calls too (benchmarks/paired_paths.py).

#: The isotropic-fabric check: every |β_yy − β_xx| on A and A→B within this many sampling noises.
FABRIC_NOISE_MULTIPLE = 2.0

_NAN = float("nan")


@dataclass(frozen=True)
class PathArrays:
    """The relaxed states of a protocol run as arrays, as the findings read them.

    ``states``: label (A, B, C, B', R<k>_end) → measures of the labelled state (history names,
    DEM units; ``summary.json`` "states" or the run's :class:`RelaxedState` measures);
    ``stage``: the stage name of every relaxed path state in path order (``relaxed_states.nc``);
    ``measures``: history name → array over those states.
    """

    states: Mapping[str, Mapping[str, Any]]
    stage: np.ndarray
    measures: Mapping[str, np.ndarray]

    def at(self, label: str, key: str) -> float:
        """The measure ``key`` of the labelled state; NaN when the run has no such state."""
        return float(self.states[label][key]) if label in self.states else _NAN

    def on(self, stage: str, key: str) -> np.ndarray:
        """The measure ``key`` of the relaxed states of ``stage``, in path order."""
        if key not in self.measures:
            return np.array([], dtype=float)
        return np.asarray(self.measures[key], dtype=float)[self.stage == stage]

    def from_a(self, stage: str, key: str) -> np.ndarray:
        """``key`` at state A (when reached) followed by the relaxed states of ``stage``: the
        path from A that the compressibility and fabric findings read (``stage`` "A_to_B":
        the isotropic path)."""
        head = [self.at("A", key)] if "A" in self.states else []
        return np.r_[np.asarray(head, dtype=float), self.on(stage, key)]


@dataclass(frozen=True)
class ProbeArrays:
    """The probes of a protocol run as arrays (one entry per probe, in probing order).

    ``label`` (state label, "" for an unlabelled path state), ``path`` (stage of the probed
    state), ``mean_stress`` p of the probed state, and the constrained moduli E_oed,v and
    E_oed,h of the linear response (``e_oed_v``, ``e_oed_h``) and of the dynamic plateau
    (``e_oed_v_dynamic``, ``e_oed_h_dynamic``), DEM stress units, NaN where not measured.
    """

    label: np.ndarray
    path: np.ndarray
    mean_stress: np.ndarray
    e_oed_v: np.ndarray
    e_oed_h: np.ndarray
    e_oed_v_dynamic: np.ndarray
    e_oed_h_dynamic: np.ndarray

    @classmethod
    def empty(cls) -> ProbeArrays:
        """No probes (a run without probing)."""
        text, number = np.array([], dtype=str), np.array([], dtype=float)
        return cls(text, text, number, number, number, number, number)

    def __len__(self) -> int:
        return len(self.label)

    def isotropic(self) -> np.ndarray:
        """Mask of the probes on the isotropic path: state A and the probes of A→B."""
        return (self.path == "A_to_B") | (self.label == "A")

    def along_k0(self) -> np.ndarray:
        """Indices of the probes of A→C by rising p (stable)."""
        at = np.flatnonzero(self.path == "A_to_C")
        return at[np.argsort(self.mean_stress[at], kind="stable")]

    def last(self, label: str) -> int:
        """Index of the last probe of the labelled state; −1 when it was not probed."""
        at = np.flatnonzero(self.label == label)
        return int(at[-1]) if at.size else -1

    def moduli_at(self, label: str) -> tuple[float, float]:
        """(E_oed,v, E_oed,h) of the linear response at the last probe of the labelled state;
        NaN when it was not probed."""
        i = self.last(label)
        return (float(self.e_oed_v[i]), float(self.e_oed_h[i])) if i >= 0 else (_NAN, _NAN)


def compressibility_slope(mean_stress: ArrayLike, specific_volume: ArrayLike) -> dict:
    """Least-squares fit ln v = a − λ* ln p over the given states; returns λ*, a, R² and rms.

    λ* is the slope of the (ln p, ln v) line (the study's compressibility index, positive for
    compression). Needs at least 3 states with p > 0.
    """
    p = np.asarray(mean_stress, dtype=float)
    v = np.asarray(specific_volume, dtype=float)
    ok = (p > 0) & (v > 0) & np.isfinite(p) & np.isfinite(v)
    if ok.sum() < 3:
        return {"lambda_star": math.nan, "intercept": math.nan, "r2": math.nan, "n": int(ok.sum())}
    x, y = np.log(p[ok]), np.log(v[ok])
    slope, intercept = np.polyfit(x, y, 1)
    fit = intercept + slope * x
    ss_res = float(np.sum((y - fit) ** 2))
    ss_tot = float(np.sum((y - y.mean()) ** 2))
    return {
        "lambda_star": float(-slope),
        "intercept": float(intercept),
        "r2": 1.0 - ss_res / ss_tot if ss_tot > 0 else math.nan,
        "rms_residual": math.sqrt(ss_res / ok.sum()),
        "n": int(ok.sum()),
    }


@dataclass(frozen=True)
class FabricIsotropy:
    """The isotropic-fabric finding: ``max_abs`` max |β_yy − β_xx| over the states, ``noise``
    the sampling noise sqrt(0.5/N), ``within_noise`` whether every |β_yy − β_xx| is at most
    :data:`FABRIC_NOISE_MULTIPLE` noises."""

    max_abs: float
    noise: float
    within_noise: bool


def fabric_isotropy(fabric_deviator: ArrayLike, n_rods: int) -> FabricIsotropy:
    """Is the rod fabric isotropic within the sampling noise over the given states (the study:
    along A→B)? ``max_abs`` is NaN and ``within_noise`` False when no state is given."""
    b = np.abs(np.asarray(fabric_deviator, dtype=float))
    noise = fabric_sampling_noise(n_rods)
    if b.size == 0:
        return FabricIsotropy(_NAN, noise, False)
    return FabricIsotropy(float(np.max(b)), noise, bool(np.all(b <= FABRIC_NOISE_MULTIPLE * noise)))


def stiffness_ratio(e_oed_h: ArrayLike, e_oed_v: ArrayLike) -> np.ndarray:
    """E_oed,h/E_oed,v elementwise; NaN where either modulus is not finite or E_oed,v = 0."""
    h = np.asarray(e_oed_h, dtype=float)
    v = np.asarray(e_oed_v, dtype=float)
    ok = np.isfinite(h) & np.isfinite(v) & (v != 0)
    return np.divide(h, v, out=np.full(np.broadcast(h, v).shape, np.nan), where=ok)


def power_law_exponent(mean_stress: ArrayLike, modulus: ArrayLike) -> float:
    """n of E ∝ p^n: the least-squares slope of ln E on ln p over the states with p and E
    finite and > 0 (the study: n ≈ 0.8 along A→B); NaN with fewer than 2 such states or a
    single p. Over a window of p in kPa, with its standard error:
    :func:`dem_taichi.analysis.mapped_window.moduli_exponent`."""
    p = np.asarray(mean_stress, dtype=float).ravel()
    e = np.asarray(modulus, dtype=float).ravel()
    ok = np.isfinite(p) & np.isfinite(e) & (p > 0) & (e > 0)
    if ok.sum() < 2 or np.ptp(p[ok]) == 0.0:
        return _NAN
    return float(np.polyfit(np.log(p[ok]), np.log(e[ok]), 1)[0])


def stress_ratio_at(path: PathArrays, label: str) -> float:
    """σ_xx/σ_yy of the labelled state (K0 at C); NaN when the run has no such state."""
    return path.at(label, "stress_xx") / path.at(label, "stress_yy")


def modulus_over_p_at(probes: ProbeArrays, label: str) -> float:
    """E_oed,v/p (linear response) at the last probe of the labelled state (the study: ≈ 125
    at B); NaN when it was not probed."""
    i = probes.last(label)
    return float(probes.e_oed_v[i] / probes.mean_stress[i]) if i >= 0 else _NAN


def max_change(values: ArrayLike, reference: float) -> float:
    """max |x − x_ref| over the values (e.g. ε_xx along K0 against A); NaN when none."""
    x = np.asarray(values, dtype=float)
    return float(np.max(np.abs(x - reference))) if x.size else _NAN


def methods_relative_difference(probes: ProbeArrays) -> np.ndarray:
    """|E_dynamic − E_linear|/|E_linear| of E_oed,v and E_oed,h at every probe where both
    methods gave a finite modulus (E_linear ≠ 0): how well the two probing methods agree."""
    pairs = ((probes.e_oed_v_dynamic, probes.e_oed_v), (probes.e_oed_h_dynamic, probes.e_oed_h))
    # probe by probe, E_oed,v then E_oed,h: the order the report has always listed them in
    d = np.stack([np.asarray(a, dtype=float) for a, _ in pairs], axis=-1).ravel()
    lin = np.stack([np.asarray(b, dtype=float) for _, b in pairs], axis=-1).ravel()
    ok = np.isfinite(d) & np.isfinite(lin) & (lin != 0)
    return np.abs(d[ok] - lin[ok]) / np.abs(lin[ok])
