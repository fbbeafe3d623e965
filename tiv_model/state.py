"""Material point state of the TIV model (frozen).

Symbols: ε total logarithmic strain (1), ε^e elastic strain (1), σ stress (kPa), v specific
volume as the model's internal variable (1, evolves by v̇ = −v ε̇^p_v and sets
p_c = p_r (v/N)^(−1/λ*)), β fabric (deviatoric, 1), p_c preconsolidation pressure (kPa).
Tensors are Mandel vectors (index 0 axial/vertical, 1 and 2 radial/horizontal); compression
positive.

The kinematic specific volume v exp(−tr ε^e) obeys v_kin = v_kin,0 exp(−Δε_v) exactly (total
logarithmic volumetric strain); the model's v is the specific volume at zero elastic strain, which
the study identifies with the measured specific volume (the two differ by the elastic volumetric
strain, ≈ 1–2 % here).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from .tensors import axial_minus_radial, deviatoric_invariant, trace


def _frozen_array(value) -> np.ndarray:
    arr = np.array(value, dtype=float, copy=True)
    if arr.shape != (6,):
        raise ValueError(f"expected a Mandel vector of shape (6,), got shape {arr.shape}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class State:
    """State of one material point after an increment.

    strain, elastic_strain, stress, fabric: Mandel vectors (1, 1, kPa, 1);
    specific_volume: model v (1); preconsolidation_pressure: p_c (kPa);
    plastic_multiplier: accumulated Σ Δλ (1/kPa); dissipated_energy: Σ d Δt (kPa);
    plastic: whether the last increment was plastic.
    """

    strain: np.ndarray
    elastic_strain: np.ndarray
    stress: np.ndarray
    specific_volume: float
    fabric: np.ndarray
    preconsolidation_pressure: float
    plastic_multiplier: float = 0.0
    dissipated_energy: float = 0.0
    plastic: bool = False

    def __post_init__(self) -> None:
        for name in ("strain", "elastic_strain", "stress", "fabric"):
            object.__setattr__(self, name, _frozen_array(getattr(self, name)))
        for name in ("specific_volume", "preconsolidation_pressure", "plastic_multiplier",
                     "dissipated_energy"):  # fmt: skip
            object.__setattr__(self, name, float(getattr(self, name)))

    def replace(self, **changes) -> State:
        return dataclasses.replace(self, **changes)

    @classmethod
    def _from_fresh(cls, strain, elastic_strain, stress, specific_volume, fabric,
                    preconsolidation_pressure, plastic_multiplier, dissipated_energy,
                    plastic) -> State:  # fmt: skip
        """A State from arrays of shape (6,) that the caller has just made and hands over (they
        are made read-only, not copied) and Python floats: the solvers' fast constructor."""
        obj = object.__new__(cls)
        for name, arr in (("strain", strain), ("elastic_strain", elastic_strain),
                          ("stress", stress), ("fabric", fabric)):  # fmt: skip
            arr.setflags(write=False)
            object.__setattr__(obj, name, arr)
        object.__setattr__(obj, "specific_volume", float(specific_volume))
        object.__setattr__(obj, "preconsolidation_pressure", float(preconsolidation_pressure))
        object.__setattr__(obj, "plastic_multiplier", float(plastic_multiplier))
        object.__setattr__(obj, "dissipated_energy", float(dissipated_energy))
        object.__setattr__(obj, "plastic", bool(plastic))
        return obj

    @property
    def mean_stress(self) -> float:
        """p (kPa)."""
        return float(trace(self.stress)) / 3.0

    @property
    def deviatoric_stress(self) -> float:
        """q (kPa), signed like σ_a − σ_r (negative in triaxial extension)."""
        q = float(deviatoric_invariant(self.stress))
        return math.copysign(q, float(axial_minus_radial(self.stress)))

    @property
    def stress_ratio(self) -> float:
        """η = q/p (1), signed like q."""
        return self.deviatoric_stress / self.mean_stress

    @property
    def fabric_scalar(self) -> float:
        """β_s signed like β_a − β_r (the triaxial scalar fabric β)."""
        b = float(deviatoric_invariant(self.fabric))
        return math.copysign(b, float(axial_minus_radial(self.fabric)))

    @property
    def volumetric_strain(self) -> float:
        """ε_v = tr ε (1, logarithmic)."""
        return float(trace(self.strain))

    @property
    def kinematic_specific_volume(self) -> float:
        """v exp(−tr ε^e) (1): the specific volume including the elastic volume change."""
        return self.specific_volume * math.exp(-float(trace(self.elastic_strain)))

    def describe(self) -> str:
        """One line naming the state (used in error messages)."""
        return (
            f"p = {self.mean_stress:.6g} kPa, q = {self.deviatoric_stress:.6g} kPa, "
            f"v = {self.specific_volume:.6g}, beta = {self.fabric_scalar:.6g}, "
            f"p_c = {self.preconsolidation_pressure:.6g} kPa, "
            f"axial strain = {self.strain[0]:.6g}"
        )


@dataclass(frozen=True)
class IncrementGuess:
    """Starting values for the Newton of an increment: the changes of a previous increment
    (``between``), scaled. Only the starting point depends on it, never the converged state.

    strain, elastic_strain, fabric: Mandel increments Δε, Δε^e, Δβ (1);
    plastic_multiplier: Δλ (1/kPa); log_specific_volume: Δ ln v (1).
    """

    strain: np.ndarray
    elastic_strain: np.ndarray
    plastic_multiplier: float
    fabric: np.ndarray
    log_specific_volume: float

    @classmethod
    def between(cls, before: State, after: State, ratio: float = 1.0) -> IncrementGuess:
        """``ratio`` × the changes from ``before`` to ``after``."""
        return cls(
            strain=ratio * (after.strain - before.strain),
            elastic_strain=ratio * (after.elastic_strain - before.elastic_strain),
            plastic_multiplier=ratio * (after.plastic_multiplier - before.plastic_multiplier),
            fabric=ratio * (after.fabric - before.fabric),
            log_specific_volume=ratio * math.log(after.specific_volume / before.specific_volume),
        )

    def __array__(self, dtype=None, copy=None):
        """The strain increment, so that code expecting a Mandel strain guess still works."""
        return np.asarray(self.strain, dtype=dtype)
