"""FIRE energy minimisation of a fixed cell as one fused serial Taichi kernel (issue 20).

FIRE, the Fast Inertial Relaxation Engine (Bitzek et al., PRL 97, 170201, 2006), with the FIRE 2.0
refinements of Guénolé et al. (Comput. Mater. Sci. 175, 109584, 2020) that fit a DEM with
history-dependent contacts: the semi-implicit (symplectic) Euler integrator with the velocity
mixing between the kick and the drift, the delay N_delay before Δt grows, and the initial delay
(no Δt decrease during the first N_delay steps). The half step back on P ≤ 0 (x ← x − Δt v/2)
is left out: it would move the bodies without the relative motion that the tangential and
rolling springs integrate (ξ += v_t Δt in :mod:`.pairs`), so the springs would no longer follow
the contacts' displacement. Δt_min clamps the decrease (FIRE 2.0 skips a decrease that would
go below it): with Δt_min = Δt of the scene, a Δt grown too large comes back to the scene's
stable Δt at the first reset, and never below it.

The generalised velocity of the N bodies is (v, ω) with the kinetic-energy metric, so that the
power and the norms carry consistent units (M mass, I moment of inertia of a body):
  P = Σ (F·v + τ ω)                        (power of the forces and torques)
  |V|² = Σ (M |v|² + I ω²) = 2 KE,  |G|² = Σ (|F|²/M + τ²/I)
Per step (F, τ at the current positions; v, ω the velocities of the last drift):
  P > 0: N+ ← N+ + 1, N− ← 0; if N+ > N_delay: Δt ← min(f_inc Δt, Δt_max), α ← f_α α
  P ≤ 0: N+ ← 0, N− ← N− + 1; unless still within the first N_delay steps:
         Δt ← max(f_dec Δt, Δt_min), α ← α_start; v, ω ← 0 (the springs ξ, ψ are kept)
  v ← v + Δt F/M,  ω ← ω + Δt τ/I                      (kick, no local damping)
  v ← (1 − α) v + α (|V|/|G|) F/M,  ω ← (1 − α) ω + α (|V|/|G|) τ/I   (mixing)
  s ← s + Δt v/L,  θ ← θ + Δt ω                          (drift)
  F, τ ← pair (and bond) forces at the new positions, springs ξ += v_t Δt as in the damped step
The cell is held (the engine refuses a minimisation with non-zero strain rates). The running Δt
is ``fire[FIRE_DT]``; the kernel copies it into ``params[P_DT]`` while it runs (the springs, the
list-rebuild test and the time use it) and puts the scene's Δt (``fire[FIRE_DT0]``) back at its
end, so the host (measures, the next damped call) always sees the scene's Δt. The FIRE scalars
(Δt, α, N+, N−, the step count, the number of resets) live in the ``fire`` array
(:mod:`.layout`, ``FIRE_*``), so a run split into several kernel calls continues the same
minimisation.

Bodies: rigid rods, or the discs of bonded rods (each a body, joined by the bond forces): the
same loops over ``pos.shape[0]`` bodies serve both.
"""

import taichi as ti

from dem_taichi.kernels.bonds import add_bond_forces
from dem_taichi.kernels.common import T, nd1, nd2, nd3, place_rod_discs_cs, rod_axis
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
    FIRE_ALPHA,
    FIRE_ALPHA_START,
    FIRE_DT,
    FIRE_DT0,
    FIRE_DT_MAX,
    FIRE_DT_MIN,
    FIRE_F_ALPHA,
    FIRE_F_DEC,
    FIRE_F_INC,
    FIRE_N_DELAY,
    FIRE_N_NEG,
    FIRE_N_POS,
    FIRE_RESETS,
    FIRE_STEPS,
    P_DT,
    P_INERTIA,
    P_MASS,
    P_MAX_OFFSET,
)
from dem_taichi.kernels.neighbours import needs_rebuild, rebuild_lists
from dem_taichi.kernels.pairs import disc_forces

__all__ = ["run_steps_fire"]

#: counters saturate here (they are compared with N_delay only; exact in single precision)
_COUNT_CAP = 1.0e6


@ti.func
def fire_update(n_rods, vel: T, omega: T, force: T, torque: T, params: T, fire: T):
    """The FIRE bookkeeping of one step from the power P; sets Δt in ``params``, updates α and
    the counters in ``fire``; returns 1 when the velocities are to be reset (P ≤ 0)."""
    power = 0.0
    for r in range(n_rods):
        power += force[r, 0] * vel[r, 0] + force[r, 1] * vel[r, 1] + torque[r] * omega[r]
    dt = params[P_DT]
    alpha = fire[FIRE_ALPHA]
    reset = 0
    if power > 0.0:
        fire[FIRE_N_POS] = ti.min(fire[FIRE_N_POS] + 1.0, _COUNT_CAP)
        fire[FIRE_N_NEG] = 0.0
        if fire[FIRE_N_POS] > fire[FIRE_N_DELAY]:
            dt = ti.min(dt * fire[FIRE_F_INC], fire[FIRE_DT_MAX])
            alpha = alpha * fire[FIRE_F_ALPHA]
    else:
        fire[FIRE_N_POS] = 0.0
        fire[FIRE_N_NEG] = ti.min(fire[FIRE_N_NEG] + 1.0, _COUNT_CAP)
        if fire[FIRE_STEPS] >= fire[FIRE_N_DELAY]:  # FIRE 2.0's initial delay
            dt = ti.max(dt * fire[FIRE_F_DEC], fire[FIRE_DT_MIN])
            alpha = fire[FIRE_ALPHA_START]
        fire[FIRE_RESETS] = ti.min(fire[FIRE_RESETS] + 1.0, _COUNT_CAP)
        reset = 1
    fire[FIRE_STEPS] = ti.min(fire[FIRE_STEPS] + 1.0, _COUNT_CAP)
    fire[FIRE_ALPHA] = alpha
    params[P_DT] = dt
    return reset


@ti.func
def fire_kick(n_rods, reset, vel: T, omega: T, force: T, torque: T, params: T):
    """v ← (0 if reset else v) + Δt F/M, ω likewise; returns (|V|², |G|²) of the module doc."""
    dt = params[P_DT]
    mass = params[P_MASS]
    inertia = params[P_INERTIA]
    vv = 0.0
    gg = 0.0
    for r in range(n_rods):
        fx = force[r, 0]
        fy = force[r, 1]
        tz = torque[r]
        vx = 0.0
        vy = 0.0
        w = 0.0
        if reset == 0:
            vx = vel[r, 0]
            vy = vel[r, 1]
            w = omega[r]
        vx += dt * fx / mass
        vy += dt * fy / mass
        w += dt * tz / inertia
        vel[r, 0] = vx
        vel[r, 1] = vy
        omega[r] = w
        vv += mass * (vx * vx + vy * vy) + inertia * w * w
        gg += (fx * fx + fy * fy) / mass + tz * tz / inertia
    return vv, gg


@ti.func
def fire_mix_drift_rod(
    ns: T,
    r,
    mix,
    keep,
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
    """Mix body r's velocity (v ← keep v + mix F/M), drift, zero the force, place the discs;
    returns (disp, speed) for the list-rebuild test (as the damped step's kick–drift)."""
    dt = params[P_DT]
    mass = params[P_MASS]
    inertia = params[P_INERTIA]
    lx = cell[C_LX]
    ly = cell[C_LY]
    vx = keep * vel[r, 0] + mix * force[r, 0] / mass
    vy = keep * vel[r, 1] + mix * force[r, 1] / mass
    w = keep * omega[r] + mix * torque[r] / inertia
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
    disp = ti.sqrt(ddx * ddx + ddy * ddy) + max_offset * ti.abs(theta - ref_angle[r])
    speed = ti.sqrt(vx * vx + vy * vy) + max_offset * ti.abs(w)
    if not (ti.abs(disp) < 1e30 and ti.abs(speed) < 1e30):
        flags[F_BLOWUP] = BLOWUP_NONFINITE
        flags[F_BLOWUP_INDEX] = r
        flags[F_STOP] = 1
    return disp, speed


@ti.kernel
def run_steps_fire(
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
    fire: nd1,
):
    """``n_steps`` fused FIRE steps at fixed cell in one serial loop (deterministic)."""
    n_rods = pos.shape[0]
    n_discs = n_rods * ns
    params[P_DT] = fire[FIRE_DT]
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
                reset = fire_update(n_rods, vel, omega, force, torque, params, fire)
                vv, gg = fire_kick(n_rods, reset, vel, omega, force, torque, params)
                alpha = fire[FIRE_ALPHA]
                mix = 0.0
                if gg > 0.0:
                    mix = alpha * ti.sqrt(vv / gg)
                keep = 1.0 - alpha
                max_disp = 0.0
                max_speed = 0.0
                for r in range(n_rods):
                    disp, speed = fire_mix_drift_rod(
                        ns,
                        r,
                        mix,
                        keep,
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
    fire[FIRE_DT] = params[P_DT]
    params[P_DT] = fire[FIRE_DT0]
