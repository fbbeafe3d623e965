"""Shared pieces of the kernels: the ndarray/template annotations, ``sign`` and the placement of a
rod's discs from its centroid and angle (``place_all_discs`` after a state restore).
"""

import taichi as ti

from dem_taichi.kernels.layout import (
    C_LX,
    C_LY,
)

# kernel array parameters carry their dimension (checked at launch; the table of
# dem_taichi.engine.device_arrays gives each array's, and a test checks the two agree)
nd1 = ti.types.ndarray(ndim=1)
nd2 = ti.types.ndarray(ndim=2)
nd3 = ti.types.ndarray(ndim=3)
T = ti.template()  # arrays passed to ti.func by reference


@ti.func
def sign(x):
    s = 0.0
    if x > 0.0:
        s = 1.0
    elif x < 0.0:
        s = -1.0
    return s


@ti.func
def rod_axis(ns: T, theta):
    """The axis (cos θ, sin θ) that places a body's discs; (1, 0) for one-disc bodies (``ns`` =
    1: bonded rods' discs, single discs), whose disc sits at the centroid (offset 0), so the
    axis places nothing and its cosine and sine are not computed. Bitwise the same positions;
    for bonded rods the trigonometry was 15 % of a step (12,160 bodies; issue 20)."""
    c = 1.0
    s = 0.0
    if ti.static(ns > 1):
        c = ti.cos(theta)
        s = ti.sin(theta)
    return c, s


@ti.func
def place_rod_discs(ns: T, r, pos: T, angle: T, offsets: T, disc_x: T, disc_off: T, lx, ly):
    """Absolute disc positions of rod r from its reduced centroid and angle."""
    c, s = rod_axis(ns, angle[r])
    place_rod_discs_cs(ns, r, pos, c, s, offsets, disc_x, disc_off, lx, ly)


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


@ti.kernel
def place_all_discs(
    ns: ti.template(), pos: nd2, angle: nd1, offsets: nd1, disc_x: nd2, disc_off: nd2, cell: nd1
):
    """Recompute the (derived) disc positions from the centroids, e.g. after a state restore."""
    for r in range(pos.shape[0]):
        place_rod_discs(ns, r, pos, angle, offsets, disc_x, disc_off, cell[C_LX], cell[C_LY])
