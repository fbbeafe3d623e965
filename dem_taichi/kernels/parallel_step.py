"""One launch per step on the parallel and gather paths with the parallel list build (the
default on a GPU).

A step there was three kernel calls (:func:`~dem_taichi.kernels.parallel_lists.
rebuild_parallel`, :func:`~dem_taichi.kernels.parallel.kick_drift_parallel`, then
:func:`~dem_taichi.kernels.parallel.forces_parallel` or :func:`~dem_taichi.kernels.parallel.
forces_gather`), each paying Taichi's per-call cost on the host (its ~20–30 array arguments
checked and packed): up to ~24,000 rods that, not the work, set a GPU's rate
(benchmarks/results/gpu_bench.md). :func:`step_parallel` runs the same three bodies, as
functions whose loops stay top-level loops, in one call: the same loops in the same order, so
the same state (bit for bit on the deterministic gather path,
``tests/dem_taichi/test_parallel_lists.py``).
"""

import taichi as ti

from dem_taichi.kernels.common import nd1, nd2, nd3
from dem_taichi.kernels.parallel import gather_forces, kick_drift_all, scatter_forces
from dem_taichi.kernels.parallel_lists import build_step

__all__ = ["step_parallel"]


@ti.kernel
def step_parallel(
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
    bond_intact: nd1,
    cell: nd1,
    params: nd1,
    flags: nd1,
):
    """One step of the parallel path (``full``: the gather path): the list built when due and
    the cell advanced, kick and drift, forces."""
    build_step(
        ns, full, phys, True, pos, angle, ref_pos, ref_angle, offsets, disc_x, disc_off, nbr,
        nbr_xi, nbr_psi, nbr_count, old_nbr, old_xi, old_psi, old_count, cell_count, cell_start,
        cell_items, disc_cell, bond_intact, cell, params, flags,
    )  # fmt: skip
    kick_drift_all(
        ns, pos, angle, vel, omega, force, torque, ref_pos, ref_angle, offsets, disc_x,
        disc_off, cell, params, flags,
    )  # fmt: skip
    if ti.static(full):
        gather_forces(
            ns, phys, pos, angle, vel, omega, force, torque, disc_x, disc_off, offsets, nbr,
            nbr_xi, nbr_psi, nbr_count, charge, pair_table, bond_intact, cell, params, flags,
        )  # fmt: skip
    else:
        scatter_forces(
            ns, phys, pos, angle, vel, omega, force, torque, disc_x, disc_off, offsets, nbr,
            nbr_xi, nbr_psi, nbr_count, charge, pair_table, bond_intact, cell, params, flags, 1,
        )  # fmt: skip
