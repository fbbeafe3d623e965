"""Pair force laws as Taichi functions (docs/science/dem-model.md §1.2, §1.8), each the
scalar form of the numpy reference of the same name in :mod:`dem_taichi.physics.forcelaw`.

Contact: normal spring-dashpot f_c = k_n δ − γ_n v_n (``contact_normal_force``); tangential
spring-dashpot F_t = −k_t ξ − γ_t v_t capped at μ|f_c|, the spring ξ reset to the cap on slip
(``tangential_force``; ξ is the scalar spring along t = (−n_y, n_x)).

Symbols: gap g = |r| − d (surface gap), overlap δ = −g; a positive scalar force is repulsive.
Long-range law of a pair with signed amplitude sF = s·F_max and signed stiffness sk = s·k_a
(s = c_i c_j, harmonic-mean pair values, range g_max = F_max/k_a):

    f = sF                    for g ≤ 0           U = sF (½ g_max − g)
    f = sF − sk g             for 0 < g ≤ g_max   U = ½ sk (g_max − g)²
    f = 0                     beyond              U = 0

so that f = −dU/dg everywhere (U = s[½ k_a g_max² + F_max δ] when touching). The van der Waals-like
term is the same law with sF = −F_w, sk = −k_w (always attractive).
"""

import taichi as ti

from dem_taichi.kernels.common import sign


@ti.func
def contact_normal_force(overlap, k_n, normal_velocity, gamma_n):
    """f_c = k_n δ − γ_n v_n (for δ > 0; positive repulsive, not clipped at zero)."""
    return k_n * overlap - gamma_n * normal_velocity


@ti.func
def tangential_force(spring, tangential_velocity, k_t, gamma_t, cap):
    """(F_t, ξ): F_t = −k_t ξ − γ_t v_t, capped at |F_t| ≤ cap = μ|f_c|; on slip ξ is reset to
    −(F_t + γ_t v_t)/k_t (the capped value)."""
    ft = -k_t * spring - gamma_t * tangential_velocity
    xi = spring
    if ti.abs(ft) > cap:
        ft = cap * sign(ft)
        if k_t > 0.0:
            xi = -(ft + gamma_t * tangential_velocity) / k_t
    return ft, xi


@ti.func
def long_range_force(gap, signed_f_max, signed_k_a, g_max):
    """Scalar force (positive repulsive) of the three-branch law; see the module docstring."""
    f = 0.0
    if gap <= 0.0:
        f = signed_f_max
    elif gap < g_max:
        f = signed_f_max - signed_k_a * gap
    return f


@ti.func
def long_range_energy(gap, signed_f_max, signed_k_a, g_max):
    """Potential U(g) of the three-branch law, continuous, with f = −dU/dg."""
    u = 0.0
    if gap <= 0.0:
        u = signed_f_max * (0.5 * g_max - gap)
    elif gap < g_max:
        u = 0.5 * signed_k_a * (g_max - gap) * (g_max - gap)
    return u
