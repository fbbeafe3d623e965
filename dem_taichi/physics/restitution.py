"""Restitution of the engine's discrete two-disc collision, and the γ_n that gives a chosen e_n.

The engine integrates with the leapfrog kick–drift scheme (``kernels/step.py``) and the contact
dashpot reads the *stored* half-step velocity at force evaluation. Per step n (Δt, two discs of
mass m on a line, separation s = x_2 − x_1, relative velocity u = v_2 − v_1 = v_n, the normal
relative velocity of ``pair_interaction``):

    u_{n+½} = u_{n−½} + Δt · 2 f_n / m         kick (each disc gets ∓f_n; reduced mass m/2)
    s_{n+1} = s_n + Δt · u_{n+½}                drift
    δ_{n+1} = d − s_{n+1}
    f_{n+1} = k_n δ_{n+1} − γ_n u_{n+½}  if δ_{n+1} > 0, else 0   (no tensile clip: the kernel)

The dashpot thus lags the spring by Δt/2, the spring has the leapfrog frequency error, and the
force jumps by ≈ γ_n|u| when the discs start and stop touching at a step boundary, so the
restitution the engine realises differs from the continuous e_n = exp(−γ_n t_c/m) by O(Δt/t_c).

The outcome of one discrete collision depends on where in a step the discs first touch: the
phase φ = δ_1 / (|u_0| Δt) ∈ (0, 1] of the first overlap δ_1 (the update is linear and scale-free
in the approach speed |u_0|, so φ is the only other variable). :func:`discrete_restitution`
returns the mean over φ (midpoint rule, ``PHASE_SAMPLES`` phases), the restitution of collisions
at random phases as in a gas; :func:`restitution_by_phase` gives single collisions.

Measured with the continuous γ_n (engine = this replica to 1e-6, 64 phases; Δt = dt_safety t_c):
phase-mean error −0.4 % / −3.8 % / −7.0 % / −13.2 % / −11.6 % for e_n = 0.3 at dt_safety 0.005 /
0.05 / 0.1 / 0.15 / 0.2 (e_n = 0.5: −0.1 … −2.4 %, e_n = 0.9: within ±0.1 %). The spread over φ
of single collisions is much larger and hardly changed by the calibration of γ_n: −1 … +0.5 % at
0.005, −8 … +5 % at 0.05, −18 … +48 % at 0.15 (e_n = 0.3), −4 … +5 % at 0.15 (e_n = 0.9).

:func:`gamma_for_discrete_restitution` inverts it with ``scipy.optimize.brentq`` at a *given* Δt.
The scene's Δt is defined from the continuous-model contact duration of the target e_n (see
``config.Scene.time_step``), which does not depend on the γ_n found here: no fixed point.

Symbols: k_n normal stiffness, γ_n normal damping, m disc mass, e_n normal restitution, Δt time
step, t_c contact duration, φ contact phase.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy.optimize import brentq

__all__ = [
    "restitution_by_phase",
    "discrete_restitution",
    "gamma_for_discrete_restitution",
]

#: contact phases φ of the midpoint rule used for the phase average
PHASE_SAMPLES = 1024


def restitution_by_phase(
    gamma_n: float, k_n: float, mass: float, time_step: float, phases: np.ndarray
) -> np.ndarray:
    """Restitution −u_after/u_before of the engine's discrete head-on collision, per phase φ.

    Replays the kick–drift update of the module docstring (float64, the kernel's order of
    operations) for unit approach speed, diameter 1, from the step before first overlap
    (δ_0 = (φ − 1) Δt ≤ 0) until the discs separate (δ ≤ 0 after contact).
    """
    phases = np.asarray(phases, dtype=float)
    dt = float(time_step)
    two_over_m = 2.0 / mass
    u = -np.ones_like(phases)  # approaching: u = v_n < 0
    delta = (phases - 1.0) * dt  # overlap after the drift of the last force-free step
    force = np.zeros_like(phases)
    touched = np.zeros(phases.shape, dtype=bool)
    done = np.zeros(phases.shape, dtype=bool)
    # a collision lasts ~t_c/Δt steps; bound the loop generously (overdamped-like γ_n lingers)
    t_c = math.pi / math.sqrt(2.0 * k_n / mass)
    max_steps = int(50.0 * t_c / dt) + 100
    for _ in range(max_steps):
        u = u + dt * (two_over_m * force)
        delta = delta - dt * u
        inside = delta > 0.0
        force = np.where(inside, k_n * delta - gamma_n * u, 0.0)
        done |= touched & ~inside
        touched |= inside
        if done.all():
            return u
    raise RuntimeError(
        f"discrete collision did not end within {max_steps} steps "
        f"(k_n = {k_n}, gamma_n = {gamma_n}, m = {mass}, dt = {dt})"
    )


def discrete_restitution(gamma_n: float, k_n: float, mass: float, time_step: float) -> float:
    """Phase-averaged restitution of the engine's discrete two-disc collision (module docstring)."""
    phases = (np.arange(PHASE_SAMPLES) + 0.5) / PHASE_SAMPLES
    return float(np.mean(restitution_by_phase(gamma_n, k_n, mass, time_step, phases)))


@functools.lru_cache(maxsize=256)
def gamma_for_discrete_restitution(e_n: float, k_n: float, mass: float, time_step: float) -> float:
    """γ_n for which the engine's discrete collision at Δt = ``time_step`` has restitution e_n.

    Solves discrete_restitution(γ_n) = e_n with ``brentq`` (relative tolerance 1e-12) on the
    first bracket [γ_a, γ_b] of the grid γ_c·(0, ½, ¾, 1, 1¼, 1½, 2, 3, 4, 6, 8, 16, 32, 64) where
    the residual changes sign (γ_c: the continuous-model γ_n; the discrete root lies near it,
    and e(γ) of the discrete collision is not monotone at large Δt: the first bracket is taken).
    The phase mean is piecewise continuous in γ_n (jumps ≲ 0.2/``PHASE_SAMPLES`` where a phase
    sample crosses a change of the number of contact steps), so the root is exact to ~2e-4.
    Raises ``ValueError`` naming the inputs when e_n is out of reach at this Δt (large dt_safety
    with small e_n: the lagged dashpot cannot dissipate that much per collision).
    """
    if e_n >= 1.0:
        return 0.0

    def residual(gamma: float) -> float:
        return discrete_restitution(gamma, k_n, mass, time_step) - e_n

    ln_e = math.log(e_n)
    scale = math.sqrt(2.0 * k_n * mass * ln_e**2 / (math.pi**2 + ln_e**2))
    lo = 0.0
    r_lo = residual(lo)
    if r_lo <= 0.0:
        raise ValueError(
            f"e_n = {e_n}: the undamped discrete collision already has restitution "
            f"{r_lo + e_n:.6f} at dt = {time_step} (k_n = {k_n}, m = {mass})"
        )
    for factor in (0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 16.0, 32.0, 64.0):
        hi = factor * scale
        try:
            r_hi = residual(hi)
        except RuntimeError:  # the lagged dashpot is unstable this far: e_n not reachable
            break
        if r_hi < 0.0:
            return float(brentq(residual, lo, hi, xtol=1e-14 * scale, rtol=1e-12))
        lo = hi
    raise ValueError(
        f"e_n = {e_n} is not reached by the engine's discrete collision at dt = {time_step} "
        f"(k_n = {k_n}, m = {mass}, gamma_n up to {hi:.6g}): reduce [integration] dt_safety "
        "or use restitution_model = 'continuous'"
    )
