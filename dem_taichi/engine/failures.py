"""How the engine fails: :class:`BlowUpError`, :class:`CapacityError` and their messages.

Every message names the likely cause and the setting to change (plain Python and numpy, no
Taichi). A blow-up need not diverge: past a body's local stability limit the leapfrog step can
settle into a bounded oscillation of period two steps (:func:`period_two_bodies`), which a
relaxation removes slowly if at all (:func:`period_two_error`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dem_taichi.kernels import layout as L
from dem_taichi.scene.config import Integration

__all__ = [
    "BlowUpError",
    "CapacityError",
    "PeriodTwo",
    "blowup_error",
    "period_two_bodies",
    "period_two_error",
    "runaway_kinetic_energy",
]

#: band of the period-two signature: 2 M |v| / (Δt (1 + α) |F|) within 1 ± this
#: (:func:`period_two_bodies`; 1 in a steady orbit, 0.86-1.49 in a chain whose orbit breathes)
PERIOD_TWO_TOLERANCE = 0.5
#: share of the unbalanced force in period-two bodies from which a failed relaxation is a blow-up
PERIOD_TWO_SHARE = 0.5


class BlowUpError(RuntimeError):
    """The run became unstable; the message names the likely cause and the fix."""


class CapacityError(RuntimeError):
    """An array capacity could not be grown; the message says what to set."""


def _dt_fix(integration: Integration) -> str:
    safety = integration.dt_safety
    return f"reduce [integration] dt_safety from {safety:g} to <= {round(safety * 0.67, 3):g}"


def blowup_error(code: int, index: int, step: int, integration: Integration) -> BlowUpError:
    """The error for a kernel's blow-up flag ``code`` (``layout.BLOWUP_*``) raised by rod or disc
    ``index`` at ``step``."""
    fix = _dt_fix(integration)
    if code == L.BLOWUP_NONFINITE:
        return BlowUpError(
            f"non-finite position or velocity of rod {index} at step {step}: the time step is "
            f"too large for the stiffest interaction or a parameter is invalid; {fix}"
        )
    bound = integration.max_overlap
    return BlowUpError(
        f"overlap beyond the bound max_overlap = {bound:g} d at disc {index}, step {step}: "
        f"contacts are too soft for the loading or the time step is too large; {fix}, lower "
        "the strain rate ([control] inertial_number_max or compression_strain_rate) or raise "
        "[contact] k_n"
    )


def runaway_kinetic_energy(
    kinetic_energy: float, limit: float, step: int, integration: Integration
) -> BlowUpError:
    """The error for a kinetic energy above ``limit`` (max_kinetic_energy_per_rod × N)."""
    safety = integration.dt_safety
    return BlowUpError(
        f"runaway kinetic energy {kinetic_energy:.3g} > {limit:.3g} (max_kinetic_energy_per_rod x "
        f"n_rods) at step {step}: the integration is unstable; reduce "
        f"[integration] dt_safety from {safety:g} to <= {round(safety * 0.67, 3):g} or "
        "raise local_damping / e_n damping"
    )


@dataclass(frozen=True)
class PeriodTwo:
    """The bodies caught in a period-two oscillation (:func:`period_two_bodies`): their indices
    and the share of the unbalanced force Σ|F| (over every body) they carry."""

    bodies: np.ndarray
    share: float


def _reverses(
    force: np.ndarray, velocity: np.ndarray, inertia: float, time_step: float, alpha: float
) -> np.ndarray:
    """Whether each body's next kick reverses its velocity: v·F < 0 and 2 M |v| / (Δt (1 + α) |F|)
    within 1 ± :data:`PERIOD_TWO_TOLERANCE` (components along the last axis, if any)."""
    if force.ndim == 1:
        force, velocity = force[:, None], velocity[:, None]
    f = np.sqrt(np.sum(force * force, axis=1))
    v = np.sqrt(np.sum(velocity * velocity, axis=1))
    against = np.sum(force * velocity, axis=1) < 0.0
    kick = time_step * (1.0 + alpha) * f
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(kick > 0.0, 2.0 * inertia * v / kick, np.inf)
    return against & (np.abs(ratio - 1.0) <= PERIOD_TWO_TOLERANCE)


def period_two_bodies(
    force: np.ndarray,
    velocity: np.ndarray,
    torque: np.ndarray,
    omega: np.ndarray,
    mass: float,
    inertia: float,
    time_step: float,
    local_damping: float,
) -> PeriodTwo:
    """The bodies whose motion flips sign every step: the leapfrog step's mode at ω Δt ≈ 2.

    The kick is v ← v + Δt (F − α|F| sign v)/M (:mod:`dem_taichi.kernels.step`). A body in a
    period-two oscillation has its half-step velocity v opposite to the force F at the current
    positions, and one kick reverses it: in a steady orbit v' = −v, so 2 M |v| = Δt (1 + α) |F|
    (the local damping α, which opposes v, then adds to F); likewise ω and the torque τ with the
    moment of inertia I. A body counts when 2 M |v| / (Δt (1 + α) |F|) is within 1 ±
    :data:`PERIOD_TWO_TOLERANCE` (a breathing orbit, whose amplitude changes from step to step,
    gives 0.86–1.49; a slow mode, whose kick is a small fraction of its velocity, far more).
    Such a mode appears where Δt exceeds a body's local stability limit (a body held by many stiff
    contacts: ω Δt < 2 for undamped springs, less with the contact dashpot and local damping), and
    contacts that open during each cycle bound it: it neither grows nor decays. The full-step
    velocity (v + v')/2 ≈ 0 of such a body, so the kinetic energy does not show it; the forces do.

    ``force`` (n, 2), ``velocity`` (n, 2), ``torque`` (n,), ``omega`` (n,): the engine's body
    arrays (the half-step velocities); ``mass``, ``inertia``: a body's M and I; ``time_step`` Δt
    and ``local_damping`` α of the step that produced them. The signature holds in a relaxation at
    fixed cell (no cell-flow term in the kick). Returns the bodies matching it in translation or
    rotation, and their share of Σ|F|: on a 1520-rod packing at twice the `paper` scene's Δt,
    71–78 rods held all of Σ|F| (share 1.0000); the same packing relaxed at the scene's Δt, 0.04
    (``benchmarks/results/period_two.md``).
    """
    force, velocity = np.asarray(force, float), np.asarray(velocity, float)
    flipped = _reverses(force, velocity, mass, time_step, local_damping) | _reverses(
        np.asarray(torque, float), np.asarray(omega, float), inertia, time_step, local_damping
    )
    magnitude = np.sqrt(np.sum(force * force, axis=1))
    total = float(magnitude.sum())
    share = float(magnitude[flipped].sum()) / total if total > 0.0 else 0.0
    return PeriodTwo(np.flatnonzero(flipped), share)


def period_two_error(
    found: PeriodTwo,
    stage: str,
    step: int,
    time_step: float,
    scene_time_step: float,
    integration: Integration,
) -> BlowUpError:
    """The error for a relaxation that did not converge because ``found`` bodies oscillate with a
    period of two steps (:func:`period_two_bodies`) at Δt = ``time_step``; ``scene_time_step`` is
    the scene's own Δt (a ``[protocol]`` time-step multiple integrates the paths at more)."""
    first = ", ".join(str(i) for i in found.bodies[:5])
    more = ", ..." if len(found.bodies) > 5 else ""
    factor = time_step / scene_time_step
    if factor > 1.0 + 1e-9:
        fix = (
            f"it is {factor:.3g} x the scene's: lower [protocol] path_time_step_factor (or "
            "aggregation_time_step_factor) toward 1"
        )
    else:
        fix = _dt_fix(integration)
    return BlowUpError(
        f"[{stage}] relaxation stopped at step {step}: {len(found.bodies)} bodies ({first}{more}) "
        f"oscillate with a period of two time steps, {found.share:.0%} of the unbalanced force; "
        f"the time step {time_step:.4g} is beyond their local stability limit (bodies held by "
        f"many stiff contacts), a mode the relaxation removes slowly if at all: {fix}"
    )
