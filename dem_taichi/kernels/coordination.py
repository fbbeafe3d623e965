"""The mechanical coordination Z_m on the device (the parallel and gather paths).

Z_m = 2 × contacts / rods after removing, repeatedly, the rods with fewer than two contacts
(the rattlers): :func:`dem_taichi.engine.network.mechanical_coordination` computes it on the host
from the copied neighbour list, pair flags and counts. At 10⁵ rods and more that copy (two
discs × capacity arrays) and its numpy work cost more than the GPU's 100 steps between two
measures (benchmarks/results/gpu_bench.md), so the parallel and gather paths count on the
device and copy three integers per pruning round instead:

1. :func:`count_rod_contacts`: every rod's contacts with other alive rods (the list entries the
   measure kernel flagged ``PAIR_CONTACT``, a rod touching itself left out, as on the host);
2. :func:`remove_rattlers`: the alive rods with fewer than two are removed; the rods removed,
   and the survivors with the sum of their counts, go to ``coordination``.

The host repeats 1–2 until a round removes none; then Z_m = sum / survivors, the same integers
as the host's and so the same float (2 × kept = Σ counts over the survivors).
"""

import taichi as ti

from dem_taichi.kernels.common import nd1, nd2
from dem_taichi.kernels.layout import IMAGE_CODES, PAIR_CONTACT, Z_ALIVE, Z_COUNTS, Z_REMOVED


@ti.kernel
def count_rod_contacts(
    first: ti.i32,
    n_rods: ti.i32,
    chain: ti.i32,
    nbr: nd2,
    nbr_count: nd1,
    pair_flags: nd2,
    rod_alive: nd1,
    rod_count: nd1,
):
    """``rod_count[r]``: the contacts of rod r with other alive rods, counting each flagged
    entry once at both ends (``chain``: discs per rod; ``first``: every rod alive first)."""
    for r in range(n_rods):
        if first == 1:
            rod_alive[r] = 1
        rod_count[r] = 0
    for i in range(nbr_count.shape[0]):
        rod_i = i // chain
        for k in range(nbr_count[i]):
            if pair_flags[i, k] & PAIR_CONTACT:
                rod_j = nbr[i, k] // IMAGE_CODES // chain
                if rod_i != rod_j and rod_alive[rod_i] == 1 and rod_alive[rod_j] == 1:
                    ti.atomic_add(rod_count[rod_i], 1)
                    ti.atomic_add(rod_count[rod_j], 1)


@ti.kernel
def remove_rattlers(n_rods: ti.i32, rod_alive: nd1, rod_count: nd1, coordination: nd1):
    """Removes the alive rods with fewer than two contacts; ``coordination`` gets the number
    removed, the survivors and the sum of their counts (final when none was removed)."""
    for q in range(coordination.shape[0]):
        coordination[q] = 0
    for r in range(n_rods):
        if rod_alive[r] == 1:
            if rod_count[r] < 2:
                rod_alive[r] = 0
                ti.atomic_add(coordination[Z_REMOVED], 1)
            else:
                ti.atomic_add(coordination[Z_ALIVE], 1)
                ti.atomic_add(coordination[Z_COUNTS], rod_count[r])
