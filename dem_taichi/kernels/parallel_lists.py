"""The neighbour-list build with parallel loops (``execution = "parallel"`` or ``"gather"`` with
``list_build = "parallel"``, the default on a GPU).

The serial build (:func:`dem_taichi.kernels.neighbours.rebuild_lists`) runs on one thread: on a
GPU that one thread is far slower than a CPU core, and at 10⁵ rods the build costs more than
all the steps between two builds. This kernel builds the *same* list, entry for entry and in
the same order, from the same per-disc functions, as a sequence of parallel loops (Taichi runs
the top-level loops of a kernel one after the other, each over all threads):

1. decide (one thread): is a build due (:func:`~dem_taichi.kernels.neighbours.needs_rebuild`)?
2. move the old list to the ``old_*`` buffers (per disc) and wrap the rods (per rod), once
   per build, as the serial build does;
3. bin the discs into cells (per disc, atomic counts); the cells' starts by rows (one thread
   per row) and the rows' offsets (one thread over the rows); fill the cells (per disc, atomic
   cursors) and sort each cell's discs by index (per cell), which restores the serial build's
   order whatever the threads' schedule;
4. each disc's row of the list (per disc, :func:`~dem_taichi.kernels.neighbours.
   list_disc_neighbours`), the overflow flagged;
5. finish (one thread) and the rods' reference positions (per rod); then the cell advances, as
   in :func:`dem_taichi.kernels.parallel.rebuild_if_needed`.

Every loop reads the decision from ``flags`` and does nothing when no build is due, so a step
without a build costs the launches of a dozen empty loops (cheap on a GPU, about 80 µs each on
a CPU's threads: the reason the CPU keeps the serial build, :mod:`dem_taichi.engine.simulation`).
"""

import taichi as ti

from dem_taichi.kernels.bonds import add_bond_forces, gather_bond_forces
from dem_taichi.kernels.common import nd1, nd2, nd3
from dem_taichi.kernels.layout import (
    C_DISP,
    C_LX,
    C_LY,
    C_VMAX,
    F_BUILD_NOW,
    F_BUILD_OVERFLOW,
    F_BUILD_SAVE,
    F_FORCE_REBUILD,
    F_NEEDED,
    F_OLD_SAVED,
    F_OVERFLOW,
    F_STOP,
)
from dem_taichi.kernels.neighbours import (
    disc_cell_of,
    finish_rebuild,
    keep_reference,
    list_cells,
    list_disc_neighbours,
    needs_rebuild,
    save_old_list,
    wrap_rod,
)
from dem_taichi.kernels.pairs import disc_forces
from dem_taichi.kernels.step import advance_cell

__all__ = ["rebuild_parallel", "prime_forces_parallel"]


@ti.kernel
def rebuild_parallel(
    ns: ti.template(),
    full: ti.template(),
    phys: ti.template(),
    advance: ti.template(),
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
    """Parallel path, part 1 (parallel loops): list build when needed, then (``advance``)
    advance the cell. With ``advance`` the same outcome as
    :func:`dem_taichi.kernels.parallel.rebuild_if_needed`; without, the build of
    :func:`~dem_taichi.kernels.step.prime_forces` (see :func:`prime_forces_parallel`)."""
    n_rods = pos.shape[0]
    n_discs = disc_x.shape[0]
    ti.loop_config(serialize=True)
    for _ in range(1):
        now = 0
        if flags[F_STOP] == 0:
            if needs_rebuild(cell, params, flags):
                flags[F_FORCE_REBUILD] = 0
                now = 1
        flags[F_BUILD_NOW] = now
        flags[F_BUILD_SAVE] = 0
        flags[F_BUILD_OVERFLOW] = 0
        if now == 1:
            if flags[F_OLD_SAVED] == 0:
                flags[F_BUILD_SAVE] = 1
            flags[F_OLD_SAVED] = 1
    for i in range(n_discs):
        if flags[F_BUILD_SAVE] == 1:
            save_old_list(phys, i, nbr, nbr_xi, nbr_psi, nbr_count, old_nbr, old_xi, old_psi,
                          old_count)  # fmt: skip
    for r in range(n_rods):
        if flags[F_BUILD_SAVE] == 1:
            wrap_rod(ns, r, pos, angle, offsets, disc_x, disc_off, cell[C_LX], cell[C_LY])
    for cx, cy in ti.ndrange(cell_count.shape[0], cell_count.shape[1]):
        if flags[F_BUILD_NOW] == 1:
            cell_count[cx, cy] = 0
    for g in range(n_discs):
        if flags[F_BUILD_NOW] == 1:
            nx, ny = list_cells(cell, params, cell_count)
            cx, cy = disc_cell_of(g, disc_x, cell[C_LX], cell[C_LY], nx, ny)
            disc_cell[g] = cx * ny + cy
            ti.atomic_add(cell_count[cx, cy], 1)
    for cx in range(cell_count.shape[0]):  # the starts within each row
        if flags[F_BUILD_NOW] == 1:
            nx, ny = list_cells(cell, params, cell_count)
            if cx < nx:
                running = 0
                for cy in range(ny):
                    cell_start[cx, cy] = running
                    running += cell_count[cx, cy]
    ti.loop_config(serialize=True)
    for _ in range(1):  # each row's offset, kept in its last cell's count (reset below)
        if flags[F_BUILD_NOW] == 1:
            nx, ny = list_cells(cell, params, cell_count)
            running = 0
            for cx in range(nx):
                total = cell_start[cx, ny - 1] + cell_count[cx, ny - 1]
                cell_count[cx, ny - 1] = running
                running += total
    for cx in range(cell_count.shape[0]):
        if flags[F_BUILD_NOW] == 1:
            nx, ny = list_cells(cell, params, cell_count)
            if cx < nx:
                offset = cell_count[cx, ny - 1]
                for cy in range(ny):
                    cell_start[cx, cy] += offset
                    cell_count[cx, cy] = 0
    for g in range(n_discs):
        if flags[F_BUILD_NOW] == 1:
            nx, ny = list_cells(cell, params, cell_count)
            cx = disc_cell[g] // ny
            cy = disc_cell[g] % ny
            slot = ti.atomic_add(cell_count[cx, cy], 1)
            cell_items[cell_start[cx, cy] + slot] = g
    for cx, cy in ti.ndrange(cell_count.shape[0], cell_count.shape[1]):
        if flags[F_BUILD_NOW] == 1:
            nx, ny = list_cells(cell, params, cell_count)
            if cx < nx and cy < ny:  # insertion sort: a cell holds a few discs
                start = cell_start[cx, cy]
                for a in range(1, cell_count[cx, cy]):
                    item = cell_items[start + a]
                    b = a - 1
                    while b >= 0:  # (Taichi's `and` does not short-circuit)
                        if cell_items[start + b] > item:
                            cell_items[start + b + 1] = cell_items[start + b]
                            b -= 1
                        else:
                            break
                    cell_items[start + b + 1] = item
    for i in range(n_discs):
        if flags[F_BUILD_NOW] == 1:
            nx, ny = list_cells(cell, params, cell_count)
            count = list_disc_neighbours(
                ns, full, phys, i, nx, ny, disc_x, nbr, nbr_xi, nbr_psi, nbr_count, old_nbr,
                old_xi, old_psi, old_count, cell_count, cell_start, cell_items, disc_cell,
                bond_intact, cell, params,
            )  # fmt: skip
            ti.atomic_max(flags[F_NEEDED], count)
            if count > nbr.shape[1]:
                flags[F_BUILD_OVERFLOW] = 1
    ti.loop_config(serialize=True)
    for _ in range(1):
        if flags[F_BUILD_NOW] == 1:
            if flags[F_BUILD_OVERFLOW] == 1:
                flags[F_OVERFLOW] = 1
                flags[F_STOP] = 1
            else:
                finish_rebuild(cell, flags)
    for r in range(n_rods):
        if flags[F_BUILD_NOW] == 1 and flags[F_BUILD_OVERFLOW] == 0:
            keep_reference(r, pos, angle, ref_pos, ref_angle)
    ti.loop_config(serialize=True)
    for _ in range(1):
        if ti.static(advance):
            if flags[F_STOP] == 0:
                advance_cell(cell, params)
                cell[C_DISP] = 0.0
                cell[C_VMAX] = 0.0
        flags[F_BUILD_NOW] = 0
        flags[F_BUILD_SAVE] = 0
        flags[F_BUILD_OVERFLOW] = 0


@ti.kernel
def prime_forces_parallel(
    ns: ti.template(),
    full: ti.template(),
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
    """The forces of :func:`dem_taichi.kernels.step.prime_forces` (after
    :func:`~dem_taichi.kernels.common.place_all_discs` and :func:`rebuild_parallel` without
    ``advance``), in parallel loops, without moving: with the full list (``full``) each rod
    gathers its discs' pairs then its bonds, in the serial kernel's order (the same forces bit
    for bit); with the half list, atomic scatter."""
    for r in range(force.shape[0]):
        if flags[F_STOP] == 0:
            force[r, 0] = 0.0
            force[r, 1] = 0.0
            torque[r] = 0.0
            if ti.static(full):
                for s in range(ns):
                    disc_forces(
                        ns, phys, False, False, True, r * ns + s, vel, omega, force, torque,
                        disc_x, disc_off, offsets, nbr, nbr_xi, nbr_psi, nbr_count, charge,
                        pair_table, rod_strength, attraction_partners, bond_intact, cell, params,
                        flags,
                    )  # fmt: skip
                if ti.static(phys.bonded):
                    gather_bond_forces(
                        phys.chain, r, pos, angle, vel, omega, force, torque, bond_intact, cell,
                        params, flags,
                    )  # fmt: skip
    if ti.static(not full):
        for i in range(disc_x.shape[0]):
            if flags[F_STOP] == 0:
                disc_forces(
                    ns, phys, True, False, False, i, vel, omega, force, torque, disc_x,
                    disc_off, offsets, nbr, nbr_xi, nbr_psi, nbr_count, charge, pair_table,
                    rod_strength, attraction_partners, bond_intact, cell, params, flags,
                )  # fmt: skip
        if ti.static(phys.bonded):
            for b in range(force.shape[0]):
                if flags[F_STOP] == 0:
                    add_bond_forces(
                        phys.chain, True, b, pos, angle, vel, omega, force, torque, bond_intact,
                        cell, params, flags,
                    )  # fmt: skip
