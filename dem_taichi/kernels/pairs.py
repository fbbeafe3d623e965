"""The interaction of one listed disc pair and the force sum over a disc's list.

``pair_interaction`` evaluates contact (normal spring-dashpot, tangential spring capped by
Coulomb friction), long-range and van der Waals forces of one list entry (the laws of
:mod:`dem_taichi.kernels.laws`, mirrored in numpy by :mod:`dem_taichi.physics.forcelaw`);
``disc_forces`` sums them over a disc's list (atomic scatter, serial or per-rod gather).
"""

import taichi as ti

from dem_taichi.kernels.bonds import is_bonded_pair
from dem_taichi.kernels.common import T
from dem_taichi.kernels.laws import (
    contact_normal_force,
    long_range_energy,
    long_range_force,
    tangential_force,
)
from dem_taichi.kernels.layout import (
    BLOWUP_OVERLAP,
    C_LX,
    C_LY,
    F_BLOWUP,
    F_BLOWUP_INDEX,
    F_STOP,
    IMAGE_CODES,
    IMAGE_RANGE,
    IMAGE_SIDE,
    P_CUT,
    P_DIAM,
    P_DT,
    P_GN,
    P_GT,
    P_KN,
    P_KT,
    P_MAX_OVERLAP,
    P_MU,
    P_RATE_X,
    P_RATE_Y,
    P_ROLL_CAP,
    P_ROLL_G,
    P_ROLL_K,
    P_VDW_F,
    P_VDW_K,
)


@ti.func
def pair_interaction(
    ns: T,
    phys: ti.template(),
    update: ti.template(),
    i,
    k,
    vel: T,
    omega: T,
    disc_x: T,
    disc_off: T,
    offsets: T,
    nbr: T,
    nbr_xi: T,
    nbr_psi: T,
    charge: T,
    pair_table: T,
    rod_strength: T,
    attraction_partners: T,
    bond_intact: T,
    cell: T,
    params: T,
):
    """Force on disc i from its k-th list neighbour j (inter-rod, half list).

    Returns (F_x, F_y, τ_i, τ_j, j, active, f_contact_normal, f_tangential, δ, U_contact, U_long,
    long_active, b_x, b_y) with F the force on i (−F on j), τ the torques on the two rods, b the
    centroid branch vector X_P − X_Q − shift. ``update``: advance ξ by v_t Δt (time step) or just
    read it (measures). Bonded rods (``phys.bonded``): every disc is a body (``ns`` = 1),
    species by the disc's place in its chain of ``phys.chain`` discs, and bonded neighbours with
    their bond intact do not interact (:mod:`dem_taichi.kernels.bonds`). Rod strengths
    (``phys.strength``): the long-range F_max and k_a of the pair are multiplied by the harmonic
    mean of ``rod_strength`` of the two discs' rods (rod = disc // ``phys.chain``). Attraction
    partners (``phys.partners``): once ``attraction_partners`` is set (at state A), an attractive
    pair (s < 0) acts only if its two rods are partners (:mod:`dem_taichi.kernels.layout`). Rolling
    resistance (``phys.rolling``): the rolling spring ψ of the entry adds the couple M (on i; −M
    on j) of :mod:`dem_taichi.physics.rolling` to the two torques, and ½ κ_r ψ² to U_contact.
    """
    lx = cell[C_LX]
    ly = cell[C_LY]
    packed = nbr[i, k]
    j = packed // IMAGE_CODES
    code = packed % IMAGE_CODES
    mx = 1.0 * (code // IMAGE_SIDE - IMAGE_RANGE)
    my = 1.0 * (code % IMAGE_SIDE - IMAGE_RANGE)
    dx = disc_x[i, 0] - disc_x[j, 0] - mx * lx
    dy = disc_x[i, 1] - disc_x[j, 1] - my * ly
    dist2 = dx * dx + dy * dy
    cut = params[P_CUT]
    d = params[P_DIAM]
    fx = 0.0
    fy = 0.0
    tau_i = 0.0
    tau_j = 0.0
    active = 0
    fc = 0.0
    ft = 0.0
    delta = 0.0
    u_contact = 0.0
    u_long = 0.0
    long_active = 0
    bx = 0.0
    by = 0.0
    m_roll = 0.0
    within = 0
    if dist2 < cut * cut:
        within = 1
    if ti.static(phys.bonded):
        if within == 1:
            within = 1 - is_bonded_pair(phys.chain, i, j, bond_intact)
    if within == 1:
        active = 1
        dist = ti.sqrt(dist2)
        nx = dx / dist
        ny = dy / dist
        delta = d - dist
        oix = disc_off[i, 0]
        oiy = disc_off[i, 1]
        ojx = disc_off[j, 0]
        ojy = disc_off[j, 1]
        bx = dx - oix + ojx
        by = dy - oiy + ojy
        # the long-range and van der Waals forces first: with [contact] cap_force = "net" the
        # caps take the pair's attraction off the contact force; fn sums f_c, f_l, f_w in order
        f_l = 0.0
        f_w = 0.0
        if ti.static(phys.long_range or phys.vdw):
            si = i % phys.chain
            sj = j % phys.chain
            gap = -delta
            if ti.static(phys.long_range):
                s_f = pair_table[si, sj, 0]
                if s_f != 0.0:
                    s_k = pair_table[si, sj, 1]
                    g_max = pair_table[si, sj, 2]
                    if ti.static(phys.strength):
                        # the rods' strengths s: F_max and k_a times their harmonic mean, the
                        # range kept ([long_range] strength_spread)
                        s_a = rod_strength[i // phys.chain]
                        s_b = rod_strength[j // phys.chain]
                        m = 2.0 * s_a * s_b / (s_a + s_b)
                        s_f *= m
                        s_k *= m
                    if ti.static(phys.partners):
                        # from state A on, only rods that attracted each other at A attract
                        # ([long_range] attraction_pairs = "bonded_at_A"); repulsion unchanged.
                        # A pair of other rods gets F_max = k_a = 0: no force, no energy.
                        if s_f < 0.0:
                            rod_a = i // phys.chain
                            n_a = attraction_partners[rod_a, 0]
                            if n_a >= 0:
                                rod_b = j // phys.chain
                                attracts = 0
                                for c in range(n_a):
                                    if attraction_partners[rod_a, 1 + c] == rod_b:
                                        attracts = 1
                                if attracts == 0:
                                    s_f = 0.0
                                    s_k = 0.0
                    f_l = long_range_force(gap, s_f, s_k, g_max)
                    if f_l != 0.0:
                        long_active = 1
                    if ti.static(not update):
                        u_long += long_range_energy(gap, s_f, s_k, g_max)
            if ti.static(phys.vdw):
                if charge[si] != 0 and charge[sj] != 0:
                    fw = params[P_VDW_F]
                    kw = params[P_VDW_K]
                    f_w = long_range_force(gap, -fw, -kw, fw / kw)
                    if f_w != 0.0:
                        long_active = 1
                    if ti.static(not update):
                        u_long += long_range_energy(gap, -fw, -kw, fw / kw)
        fn = 0.0
        if delta > 0.0:
            rod_i = i // ns
            rod_j = j // ns
            half = 0.5 * dist
            # contact point relative to the two centroids (midpoint of the overlap)
            cpx = oix - nx * half
            cpy = oiy - ny * half
            cqx = ojx + nx * half
            cqy = ojy + ny * half
            vrx = (vel[rod_i, 0] - omega[rod_i] * cpy) - (vel[rod_j, 0] - omega[rod_j] * cqy)
            vry = (vel[rod_i, 1] + omega[rod_i] * cpx) - (vel[rod_j, 1] + omega[rod_j] * cqx)
            # affine part of the relative velocity: D b with D = −diag(ε̇_xx, ε̇_yy)
            vrx -= params[P_RATE_X] * bx
            vry -= params[P_RATE_Y] * by
            vn = vrx * nx + vry * ny
            fc = contact_normal_force(delta, params[P_KN], vn, params[P_GN])
            fn += fc
            u_contact = 0.5 * params[P_KN] * delta * delta
            cap_load = ti.abs(fc)
            if ti.static(phys.net_caps):
                cap_load = ti.max(cap_load + ti.min(f_l, 0.0) + ti.min(f_w, 0.0), 0.0)
            if ti.static(phys.friction):
                vt = -vrx * ny + vry * nx
                xi = nbr_xi[i, k]
                if ti.static(update):
                    xi += vt * params[P_DT]
                kt = params[P_KT]
                ft, xi = tangential_force(xi, vt, kt, params[P_GT], params[P_MU] * cap_load)
                if ti.static(update):
                    nbr_xi[i, k] = xi
                u_contact += 0.5 * kt * xi * xi
            if ti.static(phys.rolling):
                w_rel = omega[rod_i] - omega[rod_j]
                psi = nbr_psi[i, k]
                if ti.static(update):
                    psi += w_rel * params[P_DT]
                kr = params[P_ROLL_K]
                cap_r = params[P_ROLL_CAP] * cap_load
                m_roll, psi = tangential_force(psi, w_rel, kr, params[P_ROLL_G], cap_r)
                if ti.static(update):
                    nbr_psi[i, k] = psi
                u_contact += 0.5 * kr * psi * psi
        else:
            if ti.static(phys.friction and update):
                nbr_xi[i, k] = 0.0
            if ti.static(phys.rolling and update):
                nbr_psi[i, k] = 0.0
        if ti.static(phys.long_range):
            fn += f_l
        if ti.static(phys.vdw):
            fn += f_w
        fx = fn * nx - ft * ny
        fy = fn * ny + ft * nx
        half = 0.5 * dist
        tau_i = oix * fy - oiy * fx - half * ft
        tau_j = -(ojx * fy - ojy * fx) - half * ft
        if ti.static(phys.rolling):
            tau_i += m_roll
            tau_j -= m_roll
    else:
        # beyond the cut-off (or bonded): the springs restart at zero, as for a pair within it
        # that does not touch; else a contact that opens and closes again within one list (no
        # long-range shell in between) would find its old spring
        if ti.static(update and phys.friction):
            nbr_xi[i, k] = 0.0
        if ti.static(update and phys.rolling):
            nbr_psi[i, k] = 0.0
    return fx, fy, tau_i, tau_j, j, active, fc, ft, delta, u_contact, u_long, long_active, bx, by


@ti.func
def disc_forces(
    ns: T,
    phys: ti.template(),
    atomic: ti.template(),
    update: ti.template(),
    gather: ti.template(),
    i,
    vel: T,
    omega: T,
    force: T,
    torque: T,
    disc_x: T,
    disc_off: T,
    offsets: T,
    nbr: T,
    nbr_xi: T,
    nbr_psi: T,
    nbr_count: T,
    charge: T,
    pair_table: T,
    rod_strength: T,
    attraction_partners: T,
    bond_intact: T,
    cell: T,
    params: T,
    flags: T,
):
    """Add the forces of all list pairs of disc i to both rods.

    ``atomic``: scatter with atomic adds (parallel loops); otherwise plain read-modify-write,
    valid only inside a serial loop (several times cheaper for float64). ``gather``: full list,
    only rod i is written (each rod sums its own entries: deterministic in parallel).
    """
    rod_i = i // ns
    max_overlap = params[P_MAX_OVERLAP]
    sum_fx = 0.0
    sum_fy = 0.0
    sum_tau = 0.0
    for k in range(nbr_count[i]):
        fx, fy, tau_i, tau_j, j, active, fc, ft, delta, uc, ul, la, bx, by = pair_interaction(
            ns,
            phys,
            update,
            i,
            k,
            vel,
            omega,
            disc_x,
            disc_off,
            offsets,
            nbr,
            nbr_xi,
            nbr_psi,
            charge,
            pair_table,
            rod_strength,
            attraction_partners,
            bond_intact,
            cell,
            params,
        )
        if active == 1:
            rod_j = j // ns
            sum_fx += fx
            sum_fy += fy
            sum_tau += tau_i
            if ti.static(gather):
                pass  # full list: rod j gathers this pair from its own entry
            elif ti.static(atomic):
                ti.atomic_sub(force[rod_j, 0], fx)
                ti.atomic_sub(force[rod_j, 1], fy)
                ti.atomic_add(torque[rod_j], tau_j)
            else:
                force[rod_j, 0] = force[rod_j, 0] - fx
                force[rod_j, 1] = force[rod_j, 1] - fy
                torque[rod_j] = torque[rod_j] + tau_j
            if delta > max_overlap:
                flags[F_BLOWUP] = BLOWUP_OVERLAP
                flags[F_BLOWUP_INDEX] = i
                flags[F_STOP] = 1
    if ti.static(atomic):
        ti.atomic_add(force[rod_i, 0], sum_fx)
        ti.atomic_add(force[rod_i, 1], sum_fy)
        ti.atomic_add(torque[rod_i], sum_tau)
    else:
        force[rod_i, 0] = force[rod_i, 0] + sum_fx
        force[rod_i, 1] = force[rod_i, 1] + sum_fy
        torque[rod_i] = torque[rod_i] + sum_tau
