"""Pair force laws as Taichi functions (model.md §1.2; notes/dem_interfaces.md).

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
