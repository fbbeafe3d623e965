"""The time step as Taichi kernels: the kick–drift of one body, the fused serial multi-step kernel
and the force priming (the per-step parallel kernels in :mod:`.parallel`, neighbour lists in
:mod:`.neighbours`, pair forces in :mod:`.pairs`, bonds in :mod:`.bonds`, measures in
:mod:`.measures`).

Every array is an explicit ``ti.types.ndarray`` argument of its dimension (compiled once per
dtype and physics switches, whatever the sizes), every number that may change between calls is
in ``params``; the physics switches (friction, long range, van der Waals, bonded rods, rolling
resistance) are a frozen dataclass passed as ``ti.template()`` so that physics a scene switches
off is not compiled at all.

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
  nbr_psi (M,K)    rolling spring ψ of each entry (with rolling resistance; else (1,K), unused)
  old_* buffers    the previous list, read to carry ξ and ψ across rebuilds

Time integration (leapfrog kick–drift form of velocity Verlet, per step):
  [rebuild the list if 2(max displacement + v_max Δt) + reach·|ΔL/L_build| ≥ skin]
  v ← v + Δt (F − α|F| sign v)/M + Δt ε̇ ∘ v      (local damping; g-SLLOD term of the cell flow)
  ω ← ω + Δt (τ − α|τ| sign ω)/I
  L ← L exp(−ε̇ Δt);  s ← s + Δt v / L;  θ ← θ + Δt ω
  F, τ ← pair forces at the new positions (contact velocities at the half step)
"""

import taichi as ti

from dem_taichi.kernels.bonds import add_bond_forces
from dem_taichi.kernels.common import (
    T,
    nd1,
    nd2,
    nd3,
    place_all_discs,
    place_rod_discs,
    place_rod_discs_cs,
    rod_axis,
    sign,
)
from dem_taichi.kernels.layout import (
    BLOWUP_NONFINITE,
    C_DISP,
    C_LX,
    C_LY,
    C_TIME,
    C_VMAX,
    F_BLOWUP,
    F_BLOWUP_INDEX,
    F_FORCE_REBUILD,
    F_STEPS,
    F_STOP,
    P_ALPHA,
    P_DT,
    P_INERTIA,
    P_MASS,
    P_MAX_OFFSET,
    P_RATE_X,
    P_RATE_Y,
)
from dem_taichi.kernels.measures import measure_sums
from dem_taichi.kernels.neighbours import needs_rebuild, rebuild_lists
from dem_taichi.kernels.pairs import disc_forces

# measure_sums and place_all_discs live in their own modules; importable from here as before
__all__ = [
    "kick_drift_rod",
    "advance_cell",
    "run_steps_serial",
    "prime_forces",
    "measure_sums",
    "place_all_discs",
]


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
    c, s = rod_axis(ns, theta)
    place_rod_discs_cs(ns, r, pos, c, s, offsets, disc_x, disc_off, lx, ly)
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


@ti.kernel
def run_steps_serial(
    ns: ti.template(),
    phys: ti.template(),
    n_steps: ti.i32,
    pos: nd2,
    angle: nd1,
    vel: nd2,
    omega: nd1,
    force: nd2,
    torque: nd1,
    ref_pos: nd2,
    ref_angle: nd1,
    offsets: nd1,
    disc_x: nd2,
    disc_off: nd2,
    nbr: nd2,
    nbr_xi: nd2,
    nbr_psi: nd2,
    nbr_count: nd1,
    old_nbr: nd2,
    old_xi: nd2,
    old_psi: nd2,
    old_count: nd1,
    cell_count: nd2,
    cell_start: nd2,
    cell_items: nd1,
    disc_cell: nd1,
    charge: nd1,
    pair_table: nd3,
    rod_strength: nd1,
    attraction_partners: nd2,
    bond_intact: nd1,
    cell: nd1,
    params: nd1,
    flags: nd1,
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
                    phys,
                    pos,
                    angle,
                    ref_pos,
                    ref_angle,
                    offsets,
                    disc_x,
                    disc_off,
                    nbr,
                    nbr_xi,
                    nbr_psi,
                    nbr_count,
                    old_nbr,
                    old_xi,
                    old_psi,
                    old_count,
                    cell_count,
                    cell_start,
                    cell_items,
                    disc_cell,
                    bond_intact,
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
                        nbr_psi,
                        nbr_count,
                        charge,
                        pair_table,
                        rod_strength,
                        attraction_partners,
                        bond_intact,
                        cell,
                        params,
                        flags,
                    )
                if ti.static(phys.bonded):
                    for b in range(n_rods):
                        add_bond_forces(
                            phys.chain, False, b, pos, angle, vel, omega, force, torque,
                            bond_intact, cell, params, flags,
                        )  # fmt: skip
                cell[C_TIME] += params[P_DT]
                flags[F_STEPS] += 1


@ti.kernel
def prime_forces(
    ns: ti.template(),
    full: ti.template(),
    phys: ti.template(),
    pos: nd2,
    angle: nd1,
    vel: nd2,
    omega: nd1,
    force: nd2,
    torque: nd1,
    ref_pos: nd2,
    ref_angle: nd1,
    offsets: nd1,
    disc_x: nd2,
    disc_off: nd2,
    nbr: nd2,
    nbr_xi: nd2,
    nbr_psi: nd2,
    nbr_count: nd1,
    old_nbr: nd2,
    old_xi: nd2,
    old_psi: nd2,
    old_count: nd1,
    cell_count: nd2,
    cell_start: nd2,
    cell_items: nd1,
    disc_cell: nd1,
    charge: nd1,
    pair_table: nd3,
    rod_strength: nd1,
    attraction_partners: nd2,
    bond_intact: nd1,
    cell: nd1,
    params: nd1,
    flags: nd1,
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
                phys,
                pos,
                angle,
                ref_pos,
                ref_angle,
                offsets,
                disc_x,
                disc_off,
                nbr,
                nbr_xi,
                nbr_psi,
                nbr_count,
                old_nbr,
                old_xi,
                old_psi,
                old_count,
                cell_count,
                cell_start,
                cell_items,
                disc_cell,
                bond_intact,
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
                    nbr_psi,
                    nbr_count,
                    charge,
                    pair_table,
                    rod_strength,
                    attraction_partners,
                    bond_intact,
                    cell,
                    params,
                    flags,
                )
            if ti.static(phys.bonded):
                for b in range(n_rods):
                    add_bond_forces(
                        phys.chain, False, b, pos, angle, vel, omega, force, torque,
                        bond_intact, cell, params, flags,
                    )  # fmt: skip
