"""Rolling resistance at inter-rod contacts: the law, in numpy (the kernels' reference).

MercuryDPM's rolling spring (``FrictionInteraction::computeFrictionForce``;
docs/science/dem-model.md §1.7) in 2D. At a contact of bodies P (disc i) and Q (disc j) the
rolling spring ψ [rad] accumulates the relative rotation, dψ/dt = ω_P − ω_Q (in 2D the spring is a
scalar; MercuryDPM's objectivity correction, a rotation of its spring vector, leaves a scalar
unchanged). With the effective diameter d_eff = 2 R_eff (= r = d/2 for equal discs) MercuryDPM's
rolling force F_r = −k_r d_eff ψ − γ_r d_eff ω_rel, capped at |F_r| ≤ μ_r |f_c|, acts at the lever
d_eff, so the moment on P is

    M = −κ_r ψ − η_r (ω_P − ω_Q),   κ_r = k_r d_eff²,  η_r = γ_r d_eff²,
    |M| ≤ μ_r d_eff |f_c|  (on slip ψ is reset to −(M + η_r ω_rel)/κ_r, the capped value),

and −M on Q: a pure couple (no force, so no stress term and no change of the linear momentum;
the angular momentum is conserved). The stored energy is ½ κ_r ψ². ψ is reset to 0 when the
contact opens, as the tangential spring is.

Scene keys (``[contact]``): ``rolling_stiffness`` k_r [force/length] (0, the default: no rolling
resistance, and nothing of it compiled), ``rolling_friction`` μ_r (> 0 when k_r > 0),
``rolling_damping`` γ_r [force·time/length] (default 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "RollingParameters",
    "rolling_moment",
    "rolling_period",
    "rolling_spring_step",
    "effective_diameter",
]


def effective_diameter(diameter: float) -> float:
    """d_eff = 2 R_eff = 2 r r /(r + r) = r for equal discs of diameter d (MercuryDPM)."""
    return 0.5 * float(diameter)


@dataclass(frozen=True)
class RollingParameters:
    """The rolling spring of one contact law, as moments.

    Attributes:
        stiffness: κ_r = k_r d_eff² [force·length/rad].
        damping: η_r = γ_r d_eff² [force·length·time/rad].
        cap: μ_r d_eff [length]: the moment cap per unit contact force.
    """

    stiffness: float
    damping: float
    cap: float

    @classmethod
    def from_scene_keys(
        cls, k_r: float, mu_r: float, gamma_r: float, diameter: float
    ) -> RollingParameters:
        """From ``[contact] rolling_stiffness, rolling_friction, rolling_damping``."""
        d_eff = effective_diameter(diameter)
        return cls(stiffness=k_r * d_eff**2, damping=gamma_r * d_eff**2, cap=mu_r * d_eff)

    @property
    def enabled(self) -> bool:
        return self.stiffness > 0.0


def rolling_moment(spring, relative_rotation_rate, stiffness: float, damping: float, cap: float,
                   contact_force):  # fmt: skip
    """(M, ψ, sliding): the moment on P of the rolling spring ψ (arrays broadcast).

    M = −κ_r ψ − η_r ω_rel capped at μ_r d_eff |f_c| (``cap`` × |f_c|); where capped ψ is reset
    to −(M + η_r ω_rel)/κ_r.
    """
    spring = np.asarray(spring, dtype=float)
    rate = np.asarray(relative_rotation_rate, dtype=float)
    moment = -stiffness * spring - damping * rate
    limit = cap * np.abs(np.asarray(contact_force, dtype=float))
    sliding = np.abs(moment) > limit
    moment = np.where(sliding, limit * np.sign(moment), moment)
    if stiffness > 0.0:
        spring = np.where(sliding, -(moment + damping * rate) / stiffness, spring)
    return moment, spring, sliding


def rolling_spring_step(spring, relative_rotation_rate, dt: float, stiffness: float,
                        damping: float, cap: float, contact_force):  # fmt: skip
    """One time step of the engine's rolling spring: ψ += ω_rel Δt, then :func:`rolling_moment`
    (returns (ψ, M, sliding))."""
    spring = np.asarray(spring, dtype=float) + np.asarray(relative_rotation_rate) * dt
    moment, spring, sliding = rolling_moment(
        spring, relative_rotation_rate, stiffness, damping, cap, contact_force
    )
    return spring, moment, sliding


def rolling_period(stiffness: float, inertia: float) -> float:
    """π/ω of the rolling spring between two equal free bodies of inertia I:
    ω² = κ_r (1/I + 1/I) (inf when κ_r = 0): the rolling analogue of the contact duration."""
    if stiffness <= 0.0:
        return math.inf
    return math.pi / math.sqrt(2.0 * stiffness / inertia)
