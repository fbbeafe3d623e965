"""The measure kernels: sums of stress, energies, counts and forces, and the force and
``layout.PAIR_*`` bits of every list entry for the host.

``measure_sums`` (the serial path) sums on one thread in a fixed order, into the one row its
``block_sums`` has. ``measure_sums_blocked`` (the parallel and gather paths) gives each thread a
block of ``MEASURE_BLOCK`` rods, discs or bonds, summed in order into its row of
``block_sums``, then adds the rows in a fixed order (:func:`add_rows_in_levels`): deterministic
too, and the same sums to round-off (another order of additions), without the one-thread pass
over every pair that a GPU runs far slower than a CPU core (benchmarks/results/gpu_bench.md).
Both add with the same per-rod, per-entry and per-bond functions (:func:`add_rod`,
:func:`add_disc_entries`, :func:`add_bond`).
"""

import taichi as ti

from dem_taichi.kernels.bonds import bond_interaction
from dem_taichi.kernels.common import T, nd1, nd2, nd3
from dem_taichi.kernels.layout import (
    IMAGE_CODES,
    M_BROKEN,
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
    M_U_BOND,
    M_U_CONTACT,
    M_U_LONG,
    MEASURE_BLOCK,
    P_DT,
    P_INERTIA,
    P_MASS,
    P_MU,
    PAIR_CONTACT,
    PAIR_INTERACTING,
    PAIR_LONG_RANGE,
    PAIR_SLIDING,
)
from dem_taichi.kernels.pairs import pair_interaction


@ti.func
def rod_sums(r, vel: T, omega: T, force: T, torque: T, params: T):
    """Rod ``r``'s kinetic energies (full-step velocities of velocity Verlet: v(t) = v(t − Δt/2)
    + Δt/2 F(t)/M) and the magnitude of its resultant force."""
    dt = params[P_DT]
    mass = params[P_MASS]
    inertia = params[P_INERTIA]
    vx = vel[r, 0] + 0.5 * dt * force[r, 0] / mass
    vy = vel[r, 1] + 0.5 * dt * force[r, 1] / mass
    w = omega[r] + 0.5 * dt * torque[r] / inertia
    ke = 0.5 * mass * (vx * vx + vy * vy)
    ke_rot = 0.5 * inertia * w * w
    return ke, ke_rot, ti.sqrt(force[r, 0] ** 2 + force[r, 1] ** 2)


@ti.func
def pair_bits(phys: T, active, delta, fc, ft, la, params: T):
    """The ``PAIR_*`` bits of a list entry from its interaction."""
    bits = 0
    if active == 1:
        if delta > 0.0:
            bits |= PAIR_CONTACT
            if ti.static(phys.friction):
                if ti.abs(ft) >= params[P_MU] * ti.abs(fc) * (1.0 - 1e-6):
                    bits |= PAIR_SLIDING
        if la == 1:
            bits |= PAIR_LONG_RANGE
        if bits != 0:
            bits |= PAIR_INTERACTING
    return bits


@ti.func
def add_rod(r, vel: T, omega: T, force: T, torque: T, params: T, sums: T, row):
    """Rod ``r``'s kinetic energies and resultant force into ``sums[row]``."""
    ke, ke_rot, f_rod = rod_sums(r, vel, omega, force, torque, params)
    sums[row, M_KE_TRANS] += ke
    sums[row, M_KE_ROT] += ke_rot
    sums[row, M_SUM_ROD_FORCE] += f_rod


@ti.func
def add_disc_entries(
    ns: T, full: T, phys: T, i, vel: T, omega: T, disc_x: T, disc_off: T, offsets: T, nbr: T,
    nbr_xi: T, nbr_psi: T, nbr_count: T, charge: T, pair_table: T, rod_strength: T,
    attraction_partners: T, bond_intact: T, cell: T, params: T, rod_contacts: T, pair_out: T,
    pair_flags: T, sums: T, row,
):  # fmt: skip
    """Disc ``i``'s list entries in order: stress, energies and counts into ``sums[row]``, the
    contacts into ``rod_contacts`` (both rods), each entry's forces and bits into ``pair_out``
    and ``pair_flags`` (a full list: the entries with j < i, listed twice, flagged 0 and
    skipped)."""
    rod_i = i // ns
    for k in range(nbr_count[i]):
        listed = True
        if ti.static(full):
            if nbr[i, k] // IMAGE_CODES < i:
                pair_flags[i, k] = 0
                listed = False
        if listed:
            fx, fy, tau_i, tau_j, j, active, fc, ft, delta, uc, ul, la, bx, by = pair_interaction(
                ns, phys, False, i, k, vel, omega, disc_x, disc_off, offsets, nbr, nbr_xi,
                nbr_psi, charge, pair_table, rod_strength, attraction_partners, bond_intact, cell,
                params,
            )  # fmt: skip
            bits = pair_bits(phys, active, delta, fc, ft, la, params)
            if active == 1:
                sums[row, M_SXX] += fx * bx
                sums[row, M_SXY] += fx * by
                sums[row, M_SYX] += fy * bx
                sums[row, M_SYY] += fy * by
                sums[row, M_U_CONTACT] += uc
                sums[row, M_U_LONG] += ul
                if bits & PAIR_CONTACT:
                    sums[row, M_CONTACTS] += 1.0
                    ti.atomic_add(rod_contacts[rod_i], 1)
                    ti.atomic_add(rod_contacts[j // ns], 1)
                if bits & PAIR_SLIDING:
                    sums[row, M_SLIDING] += 1.0
                if bits & PAIR_LONG_RANGE:
                    sums[row, M_LONG_PAIRS] += 1.0
                if bits != 0:
                    sums[row, M_INTERACTING] += 1.0
                    sums[row, M_SUM_PAIR_FORCE] += ti.sqrt(fx * fx + fy * fy)
            pair_out[i, k, 0] = fx
            pair_out[i, k, 1] = fy
            pair_out[i, k, 2] = fc
            pair_out[i, k, 3] = ft
            pair_flags[i, k] = bits


@ti.func
def add_bond(chain: T, g, pos: T, angle: T, vel: T, omega: T, bond_intact: T, cell: T,
             params: T, sums: T, row):  # fmt: skip
    """The bond of body ``g`` to ``g + 1`` (none for a rod's last disc): its stress, energy and
    force into ``sums[row]``, or a broken bond counted."""
    if g % chain != chain - 1:
        if bond_intact[g] == 1:
            fx, fy, tau_h, tau_g, dx, dy, energy, e_n = bond_interaction(
                g, pos, angle, vel, omega, cell, params
            )
            sums[row, M_SXX] += fx * dx
            sums[row, M_SXY] += fx * dy
            sums[row, M_SYX] += fy * dx
            sums[row, M_SYY] += fy * dy
            sums[row, M_U_BOND] += energy
            sums[row, M_SUM_PAIR_FORCE] += ti.sqrt(fx * fx + fy * fy)
        else:
            sums[row, M_BROKEN] += 1.0


@ti.kernel
def measure_sums(
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
    measures: nd1,
    rod_contacts: nd1,
    pair_out: nd3,
    pair_flags: nd2,
    block_sums: nd2,
):
    """Serial sums for the measures (deterministic order), in the one row of ``block_sums``;
    also per-entry pair data.

    pair_out (M,K,4): F_x, F_y, f_contact_normal, f_tangential of each list entry;
    pair_flags (M,K): bits PAIR_CONTACT, PAIR_LONG_RANGE, PAIR_SLIDING, PAIR_INTERACTING (layout).
    Bonded rods: the bonds add to the stress (f ⊗ d), their energy and the count of broken bonds
    to the measures.
    """
    n_rods = vel.shape[0]
    n_discs = n_rods * ns
    ti.loop_config(serialize=True)
    for _ in range(1):
        for q in range(measures.shape[0]):
            block_sums[0, q] = 0.0
        for r in range(n_rods):
            rod_contacts[r] = 0
        for r in range(n_rods):
            add_rod(r, vel, omega, force, torque, params, block_sums, 0)
        for i in range(n_discs):
            add_disc_entries(
                ns, full, phys, i, vel, omega, disc_x, disc_off, offsets, nbr, nbr_xi, nbr_psi,
                nbr_count, charge, pair_table, rod_strength, attraction_partners, bond_intact, cell,
                params, rod_contacts, pair_out, pair_flags, block_sums, 0,
            )  # fmt: skip
        if ti.static(phys.bonded):
            for g in range(n_rods):
                add_bond(phys.chain, g, pos, angle, vel, omega, bond_intact, cell, params,
                         block_sums, 0)  # fmt: skip
        for q in range(measures.shape[0]):
            measures[q] = block_sums[0, q]


@ti.kernel
def measure_sums_blocked(
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
    measures: nd1,
    rod_contacts: nd1,
    pair_out: nd3,
    pair_flags: nd2,
    block_sums: nd2,
):
    """The sums and per-entry data of :func:`measure_sums`, in parallel: each thread sums a block
    of ``MEASURE_BLOCK`` rods, discs or bonds in order into its row of ``block_sums`` (rows: the
    rod blocks, then the disc blocks, then the bond blocks), then the rows are added in a fixed
    order (:func:`add_rows_in_levels`). Deterministic; equal to the serial sums to round-off."""
    n_rods = vel.shape[0]
    n_discs = n_rods * ns
    rod_blocks = (n_rods + MEASURE_BLOCK - 1) // MEASURE_BLOCK
    disc_blocks = (n_discs + MEASURE_BLOCK - 1) // MEASURE_BLOCK
    for b, q in ti.ndrange(block_sums.shape[0], block_sums.shape[1]):
        block_sums[b, q] = 0.0
    for r in range(n_rods):
        rod_contacts[r] = 0
    for b in range(rod_blocks):
        for r in range(b * MEASURE_BLOCK, ti.min((b + 1) * MEASURE_BLOCK, n_rods)):
            add_rod(r, vel, omega, force, torque, params, block_sums, b)
    for d in range(disc_blocks):
        for i in range(d * MEASURE_BLOCK, ti.min((d + 1) * MEASURE_BLOCK, n_discs)):
            add_disc_entries(
                ns, full, phys, i, vel, omega, disc_x, disc_off, offsets, nbr, nbr_xi, nbr_psi,
                nbr_count, charge, pair_table, rod_strength, attraction_partners, bond_intact, cell,
                params, rod_contacts, pair_out, pair_flags, block_sums, rod_blocks + d,
            )  # fmt: skip
    if ti.static(phys.bonded):
        for b in range(rod_blocks):
            for g in range(b * MEASURE_BLOCK, ti.min((b + 1) * MEASURE_BLOCK, n_rods)):
                add_bond(phys.chain, g, pos, angle, vel, omega, bond_intact, cell, params,
                         block_sums, rod_blocks + disc_blocks + b)  # fmt: skip
    add_rows_in_levels(block_sums, measures)


@ti.func
def add_rows_in_levels(block_sums: T, measures: T):
    """``measures[q]`` = Σ_b ``block_sums[b, q]`` in a fixed order: in three levels, each thread
    adding 64 rows at a stride of 1, 64 and 4,096 rows in order into the first of them, then one
    thread the rows left (every 262,144th: one up to 1.7 × 10⁷ rods and discs). One thread over
    every row took 34 ms at 492,480 rods on an H200 (benchmarks/results/gpu_bench.md)."""
    rows = block_sums.shape[0]
    for level in ti.static(range(3)):
        stride = ti.static(MEASURE_BLOCK**level)
        span = ti.static(stride * MEASURE_BLOCK)
        for g, q in ti.ndrange((rows + span - 1) // span, block_sums.shape[1]):
            first = g * span
            total = block_sums[first, q]
            for m in range(1, MEASURE_BLOCK):
                b = first + m * stride
                if b < rows:
                    total += block_sums[b, q]
            block_sums[first, q] = total
    ti.loop_config(serialize=True)
    for q in range(measures.shape[0]):
        total = 0.0
        top = ti.static(MEASURE_BLOCK**3)
        for g in range((rows + top - 1) // top):
            total += block_sums[g * top, q]
        measures[q] = total
