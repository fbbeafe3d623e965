"""Numpy-only analysis of DEM results: transition detection, elastic plateaus, fabric statistics.

Nothing here imports Taichi, so results can be analysed on a machine without it.

Symbols
-------
p        mean stress (σ_xx + σ_yy)/2, DEM stress units (force/length), compression positive
Z_m      mechanical coordination number: contacts per rod counted over non-rattler rods (the exact
         definition is the ``definition`` attribute of ``mechanical_coordination_number``)
E(Δε)    secant constrained modulus of a dynamic strain probe of amplitude Δε
N        number of rods
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
