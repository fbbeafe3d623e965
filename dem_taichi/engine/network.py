"""The interaction network as the host reads it from the engine's arrays (numpy only).

The measure kernel leaves the ``layout.PAIR_*`` bits of every neighbour-list entry in
``pair_flags``; from them and the list come the interacting entries, the mechanical coordination
number (rattlers removed) and the :class:`dem_taichi.physics.snapshot.NetworkSnapshot` of the
linear- response probes. :class:`dem_taichi.engine.simulation.Simulation` calls these with its
arrays.

Symbols: Z_m mechanical coordination number (contacts per rod among rods with ≥ 2 contacts),
ξ tangential spring, L cell lengths.
"""

from __future__ import annotations

import numpy as np

from dem_taichi.engine.parameters import EngineParameters
from dem_taichi.kernels import layout as L
from dem_taichi.physics.snapshot import NetworkSnapshot

__all__ = ["interacting_entries", "mechanical_coordination", "network_snapshot"]


def interacting_entries(
    counts: np.ndarray, bits: np.ndarray, neighbours: np.ndarray, capacity: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(disc i, list slot k, packed entry, flag bits) of every interacting list entry."""
    slots = np.arange(capacity)[None, :] < counts[:, None]
    i, k = np.nonzero(slots & (bits & L.PAIR_INTERACTING != 0))
    packed = neighbours[i, k]
    return i, k, packed, bits[i, k]


def mechanical_coordination(
    i: np.ndarray, packed: np.ndarray, bits: np.ndarray, n_spheres: int, n_rods: int
) -> float:
    """Z_m: 2 × contacts / rods after removing, repeatedly, the rods with fewer than two
    contacts (rattlers); 0 when none is left."""
    touching = (bits & L.PAIR_CONTACT) != 0
    ns = n_spheres
    rod_i = (i[touching] // ns).astype(np.int64)
    rod_j = (packed[touching] // L.IMAGE_CODES // ns).astype(np.int64)
    if np.any(rod_i == rod_j):  # a bonded rod touching itself: not a contact between rods
        rod_i, rod_j = rod_i[rod_i != rod_j], rod_j[rod_i != rod_j]
    alive = np.ones(n_rods, dtype=bool)
    while True:
        keep = alive[rod_i] & alive[rod_j]
        count = np.bincount(rod_i[keep], minlength=n_rods) + np.bincount(
            rod_j[keep], minlength=n_rods
        )
        rattlers = alive & (count < 2)
        if not rattlers.any():
            break
        alive &= ~rattlers
    n_alive = int(alive.sum())
    if n_alive == 0:
        return 0.0
    keep = alive[rod_i] & alive[rod_j]
    return 2.0 * int(keep.sum()) / n_alive


def network_snapshot(
    entries: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    disc_x: np.ndarray,
    springs: np.ndarray,
    lengths: np.ndarray,
    wrapped: np.ndarray,
    th: np.ndarray,
    geometry,
    species: tuple[np.ndarray, np.ndarray, np.ndarray],
    params: EngineParameters,
    vdw: bool,
    bonds=None,
    rolling_springs: np.ndarray | None = None,
    rod_strength: np.ndarray | None = None,
    attraction_partners: np.ndarray | None = None,
    cap_force: str = "contact",
) -> NetworkSnapshot:
    """The snapshot of the interacting ``entries`` (:func:`interacting_entries`): disc positions
    ``disc_x`` (M, 2), list springs ξ (M, K), cell ``lengths``, wrapped centroids and angles,
    the rod ``geometry``, ``species`` (charge, F_max, k_a) and the runtime ``params`` (k_n, k_t,
    μ, van der Waals when ``vdw``; :class:`dem_taichi.engine.parameters.EngineParameters`);
    ``bonds`` (a :class:`dem_taichi.physics.snapshot.BondNetwork`)
    for bonded rods, whose bodies are discs (``geometry`` of one disc, centroids contiguous along
    each rod); ``rolling_springs`` ψ (M, K) with rolling resistance (κ_r and the cap from
    ``params``); ``rod_strength`` (N,) the rods' long-range strengths (None: alike);
    ``attraction_partners`` the rods' partner table (None: every pair attracts)."""
    i, k, packed, bits = entries
    j = packed // L.IMAGE_CODES
    code = packed % L.IMAGE_CODES
    image = np.stack(L.image_of_code(code), axis=1).astype(float)
    r_ij = disc_x[i] - disc_x[j] - image * lengths
    ns = geometry.n_spheres
    offsets = geometry.offsets
    axis = np.stack([np.cos(th), np.sin(th)], axis=1)
    x_w = wrapped[:, None, :] + offsets[None, :, None] * axis[:, None, :]
    x_w = x_w.reshape(-1, 2)
    shift = x_w[i] - x_w[j] - r_ij
    shift = np.round(shift / lengths) * lengths
    normal = r_ij / np.linalg.norm(r_ij, axis=1)[:, None]
    tangent = np.stack([-normal[:, 1], normal[:, 0]], axis=1)
    xi = springs[i, k]
    touching = (bits & L.PAIR_CONTACT) != 0
    xi = np.where(touching, xi, 0.0)
    charge, f_max, k_a = species
    psi = None
    if rolling_springs is not None:
        psi = np.where(touching, rolling_springs[i, k], 0.0)
    return NetworkSnapshot(
        cell_lengths=lengths.copy(),
        rod_position=wrapped,
        rod_angle=th,
        n_spheres=ns,
        spacing=geometry.spacing,
        diameter=geometry.diameter,
        disc_mass=geometry.disc_mass,
        charge=charge,
        f_max=f_max,
        k_a=k_a,
        k_n=params.k_n,
        k_t=params.k_t,
        mu=params.mu,
        vdw_f_max=params.vdw_f_max if vdw else 0.0,
        vdw_k=params.vdw_k if vdw else 0.0,
        pair_i=i.astype(np.int64),
        pair_j=j.astype(np.int64),
        pair_shift=shift,
        tangential_spring=xi[:, None] * tangent,
        sliding=(bits & L.PAIR_SLIDING) != 0,
        bonds=bonds,
        rolling_spring=psi,
        rolling_stiffness=params.rolling_stiffness if psi is not None else 0.0,
        rolling_cap=params.rolling_cap if psi is not None else 0.0,
        rod_strength=rod_strength,
        attraction_partners=attraction_partners,
        cap_force=cap_force,
    )
