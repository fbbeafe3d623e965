"""The engine's device arrays, declared once (plain Python, no Taichi).

:data:`DEVICE_ARRAYS` lists every Taichi ndarray of :class:`dem_taichi.engine.simulation.Simulation`
(``sim.a[name]``): its dtype (``"real"``: the run's precision; ``"i32"``), its shape rule, its
role and, for the arrays of the state, its key in ``get_state()`` (and so in checkpoints). The
engine derives from this one table the allocation, the growth of the neighbour-list capacity,
the state dict and the arguments of every kernel launch: a kernel's array parameters carry the
names of the arrays (:func:`kernel_parameters`), so no argument list is spelled by hand and two
arrays cannot be swapped by position.

Shape symbols: ``rods`` the bodies (N rigid rods, or the N n_s discs of bonded rods), ``discs``
M = N n_s, ``spheres`` the discs per body (n_s, or 1 for bonded rods), ``species`` n_s (the
places in a rod, for the charge pattern), ``capacity`` K (neighbour-list entries per disc, grown
on overflow), ``rolling_discs`` M with rolling resistance at the contacts, else 1 (the rolling
springs ψ, one per list entry, cost no memory where the scene has none), ``strength_rods`` N
with a spread of the rods' strengths (``[long_range] strength_spread``), else 1,
``partner_rods`` N (the rods, not the bodies) with ``[long_range] attraction_pairs =
"bonded_at_A"``, else 1 (row r: the number of rod r's partners, -1 before state A, then the
partners: :mod:`dem_taichi.kernels.layout`), ``cells`` the
side of the cell-list grid; integers are fixed sizes (the small arrays of
:mod:`dem_taichi.kernels.layout`). ``bond_intact`` (bonded rods: 1 while the bond of body b
to b + 1 holds) is allocated for rigid rods too, never read there. ``fire`` holds the FIRE
minimiser's constants and running scalars (:mod:`dem_taichi.kernels.fire`), set at the start of
every minimising call: work, not state.

Roles: ``state`` (the dynamical state, restored bit for bit), ``constant`` (set once from the
scene), ``derived`` (recomputed from the state: disc positions), ``work`` (kernel scratch: cell
lists, the previous neighbour list), ``output`` (written by the measure kernels for the host).
``rod_alive``, ``rod_count`` and ``coordination`` (the mechanical coordination counted on the
device, the parallel and gather paths: :mod:`dem_taichi.kernels.coordination`) are sized by the
bodies, of which the rods are the first N.
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from dem_taichi.kernels import layout as L

__all__ = ["DeviceArray", "DEVICE_ARRAYS", "HOST_STATE_KEYS", "STATE_ARRAYS", "kernel_parameters"]


@dataclass(frozen=True)
class DeviceArray:
    """One device array: ``name`` (as the kernels' parameters call it), ``dtype`` ("real" |
    "i32"), ``shape`` (symbols of the module docstring or ints), ``role``, ``state_key`` (its
    key in the state dict; ``None`` outside the state), ``copy_on_growth`` (keep the entries
    when the capacity grows; otherwise the array is allocated afresh)."""

    name: str
    dtype: str
    shape: tuple[str | int, ...]
    role: str
    state_key: str | None = None
    copy_on_growth: bool = False

    def __post_init__(self) -> None:
        if self.dtype not in ("real", "i32"):
            raise ValueError(f"{self.name}: dtype = {self.dtype!r}: allowed real | i32")
        if self.role not in ("state", "constant", "derived", "work", "output"):
            raise ValueError(f"{self.name}: unknown role {self.role!r}")
        if (self.role == "state") != (self.state_key is not None):
            raise ValueError(f"{self.name}: state arrays, and only they, have a state key")

    def shape_for(self, sizes: Mapping[str, int]) -> tuple[int, ...]:
        """The concrete shape for the ``sizes`` of the symbols."""
        return tuple(int(s) if isinstance(s, int) else int(sizes[s]) for s in self.shape)

    @property
    def grows(self) -> bool:
        """Whether the array is reallocated when the neighbour-list capacity changes."""
        return "capacity" in self.shape


_R, _I = "real", "i32"

#: Every device array; the state arrays in the order of the state dict
# (:mod:`dem_taichi.engine.state`).
DEVICE_ARRAYS: tuple[DeviceArray, ...] = (
    DeviceArray("pos", _R, ("rods", 2), "state", "reduced_position"),
    DeviceArray("angle", _R, ("rods",), "state", "angle"),
    DeviceArray("vel", _R, ("rods", 2), "state", "velocity"),
    DeviceArray("omega", _R, ("rods",), "state", "angular_velocity"),
    DeviceArray("force", _R, ("rods", 2), "state", "force"),
    DeviceArray("torque", _R, ("rods",), "state", "torque"),
    DeviceArray("ref_pos", _R, ("rods", 2), "state", "ref_position"),
    DeviceArray("ref_angle", _R, ("rods",), "state", "ref_angle"),
    DeviceArray("offsets", _R, ("spheres",), "constant"),
    DeviceArray("disc_x", _R, ("discs", 2), "derived"),
    DeviceArray("disc_off", _R, ("discs", 2), "derived"),
    DeviceArray("nbr", _I, ("discs", "capacity"), "state", "neighbours", copy_on_growth=True),
    DeviceArray(
        "nbr_xi", _R, ("discs", "capacity"), "state", "tangential_spring", copy_on_growth=True
    ),
    DeviceArray(
        "nbr_psi",
        _R,
        ("rolling_discs", "capacity"),
        "state",
        "rolling_spring",
        copy_on_growth=True,
    ),  # fmt: skip
    DeviceArray("nbr_count", _I, ("discs",), "state", "neighbour_count"),
    DeviceArray("old_nbr", _I, ("discs", "capacity"), "work", copy_on_growth=True),
    DeviceArray("old_xi", _R, ("discs", "capacity"), "work", copy_on_growth=True),
    DeviceArray("old_psi", _R, ("rolling_discs", "capacity"), "work", copy_on_growth=True),
    DeviceArray("old_count", _I, ("discs",), "work"),
    DeviceArray("cell_count", _I, ("cells", "cells"), "work"),
    DeviceArray("cell_start", _I, ("cells", "cells"), "work"),
    DeviceArray("cell_items", _I, ("discs",), "work"),
    DeviceArray("disc_cell", _I, ("discs",), "work"),
    DeviceArray("charge", _I, ("species",), "constant"),
    DeviceArray("pair_table", _R, ("species", "species", 3), "constant"),
    DeviceArray("rod_strength", _R, ("strength_rods",), "constant"),
    DeviceArray("cell", _R, (L.N_CELL,), "state", "cell"),
    DeviceArray("flags", _I, (L.N_FLAGS,), "state", "flags"),
    DeviceArray("params", _R, (L.N_PARAMS,), "state", "params"),
    DeviceArray("bond_intact", _I, ("rods",), "state", "bond_intact"),
    DeviceArray(
        "attraction_partners",
        _I,
        ("partner_rods", L.PARTNER_COLUMNS),
        "state",
        "attraction_partners",
    ),  # fmt: skip
    DeviceArray("fire", _R, (L.N_FIRE,), "work"),
    DeviceArray("measures", _R, (L.N_MEASURES,), "output"),
    DeviceArray("block_sums", _R, ("measure_blocks", L.N_MEASURES), "work"),
    DeviceArray("rod_contacts", _I, ("rods",), "output"),
    DeviceArray("rod_alive", _I, ("rods",), "work"),
    DeviceArray("rod_count", _I, ("rods",), "work"),
    DeviceArray("coordination", _I, (L.N_COORDINATION,), "output"),
    DeviceArray("pair_out", _R, ("discs", "capacity", 4), "output"),
    DeviceArray("pair_flags", _I, ("discs", "capacity"), "output"),
)

#: The state arrays, in the order of the state dict.
STATE_ARRAYS: tuple[DeviceArray, ...] = tuple(a for a in DEVICE_ARRAYS if a.role == "state")

#: Keys of the state dict kept on the host (after the arrays').
HOST_STATE_KEYS = ("reference_lengths", "step", "full_list")


@functools.cache
def kernel_parameters(kernel: Callable) -> tuple[str, ...]:
    """Names of a kernel's parameters, in order (Taichi keeps the Python signature)."""
    return tuple(inspect.signature(kernel).parameters)
