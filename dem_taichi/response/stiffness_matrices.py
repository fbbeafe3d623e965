"""The stiffness matrices of a rod network (numpy/scipy, no Taichi), for the linear response.

Pair Jacobians of the pair forces for any body (rod or disc: offset vectors), with the variants
of :class:`StiffnessVariant` (k_t, long-range factor, rolling springs at fixed forces); the
pruning of rattlers and of clusters that do not span the cell; the assembly of the stiffness
matrix H, the mixed block Γ and the stress derivatives D (:class:`NetworkMatrices`). Symbols,
conventions and the method: :mod:`dem_taichi.response.linear`, which solves the relaxed response
with them and re-exports these names.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
import scipy.sparse as sparse
import scipy.sparse.csgraph as csgraph

from dem_taichi.physics import forcelaw
from dem_taichi.physics.snapshot import NetworkSnapshot

__all__ = [
    "ENGINE_STIFFNESS",
    "NetworkMatrices",
    "PairGraph",
    "StiffnessVariant",
    "assemble",
    "kept_network",
    "network_matrices",
    "pair_jacobians",
    "rolling_terms",
]


def _perp(vector: np.ndarray) -> np.ndarray:
    """ẑ × v = (-v_y, v_x) for (..., 2) arrays."""
    return np.stack([-vector[..., 1], vector[..., 0]], axis=-1)


def _scatter_rows(index: np.ndarray, values: np.ndarray, n_rows: int) -> np.ndarray:
    """Sum values (P, 6, C) into rows index (P, 6) of an (n_rows, C) array."""
    flat = index.ravel()
    return np.stack(
        [
            np.bincount(flat, values[..., c].ravel(), minlength=n_rows)
            for c in range(values.shape[-1])
        ],
        axis=1,
    )


def _active_pairs(pairs: forcelaw.PairForces) -> np.ndarray:
    """Pairs that carry a force or a stiffness (contacts, long-range/vdW within range)."""
    return pairs.in_contact | (pairs.normal_force != 0.0) | (pairs.normal_stiffness != 0.0)


def _prune_rattlers(rod_i, rod_j, active, n_rods) -> np.ndarray:
    """Iteratively mark rods with at most one active pair to kept rods; returns the keep mask."""
    keep = np.ones(n_rods, dtype=bool)
    while True:
        used = active & keep[rod_i] & keep[rod_j]
        count = np.bincount(rod_i[used], minlength=n_rods) + np.bincount(
            rod_j[used], minlength=n_rods
        )
        drop = keep & (count <= 1)
        if not np.any(drop):
            return keep
        keep &= ~drop


def _rigid_clusters(rod_i, rod_j, used, image, keep, n_rods):
    """Connected clusters of kept rods and whether each wraps around the periodic cell.

    ``image`` (P, 2) integer image vectors (shift / cell length). Rods get unwrapped image labels
    along a breadth-first spanning tree; a cluster wraps (spans the cell) iff some pair is
    inconsistent with them. Returns (labels (N,) with -1 for rods not kept, wraps (n_clusters,)).
    """
    p, q, m = rod_i[used], rod_j[used], image[used]
    # r = x_i - x_j - shift: next to P (unwrapped image M_P) sits Q's copy with M_Q = M_P + m
    graph = sparse.coo_matrix((np.ones(p.size), (p, q)), shape=(n_rods, n_rods)).tocsr()
    n_labels, labels = csgraph.connected_components(graph, directed=False)
    labels = np.where(keep, labels, -1)
    wraps = np.zeros(n_labels, dtype=bool)
    if p.size == 0:
        return labels, wraps
    key = np.concatenate([p * n_rods + q, q * n_rods + p])
    step = np.concatenate([m, -m])
    order = np.argsort(key, kind="stable")
    key, step = key[order], step[order]
    unwrapped = np.zeros((n_rods, 2), dtype=np.int64)
    symmetric = graph + graph.T
    roots = [int(np.flatnonzero(labels == label)[0]) for label in np.unique(labels[labels >= 0])]
    for root in roots:
        nodes, predecessors = csgraph.breadth_first_order(
            symmetric, root, directed=False, return_predecessors=True
        )
        nodes = nodes[1:]
        edge = np.searchsorted(key, predecessors[nodes] * n_rods + nodes)
        for node, parent, shift in zip(nodes, predecessors[nodes], step[edge], strict=True):
            unwrapped[node] = unwrapped[parent] + shift
    mismatch = np.any(unwrapped[q] != unwrapped[p] + m, axis=1)
    wraps[labels[p][mismatch]] = True
    return labels, wraps


@dataclass(frozen=True)
class StiffnessVariant:
    """Changes of the network's *stiffness* at fixed forces, for frozen-network experiments.

    The snapshot's forces (and so its equilibrium and static stress) are kept; only the springs
    of the linearisation change. Defaults reproduce the engine's own linearisation exactly.

    Attributes:
        tangential_stiffness: k_t of stuck contacts [force/length]; None = the snapshot's k_t.
        long_range_factor: factor on the long-range (charge and vdW) normal stiffness (≥ 0).
        rolling_stiffness: κ_r [force·length/rad] of a rolling spring at every contact on the
            relative rotation of the two bodies (torque -κ_r (φ_P - φ_Q) on P, +κ_r (φ_P - φ_Q)
            on Q; MercuryDPM's rolling spring k_r gives κ_r = k_r d_eff², with d_eff = r = d/2
            for equal spheres as in docs/science/dem-model.md §1.7). It carries no force, hence no
            stress term; always stuck (no rolling cap μ_r |f_n|). Added to the engine's own rolling
            springs (the snapshot's, :func:`rolling_terms`), which it leaves as they are.
    """

    tangential_stiffness: float | None = None
    long_range_factor: float = 1.0
    rolling_stiffness: float = 0.0

    def __post_init__(self) -> None:
        k_t = self.tangential_stiffness
        if k_t is not None and not (np.isfinite(k_t) and k_t >= 0.0):
            raise ValueError(f"StiffnessVariant.tangential_stiffness = {k_t!r}: need >= 0 or None")
        for name in ("long_range_factor", "rolling_stiffness"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"StiffnessVariant.{name} = {value!r}: need a finite value >= 0")

    def normal_stiffness(self, snapshot: NetworkSnapshot, pairs: forcelaw.PairForces):
        """k_N of every pair with the long-range part scaled."""
        if self.long_range_factor == 1.0:
            return pairs.normal_stiffness
        contact = forcelaw.contact_normal_stiffness(pairs.overlap, snapshot.k_n)
        return contact + self.long_range_factor * (pairs.normal_stiffness - contact)

    def k_t(self, snapshot: NetworkSnapshot) -> float:
        """k_t of stuck contacts."""
        return snapshot.k_t if self.tangential_stiffness is None else self.tangential_stiffness


ENGINE_STIFFNESS = StiffnessVariant()


def rolling_terms(snapshot: NetworkSnapshot, pairs: forcelaw.PairForces, sliding_free: bool,
                  variant: StiffnessVariant = ENGINE_STIFFNESS):  # fmt: skip
    """(κ (P,), slope (P,)): the rolling stiffness of every pair and, at the rolling cap, the
    slope of the capped couple with the overlap.

    The engine's rolling springs (:mod:`dem_taichi.physics.rolling`): κ_r at contacts whose couple
    is below the cap; at the cap (``sliding_free``, as sliding contacts are free) the couple
    M = ±μ_r d_eff k_n δ follows the overlap only (κ 0, slope sign(M) μ_r d_eff k_n). With
    ``sliding_free`` False every contact's rolling spring is stuck. The variant's rolling
    stiffness is added at every contact.
    """
    contact = pairs.in_contact
    kappa = np.where(contact, snapshot.rolling_stiffness + variant.rolling_stiffness, 0.0)
    slope = np.zeros(snapshot.n_pairs)
    if sliding_free and snapshot.rolling_stiffness > 0.0:
        capped = pairs.rolling_sliding
        kappa = np.where(capped, variant.rolling_stiffness, kappa)
        slope = np.where(
            capped, np.sign(pairs.rolling_moment) * snapshot.rolling_cap * snapshot.k_n, 0.0
        )
    return kappa, slope


def pair_jacobians(
    pairs: forcelaw.PairForces,
    offset_i: np.ndarray,
    offset_j: np.ndarray,
    branch: np.ndarray,
    normal_stiffness: np.ndarray,
    k_t: float,
    mu: float,
    k_n: float,
    sliding_free: np.ndarray,
    include_geometric: bool,
    rolling_stiffness: float | np.ndarray = 0.0,
    rolling_slope: np.ndarray | None = None,
):  # fmt: skip
    """Per-pair K (P, 6, 4) = d(F_P, τ_P, F_Q, τ_Q)/dw and Jσ (P, 4, 4) = d(f ⊗ l)/dw.

    Bodies P, Q carry the two discs at offset vectors c_i = x_i - X_P and c_j = x_j - X_Q (rod
    bodies: c = o a; disc bodies: c = 0); ``branch`` l is the stress branch vector of each pair;
    ``normal_stiffness`` k_N, stuck-spring ``k_t`` and the Coulomb slope μ k_n of sliding
    contacts; ``rolling_stiffness`` κ_r at contacts (a scalar, or one per pair) and
    ``rolling_slope`` dM/dδ of couples at the rolling cap (:func:`rolling_terms`).
    """
    perp_i = _perp(offset_i)  # d c_i / d φ_P = ẑ × c_i
    perp_j = _perp(offset_j)
    n_pairs = offset_i.shape[0]
    geometric = 1.0 if include_geometric else 0.0

    r = pairs.separation
    rho = pairs.distance
    n = pairs.normal
    t = pairs.tangent
    f = pairs.force
    tangential = np.sum(pairs.tangential_force * t, axis=-1)  # T
    normal_force = pairs.normal_force  # N

    b = np.zeros((n_pairs, 2, 4))  # dr = B w
    b[:, 0, 0] = 1.0
    b[:, 1, 1] = 1.0
    b[:, :, 2] = perp_i
    b[:, :, 3] = -perp_j
    n_b = np.einsum("pa,pak->pk", n, b)  # n·dr per unit w
    t_b = np.einsum("pa,pak->pk", t, b)  # t·dr per unit w

    # dT: stuck springs (contacts not sliding freely) and sliding contacts on the cap
    stuck = pairs.in_contact & ~sliding_free
    d_tangential = np.zeros((n_pairs, 4))
    rolling = np.zeros((n_pairs, 4))
    rolling[:, 2] = rolling[:, 3] = 0.5 * rho
    d_tangential[stuck] = -k_t * (t_b[stuck] - rolling[stuck])
    slide = pairs.in_contact & sliding_free
    d_tangential[slide] = -np.sign(tangential[slide])[:, None] * mu * k_n * n_b[slide]

    j_f = (
        -normal_stiffness[:, None, None] * n[:, :, None] * n_b[:, None, :]
        + t[:, :, None] * d_tangential[:, None, :]
        + geometric
        * (
            (normal_force / rho)[:, None, None] * t[:, :, None] * t_b[:, None, :]
            - (tangential / rho)[:, None, None] * n[:, :, None] * t_b[:, None, :]
        )
    )

    lever_i = offset_i - 0.5 * r
    lever_j = offset_j + 0.5 * r
    d_lever_i = -0.5 * b
    d_lever_i[:, :, 2] += perp_i
    d_lever_j = 0.5 * b.copy()
    d_lever_j[:, :, 3] += perp_j
    j_force = np.stack([f[:, 1], -f[:, 0]], axis=-1)  # dh × f = (f_y, -f_x)·dh
    d_torque_i = np.einsum("pa,pak->pk", _perp(lever_i), j_f) + geometric * np.einsum(
        "pa,pak->pk", j_force, d_lever_i
    )
    d_torque_j = -np.einsum("pa,pak->pk", _perp(lever_j), j_f) - geometric * np.einsum(
        "pa,pak->pk", j_force, d_lever_j
    )
    roll = np.where(pairs.in_contact, rolling_stiffness, 0.0)
    if np.any(roll != 0.0):
        d_torque_i[:, 2] -= roll
        d_torque_i[:, 3] += roll
        d_torque_j[:, 2] += roll
        d_torque_j[:, 3] -= roll
    if rolling_slope is not None and np.any(rolling_slope != 0.0):
        # M_P = sign(M) μ_r d_eff k_n δ with dδ = −n·dr
        d_torque_i -= rolling_slope[:, None] * n_b
        d_torque_j += rolling_slope[:, None] * n_b
    k = np.empty((n_pairs, 6, 4))
    k[:, 0:2] = j_f
    k[:, 2] = d_torque_i
    k[:, 3:5] = -j_f
    k[:, 5] = d_torque_j

    j_sigma = np.einsum("pak,pb->pabk", j_f, branch)
    for a in range(2):
        for bb in range(2):
            j_sigma[:, a, bb, bb] += geometric * f[:, a]
    return k, j_sigma.reshape(n_pairs, 4, 4)


def _rod_pair_jacobians(snapshot: NetworkSnapshot, pairs: forcelaw.PairForces,
                        sliding_free: np.ndarray, include_geometric: bool,
                        variant: StiffnessVariant = ENGINE_STIFFNESS,
                        rolling_free: bool = True):  # fmt: skip
    """:func:`pair_jacobians` for rigid-rod bodies (c = o_s a_r, centroid branch vectors)."""
    n_s = snapshot.n_spheres
    offsets = forcelaw.disc_offsets(n_s, snapshot.spacing)
    rod_i = snapshot.pair_i // n_s
    rod_j = snapshot.pair_j // n_s
    o_i = offsets[snapshot.pair_i % n_s]
    o_j = offsets[snapshot.pair_j % n_s]
    angle_i = snapshot.rod_angle[rod_i]
    angle_j = snapshot.rod_angle[rod_j]
    axis_i = np.stack([np.cos(angle_i), np.sin(angle_i)], axis=-1)
    axis_j = np.stack([np.cos(angle_j), np.sin(angle_j)], axis=-1)
    kappa, slope = rolling_terms(snapshot, pairs, rolling_free, variant)
    return pair_jacobians(
        pairs, o_i[:, None] * axis_i, o_j[:, None] * axis_j, pairs.branch,
        variant.normal_stiffness(snapshot, pairs), variant.k_t(snapshot), snapshot.mu,
        snapshot.k_n, sliding_free, include_geometric, kappa, slope,
    )  # fmt: skip


def assemble(k_pair, j_sigma, branch, body_i, body_j, n_bodies: int, area: float,
             stress: np.ndarray, include_geometric: bool):  # fmt: skip
    """Sparse H (3n, 3n), Γ (3n, 4), D_q (4, 3n), D_G (4, 4) from per-pair blocks.

    ``k_pair`` (P, 6, 4) and ``j_sigma`` (P, 4, 4) from :func:`pair_jacobians` (or any pair term
    of that form, such as a bond), ``branch`` (P, 2) the stress branch vectors, ``body_i``,
    ``body_j`` (P,) the two bodies (3 DOFs each: x, y, θ) of every pair.
    """
    n_used = k_pair.shape[0]
    # w = S q_pair + W_G G
    select = np.zeros((4, 6))
    select[0, 0] = select[1, 1] = 1.0
    select[0, 3] = select[1, 4] = -1.0
    select[2, 2] = select[3, 5] = 1.0
    w_strain = np.zeros((n_used, 4, 4))
    w_strain[:, 0, 0] = branch[:, 0]  # dl_x = G_xx l_x + G_xy l_y
    w_strain[:, 0, 1] = branch[:, 1]
    w_strain[:, 1, 2] = branch[:, 0]  # dl_y = G_yx l_x + G_yy l_y
    w_strain[:, 1, 3] = branch[:, 1]

    dofs = np.concatenate(
        [3 * body_i[:, None] + np.arange(3), 3 * body_j[:, None] + np.arange(3)], axis=1
    )  # (P, 6)
    n_dof_all = 3 * n_bodies
    h_local = -np.einsum("pik,kj->pij", k_pair, select)
    hessian = sparse.coo_matrix(
        (
            h_local.ravel(),
            (np.repeat(dofs, 6, axis=1).ravel(), np.tile(dofs, (1, 6)).ravel()),
        ),
        shape=(n_dof_all, n_dof_all),
    ).tocsc()
    gamma = _scatter_rows(dofs, np.einsum("pik,pkc->pic", k_pair, w_strain), n_dof_all)
    d_q = _scatter_rows(dofs, np.einsum("pak,kj->pja", j_sigma, select) / area, n_dof_all).T
    geometric = 1.0 if include_geometric else 0.0
    d_g = (
        -geometric * np.outer(stress.ravel(), [1.0, 0.0, 0.0, 1.0])
        + np.einsum("pak,pkc->ac", j_sigma, w_strain) / area
    )
    return hessian, gamma, d_q, d_g


class PairGraph(Protocol):
    """What :func:`kept_network` reads of a network: ``n_rods`` bodies of ``n_spheres`` discs
    and the pairs of discs ``pair_i``, ``pair_j`` with their image shifts ``pair_shift`` in the
    cell ``cell_lengths`` (a :class:`NetworkSnapshot`, or the fragments of bonded rods)."""

    @property
    def n_rods(self) -> int: ...
    @property
    def n_spheres(self) -> int: ...
    @property
    def pair_i(self) -> np.ndarray: ...
    @property
    def pair_j(self) -> np.ndarray: ...
    @property
    def pair_shift(self) -> np.ndarray: ...
    @property
    def cell_lengths(self) -> np.ndarray: ...


def kept_network(snapshot: PairGraph, active: np.ndarray, prune_rattlers: bool = True):
    """Rods kept in the linear response, the pairs used, and the cluster label of every rod.

    With ``prune_rattlers``: rods with at most one active pair are dropped iteratively, then
    clusters that do not span the periodic cell (see the module docstring). Returns
    (keep_rod (N,) bool, used (P,) bool, labels (N,) int with -1 for dropped rods).
    """
    n_rods = snapshot.n_rods
    n_s = snapshot.n_spheres
    rod_i = snapshot.pair_i // n_s
    rod_j = snapshot.pair_j // n_s
    image = np.rint(snapshot.pair_shift / snapshot.cell_lengths).astype(np.int64)
    if prune_rattlers:
        keep_rod = _prune_rattlers(rod_i, rod_j, active, n_rods)
        used = active & keep_rod[rod_i] & keep_rod[rod_j]
        labels, wraps = _rigid_clusters(rod_i, rod_j, used, image, keep_rod, n_rods)
        keep_rod &= (labels >= 0) & wraps[np.maximum(labels, 0)]
    else:
        keep_rod = np.ones(n_rods, dtype=bool)
    used = active & keep_rod[rod_i] & keep_rod[rod_j]
    labels, _ = _rigid_clusters(rod_i, rod_j, used, image, keep_rod, n_rods)
    return keep_rod, used, labels


@dataclass(frozen=True)
class NetworkMatrices:
    """Linearised network: dR = -H dq + Γ dG and dσ = D_q dq + D_G dG (flattened xx, xy, yx, yy).

    Attributes:
        hessian: H (3N, 3N) sparse CSC, -∂R/∂q over rod DOFs (X, Y, θ per rod, rod-major).
        strain_coupling: Γ (3N, 4), ∂R/∂G at fixed non-affine DOFs.
        stress_dof: D_q (4, 3N), ∂σ/∂q.
        stress_strain: D_G (4, 4), ∂σ/∂G of the affine deformation (area and branch terms in).
        stress: σ (2, 2) of the snapshot.
        used_pairs: (P,) bool, active pairs between kept rods (the ones assembled).
        kept_rods: (N,) bool, rods not pruned (rattlers, dangling rods, finite clusters).
        cluster: (N,) label of the connected cluster of every kept rod (-1 for pruned rods).
        sliding_free: (P,) bool, contacts treated as sliding on the Coulomb cap.
        unbalanced_force: max |R| / mean |f| over active pairs (0 = exact equilibrium).
    """

    hessian: sparse.csc_matrix
    strain_coupling: np.ndarray
    stress_dof: np.ndarray
    stress_strain: np.ndarray
    stress: np.ndarray
    used_pairs: np.ndarray
    kept_rods: np.ndarray
    cluster: np.ndarray
    sliding_free: np.ndarray
    unbalanced_force: float


def network_matrices(
    snapshot: NetworkSnapshot,
    sliding_contacts: Literal["free", "stuck"] = "free",
    include_geometric: bool = True,
    prune_rattlers: bool = True,
    variant: StiffnessVariant = ENGINE_STIFFNESS,
) -> NetworkMatrices:
    """Assemble H, Γ, D_q, D_G of a snapshot (see the module docstring for every term).

    Args:
        snapshot: the network.
        sliding_contacts: "free" or "stuck", as in :func:`linear_response`.
        include_geometric: keep the pre-stress terms.
        prune_rattlers: drop rods with at most one active pair (iteratively), then clusters that
            do not span the periodic cell, and their pairs (see the module docstring).
        variant: stiffness changes at fixed forces (default: the engine's own springs).
    """
    if sliding_contacts not in ("free", "stuck"):
        raise ValueError(f"sliding_contacts = {sliding_contacts!r}: allowed 'free' or 'stuck'")
    pairs = forcelaw.pair_forces(snapshot)
    n_rods = snapshot.n_rods
    n_s = snapshot.n_spheres
    rod_i = snapshot.pair_i // n_s
    rod_j = snapshot.pair_j // n_s
    area = float(np.prod(snapshot.cell_lengths))
    stress = np.einsum("pa,pb->ab", pairs.force, pairs.branch) / area

    force, torque = forcelaw.rod_forces_and_torques(snapshot)
    active = _active_pairs(pairs)
    force_scale = np.mean(np.linalg.norm(pairs.force[active], axis=-1)) if np.any(active) else 0.0
    unbalanced = (
        max(np.max(np.abs(force)), np.max(np.abs(torque))) / force_scale
        if force_scale > 0.0 and n_rods
        else 0.0
    )

    keep_rod, used, labels = kept_network(snapshot, active, prune_rattlers)
    flagged = (snapshot.sliding | pairs.sliding) & pairs.in_contact
    sliding_free = flagged if sliding_contacts == "free" else np.zeros_like(flagged)

    k_pair, j_sigma = _rod_pair_jacobians(
        snapshot, pairs, sliding_free, include_geometric, variant, sliding_contacts == "free"
    )
    hessian, gamma, d_q, d_g = assemble(
        k_pair[used], j_sigma[used], pairs.branch[used], rod_i[used], rod_j[used], n_rods, area,
        stress, include_geometric,
    )  # fmt: skip
    return NetworkMatrices(
        hessian=hessian,
        strain_coupling=gamma,
        stress_dof=d_q,
        stress_strain=d_g,
        stress=stress,
        used_pairs=used,
        kept_rods=keep_rod,
        cluster=labels,
        sliding_free=sliding_free,
        unbalanced_force=float(unbalanced),
    )
