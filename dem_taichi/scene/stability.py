"""The time step's stability bounds that scenes are held to at load (a pure module, imported by
the scene loader :mod:`dem_taichi.scene.config` and by the sections' own checks).

- :data:`BONDED_DT_SAFETY_LIMIT`: the largest ``dt_safety`` of bonded rods, measured.
- :data:`RIGID_DT_SAFETY_LIMIT`: the largest ``dt_safety`` of rigid rods on jammed packings,
  measured.
- :func:`tangential_stiffness_limit`: the largest k_t/k_n the leapfrog step resolves.
- :func:`check_time_step_factor`: a ``[protocol]`` time-step multiple held to these (a
  scene's own ``dt_safety`` of rigid rods is not: past the limit a run stops at the blow-up).
"""

from __future__ import annotations

import math

from dem_taichi.scene.base import SceneError

__all__ = [
    "BONDED_DT_SAFETY_LIMIT",
    "RIGID_DT_SAFETY_LIMIT",
    "tangential_stiffness_limit",
    "check_time_step_factor",
]

#: Largest dt_safety of bonded rods: stable to 0.40, blown up at 0.45 within 100 steps on jammed
#: 300-rod packings, bending 0.3 and 1 (``benchmarks/bench_bonded.py --stability``).
BONDED_DT_SAFETY_LIMIT = 0.4
#: Largest dt_safety of rigid rods on jammed packings: stable to 0.35, blown up at 0.40 (an
#: overlap past 0.2 d) under the stress servo, 300 rods of 5 discs at p = 10 without long-range
#: forces (``benchmarks/results/dem_stability.csv``, ``benchmarks/bench_dem.py --stability``).
RIGID_DT_SAFETY_LIMIT = 0.35


def tangential_stiffness_limit(dt_safety: float) -> float:
    """Largest k_t/k_n whose tangential spring the leapfrog step resolves at ``dt_safety``.

    Two free discs (I = m r²/2) oscillate tangentially at ω_t = sqrt(3 k_t/k_n) ω_n, and Δt is
    set from the normal contact alone, ω_n Δt = π dt_safety; leapfrog is stable for ω Δt < 2, so
    k_t/k_n < (2 / (π dt_safety))² / 3: 6.0 at dt_safety 0.15, 0.84 at 0.4. (Elastic discs have
    k_t/k_n = 2(1−ν)/(2−ν), 2/3 to 1 for ν from 1/2 to 0; the scenes use 0.2.)"""
    return (2.0 / (math.pi * dt_safety)) ** 2 / 3.0


def check_time_step_factor(
    scene, key: str, factor: float | None, bonded: bool, jammed: bool = False
) -> None:
    """Refuse a ``[protocol]`` time-step multiple (``key``, ``factor``) that takes the scene's
    integration past what its own ``dt_safety`` is held to: the measured stability limit of
    bonded rods (``bonded``: the stage integrates bonds), that of rigid rods on jammed packings
    (``jammed``: the stage loads the packing of A, as the paths from A do) and the tangential
    spring's leapfrog bound (:func:`tangential_stiffness_limit`)."""
    if factor is None or factor <= 1.0:
        return
    dt_safety = scene.integration.dt_safety
    effective = dt_safety * factor
    if bonded:
        limit, rods = BONDED_DT_SAFETY_LIMIT, "bonded rods"
    elif jammed:
        limit, rods = RIGID_DT_SAFETY_LIMIT, "rigid rods on jammed packings"
    else:
        limit, rods = math.inf, ""
    if effective > limit:
        raise SceneError(
            f"[protocol] {key} = {factor!r} × [integration] dt_safety = {dt_safety!r} is "
            f"{effective:.3g}, beyond the measured stability limit of {rods}, {limit}: "
            f"allowed {key} <= {limit / dt_safety:.3g} (e.g. --set protocol.{key}=1), or a "
            "smaller dt_safety"
        )
    c = scene.contact
    limit = tangential_stiffness_limit(effective)
    if c.k_t > limit * c.k_n:
        raise SceneError(
            f"[protocol] {key} = {factor!r}: at dt_safety {effective:.3g} the tangential spring "
            f"k_t = {c.k_t!r} ({c.k_t / c.k_n:.3g} × k_n) is beyond the leapfrog bound k_t/k_n "
            f"<= {limit:.3g}: lower {key} or k_t"
        )
