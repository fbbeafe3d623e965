"""The engine's device arrays on the device: allocated from their table
(:data:`dem_taichi.engine.device_arrays.DEVICE_ARRAYS`), grown when a disc's neighbour list
overflows, and loaded with a starting gas. :class:`dem_taichi.engine.simulation.Simulation`
calls these functions on its arrays (``sim.a``, a dict by name that the simulation's state and
views share: growth replaces entries of that same dict).

Taichi is imported inside the functions that allocate, so the engine imports without it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from dem_taichi.engine.device_arrays import DEVICE_ARRAYS
from dem_taichi.engine.failures import CapacityError
from dem_taichi.kernels import layout as L
from dem_taichi.scene.geometry import GasState

__all__ = [
    "CAPACITY_LIMIT",
    "allocate_arrays",
    "check_cell",
    "grow_arrays",
    "initial_capacity",
    "upload_gas",
]

#: The most neighbour-list entries per disc: a disc that needs more means an unphysical packing
#: or list radius (:func:`grow_arrays` refuses it).
CAPACITY_LIMIT = 4096


def initial_capacity(list_radius: float, diameter: float, full_list: bool) -> int:
    """Neighbour-list entries per disc to start with (twice as many for a full list)."""
    # half list: about half the discs within r_list of a disc at the densest packing
    r = list_radius / diameter
    return (2 if full_list else 1) * (int(2.2 * r * r) + 6)


def allocate_arrays(sizes: Mapping[str, int], dtypes: Mapping[str, Any]) -> dict[str, Any]:
    """Every device array of :data:`DEVICE_ARRAYS`, by name, allocated (not filled) for the
    ``sizes`` of the shape symbols, with the Taichi type of each dtype (``dtypes``: "real",
    "i32" → Taichi type)."""
    import taichi as ti

    nd = ti.ndarray
    return {spec.name: nd(dtypes[spec.dtype], spec.shape_for(sizes)) for spec in DEVICE_ARRAYS}


def grow_arrays(
    arrays: dict[str, Any], sizes: Mapping[str, int], dtypes: Mapping[str, Any], capacity: int
) -> dict[str, int]:
    """Reallocate, in ``arrays`` itself, every array whose shape has the neighbour-list
    capacity, for ``capacity`` entries per disc (those marked ``copy_on_growth`` keep their
    entries); returns the new sizes. :class:`~dem_taichi.engine.failures.CapacityError` above
    :data:`CAPACITY_LIMIT`, before anything changes."""
    import taichi as ti

    limit = CAPACITY_LIMIT
    if capacity > limit:
        raise CapacityError(
            f"a disc has {capacity} list neighbours (limit {limit}): the packing or the "
            "list radius is unphysical; reduce [integration] skin or the long-range range "
            "(f_max / k_a)"
        )
    sizes = dict(sizes, capacity=capacity)
    for spec in DEVICE_ARRAYS:
        if not spec.grows:
            continue
        shape = spec.shape_for(sizes)
        grown = ti.ndarray(dtypes[spec.dtype], shape)
        if spec.copy_on_growth:
            old = arrays[spec.name].to_numpy()
            new = np.zeros(shape, dtype=old.dtype)
            keep = min(capacity, old.shape[1])
            new[:, :keep] = old[:, :keep]
            grown.from_numpy(new)
        arrays[spec.name] = grown
    return sizes


def check_cell(cell_lengths: np.ndarray, rod_length: float, list_radius: float) -> None:
    """:class:`~dem_taichi.engine.failures.CapacityError` when the cell is too small for the
    minimum image with rods of ``rod_length`` and the neighbour list's ``list_radius``."""
    reach = rod_length + list_radius
    if np.min(cell_lengths) < 2.0 * list_radius + rod_length:
        raise CapacityError(
            f"cell lengths {np.round(cell_lengths, 4).tolist()} are too small for the minimum "
            f"image with rods of length {rod_length} and list radius "
            f"{list_radius:.3g} (need > {2 * list_radius + rod_length:.3g}"
            f"; reach {reach:.3g}): use more rods ([particles] n_rods) or a smaller "
            "[integration] skin"
        )


def upload_gas(
    arrays: dict[str, Any], gas: GasState, real: type, rod_length: float, list_radius: float
) -> None:
    """Load the bodies and the cell of ``gas`` into ``arrays`` (``real``: the numpy type of the
    run's precision), after :func:`check_cell`; the reference positions are the gas's, and the
    neighbour list is marked to be rebuilt."""
    cell_lengths = np.asarray(gas.cell_lengths, dtype=float)
    check_cell(cell_lengths, rod_length, list_radius)
    reduced = np.asarray(gas.position, dtype=float) / cell_lengths
    arrays["pos"].from_numpy(reduced.astype(real))
    arrays["angle"].from_numpy(np.asarray(gas.angle, dtype=real))
    arrays["vel"].from_numpy(np.asarray(gas.velocity, dtype=real))
    arrays["omega"].from_numpy(np.asarray(gas.angular_velocity, dtype=real))
    arrays["ref_pos"].from_numpy(reduced.astype(real))
    arrays["ref_angle"].from_numpy(np.asarray(gas.angle, dtype=real))
    cell = np.zeros(L.N_CELL)
    cell[[L.C_LX, L.C_LY]] = cell_lengths
    cell[[L.C_LBX, L.C_LBY]] = cell_lengths
    arrays["cell"].from_numpy(cell.astype(real))
    flags = np.zeros(L.N_FLAGS, dtype=np.int32)
    flags[L.F_FORCE_REBUILD] = 1
    arrays["flags"].from_numpy(flags)
