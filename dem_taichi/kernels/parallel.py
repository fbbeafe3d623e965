"""The per-step parallel kernels (``execution = "parallel"`` and ``"gather"``, for GPUs and very
large N): list rebuild and cell update, kick–drift parallel over bodies, pair (and bond) forces
parallel over discs with atomic scatter, or gathered per body from a full list (deterministic).
The serial fused kernel and the shared per-body step are in :mod:`.step`.
"""

import taichi as ti

from dem_taichi.kernels.bonds import add_bond_forces, gather_bond_forces
from dem_taichi.kernels.common import nd1, nd2, nd3
from dem_taichi.kernels.layout import C_DISP, C_TIME, C_VMAX, F_FORCE_REBUILD, F_STEPS, F_STOP, P_DT
from dem_taichi.kernels.neighbours import needs_rebuild, rebuild_lists
from dem_taichi.kernels.pairs import disc_forces
from dem_taichi.kernels.step import advance_cell, kick_drift_rod

__all__ = ["rebuild_if_needed", "kick_drift_parallel", "forces_parallel", "forces_gather"]


@ti.kernel
def rebuild_if_needed(
    ns: ti.template(),
    full: ti.template(),
    phys: ti.template(),
    pos: nd2,
    angle: nd1,
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
    bond_intact: nd1,
    cell: nd1,
    params: nd1,
    flags: nd1,
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
                cell[C_DISP] = 0.0
                cell[C_VMAX] = 0.0


@ti.kernel
def kick_drift_parallel(
    ns: ti.template(),
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
    cell: nd1,
    params: nd1,
    flags: nd1,
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
    pos: nd2,
    angle: nd1,
    vel: nd2,
    omega: nd1,
    force: nd2,
    torque: nd1,
    disc_x: nd2,
    disc_off: nd2,
    offsets: nd1,
    nbr: nd2,
    nbr_xi: nd2,
    nbr_psi: nd2,
    nbr_count: nd1,
    charge: nd1,
    pair_table: nd3,
    rod_strength: nd1,
    attraction_partners: nd2,
    bond_intact: nd1,
    cell: nd1,
    params: nd1,
    flags: nd1,
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
        for b in range(force.shape[0]):
            if flags[F_STOP] == 0:
                add_bond_forces(
                    phys.chain, True, b, pos, angle, vel, omega, force, torque, bond_intact,
                    cell, params, flags,
                )  # fmt: skip
    if count_step == 1 and flags[F_STOP] == 0:
        cell[C_TIME] += params[P_DT]
        flags[F_STEPS] += 1


@ti.kernel
def forces_gather(
    ns: ti.template(),
    phys: ti.template(),
    pos: nd2,
    angle: nd1,
    vel: nd2,
    omega: nd1,
    force: nd2,
    torque: nd1,
    disc_x: nd2,
    disc_off: nd2,
    offsets: nd1,
    nbr: nd2,
    nbr_xi: nd2,
    nbr_psi: nd2,
    nbr_count: nd1,
    charge: nd1,
    pair_table: nd3,
    rod_strength: nd1,
    attraction_partners: nd2,
    bond_intact: nd1,
    cell: nd1,
    params: nd1,
    flags: nd1,
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
                gather_bond_forces(
                    phys.chain, r, pos, angle, vel, omega, force, torque, bond_intact, cell,
                    params, flags,
                )  # fmt: skip
    if flags[F_STOP] == 0:
        cell[C_TIME] += params[P_DT]
        flags[F_STEPS] += 1
