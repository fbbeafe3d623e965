"""Linear response of a network of *flexible* (bonded) rods on disc degrees of freedom (numpy).

The frozen-network version of the bonded-rod model of docs/science/dem-model.md §1.7: every disc
is a body (x, y, θ); neighbouring discs of a rod are joined by a bond in its reference state (the
stored rigid rod, straight); inter-rod contacts and long-range pairs act between discs exactly as
in :mod:`dem_taichi.response.linear` (disc-centred levers). The result is the zero-amplitude
stiffness dσ/dε of the network *had its rods been bonded chains*, at the stored forces.

Bond between disc g = (rod r, s) and h = (r, s + 1), reference length s_0 (the spacing),
d = x_h − x_g:
    θ_m = (θ_g + θ_h)/2, a_m = (cos θ_m, sin θ_m), t_m = ẑ × a_m
    e_n = d·a_m − s_0   (stretch, stiffness k_bn)
    e_t = d·t_m         (shear, k_bt; linearised: (u_h − u_g)·t − (s_0/2)(φ_g + φ_h))
    e_b = θ_h − θ_g     (bending, κ_b)
    U_b = λ·e + ½ (k_bn e_n² + k_bt e_t² + κ_b e_b²)
These measures vanish exactly on rigid motions of the pair (objective), so the bonds constrain
exactly to a rigid rod as their stiffness → ∞. λ = (λ_n, λ_t, λ_b) are the bond *pre-forces*:
with ``pre_force = "equilibrium"`` (default) they are the internal forces of the stored rigid rod
(statically determinate along the chain: λ_n, λ_t = −(Σ_{k≤s} F_k)·(a, t),
λ_b^s = λ_b^{s−1} − τ_s − (s_0/2)(λ_t^{s−1} + λ_t^s), F_k, τ_k the inter-rod force and torque on
disc k about its centre), so every disc is in equilibrium and the response is exact; their
geometric terms λ·∇²e make the rigid limit reproduce :func:`linear_response` exactly (a stiff
penalty with the constraint's Lagrange multiplier). ``pre_force = "none"`` drops them (discs then
not in equilibrium: an approximation, stated in the result).

Stress: σ = (1/A) Σ_all pairs f ⊗ (x_i − x_j − shift) over inter-rod pairs and bonds (disc-level
branch vectors; bonds never cross the cell boundary since discs are placed from their rod's
centroid). In equilibrium it equals the engine's centroid-branch stress (both reduce to
−(1/A) Σ f ⊗ shift), and so do their relaxed derivatives.

Bending compliance of one bond: a moment M across it turns it by M/κ_b; a bonded chain of n
discs under a three-point load P (ends supported) deflects by
δ = P Σ_bonds [(x_k/2)²/κ_b + 1/(4 k_bt)], x_k the distance of bond k's midpoint from the nearer
end disc (Castigliano on M_k = P x_k/2, V_k = P/2) — the closed form the tests use.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Literal

import numpy as np

from dem_taichi.physics import forcelaw
from dem_taichi.response.linear import (
    ENGINE_STIFFNESS,
    LinearResponse,
    NetworkSnapshot,
    StiffnessVariant,
    assemble,
    kept_network,
    pair_jacobians,
    relaxed_response,
    rolling_terms,
)

__all__ = [
    "BondStiffness",
    "bond_pre_forces",
    "chain_stiffness",
    "flexible_response",
    "three_point_compliance",
]


@dataclass(frozen=True)
class BondStiffness:
    """Springs of the intra-rod bonds (docs/science/dem-model.md §1.7), DEM units.

    Attributes:
        normal: k_bn [force/length], stretch of the centre distance.
        shear: k_bt [force/length], relative transverse displacement at the bond midpoint
            (lever s_0/2 to each disc).
        bending: κ_b [force·length/rad], relative rotation of the two discs.
        pre_force: "equilibrium" (the stored rigid rod's internal forces; exact) or "none".
    """

    normal: float
    shear: float
    bending: float
    pre_force: Literal["equilibrium", "none"] = "equilibrium"

    def __post_init__(self) -> None:
        for name in ("normal", "shear", "bending"):
            value = float(getattr(self, name))
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(
                    f"BondStiffness.{name} = {value!r}: need a finite value > 0 (rigid rods: "
                    "use dem_taichi.response.linear.linear_response)"
                )
            object.__setattr__(self, name, value)
        if self.pre_force not in ("equilibrium", "none"):
            raise ValueError(
                f"BondStiffness.pre_force = {self.pre_force!r}: allowed 'equilibrium' or 'none'"
            )

    @classmethod
    def relative(
        cls, k_n: float, diameter: float = 1.0, normal: float = 1.0, shear: float = 1.0,
        bending: float = 1.0, pre_force: Literal["equilibrium", "none"] = "equilibrium",
    ) -> BondStiffness:  # fmt: skip
        """Bonds from ratios: k_bn = normal k_n, k_bt = shear k_n, κ_b = bending k_n d²."""
        return cls(normal * k_n, shear * k_n, bending * k_n * diameter**2, pre_force)


def _rod_frames(snapshot: NetworkSnapshot):
    angle = snapshot.rod_angle
    axis = np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    return axis, np.stack([-axis[:, 1], axis[:, 0]], axis=-1)


def disc_forces_and_torques(snapshot: NetworkSnapshot, pairs: forcelaw.PairForces):
    """Inter-rod force (N n_s, 2) and torque about its own centre (N n_s,) on every disc.

    Both discs of a pair get the torque −(r/2) × f (contact point at the overlap midpoint);
    the rolling couple adds M to disc i and −M to disc j.
    """
    n_discs = snapshot.n_rods * snapshot.n_spheres
    discs = np.concatenate([snapshot.pair_i, snapshot.pair_j])
    force = np.stack(
        [
            np.bincount(discs, np.concatenate([pairs.force[:, a], -pairs.force[:, a]]), n_discs)
            for a in range(2)
        ],
        axis=1,
    )
    moment = -0.5 * forcelaw.cross(pairs.separation, pairs.force)
    roll = pairs.rolling_moment
    torque = np.bincount(discs, np.concatenate([moment + roll, moment - roll]), n_discs)
    return force, torque


def bond_pre_forces(snapshot: NetworkSnapshot, pairs: forcelaw.PairForces | None = None):
    """Internal forces λ (N, n_s − 1, 3) = (λ_n, λ_t, λ_b) of the stored rigid rods' bonds.

    Returns (λ, residual): residual (N, 3) is the force and torque left on the last disc, i.e.
    the rod's unbalanced force and torque (0 in exact equilibrium).
    """
    pairs = forcelaw.pair_forces(snapshot) if pairs is None else pairs
    n_rods, n_s, s0 = snapshot.n_rods, snapshot.n_spheres, snapshot.spacing
    force, torque = disc_forces_and_torques(snapshot, pairs)
    force = force.reshape(n_rods, n_s, 2)
    torque = torque.reshape(n_rods, n_s)
    axis, tangent = _rod_frames(snapshot)
    lam = np.zeros((n_rods, max(n_s - 1, 0), 3))
    cumulative = np.zeros((n_rods, 2))
    previous = np.zeros((n_rods, 3))
    for s in range(n_s - 1):
        cumulative = cumulative + force[:, s]
        lam[:, s, 0] = -np.sum(cumulative * axis, axis=-1)
        lam[:, s, 1] = -np.sum(cumulative * tangent, axis=-1)
        lam[:, s, 2] = previous[:, 2] - torque[:, s] - 0.5 * s0 * (previous[:, 1] + lam[:, s, 1])
        previous = lam[:, s]
    last = n_s - 1
    residual = np.zeros((n_rods, 3))
    residual[:, :2] = force[:, last] - previous[:, 0:1] * axis - previous[:, 1:2] * tangent
    residual[:, 2] = torque[:, last] + 0.5 * s0 * previous[:, 1] - previous[:, 2]
    return lam, residual


def bond_jacobians(axis, tangent, separation, lam, bonds: BondStiffness, include_geometric: bool):
    """Bond blocks in the form of :func:`dem_taichi.response.linear.pair_jacobians`.

    Body i is disc h (s + 1), body j disc g (s); w = (dd_x, dd_y, φ_h, φ_g), d = x_h − x_g.
    Returns K (B, 6, 4) = d(F_h, τ_h, F_g, τ_g)/dw, Jσ (B, 4, 4) = d(F_h ⊗ d)/dw and the static
    bond force F_h (B, 2) on disc h.
    """
    n_bonds = axis.shape[0]
    half = 0.5 * np.sum(separation * axis, axis=-1)  # s_0/2 (d·a_m/2)
    d_t = np.sum(separation * tangent, axis=-1)  # 0 for a straight rod
    grad = np.zeros((n_bonds, 3, 4))  # ∂(e_n, e_t, e_b)/∂(d_x, d_y, θ_h, θ_g)
    grad[:, 0, :2] = axis
    grad[:, 0, 2:] = 0.5 * d_t[:, None]
    grad[:, 1, :2] = tangent
    grad[:, 1, 2:] = -half[:, None]
    grad[:, 2, 2] = 1.0
    grad[:, 2, 3] = -1.0
    k_diag = np.array([bonds.normal, bonds.shear, bonds.bending])
    hess = np.einsum("bek,e,bel->bkl", grad, k_diag, grad)
    geometric = 1.0 if include_geometric else 0.0
    if include_geometric:
        l_n, l_t = lam[:, 0], lam[:, 1]
        for col in (2, 3):
            # ∂²e_n/∂d∂θ = ½ t_m, ∂²e_t/∂d∂θ = −½ a_m
            cross_term = 0.5 * (l_n[:, None] * tangent - l_t[:, None] * axis)
            hess[:, :2, col] += cross_term
            hess[:, col, :2] += cross_term
        # ∂²e_n/∂θ∂θ = −¼ d·a_m, ∂²e_t/∂θ∂θ = −¼ d·t_m (each of the four θ pairs)
        hess[:, 2:, 2:] += (-0.5 * half * l_n - 0.25 * d_t * l_t)[:, None, None]
    k = np.empty((n_bonds, 6, 4))
    k[:, 0:2] = -hess[:, 0:2]
    k[:, 2] = -hess[:, 2]
    k[:, 3:5] = hess[:, 0:2]
    k[:, 5] = -hess[:, 3]
    force_h = -(lam[:, 0:1] * axis + lam[:, 1:2] * tangent)
    j_sigma = np.einsum("pak,pb->pabk", k[:, 0:2], separation)
    for a in range(2):
        for bb in range(2):
            j_sigma[:, a, bb, bb] += geometric * force_h[:, a]
    return k, j_sigma.reshape(n_bonds, 4, 4), force_h


def _bond_geometry(snapshot: NetworkSnapshot):
    """Per bond (rod-major, s = 0..n_s−2): disc h, disc g, axis, tangent, d = x_h − x_g."""
    n_rods, n_s = snapshot.n_rods, snapshot.n_spheres
    discs = forcelaw.disc_positions(snapshot.rod_position, snapshot.rod_angle, n_s,
                                    snapshot.spacing)  # fmt: skip
    axis, tangent = _rod_frames(snapshot)
    g = (np.arange(n_rods)[:, None] * n_s + np.arange(n_s - 1)[None, :]).ravel()
    h = g + 1
    rod = g // n_s
    return h, g, axis[rod], tangent[rod], discs[h] - discs[g]


def flexible_response(
    snapshot: NetworkSnapshot,
    bonds: BondStiffness,
    sliding_contacts: Literal["free", "stuck"] = "stuck",
    include_geometric: bool = True,
    variant: StiffnessVariant = ENGINE_STIFFNESS,
    regularisation: float = 1e-10,
    stability: bool = False,
) -> LinearResponse:
    """Zero-amplitude stiffness of the network with its rods as bonded chains of discs.

    Args as :func:`dem_taichi.response.linear.linear_response` (``sliding_contacts`` defaults to
    "stuck", as the protocol's probes), plus ``bonds``. Rods are pruned as rigid rods would be
    (rattlers, dangling rods, finite clusters; a rod with two pairs still bends, but a dangling
    one carries no force either way). ``solver.n_dof`` counts disc DOFs.
    """
    if sliding_contacts not in ("free", "stuck"):
        raise ValueError(f"sliding_contacts = {sliding_contacts!r}: allowed 'free' or 'stuck'")
    if not (np.isfinite(regularisation) and regularisation > 0.0):
        raise ValueError(f"regularisation = {regularisation!r}: need a finite value > 0")
    start = time.perf_counter()
    n_rods, n_s = snapshot.n_rods, snapshot.n_spheres
    n_discs = n_rods * n_s
    pairs = forcelaw.pair_forces(snapshot)
    area = float(np.prod(snapshot.cell_lengths))
    active = pairs.in_contact | (pairs.normal_force != 0.0) | (pairs.normal_stiffness != 0.0)
    keep_rod, used, labels = kept_network(snapshot, active)
    flagged = (snapshot.sliding | pairs.sliding) & pairs.in_contact
    sliding_free = flagged if sliding_contacts == "free" else np.zeros_like(flagged)

    zero = np.zeros((snapshot.n_pairs, 2))
    kappa, slope = rolling_terms(snapshot, pairs, sliding_contacts == "free", variant)
    k_pair, j_pair = pair_jacobians(
        pairs, zero, zero, pairs.separation, variant.normal_stiffness(snapshot, pairs),
        variant.k_t(snapshot), snapshot.mu, snapshot.k_n, sliding_free, include_geometric,
        kappa, slope,
    )  # fmt: skip

    lam, residual = bond_pre_forces(snapshot, pairs)
    if bonds.pre_force == "none":
        lam = np.zeros_like(lam)
    h, g, axis, tangent, separation = _bond_geometry(snapshot)
    lam = lam.reshape(-1, 3)
    bond_kept = keep_rod[g // n_s]
    k_bond, j_bond, force_h = bond_jacobians(
        axis[bond_kept], tangent[bond_kept], separation[bond_kept], lam[bond_kept], bonds,
        include_geometric,
    )  # fmt: skip

    stress = (
        np.einsum("pa,pb->ab", pairs.force[used], pairs.separation[used])
        + np.einsum("pa,pb->ab", force_h, separation[bond_kept])
    ) / area
    # pairs between pruned rods carry stress in equilibrium only through finite clusters (zero)
    # and rattlers (no force); keep the engine's full static stress for the area term
    stress_all = np.einsum("pa,pb->ab", pairs.force, pairs.branch) / area
    hessian, gamma, d_q, d_g = assemble(
        np.concatenate([k_pair[used], k_bond]),
        np.concatenate([j_pair[used], j_bond]),
        np.concatenate([pairs.separation[used], separation[bond_kept]]),
        np.concatenate([snapshot.pair_i[used], h[bond_kept]]),
        np.concatenate([snapshot.pair_j[used], g[bond_kept]]),
        n_discs, area, stress_all if bonds.pre_force == "equilibrium" else stress,
        include_geometric,
    )  # fmt: skip

    keep_dof = np.repeat(np.repeat(keep_rod, n_s), 3)
    rod_i, rod_j = snapshot.pair_i // n_s, snapshot.pair_j // n_s
    count = np.bincount(rod_i[used], minlength=n_rods) + np.bincount(rod_j[used], minlength=n_rods)
    pinned = []
    for label in np.unique(labels[keep_rod]):
        members = np.flatnonzero(labels == label)
        rod = int(members[np.argmax(count[members])])
        pinned.append(rod)
        disc = rod * n_s + n_s // 2
        keep_dof[3 * disc : 3 * disc + 2] = False
    force_scale = np.mean(np.linalg.norm(pairs.force[active], axis=-1)) if np.any(active) else 0.0
    unbalanced = float(np.max(np.abs(residual)) / force_scale) if force_scale > 0.0 else 0.0
    return relaxed_response(
        hessian, gamma, d_q, d_g, stress_all, keep_dof, regularisation, start,
        n_pairs_used=int(np.count_nonzero(used)), pinned=pinned, keep_rod=keep_rod,
        unbalanced_force=unbalanced, sliding_contacts=sliding_contacts,
        include_geometric=include_geometric, stability=stability,
    )  # fmt: skip


def chain_stiffness(n_spheres: int, spacing: float, angle: float, bonds: BondStiffness):
    """Stiffness matrix (3n, 3n) of one free bonded chain (no pre-force), DOFs (x, y, θ) per disc.

    H = −∂R/∂q from the same bond blocks that :func:`flexible_response` assembles.
    """
    axis = np.tile([np.cos(angle), np.sin(angle)], (n_spheres - 1, 1))
    tangent = np.stack([-axis[:, 1], axis[:, 0]], axis=-1)
    separation = spacing * axis
    lam = np.zeros((n_spheres - 1, 3))
    k_bond, _, _ = bond_jacobians(axis, tangent, separation, lam, bonds, include_geometric=True)
    h = np.arange(1, n_spheres)
    g = h - 1
    hessian, _, _, _ = assemble(
        k_bond, np.zeros((n_spheres - 1, 4, 4)), separation, h, g, n_spheres, 1.0,
        np.zeros((2, 2)), include_geometric=False,
    )  # fmt: skip
    return hessian.toarray()


def three_point_compliance(n_spheres: int, spacing: float, bonds: BondStiffness) -> float:
    """Closed-form δ/P of a bonded chain (odd n) loaded by P at the middle disc, P/2 at each end.

    Castigliano on the bond section forces M_k = P x_k/2, V_k = P/2 (see the module docstring).
    """
    if n_spheres < 3 or n_spheres % 2 == 0:
        raise ValueError(f"n_spheres = {n_spheres}: the three-point load needs an odd n >= 3")
    x = (np.arange(n_spheres - 1) + 0.5) * spacing
    x = np.minimum(x, (n_spheres - 1) * spacing - x)
    return float(np.sum((0.5 * x) ** 2 / bonds.bending + 0.25 / bonds.shear))
