"""Linear-response (zero-amplitude) elastic stiffness of a rod network (numpy/scipy, no Taichi).

Defines :func:`linear_response`, the linear-response probe of docs/science/dem-model.md §1.6:
the exact derivative dσ/dε of the engine's stress definition after relaxation to
force-and-torque equilibrium, i.e. the zero-amplitude limit of the dynamic strain probe, on a
:class:`NetworkSnapshot` (the numpy picture of a static network that the engine exports,
``Simulation.snapshot()``; defined in :mod:`dem_taichi.physics.snapshot`, re-exported here).

Symbols (DEM units; see :mod:`dem_taichi.physics.forcelaw` for the pair laws)
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
import scipy.sparse.linalg as sparse_linalg

from dem_taichi.physics.snapshot import NetworkSnapshot
from dem_taichi.response.stiffness_matrices import (
    ENGINE_STIFFNESS,
    NetworkMatrices,
    StiffnessVariant,
    assemble,
    kept_network,
    network_matrices,
    pair_jacobians,
    rolling_terms,
)

# the matrices (stiffness_matrices) and the snapshot (snapshot) are defined below this module
# and re-exported from here, where they were before
__all__ = [
    "ENGINE_STIFFNESS",
    "LinearResponse",
    "NetworkMatrices",
    "NetworkSnapshot",
    "SolverInfo",
    "StiffnessVariant",
    "assemble",
    "kept_network",
    "linear_response",
    "negative_modes",
    "network_matrices",
    "pair_jacobians",
    "relaxed_response",
    "rolling_terms",
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
