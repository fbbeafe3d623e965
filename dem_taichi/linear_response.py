"""Linear-response (zero-amplitude) elastic stiffness of a rod network (numpy/scipy, no Taichi).

Defines :func:`linear_response`, the linear-response probe of ``shared/design/model.md`` §1.6:
the exact derivative dσ/dε of the engine's stress definition after relaxation to
force-and-torque equilibrium, i.e. the zero-amplitude limit of the dynamic strain probe, on a
:class:`NetworkSnapshot` (the numpy picture of a static network that the engine exports,
``Simulation.snapshot()``; defined in :mod:`dem_taichi.snapshot`, re-exported here).

Symbols (DEM units; see :mod:`dem_taichi.forcelaw` for the pair laws)
    q = (X_r, Y_r, θ_r)   rod DOFs (3 per rod); u, φ their non-affine increments
    G                     affine displacement gradient of the cell: X -> (I + G) X,
                          shift -> (I + G) shift; rod angles are not driven affinely (they relax).
                          Compression-positive strain ε: G = -ε (tension-convention gradient).
    r, ρ, n, t            pair vector x_i - x_j - shift, its length, normal, tangent t = ẑ × n
    l                     centroid branch vector X_P - X_Q - shift
    w = (dl_x, dl_y, φ_P, φ_Q)   the increments a pair feels; dl = G l + u_P - u_Q
    B                     dr = B w: B = [I | o_i ẑ×a_P | -o_j ẑ×a_Q]
    N, k_N                total normal force (repulsive > 0) and -dN/dρ (k_n + s k_a + vdW)
    T                     tangential force along t (F_t = T t = -k_t ξ_t t)
    R                     generalised forces (F_x, F_y, torque) on every rod
    H = -∂R/∂q            stiffness matrix ("Hessian"; symmetric when all forces are conservative)
    Γ = ∂R/∂G             mixed DOF-strain block
    σ = (1/A) Σ f ⊗ l     engine stress, compression positive, A = det(I + G) A_0

Linearised pair force (exact first derivatives of f = N n + T t):
    df = -k_N n (n·dr) + (N/ρ) t (t·dr) - (T/ρ) n (t·dr) + t dT,
    stuck contact:   dT = -k_t (t·dr - ρ (φ_P + φ_Q)/2)    (ξ_t += tangential relative displacement
                     of the contact points, the spring vector turning with n as in the engine);
    sliding, "free": dT = -sign(T) μ k_n (n·dr)            (force stays on the Coulomb cap μ k_n δ).
Torques about the centroids, contact point x_c = x_i - r/2: τ_P = h_P × f, h_P = o_i a_P - r/2;
τ_Q = -h_Q × f, h_Q = o_j a_Q + r/2; their derivatives include dh × f (lever-arm terms).
The terms proportional to the current forces (N/ρ, T/ρ, dh × f, and in the stress f ⊗ dl and
-tr(G) σ) are the geometric (pre-stress) terms; ``include_geometric=False`` drops all of them.

Relaxation and stiffness (all exact at first order):
    dR = -H dq + Γ dG = 0  ->  dq = H⁻¹ Γ dG
    dσ/dG = D_G + D_q H⁻¹ Γ,  D_G = -σ ⊗ I + (1/A) Σ ∂(f ⊗ l)/∂G|_affine,  D_q = (1/A) Σ ∂(f ⊗ l)/∂q
For conservative forces (no tangential springs) H is symmetric, D_q = Γᵀ/A (both are mixed
second derivatives of the energy, since A σ = -∂U/∂G), and this is the familiar
C = (1/A)[Born term - Γᵀ H⁻¹ Γ] plus the stress terms.

Zero modes: (i) rods with at most one active pair are pruned iteratively (exact: in equilibrium
such a pair carries no force and the dangling rod follows its partner, so it adds nothing to the
relaxed response; a rod with no pair is a rattler), then clusters that do not span the periodic
cell (found by unwrapping image labels along the pairs) are pruned too (exact: relaxation undoes
their affine displacement, so they add only their static stress to the -tr(G) σ area term, and
that stress Σ f ⊗ l = Σ_P F_P ⊗ X_P vanishes for a finite cluster in equilibrium);
(ii) the rigid translations of every remaining cluster are removed exactly by pinning the
translation of its best-connected rod (every pair exerts equal and opposite forces, so the rows
of the pinned DOFs follow from the others); DOFs with a zero row and column of H (below 1e-12 of
the largest row sum, e.g. the spin of single-disc bodies without friction) are left out;
(iii) the reduced H is factorised with SuperLU; if it is exactly singular (other floppy modes),
H + η s I is used with η = ``regularisation`` (relative) and
s = max|diag H|: modes that the strain does not excite drop out as η -> 0 and the flag
``regularised`` is set in :class:`SolverInfo` (modes that it does excite make the response blow
up like 1/η: such a network is not rigid, and the residual/size of the result shows it).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sparse
import scipy.sparse.csgraph as csgraph
import scipy.sparse.linalg as sparse_linalg

from dem_taichi import forcelaw
from dem_taichi.snapshot import NetworkSnapshot

__all__ = [
    "LinearResponse",
    "NetworkMatrices",
    "NetworkSnapshot",
    "SolverInfo",
    "linear_response",
    "network_matrices",
    "voigt_stiffness",
]


# --------------------------------------------------------------------------------------------
# Linear response
# --------------------------------------------------------------------------------------------

_FLAT = ("xx", "xy", "yx", "yy")  # flattening of 2x2 tensors: index 2a + b


@dataclass(frozen=True)
class SolverInfo:
    """How the non-affine relaxation was solved.

    Attributes:
        n_dof: rod DOFs of the reduced system (3 per kept rod minus 2 pinned translations,
            minus decoupled DOFs).
        n_decoupled_dof: DOFs of kept rods with an all-zero row and column of H, left out.
        n_pairs_used: active pairs between kept rods.
        pinned_rods: one rod per kept (spanning) cluster whose translation was fixed, removing
            the rigid translations of that cluster.
        regularised: True if H was exactly singular and H + η s I was solved instead.
        regularisation: η s actually added (0 when not regularised).
        residual: max |H u - Γ| / max |Γ| of the solution.
        unbalanced_force: max |R| over rods (forces and torques) / mean |f| of active pairs;
            the response is exact only for an equilibrium (small value).
        stress_asymmetry: |dσ_xy - dσ_yx| / max |dσ| of the relaxed response (0 in equilibrium).
        seconds: wall time of the assembly and solve.
        n_negative_modes: negative eigenvalues of the symmetric part of the reduced H (Sylvester
            inertia of a symmetric-mode LU), only with ``stability=True``; > 0: the frozen
            network is not stable under its own forces (e.g. pre-stressed soft rods buckle) and
            its moduli mean nothing. -1 = not computed.
    """

    n_dof: int
    n_decoupled_dof: int
    n_pairs_used: int
    pinned_rods: np.ndarray
    regularised: bool
    regularisation: float
    residual: float
    unbalanced_force: float
    stress_asymmetry: float
    seconds: float
    n_negative_modes: int = -1


def negative_modes(matrix) -> int:
    """Number of negative eigenvalues of the symmetric part of a sparse matrix.

    SuperLU in symmetric mode (diagonal pivots only, the same permutation on rows and columns)
    gives P S Pᵀ = L U with U = D Lᵀ, and by Sylvester's law of inertia the negative entries of
    D count the negative eigenvalues. Returns -1 if the factorisation had to pivot off the
    diagonal (the count would not be an inertia) or failed.
    """
    sym = (0.5 * (matrix + matrix.T)).tocsc()
    try:
        factor = sparse_linalg.splu(
            sym, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
            options={"SymmetricMode": True},
        )  # fmt: skip
    except RuntimeError:
        return -1
    if not np.array_equal(factor.perm_r, factor.perm_c):
        return -1
    return int(np.count_nonzero(factor.U.diagonal() < 0.0))


@dataclass(frozen=True)
class LinearResponse:
    """Zero-amplitude elastic stiffness of a network (stress units, force/length).

    Voigt order (xx, yy, xy); Δσ = C Δε with σ and ε compression positive, ε_xy columns in
    engineering shear γ = 2 ε_xy, σ_xy the symmetric part.

    Attributes:
        stiffness: C (3, 3) after non-affine relaxation.
        affine_stiffness: the affine part (no relaxation, including the stress-definition terms).
        non_affine_stiffness: the relaxation correction, stiffness - affine_stiffness.
        tangent: (2, 2, 2, 2) dσ_ab/dG_cd for the tension-convention displacement gradient G
            (ε = -G), including rotations; the source of every modulus below.
        stress: σ (2, 2) of the snapshot, compression positive.
        e_oed_v: C_yyyy, constrained modulus for ε_yy with ε_xx fixed (= dynamic-probe E_oed,v).
        e_oed_h: C_xxxx.
        bulk_modulus: dp/dε_v with p = (σ_xx + σ_yy)/2, ε_v = ε_xx + ε_yy: (C11+C12+C21+C22)/4.
        pure_shear_modulus: ½ d(σ_xx - σ_yy)/d(ε_xx - ε_yy) = (C11 + C22 - C12 - C21)/4.
        simple_shear_modulus: dσ_xy/dγ under simple shear x += γ y (includes the rotation).
        voigt_shear_modulus: C_33 = dσ_xy/dγ for the symmetric shear ε_xy = ε_yx = γ/2.
        n_rattlers: rods pruned (no pair, dangling by one pair iteratively, or in a cluster that
            does not span the cell).
        rattlers: their indices.
        n_floppy_modes: estimate, LU pivots below 1e-8 max pivot of the solved matrix (0 if the
            exact factorisation succeeded without tiny pivots).
        sliding_contacts: "free" or "stuck"; include_geometric: whether pre-stress terms are in.
        solver: :class:`SolverInfo`.
    """

    stiffness: np.ndarray
    affine_stiffness: np.ndarray
    non_affine_stiffness: np.ndarray
    tangent: np.ndarray
    stress: np.ndarray
    e_oed_v: float
    e_oed_h: float
    bulk_modulus: float
    pure_shear_modulus: float
    simple_shear_modulus: float
    voigt_shear_modulus: float
    n_rattlers: int
    rattlers: np.ndarray
    n_floppy_modes: int
    sliding_contacts: str
    include_geometric: bool
    solver: SolverInfo


def voigt_stiffness(tangent: np.ndarray) -> np.ndarray:
    """Voigt C (3, 3) (xx, yy, xy; engineering γ) from T_abcd = dσ_ab/dG_cd, with ε = -G.

    Columns: ε_xx -> G_xx = -ε_xx; ε_yy -> G_yy = -ε_yy; γ -> G_xy = G_yx = -γ/2.
    Rows: σ_xx, σ_yy, (σ_xy + σ_yx)/2.
    """
    t = np.asarray(tangent, dtype=float).reshape(4, 4)
    columns = np.stack([-t[:, 0], -t[:, 3], -0.5 * (t[:, 1] + t[:, 2])], axis=1)
    return np.stack([columns[0], columns[3], 0.5 * (columns[1] + columns[2])], axis=0)


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
            for equal spheres as in model.md §1.7). It carries no force, hence no stress term;
            always stuck (no rolling cap μ_r |f_n|).
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
    rolling_stiffness: float = 0.0,
):  # fmt: skip
    """Per-pair K (P, 6, 4) = d(F_P, τ_P, F_Q, τ_Q)/dw and Jσ (P, 4, 4) = d(f ⊗ l)/dw.

    Bodies P, Q carry the two discs at offset vectors c_i = x_i - X_P and c_j = x_j - X_Q (rod
    bodies: c = o a; disc bodies: c = 0); ``branch`` l is the stress branch vector of each pair;
    ``normal_stiffness`` k_N, stuck-spring ``k_t`` and the Coulomb slope μ k_n of sliding
    contacts; ``rolling_stiffness`` κ_r at contacts (see :class:`StiffnessVariant`).
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
    if rolling_stiffness > 0.0:
        roll = np.where(pairs.in_contact, rolling_stiffness, 0.0)
        d_torque_i[:, 2] -= roll
        d_torque_i[:, 3] += roll
        d_torque_j[:, 2] += roll
        d_torque_j[:, 3] -= roll
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
                        variant: StiffnessVariant = ENGINE_STIFFNESS):  # fmt: skip
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
    return pair_jacobians(
        pairs, o_i[:, None] * axis_i, o_j[:, None] * axis_j, pairs.branch,
        variant.normal_stiffness(snapshot, pairs), variant.k_t(snapshot), snapshot.mu,
        snapshot.k_n, sliding_free, include_geometric, variant.rolling_stiffness,
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


def kept_network(snapshot: NetworkSnapshot, active: np.ndarray, prune_rattlers: bool = True):
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

    k_pair, j_sigma = _rod_pair_jacobians(snapshot, pairs, sliding_free, include_geometric, variant)
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


def linear_response(
    snapshot: NetworkSnapshot,
    sliding_contacts: Literal["free", "stuck"] = "free",
    include_geometric: bool = True,
    regularisation: float = 1e-10,
    variant: StiffnessVariant = ENGINE_STIFFNESS,
    stability: bool = False,
) -> LinearResponse:
    """Zero-amplitude stiffness dσ/dε of a network in force-and-torque equilibrium.

    Args:
        snapshot: the network (positions, pairs, tangential springs, sliding flags).
        sliding_contacts: "free": contacts at the Coulomb cap (snapshot flag, or |k_t ξ| above the
            cap) keep their tangential force on the cap μ k_n δ while the contact keeps sliding
            (the loading branch); "stuck": every contact, sliding or not, responds with its spring
            k_t (the reversal/unloading branch).
        include_geometric: keep the pre-stress terms (needed for the exact dσ/dε).
        regularisation: relative η used only if the reduced H is exactly singular.
        variant: stiffness changes at fixed forces (:class:`StiffnessVariant`; default: none).
        stability: also count the negative modes of H (``solver.n_negative_modes``).

    Returns: :class:`LinearResponse`. See the module docstring for the method.
    """
    if not (np.isfinite(regularisation) and regularisation > 0.0):
        raise ValueError(f"regularisation = {regularisation!r}: need a finite value > 0")
    start = time.perf_counter()
    matrices = network_matrices(snapshot, sliding_contacts, include_geometric, variant=variant)
    n_rods = snapshot.n_rods
    n_s = snapshot.n_spheres
    used = matrices.used_pairs
    keep_rod = matrices.kept_rods
    rod_i = snapshot.pair_i // n_s
    rod_j = snapshot.pair_j // n_s
    # reduced system: kept rods, translation of the best-connected rod of each cluster pinned
    keep_dof = np.repeat(keep_rod, 3)
    count = np.bincount(rod_i[used], minlength=n_rods) + np.bincount(rod_j[used], minlength=n_rods)
    pinned = []
    for label in np.unique(matrices.cluster[keep_rod]):
        members = np.flatnonzero(matrices.cluster == label)
        rod = int(members[np.argmax(count[members])])
        pinned.append(rod)
        keep_dof[3 * rod : 3 * rod + 2] = False
    return relaxed_response(
        matrices.hessian, matrices.strain_coupling, matrices.stress_dof, matrices.stress_strain,
        matrices.stress, keep_dof, regularisation, start,
        n_pairs_used=int(np.count_nonzero(used)), pinned=pinned, keep_rod=keep_rod,
        unbalanced_force=matrices.unbalanced_force, sliding_contacts=sliding_contacts,
        include_geometric=include_geometric, stability=stability,
    )  # fmt: skip


def relaxed_response(
    hessian, gamma, d_q, d_g, stress, keep_dof, regularisation: float, start: float, *,
    n_pairs_used: int, pinned, keep_rod, unbalanced_force: float, sliding_contacts: str,
    include_geometric: bool, stability: bool = False,
) -> LinearResponse:  # fmt: skip
    """Solve H dq = Γ on the kept DOFs and build the :class:`LinearResponse` (any body kind).

    ``keep_dof`` (n_dof,) bool: DOFs of kept bodies, pinned translations already removed; DOFs
    with a zero row and column of H are dropped here. ``start``: perf_counter at the assembly.
    """
    n_dof_all = hessian.shape[0]
    keep_dof = keep_dof.copy()
    # DOFs with a zero row and column of H are decoupled (e.g. the spin of a single-disc
    # "rod" without tangential forces): their displacement is arbitrary and changes nothing.
    # "Zero" is 1e-12 of the largest row sum: those terms cancel only to rounding.
    absolute = abs(hessian)
    column_sum = np.asarray(absolute.sum(axis=0)).ravel()
    row_sum = np.asarray(absolute.sum(axis=1)).ravel()
    threshold = 1e-12 * (float(row_sum.max()) if row_sum.size else 0.0)
    coupled = (column_sum > threshold) | (row_sum > threshold)
    n_decoupled = int(np.count_nonzero(keep_dof & ~coupled))
    keep_dof &= coupled
    index = np.flatnonzero(keep_dof)
    relaxation = np.zeros((n_dof_all, 4))
    regularised = False
    added = 0.0
    residual = 0.0
    n_floppy = 0
    n_negative = -1
    if index.size:
        reduced = hessian[index][:, index].tocsc()
        if stability:
            n_negative = negative_modes(reduced)
        rhs = gamma[index]
        try:
            factor = sparse_linalg.splu(reduced)
            solution = factor.solve(rhs)
            if not np.all(np.isfinite(solution)):
                raise RuntimeError("non-finite solution")
        except RuntimeError:
            regularised = True
            scale = float(np.max(np.abs(reduced.diagonal()))) or 1.0
            added = regularisation * scale
            reduced = (reduced + added * sparse.identity(index.size, format="csc")).tocsc()
            factor = sparse_linalg.splu(reduced)
            solution = factor.solve(rhs)
        pivots = np.abs(factor.U.diagonal())
        n_floppy = int(np.count_nonzero(pivots <= 1e-8 * pivots.max()))
        rhs_scale = float(np.max(np.abs(rhs))) or 1.0
        residual = float(np.max(np.abs(reduced @ solution - rhs))) / rhs_scale
        relaxation[index] = solution

    non_affine = d_q @ relaxation
    tangent = d_g + non_affine
    asymmetry_scale = float(np.max(np.abs(tangent))) or 1.0
    asymmetry = float(np.max(np.abs(tangent[1] - tangent[2]))) / asymmetry_scale

    stiffness = voigt_stiffness(tangent)
    info = SolverInfo(
        n_dof=int(index.size),
        n_decoupled_dof=n_decoupled,
        n_pairs_used=n_pairs_used,
        pinned_rods=np.asarray(pinned, dtype=np.int64),
        regularised=regularised,
        regularisation=added,
        residual=residual,
        unbalanced_force=unbalanced_force,
        stress_asymmetry=asymmetry,
        seconds=time.perf_counter() - start,
        n_negative_modes=n_negative,
    )
    return LinearResponse(
        stiffness=stiffness,
        affine_stiffness=voigt_stiffness(d_g),
        non_affine_stiffness=voigt_stiffness(non_affine),
        tangent=tangent.reshape(2, 2, 2, 2),
        stress=stress,
        e_oed_v=float(stiffness[1, 1]),
        e_oed_h=float(stiffness[0, 0]),
        bulk_modulus=float(0.25 * np.sum(stiffness[:2, :2])),
        pure_shear_modulus=float(
            0.25 * (stiffness[0, 0] + stiffness[1, 1] - stiffness[0, 1] - stiffness[1, 0])
        ),
        simple_shear_modulus=float(-0.5 * (tangent[1, 1] + tangent[2, 1])),
        voigt_shear_modulus=float(stiffness[2, 2]),
        n_rattlers=int(np.count_nonzero(~keep_rod)),
        rattlers=np.flatnonzero(~keep_rod),
        n_floppy_modes=n_floppy,
        sliding_contacts=sliding_contacts,
        include_geometric=include_geometric,
        solver=info,
    )
