"""Neighbour lists, the time step and the measures as Taichi kernels.

Every array is an explicit ``ti.types.ndarray`` argument (compiled once per dtype and physics
switches, whatever the sizes), every number that may change between calls is in ``params``;
the physics switches (friction, long range, van der Waals) are a frozen dataclass passed as
``ti.template()`` so that physics a scene switches off is not compiled at all.

State (N rods of n_s discs, M = N n_s discs, K list capacity per disc):
  pos (N,2)        reduced centroid coordinates s: X = s ∘ L (wrapped into [0,1) at list builds)
  angle (N,)       θ; rod axis a = (cos θ, sin θ)
  vel (N,2)        fluctuating centroid velocity at the half step (total = vel + D X, D = −ε̇)
  omega (N,)       angular velocity at the half step
  force (N,2), torque (N,)  total pair forces/torques at the current positions
  ref_pos, ref_angle        positions at the last list build
  disc_x (M,2)     absolute disc positions X + o_s a; disc_off (M,2) = o_s a
  nbr (M,K) int32  half list: entries j*IMAGE_CODES + image code for j > i, |r_ij| < r_list at build
  nbr_xi (M,K)     tangential spring ξ (scalar along t = (−n_y, n_x)) of each entry
  old_* buffers    the previous list, read to carry ξ across rebuilds

Time integration (leapfrog kick–drift form of velocity Verlet, per step):
  [rebuild the list if 2(max displacement + v_max Δt) + reach·|ΔL/L_build| ≥ skin]
  v ← v + Δt (F − α|F| sign v)/M + Δt ε̇ ∘ v      (local damping; g-SLLOD term of the cell flow)
  ω ← ω + Δt (τ − α|τ| sign ω)/I
  L ← L exp(−ε̇ Δt);  s ← s + Δt v / L;  θ ← θ + Δt ω
  F, τ ← pair forces at the new positions (contact velocities at the half step)
"""

import taichi as ti

from dem_taichi.kernels.laws import long_range_energy, long_range_force
from dem_taichi.kernels.layout import (
    BLOWUP_NONFINITE,
    BLOWUP_OVERLAP,
    C_DISP,
    C_LBX,
    C_LBY,
    C_LX,
    C_LY,
    C_TIME,
    C_VMAX,
    F_BLOWUP,
    F_BLOWUP_INDEX,
    F_FORCE_REBUILD,
    F_NEEDED,
    F_OLD_SAVED,
    F_OVERFLOW,
    F_REBUILDS,
    F_STEPS,
    F_STOP,
    IMAGE_CODES,
    IMAGE_RANGE,
    IMAGE_SIDE,
    M_CONTACTS,
    M_INTERACTING,
    M_KE_ROT,
    M_KE_TRANS,
    M_LONG_PAIRS,
    M_SLIDING,
    M_SUM_PAIR_FORCE,
    M_SUM_ROD_FORCE,
    M_SXX,
    M_SXY,
    M_SYX,
    M_SYY,
    M_U_CONTACT,
    M_U_LONG,
    P_ALPHA,
    P_CUT,
    P_DIAM,
    P_DT,
    P_GN,
    P_GT,
    P_INERTIA,
    P_KN,
    P_KT,
    P_MASS,
    P_MAX_OFFSET,
    P_MAX_OVERLAP,
    P_MU,
    P_RATE_X,
    P_RATE_Y,
    P_REACH,
    P_RLIST,
    P_SKIN,
    P_VDW_F,
    P_VDW_K,
    PAIR_CONTACT,
    PAIR_INTERACTING,
    PAIR_LONG_RANGE,
    PAIR_SLIDING,
)

nd = ti.types.ndarray()
T = ti.template()  # arrays passed to ti.func by reference


# ----------------------------------------------------------------------------------------------
# small helpers
@ti.func
def sign(x):
    s = 0.0
    if x > 0.0:
        s = 1.0
    elif x < 0.0:
        s = -1.0
    return s


@ti.func
def place_rod_discs(ns: T, r, pos: T, angle: T, offsets: T, disc_x: T, disc_off: T, lx, ly):
    """Absolute disc positions of rod r from its reduced centroid and angle."""
    place_rod_discs_cs(
        ns, r, pos, ti.cos(angle[r]), ti.sin(angle[r]), offsets, disc_x, disc_off, lx, ly
    )


@ti.func
def place_rod_discs_cs(ns: T, r, pos: T, c, s, offsets: T, disc_x: T, disc_off: T, lx, ly):
    """As place_rod_discs with the axis (c, s) = (cos θ, sin θ) given."""
    cx = pos[r, 0] * lx
    cy = pos[r, 1] * ly
    for k in range(ns):
        g = r * ns + k
        ox = offsets[k] * c
        oy = offsets[k] * s
        disc_off[g, 0] = ox
        disc_off[g, 1] = oy
        disc_x[g, 0] = cx + ox
        disc_x[g, 1] = cy + oy


# ----------------------------------------------------------------------------------------------
# neighbour list (serial code: call it from inside a serial loop)
@ti.func
def rebuild_lists(
    ns: T,
    full: T,
    pos: T,
    angle: T,
    ref_pos: T,
    ref_angle: T,
    offsets: T,
    disc_x: T,
    disc_off: T,
    nbr: T,
    nbr_xi: T,
    nbr_count: T,
    old_nbr: T,
    old_xi: T,
    old_count: T,
    cell_count: T,
    cell_start: T,
    cell_items: T,
    disc_cell: T,
    cell: T,
    params: T,
    flags: T,
):
    """Cell-list build of the half Verlet list; carries ξ of surviving pairs; flags overflow.

    The old list is moved to the ``old_*`` buffers once (``F_OLD_SAVED``) so that a build that
    overflowed can be repeated after the host grew the capacity, without losing any ξ.
    """
    n_rods = pos.shape[0]
    n_discs = n_rods * ns
    capacity = nbr.shape[1]
    lx = cell[C_LX]
    ly = cell[C_LY]
    if flags[F_OLD_SAVED] == 0:
        for i in range(n_discs):
            c = nbr_count[i]
            old_count[i] = c
            for k in range(c):
                old_nbr[i, k] = nbr[i, k]
                old_xi[i, k] = nbr_xi[i, k]
        for r in range(n_rods):
            pos[r, 0] -= ti.floor(pos[r, 0])
            pos[r, 1] -= ti.floor(pos[r, 1])
            place_rod_discs(ns, r, pos, angle, offsets, disc_x, disc_off, lx, ly)
        flags[F_OLD_SAVED] = 1
    r_list = params[P_RLIST]
    r_list2 = r_list * r_list
    max_cells = cell_count.shape[0]
    nx = ti.max(1, ti.min(ti.cast(lx / r_list, ti.i32), max_cells))
    ny = ti.max(1, ti.min(ti.cast(ly / r_list, ti.i32), cell_count.shape[1]))
    for cx in range(nx):
        for cy in range(ny):
            cell_count[cx, cy] = 0
    for g in range(n_discs):
        xw = disc_x[g, 0] - ti.floor(disc_x[g, 0] / lx) * lx
        yw = disc_x[g, 1] - ti.floor(disc_x[g, 1] / ly) * ly
        cx = ti.min(ti.max(ti.cast(xw / lx * nx, ti.i32), 0), nx - 1)
        cy = ti.min(ti.max(ti.cast(yw / ly * ny, ti.i32), 0), ny - 1)
        disc_cell[g] = cx * ny + cy
        cell_count[cx, cy] += 1
    running = 0
    for cx in range(nx):
        for cy in range(ny):
            cell_start[cx, cy] = running
            running += cell_count[cx, cy]
            cell_count[cx, cy] = 0
    for g in range(n_discs):
        cx = disc_cell[g] // ny
        cy = disc_cell[g] % ny
        cell_items[cell_start[cx, cy] + cell_count[cx, cy]] = g
        cell_count[cx, cy] += 1
    overflow = 0
    needed = 0
    # with fewer than 3 cells along an axis, visit each distinct neighbour cell once
    n_off_x = ti.min(nx, 3)
    n_off_y = ti.min(ny, 3)
    shift_x = 1 if nx >= 3 else 0
    shift_y = 1 if ny >= 3 else 0
    for i in range(n_discs):
        rod_i = i // ns
        cx = disc_cell[i] // ny
        cy = disc_cell[i] % ny
        count = 0
        xi_x = disc_x[i, 0]
        xi_y = disc_x[i, 1]
        for ox in range(n_off_x):
            ccx = (cx + ox - shift_x + nx) % nx
            for oy in range(n_off_y):
                ccy = (cy + oy - shift_y + ny) % ny
                start = cell_start[ccx, ccy]
                for t in range(cell_count[ccx, ccy]):
                    j = cell_items[start + t]
                    accept = j > i
                    if ti.static(full):
                        accept = j != i
                    if accept and j // ns != rod_i:
                        dx = xi_x - disc_x[j, 0]
                        dy = xi_y - disc_x[j, 1]
                        mx = ti.floor(dx / lx + 0.5)
                        my = ti.floor(dy / ly + 0.5)
                        dx -= mx * lx
                        dy -= my * ly
                        if dx * dx + dy * dy < r_list2:
                            if count < capacity:
                                code = (ti.cast(mx, ti.i32) + IMAGE_RANGE) * IMAGE_SIDE + (
                                    ti.cast(my, ti.i32) + IMAGE_RANGE
                                )
                                nbr[i, count] = j * IMAGE_CODES + code
                                xi_old = 0.0
                                for k in range(old_count[i]):
                                    if old_nbr[i, k] // IMAGE_CODES == j:
                                        xi_old = old_xi[i, k]
                                nbr_xi[i, count] = xi_old
                            count += 1
        if count > capacity:
            overflow = 1
        needed = ti.max(needed, count)
        nbr_count[i] = ti.min(count, capacity)
    flags[F_NEEDED] = ti.max(flags[F_NEEDED], needed)
    if overflow == 1:
        flags[F_OVERFLOW] = 1
        flags[F_STOP] = 1
    else:
        flags[F_OLD_SAVED] = 0
        flags[F_REBUILDS] += 1
        for r in range(n_rods):
            ref_pos[r, 0] = pos[r, 0]
            ref_pos[r, 1] = pos[r, 1]
            ref_angle[r] = angle[r]
        cell[C_LBX] = lx
        cell[C_LBY] = ly
        cell[C_DISP] = 0.0


@ti.func
def needs_rebuild(cell: T, params: T, flags: T):
    dt = params[P_DT]
    strain = ti.max(ti.abs(cell[C_LX] / cell[C_LBX] - 1.0), ti.abs(cell[C_LY] / cell[C_LBY] - 1.0))
    moved = 2.0 * (cell[C_DISP] + 2.0 * cell[C_VMAX] * dt) + params[P_REACH] * strain
    return flags[F_OLD_SAVED] == 1 or flags[F_FORCE_REBUILD] == 1 or moved >= params[P_SKIN]


# ----------------------------------------------------------------------------------------------
# pair interaction
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
    charge: T,
    pair_table: T,
    cell: T,
    params: T,
):
    """Force on disc i from its k-th list neighbour j (inter-rod, half list).

    Returns (F_x, F_y, τ_i, τ_j, j, active, f_contact_normal, f_tangential, δ, U_contact, U_long,
    long_active, b_x, b_y) with F the force on i (−F on j), τ the torques on the two rods, b the
    centroid branch vector X_P − X_Q − shift. ``update``: advance ξ by v_t Δt (time step) or just
    read it (measures).
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
    if dist2 < cut * cut:
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
            fc = params[P_KN] * delta - params[P_GN] * vn
            fn += fc
            u_contact = 0.5 * params[P_KN] * delta * delta
            if ti.static(phys.friction):
                vt = -vrx * ny + vry * nx
                xi = nbr_xi[i, k]
                if ti.static(update):
                    xi += vt * params[P_DT]
                kt = params[P_KT]
                gt = params[P_GT]
                ft = -kt * xi - gt * vt
                cap = params[P_MU] * ti.abs(fc)
                if ti.abs(ft) > cap:
                    ft = cap * sign(ft)
                    if kt > 0.0:
                        xi = -(ft + gt * vt) / kt
                if ti.static(update):
                    nbr_xi[i, k] = xi
                u_contact += 0.5 * kt * xi * xi
        else:
            if ti.static(phys.friction and update):
                nbr_xi[i, k] = 0.0
        if ti.static(phys.long_range or phys.vdw):
            si = i % ns
            sj = j % ns
            gap = -delta
            if ti.static(phys.long_range):
                s_f = pair_table[si, sj, 0]
                if s_f != 0.0:
                    s_k = pair_table[si, sj, 1]
                    g_max = pair_table[si, sj, 2]
                    f_l = long_range_force(gap, s_f, s_k, g_max)
                    fn += f_l
                    if f_l != 0.0:
                        long_active = 1
                    if ti.static(not update):
                        u_long += long_range_energy(gap, s_f, s_k, g_max)
            if ti.static(phys.vdw):
                if charge[si] != 0 and charge[sj] != 0:
                    fw = params[P_VDW_F]
                    kw = params[P_VDW_K]
                    f_w = long_range_force(gap, -fw, -kw, fw / kw)
                    fn += f_w
                    if f_w != 0.0:
                        long_active = 1
                    if ti.static(not update):
                        u_long += long_range_energy(gap, -fw, -kw, fw / kw)
        fx = fn * nx - ft * ny
        fy = fn * ny + ft * nx
        half = 0.5 * dist
        tau_i = oix * fy - oiy * fx - half * ft
        tau_j = -(ojx * fy - ojy * fx) - half * ft
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
    nbr_count: T,
    charge: T,
    pair_table: T,
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
            charge,
            pair_table,
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


# ----------------------------------------------------------------------------------------------
# integration of one rod
@ti.func
def kick_drift_rod(
    ns: T,
    r,
    pos: T,
    angle: T,
    vel: T,
    omega: T,
    force: T,
    torque: T,
    ref_pos: T,
    ref_angle: T,
    offsets: T,
    disc_x: T,
    disc_off: T,
    cell: T,
    params: T,
    flags: T,
):
    """Kick (damped force), drift, zero the force, place the discs; returns (disp, speed)."""
    dt = params[P_DT]
    alpha = params[P_ALPHA]
    mass = params[P_MASS]
    inertia = params[P_INERTIA]
    lx = cell[C_LX]
    ly = cell[C_LY]
    rate_x = params[P_RATE_X]
    rate_y = params[P_RATE_Y]
    fx = force[r, 0]
    fy = force[r, 1]
    tz = torque[r]
    vx = vel[r, 0]
    vy = vel[r, 1]
    w = omega[r]
    vx += dt * (fx - alpha * ti.abs(fx) * sign(vx)) / mass + dt * rate_x * vx
    vy += dt * (fy - alpha * ti.abs(fy) * sign(vy)) / mass + dt * rate_y * vy
    w += dt * (tz - alpha * ti.abs(tz) * sign(w)) / inertia
    vel[r, 0] = vx
    vel[r, 1] = vy
    omega[r] = w
    pos[r, 0] += dt * vx / lx
    pos[r, 1] += dt * vy / ly
    theta = angle[r] + dt * w
    angle[r] = theta
    force[r, 0] = 0.0
    force[r, 1] = 0.0
    torque[r] = 0.0
    place_rod_discs_cs(ns, r, pos, ti.cos(theta), ti.sin(theta), offsets, disc_x, disc_off, lx, ly)
    max_offset = params[P_MAX_OFFSET]
    ddx = (pos[r, 0] - ref_pos[r, 0]) * lx
    ddy = (pos[r, 1] - ref_pos[r, 1]) * ly
    # |o (a − a_ref)| = 2 |o| |sin(Δθ/2)| <= |o| |Δθ|: a trig-free bound
    disp = ti.sqrt(ddx * ddx + ddy * ddy) + max_offset * ti.abs(theta - ref_angle[r])
    speed = ti.sqrt(vx * vx + vy * vy) + max_offset * ti.abs(w)
    if not (ti.abs(disp) < 1e30 and ti.abs(speed) < 1e30):
        flags[F_BLOWUP] = BLOWUP_NONFINITE
        flags[F_BLOWUP_INDEX] = r
        flags[F_STOP] = 1
    return disp, speed


@ti.func
def advance_cell(cell: T, params: T):
    dt = params[P_DT]
    cell[C_LX] *= ti.exp(-params[P_RATE_X] * dt)
    cell[C_LY] *= ti.exp(-params[P_RATE_Y] * dt)


# ----------------------------------------------------------------------------------------------
# kernels
@ti.kernel
def run_steps_serial(
    ns: ti.template(),
    phys: ti.template(),
    n_steps: ti.i32,
    pos: nd,
    angle: nd,
    vel: nd,
    omega: nd,
    force: nd,
    torque: nd,
    ref_pos: nd,
    ref_angle: nd,
    offsets: nd,
    disc_x: nd,
    disc_off: nd,
    nbr: nd,
    nbr_xi: nd,
    nbr_count: nd,
    old_nbr: nd,
    old_xi: nd,
    old_count: nd,
    cell_count: nd,
    cell_start: nd,
    cell_items: nd,
    disc_cell: nd,
    charge: nd,
    pair_table: nd,
    cell: nd,
    params: nd,
    flags: nd,
):
    """``n_steps`` fused time steps in one serial loop (one thread, no launch per step)."""
    n_rods = pos.shape[0]
    n_discs = n_rods * ns
    ti.loop_config(serialize=True)
    for _step in range(n_steps):
        if flags[F_STOP] == 0:
            if needs_rebuild(cell, params, flags):
                flags[F_FORCE_REBUILD] = 0
                rebuild_lists(
                    ns,
                    False,
                    pos,
                    angle,
                    ref_pos,
                    ref_angle,
                    offsets,
                    disc_x,
                    disc_off,
                    nbr,
                    nbr_xi,
                    nbr_count,
                    old_nbr,
                    old_xi,
                    old_count,
                    cell_count,
                    cell_start,
                    cell_items,
                    disc_cell,
                    cell,
                    params,
                    flags,
                )
            if flags[F_STOP] == 0:
                advance_cell(cell, params)
                max_disp = 0.0
                max_speed = 0.0
                for r in range(n_rods):
                    disp, speed = kick_drift_rod(
                        ns,
                        r,
                        pos,
                        angle,
                        vel,
                        omega,
                        force,
                        torque,
                        ref_pos,
                        ref_angle,
                        offsets,
                        disc_x,
                        disc_off,
                        cell,
                        params,
                        flags,
                    )
                    max_disp = ti.max(max_disp, disp)
                    max_speed = ti.max(max_speed, speed)
                cell[C_DISP] = max_disp
                cell[C_VMAX] = max_speed
                for i in range(n_discs):
                    disc_forces(
                        ns,
                        phys,
                        False,
                        True,
                        False,
                        i,
                        vel,
                        omega,
                        force,
                        torque,
                        disc_x,
                        disc_off,
                        offsets,
                        nbr,
                        nbr_xi,
                        nbr_count,
                        charge,
                        pair_table,
                        cell,
                        params,
                        flags,
                    )
                cell[C_TIME] += params[P_DT]
                flags[F_STEPS] += 1


@ti.kernel
def rebuild_if_needed(
    ns: ti.template(),
    full: ti.template(),
    pos: nd,
    angle: nd,
    ref_pos: nd,
    ref_angle: nd,
    offsets: nd,
    disc_x: nd,
    disc_off: nd,
    nbr: nd,
    nbr_xi: nd,
    nbr_count: nd,
    old_nbr: nd,
    old_xi: nd,
    old_count: nd,
    cell_count: nd,
    cell_start: nd,
    cell_items: nd,
    disc_cell: nd,
    cell: nd,
    params: nd,
    flags: nd,
):
    """Parallel path, part 1 (serial): list rebuild when needed, then advance the cell."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        if flags[F_STOP] == 0:
            if needs_rebuild(cell, params, flags):
                flags[F_FORCE_REBUILD] = 0
                rebuild_lists(
                    ns,
                    full,
                    pos,
                    angle,
                    ref_pos,
                    ref_angle,
                    offsets,
                    disc_x,
                    disc_off,
                    nbr,
                    nbr_xi,
                    nbr_count,
                    old_nbr,
                    old_xi,
                    old_count,
                    cell_count,
                    cell_start,
                    cell_items,
                    disc_cell,
                    cell,
                    params,
                    flags,
                )
            if flags[F_STOP] == 0:
                advance_cell(cell, params)
                cell[C_DISP] = 0.0
                cell[C_VMAX] = 0.0


@ti.kernel
def kick_drift_parallel(
    ns: ti.template(),
    pos: nd,
    angle: nd,
    vel: nd,
    omega: nd,
    force: nd,
    torque: nd,
    ref_pos: nd,
    ref_angle: nd,
    offsets: nd,
    disc_x: nd,
    disc_off: nd,
    cell: nd,
    params: nd,
    flags: nd,
):
    """Parallel path, part 2: kick and drift of every rod (parallel over rods)."""
    for r in range(pos.shape[0]):
        if flags[F_STOP] == 0:
            disp, speed = kick_drift_rod(
                ns,
                r,
                pos,
                angle,
                vel,
                omega,
                force,
                torque,
                ref_pos,
                ref_angle,
                offsets,
                disc_x,
                disc_off,
                cell,
                params,
                flags,
            )
            ti.atomic_max(cell[C_DISP], disp)
            ti.atomic_max(cell[C_VMAX], speed)


@ti.kernel
def forces_parallel(
    ns: ti.template(),
    phys: ti.template(),
    vel: nd,
    omega: nd,
    force: nd,
    torque: nd,
    disc_x: nd,
    disc_off: nd,
    offsets: nd,
    nbr: nd,
    nbr_xi: nd,
    nbr_count: nd,
    charge: nd,
    pair_table: nd,
    cell: nd,
    params: nd,
    flags: nd,
    count_step: ti.i32,
):
    """Parallel path, part 3: pair forces (parallel over discs, atomic scatter to rods)."""
    for i in range(disc_x.shape[0]):
        if flags[F_STOP] == 0:
            disc_forces(
                ns,
                phys,
                True,
                True,
                False,
                i,
                vel,
                omega,
                force,
                torque,
                disc_x,
                disc_off,
                offsets,
                nbr,
                nbr_xi,
                nbr_count,
                charge,
                pair_table,
                cell,
                params,
                flags,
            )
    if count_step == 1 and flags[F_STOP] == 0:
        cell[C_TIME] += params[P_DT]
        flags[F_STEPS] += 1


@ti.kernel
def prime_forces(
    ns: ti.template(),
    full: ti.template(),
    phys: ti.template(),
    pos: nd,
    angle: nd,
    vel: nd,
    omega: nd,
    force: nd,
    torque: nd,
    ref_pos: nd,
    ref_angle: nd,
    offsets: nd,
    disc_x: nd,
    disc_off: nd,
    nbr: nd,
    nbr_xi: nd,
    nbr_count: nd,
    old_nbr: nd,
    old_xi: nd,
    old_count: nd,
    cell_count: nd,
    cell_start: nd,
    cell_items: nd,
    disc_cell: nd,
    charge: nd,
    pair_table: nd,
    cell: nd,
    params: nd,
    flags: nd,
):
    """Place the discs, build the list (when needed) and compute the forces, without moving."""
    n_rods = pos.shape[0]
    n_discs = n_rods * ns
    ti.loop_config(serialize=True)
    for _ in range(1):
        for r in range(n_rods):
            place_rod_discs(ns, r, pos, angle, offsets, disc_x, disc_off, cell[C_LX], cell[C_LY])
        if needs_rebuild(cell, params, flags):
            flags[F_FORCE_REBUILD] = 0
            rebuild_lists(
                ns,
                full,
                pos,
                angle,
                ref_pos,
                ref_angle,
                offsets,
                disc_x,
                disc_off,
                nbr,
                nbr_xi,
                nbr_count,
                old_nbr,
                old_xi,
                old_count,
                cell_count,
                cell_start,
                cell_items,
                disc_cell,
                cell,
                params,
                flags,
            )
        if flags[F_STOP] == 0:
            for r in range(n_rods):
                force[r, 0] = 0.0
                force[r, 1] = 0.0
                torque[r] = 0.0
            for i in range(n_discs):
                disc_forces(
                    ns,
                    phys,
                    False,
                    False,
                    full,
                    i,
                    vel,
                    omega,
                    force,
                    torque,
                    disc_x,
                    disc_off,
                    offsets,
                    nbr,
                    nbr_xi,
                    nbr_count,
                    charge,
                    pair_table,
                    cell,
                    params,
                    flags,
                )


@ti.kernel
def measure_sums(
    ns: ti.template(),
    full: ti.template(),
    phys: ti.template(),
    vel: nd,
    omega: nd,
    force: nd,
    torque: nd,
    disc_x: nd,
    disc_off: nd,
    offsets: nd,
    nbr: nd,
    nbr_xi: nd,
    nbr_count: nd,
    charge: nd,
    pair_table: nd,
    cell: nd,
    params: nd,
    measures: nd,
    rod_contacts: nd,
    pair_out: nd,
    pair_flags: nd,
):
    """Serial sums for the measures (deterministic order); also per-entry pair data.

    pair_out (M,K,4): F_x, F_y, f_contact_normal, f_tangential of each list entry;
    pair_flags (M,K): bits PAIR_CONTACT, PAIR_LONG_RANGE, PAIR_SLIDING, PAIR_INTERACTING (layout).
    """
    n_rods = vel.shape[0]
    n_discs = n_rods * ns
    ti.loop_config(serialize=True)
    for _ in range(1):
        for q in range(measures.shape[0]):
            measures[q] = 0.0
        for r in range(n_rods):
            rod_contacts[r] = 0
        dt = params[P_DT]
        mass = params[P_MASS]
        inertia = params[P_INERTIA]
        for r in range(n_rods):
            # full-step velocities of velocity Verlet: v(t) = v(t − Δt/2) + Δt/2 F(t)/M
            vx = vel[r, 0] + 0.5 * dt * force[r, 0] / mass
            vy = vel[r, 1] + 0.5 * dt * force[r, 1] / mass
            w = omega[r] + 0.5 * dt * torque[r] / inertia
            measures[M_KE_TRANS] += 0.5 * mass * (vx * vx + vy * vy)
            measures[M_KE_ROT] += 0.5 * inertia * w * w
            measures[M_SUM_ROD_FORCE] += ti.sqrt(force[r, 0] ** 2 + force[r, 1] ** 2)
        for i in range(n_discs):
            rod_i = i // ns
            for k in range(nbr_count[i]):
                if ti.static(full):
                    if nbr[i, k] // IMAGE_CODES < i:
                        pair_flags[i, k] = 0
                        continue
                fx, fy, tau_i, tau_j, j, active, fc, ft, delta, uc, ul, la, bx, by = (
                    pair_interaction(
                        ns,
                        phys,
                        False,
                        i,
                        k,
                        vel,
                        omega,
                        disc_x,
                        disc_off,
                        offsets,
                        nbr,
                        nbr_xi,
                        charge,
                        pair_table,
                        cell,
                        params,
                    )
                )
                bits = 0
                if active == 1:
                    measures[M_SXX] += fx * bx
                    measures[M_SXY] += fx * by
                    measures[M_SYX] += fy * bx
                    measures[M_SYY] += fy * by
                    measures[M_U_CONTACT] += uc
                    measures[M_U_LONG] += ul
                    if delta > 0.0:
                        bits |= PAIR_CONTACT
                        measures[M_CONTACTS] += 1.0
                        rod_contacts[rod_i] += 1
                        rod_contacts[j // ns] += 1
                        if ti.static(phys.friction):
                            if ti.abs(ft) >= params[P_MU] * ti.abs(fc) * (1.0 - 1e-6):
                                bits |= PAIR_SLIDING
                                measures[M_SLIDING] += 1.0
                    if la == 1:
                        bits |= PAIR_LONG_RANGE
                        measures[M_LONG_PAIRS] += 1.0
                    if bits != 0:
                        bits |= PAIR_INTERACTING
                        measures[M_INTERACTING] += 1.0
                        measures[M_SUM_PAIR_FORCE] += ti.sqrt(fx * fx + fy * fy)
                pair_out[i, k, 0] = fx
                pair_out[i, k, 1] = fy
                pair_out[i, k, 2] = fc
                pair_out[i, k, 3] = ft
                pair_flags[i, k] = bits


@ti.kernel
def place_all_discs(
    ns: ti.template(), pos: nd, angle: nd, offsets: nd, disc_x: nd, disc_off: nd, cell: nd
):
    """Recompute the (derived) disc positions from the centroids, e.g. after a state restore."""
    for r in range(pos.shape[0]):
        place_rod_discs(ns, r, pos, angle, offsets, disc_x, disc_off, cell[C_LX], cell[C_LY])


@ti.kernel
def forces_gather(
    ns: ti.template(),
    phys: ti.template(),
    vel: nd,
    omega: nd,
    force: nd,
    torque: nd,
    disc_x: nd,
    disc_off: nd,
    offsets: nd,
    nbr: nd,
    nbr_xi: nd,
    nbr_count: nd,
    charge: nd,
    pair_table: nd,
    cell: nd,
    params: nd,
    flags: nd,
):
    """Deterministic parallel forces (full list): each rod gathers the pairs of its own discs.

    Every pair is evaluated twice (once from each side; the two tangential springs evolve as
    exact mirror images), no atomics: bitwise reproducible whatever the thread schedule.
    """
    for r in range(force.shape[0]):
        if flags[F_STOP] == 0:
            force[r, 0] = 0.0
            force[r, 1] = 0.0
            torque[r] = 0.0
            for s in range(ns):
                disc_forces(
                    ns,
                    phys,
                    False,
                    True,
                    True,
                    r * ns + s,
                    vel,
                    omega,
                    force,
                    torque,
                    disc_x,
                    disc_off,
                    offsets,
                    nbr,
                    nbr_xi,
                    nbr_count,
                    charge,
                    pair_table,
                    cell,
                    params,
                    flags,
                )
    if flags[F_STOP] == 0:
        cell[C_TIME] += params[P_DT]
        flags[F_STEPS] += 1
