"""Intra-rod bonds of the bonded-rod model (docs/science/dem-model.md §1.7) as Taichi functions.

In bonded mode every disc is a body (x, y, θ) and disc b is bonded to disc b + 1 of the same rod
(rod-major order, chains of ``chain`` discs). The bond is in its reference state
(total-Lagrangian: straight rod, centre spacing s_0), with d = x_h − x_g (minimum image; g = b,
h = b + 1), θ_m = (θ_g + θ_h)/2, a_m = (cos θ_m, sin θ_m), t_m = ẑ × a_m:

    e_n = d·a_m − s_0      stretch       (stiffness k_bn, damping γ_bn)
    e_t = d·t_m            shear         (k_bt, γ_bt)
    e_b = θ_h − θ_g        bending       (κ_b, γ_bb)

These vanish on rigid motions of the pair (objective). Generalised forces Λ_e = k_e e + γ_e ė,
with the rates ė_n = ḋ·a_m + e_t ω_m, ė_t = ḋ·t_m − (d·a_m) ω_m, ė_b = ω_h − ω_g
(ω_m = (ω_g + ω_h)/2, ḋ the relative velocity including the affine cell flow). Forces and
torques are −∂U/∂q with U = ½ Σ k_e e², the damping through the same Jacobian:

    F_h = −(Λ_n a_m + Λ_t t_m) = −F_g
    τ_h = −(½ Λ_n e_t − ½ Λ_t (d·a_m) + Λ_b),   τ_g = −(½ Λ_n e_t − ½ Λ_t (d·a_m) − Λ_b)

(linear and angular momentum conserved exactly). The same law in numpy is
:func:`dem_taichi.physics.bonds.bond_forces` (the reference the kernels are tested against).

Breakage (optional, the MercuryDPM rule): when the elastic tension k_bn e_n exceeds F_b the
bond breaks for good (``bond_intact[g] = 0``); from then on the two discs interact like any
other pair (contact and long-range forces).
"""

import taichi as ti

from dem_taichi.kernels.common import T
from dem_taichi.kernels.layout import (
    C_LX,
    C_LY,
    F_FORCE_REBUILD,
    P_BOND_BREAK,
    P_BOND_GB,
    P_BOND_GN,
    P_BOND_GT,
    P_BOND_KB,
    P_BOND_KN,
    P_BOND_KT,
    P_RATE_X,
    P_RATE_Y,
    P_SPACING,
)


@ti.func
def bond_interaction(g, pos: T, angle: T, vel: T, omega: T, cell: T, params: T):
    """The bond between bodies g and g + 1.

    Returns (F_hx, F_hy, τ_h, τ_g, d_x, d_y, U, e_n): the force on h (−F on g), the torques,
    the bond vector d = x_h − x_g and the elastic energy, the stretch.
    """
    h = g + 1
    lx = cell[C_LX]
    ly = cell[C_LY]
    sx = pos[h, 0] - pos[g, 0]
    sy = pos[h, 1] - pos[g, 1]
    sx -= ti.floor(sx + 0.5)
    sy -= ti.floor(sy + 0.5)
    dx = sx * lx
    dy = sy * ly
    theta_m = 0.5 * (angle[g] + angle[h])
    ax = ti.cos(theta_m)
    ay = ti.sin(theta_m)
    tx = -ay
    ty = ax
    d_a = dx * ax + dy * ay
    e_n = d_a - params[P_SPACING]
    e_t = dx * tx + dy * ty
    e_b = angle[h] - angle[g]
    # relative velocity with the affine flow D d, D = −diag(ε̇_xx, ε̇_yy)
    vdx = vel[h, 0] - vel[g, 0] - params[P_RATE_X] * dx
    vdy = vel[h, 1] - vel[g, 1] - params[P_RATE_Y] * dy
    w_m = 0.5 * (omega[g] + omega[h])
    rate_n = vdx * ax + vdy * ay + e_t * w_m
    rate_t = vdx * tx + vdy * ty - d_a * w_m
    rate_b = omega[h] - omega[g]
    k_n = params[P_BOND_KN]
    k_t = params[P_BOND_KT]
    k_b = params[P_BOND_KB]
    lam_n = k_n * e_n + params[P_BOND_GN] * rate_n
    lam_t = k_t * e_t + params[P_BOND_GT] * rate_t
    lam_b = k_b * e_b + params[P_BOND_GB] * rate_b
    fx = -(lam_n * ax + lam_t * tx)
    fy = -(lam_n * ay + lam_t * ty)
    common = 0.5 * lam_n * e_t - 0.5 * lam_t * d_a
    tau_h = -(common + lam_b)
    tau_g = -(common - lam_b)
    energy = 0.5 * (k_n * e_n * e_n + k_t * e_t * e_t + k_b * e_b * e_b)
    return fx, fy, tau_h, tau_g, dx, dy, energy, e_n


@ti.func
def is_bonded_pair(chain: T, i, j, bond_intact: T):
    """Whether discs i and j are bonded neighbours of one rod with their bond intact."""
    lo = ti.min(i, j)
    result = 0
    if ti.abs(i - j) == 1 and lo % chain != chain - 1:
        if bond_intact[lo] == 1:
            result = 1
    return result


@ti.func
def bond_breaks(e_n, params: T):
    """The MercuryDPM rule: the elastic tension k_bn e_n beyond F_b (F_b ≤ 0: unbreakable)."""
    f_b = params[P_BOND_BREAK]
    return f_b > 0.0 and params[P_BOND_KN] * e_n > f_b


@ti.func
def holding_bond(
    g, pos: T, angle: T, vel: T, omega: T, bond_intact: T, cell: T, params: T, flags: T
):
    """The bond g—g+1 if it holds: (1, F_hx, F_hy, τ_h, τ_g), else (0, 0, 0, 0, 0). A bond whose
    tension exceeds F_b breaks here, for good (``bond_intact[g] = 0``), adds nothing, and forces
    a list rebuild before the next step's forces (an intact bond's discs are not listed,
    :func:`dem_taichi.kernels.neighbours.rebuild_lists`; from the next step on they interact
    like any other pair). The caller checks that g has a bond (g % chain != chain − 1)."""
    held = 0
    fx = 0.0
    fy = 0.0
    tau_h = 0.0
    tau_g = 0.0
    if bond_intact[g] == 1:
        fx, fy, tau_h, tau_g, dx, dy, energy, e_n = bond_interaction(
            g, pos, angle, vel, omega, cell, params
        )
        if bond_breaks(e_n, params):
            bond_intact[g] = 0
            flags[F_FORCE_REBUILD] = 1
        else:
            held = 1
    return held, fx, fy, tau_h, tau_g


@ti.func
def add_bond_forces(
    chain: T,
    atomic: ti.template(),
    g,
    pos: T,
    angle: T,
    vel: T,
    omega: T,
    force: T,
    torque: T,
    bond_intact: T,
    cell: T,
    params: T,
    flags: T,
):
    """Add the forces of the bond g—g+1 (if it exists and holds) to both bodies; break it when
    its tension exceeds F_b (then it adds nothing)."""
    if g % chain != chain - 1:
        held, fx, fy, tau_h, tau_g = holding_bond(
            g, pos, angle, vel, omega, bond_intact, cell, params, flags
        )
        if held == 1:
            h = g + 1
            if ti.static(atomic):
                ti.atomic_add(force[h, 0], fx)
                ti.atomic_add(force[h, 1], fy)
                ti.atomic_add(torque[h], tau_h)
                ti.atomic_sub(force[g, 0], fx)
                ti.atomic_sub(force[g, 1], fy)
                ti.atomic_add(torque[g], tau_g)
            else:
                force[h, 0] = force[h, 0] + fx
                force[h, 1] = force[h, 1] + fy
                torque[h] = torque[h] + tau_h
                force[g, 0] = force[g, 0] - fx
                force[g, 1] = force[g, 1] - fy
                torque[g] = torque[g] + tau_g


@ti.func
def gather_bond_forces(
    chain: T, b, pos: T, angle: T, vel: T, omega: T, force: T, torque: T, bond_intact: T,
    cell: T, params: T, flags: T,
):  # fmt: skip
    """Add to body b only the forces of its two bonds (b−1—b and b—b+1): deterministic in
    parallel (each bond evaluated by both its bodies with the same arithmetic)."""
    if b % chain != 0:
        held, fx, fy, tau_h, tau_g = holding_bond(
            b - 1, pos, angle, vel, omega, bond_intact, cell, params, flags
        )
        if held == 1:
            force[b, 0] = force[b, 0] + fx
            force[b, 1] = force[b, 1] + fy
            torque[b] = torque[b] + tau_h
    if b % chain != chain - 1:
        held, fx, fy, tau_h, tau_g = holding_bond(
            b, pos, angle, vel, omega, bond_intact, cell, params, flags
        )
        if held == 1:
            force[b, 0] = force[b, 0] - fx
            force[b, 1] = force[b, 1] - fy
            torque[b] = torque[b] + tau_g
