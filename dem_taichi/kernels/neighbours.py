"""The half (or full) Verlet neighbour list from cell lists across periodic images, and the
rebuild criterion: ``rebuild_lists`` is serial code (called from inside a serial loop), built
from per-disc functions that :mod:`dem_taichi.kernels.parallel_lists` runs in parallel loops.

Entries pack disc j with its periodic image (``layout.IMAGE_*``); the tangential springs ξ (and
the rolling springs ψ) of the previous list are carried to the pairs that remain.
"""

import taichi as ti

from dem_taichi.kernels.bonds import is_bonded_pair
from dem_taichi.kernels.common import T, place_rod_discs
from dem_taichi.kernels.layout import (
    C_DISP,
    C_LBX,
    C_LBY,
    C_LX,
    C_LY,
    C_VMAX,
    F_FORCE_REBUILD,
    F_NEEDED,
    F_OLD_SAVED,
    F_OVERFLOW,
    F_REBUILDS,
    F_STOP,
    IMAGE_CODES,
    IMAGE_RANGE,
    IMAGE_SIDE,
    P_DT,
    P_REACH,
    P_RLIST,
    P_SKIN,
)


@ti.func
def rebuild_lists(
    ns: T,
    full: T,
    phys: T,
    pos: T,
    angle: T,
    ref_pos: T,
    ref_angle: T,
    offsets: T,
    disc_x: T,
    disc_off: T,
    nbr: T,
    nbr_xi: T,
    nbr_psi: T,
    nbr_count: T,
    old_nbr: T,
    old_xi: T,
    old_psi: T,
    old_count: T,
    cell_count: T,
    cell_start: T,
    cell_items: T,
    disc_cell: T,
    bond_intact: T,
    cell: T,
    params: T,
    flags: T,
):
    """Cell-list build of the half Verlet list; carries ξ (and, with ``phys.rolling``, the
    rolling spring ψ) of surviving pairs; flags overflow. Bonded rods (``phys.bonded``): the two
    discs of an intact bond are not listed (they never interact; a bond that breaks forces the
    next build, :func:`dem_taichi.kernels.bonds.holding_bond`): one entry fewer per disc, the
    forces bit for bit the same.

    The old list is moved to the ``old_*`` buffers once (``F_OLD_SAVED``) so that a build that
    overflowed can be repeated after the host grew the capacity, without losing any ξ.

    Serial code; :mod:`dem_taichi.kernels.parallel_lists` builds the same list (the same
    entries in the same order) with parallel loops, from the same per-disc functions below.
    """
    n_rods = pos.shape[0]
    n_discs = n_rods * ns
    lx = cell[C_LX]
    ly = cell[C_LY]
    if flags[F_OLD_SAVED] == 0:
        for i in range(n_discs):
            save_old_list(phys, i, nbr, nbr_xi, nbr_psi, nbr_count, old_nbr, old_xi, old_psi,
                          old_count)  # fmt: skip
        for r in range(n_rods):
            wrap_rod(ns, r, pos, angle, offsets, disc_x, disc_off, lx, ly)
        flags[F_OLD_SAVED] = 1
    nx, ny = list_cells(cell, params, cell_count)
    for cx in range(nx):
        for cy in range(ny):
            cell_count[cx, cy] = 0
    for g in range(n_discs):
        cx, cy = disc_cell_of(g, disc_x, lx, ly, nx, ny)
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
    for i in range(n_discs):
        count = list_disc_neighbours(
            ns, full, phys, i, nx, ny, disc_x, nbr, nbr_xi, nbr_psi, nbr_count, old_nbr, old_xi,
            old_psi, old_count, cell_count, cell_start, cell_items, disc_cell, bond_intact, cell,
            params,
        )  # fmt: skip
        if count > nbr.shape[1]:
            overflow = 1
        needed = ti.max(needed, count)
    flags[F_NEEDED] = ti.max(flags[F_NEEDED], needed)
    if overflow == 1:
        flags[F_OVERFLOW] = 1
        flags[F_STOP] = 1
    else:
        finish_rebuild(cell, flags)
        for r in range(n_rods):
            keep_reference(r, pos, angle, ref_pos, ref_angle)


@ti.func
def save_old_list(
    phys: T, i, nbr: T, nbr_xi: T, nbr_psi: T, nbr_count: T, old_nbr: T, old_xi: T, old_psi: T,
    old_count: T,
):  # fmt: skip
    """Move disc ``i``'s list (entries, ξ, ψ) to the ``old_*`` buffers."""
    c = nbr_count[i]
    old_count[i] = c
    for k in range(c):
        old_nbr[i, k] = nbr[i, k]
        old_xi[i, k] = nbr_xi[i, k]
        if ti.static(phys.rolling):
            old_psi[i, k] = nbr_psi[i, k]


@ti.func
def wrap_rod(ns: T, r, pos: T, angle: T, offsets: T, disc_x: T, disc_off: T, lx, ly):
    """Bring rod ``r``'s reduced position into [0, 1) and place its discs."""
    pos[r, 0] -= ti.floor(pos[r, 0])
    pos[r, 1] -= ti.floor(pos[r, 1])
    place_rod_discs(ns, r, pos, angle, offsets, disc_x, disc_off, lx, ly)


@ti.func
def list_cells(cell: T, params: T, cell_count: T):
    """The cell grid of the list build: nx × ny cells of side ≥ the list radius (at most the
    allocated ``cell_count``)."""
    r_list = params[P_RLIST]
    nx = ti.max(1, ti.min(ti.cast(cell[C_LX] / r_list, ti.i32), cell_count.shape[0]))
    ny = ti.max(1, ti.min(ti.cast(cell[C_LY] / r_list, ti.i32), cell_count.shape[1]))
    return nx, ny


@ti.func
def disc_cell_of(g, disc_x: T, lx, ly, nx, ny):
    """The cell (cx, cy) of disc ``g``'s wrapped position."""
    xw = disc_x[g, 0] - ti.floor(disc_x[g, 0] / lx) * lx
    yw = disc_x[g, 1] - ti.floor(disc_x[g, 1] / ly) * ly
    cx = ti.min(ti.max(ti.cast(xw / lx * nx, ti.i32), 0), nx - 1)
    cy = ti.min(ti.max(ti.cast(yw / ly * ny, ti.i32), 0), ny - 1)
    return cx, cy


@ti.func
def list_disc_neighbours(
    ns: T,
    full: T,
    phys: T,
    i,
    nx,
    ny,
    disc_x: T,
    nbr: T,
    nbr_xi: T,
    nbr_psi: T,
    nbr_count: T,
    old_nbr: T,
    old_xi: T,
    old_psi: T,
    old_count: T,
    cell_count: T,
    cell_start: T,
    cell_items: T,
    disc_cell: T,
    bond_intact: T,
    cell: T,
    params: T,
):
    """Disc ``i``'s row of the list from the cells around it (each cell's discs in increasing
    index), with the springs of the pairs it had; returns the number of neighbours found (more
    than the capacity: the row is cut and the build must be repeated)."""
    capacity = nbr.shape[1]
    lx = cell[C_LX]
    ly = cell[C_LY]
    r_list = params[P_RLIST]
    r_list2 = r_list * r_list
    # with fewer than 3 cells along an axis, visit each distinct neighbour cell once
    n_off_x = ti.min(nx, 3)
    n_off_y = ti.min(ny, 3)
    shift_x = 1 if nx >= 3 else 0
    shift_y = 1 if ny >= 3 else 0
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
                if ti.static(phys.bonded):
                    # an intact bond's two discs never interact (pairs.pair_interaction):
                    # not listed; a bond that breaks forces a rebuild (bonds.holding_bond)
                    if accept and is_bonded_pair(phys.chain, i, j, bond_intact) == 1:
                        accept = False
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
                            psi_old = 0.0
                            for k in range(old_count[i]):
                                if old_nbr[i, k] // IMAGE_CODES == j:
                                    xi_old = old_xi[i, k]
                                    if ti.static(phys.rolling):
                                        psi_old = old_psi[i, k]
                            nbr_xi[i, count] = xi_old
                            if ti.static(phys.rolling):
                                nbr_psi[i, count] = psi_old
                        count += 1
    nbr_count[i] = ti.min(count, capacity)
    return count


@ti.func
def finish_rebuild(cell: T, flags: T):
    """A build that did not overflow: the old list is spent, the build counted, and the cell's
    lengths and the displacement bound reset to the build's."""
    flags[F_OLD_SAVED] = 0
    flags[F_REBUILDS] += 1
    cell[C_LBX] = cell[C_LX]
    cell[C_LBY] = cell[C_LY]
    cell[C_DISP] = 0.0


@ti.func
def keep_reference(r, pos: T, angle: T, ref_pos: T, ref_angle: T):
    """Rod ``r``'s position and angle at the build (the rebuild criterion's reference)."""
    ref_pos[r, 0] = pos[r, 0]
    ref_pos[r, 1] = pos[r, 1]
    ref_angle[r] = angle[r]


@ti.func
def needs_rebuild(cell: T, params: T, flags: T):
    dt = params[P_DT]
    strain = ti.max(ti.abs(cell[C_LX] / cell[C_LBX] - 1.0), ti.abs(cell[C_LY] / cell[C_LBY] - 1.0))
    moved = 2.0 * (cell[C_DISP] + 2.0 * cell[C_VMAX] * dt) + params[P_REACH] * strain
    return flags[F_OLD_SAVED] == 1 or flags[F_FORCE_REBUILD] == 1 or moved >= params[P_SKIN]
