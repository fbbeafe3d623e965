"""Linear response of a network of *bonded* rods as the engine holds it (numpy, no Taichi).

The zero-amplitude stiffness dσ/dε of a state of the bonded-rod model (``[particles] rod_model =
"bonded"``, docs/science/dem-model.md §1.7): every disc a body (x, y, θ), inter-rod (and non-bonded
intra-rod) pairs as in :mod:`dem_taichi.response.linear` with disc-centred levers, and every intact
bond with its Hessian at the *current* deformation and its current forces as pre-forces (Λ = k e,
the geometric terms of :func:`dem_taichi.response.flexible.bond_jacobians`). So the response is
exact for the bonded state, checked against the engine's dynamic probes.

Pruning works on *fragments* (the pieces of a rod held together by intact bonds: a whole rod
unless a bond broke): a fragment with at most one active pair to other fragments is a rattler,
non-spanning clusters of fragments are dropped, as rigid rods are in the rigid response.

:func:`network_response` is the one entry of the probes and the servo: it picks this response
for a snapshot with bonds and :func:`dem_taichi.response.linear.linear_response` otherwise.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Literal

import numpy as np

from dem_taichi.physics import forcelaw
from dem_taichi.physics.bonds import BondParameters, bond_forces
from dem_taichi.response.flexible import BondStiffness, bond_jacobians, disc_forces_and_torques
from dem_taichi.response.linear import (
    ENGINE_STIFFNESS,
    LinearResponse,
    NetworkSnapshot,
    StiffnessVariant,
    assemble,
    kept_network,
    linear_response,
    pair_jacobians,
    relaxed_response,
    rolling_terms,
)

__all__ = ["bond_state", "bonded_response", "fragments", "network_response"]


def network_response(
    snapshot: NetworkSnapshot,
    sliding_contacts: Literal["free", "stuck"] = "free",
    include_geometric: bool = True,
    regularisation: float = 1e-10,
    variant: StiffnessVariant = ENGINE_STIFFNESS,
    stability: bool = False,
) -> LinearResponse:
    """The linear response of a snapshot of either rod model (same arguments as
    :func:`dem_taichi.response.linear.linear_response`)."""
    respond = linear_response if snapshot.bonds is None else bonded_response
    return respond(
        snapshot, sliding_contacts=sliding_contacts, include_geometric=include_geometric,
        regularisation=regularisation, variant=variant, stability=stability,
    )  # fmt: skip


@dataclass(frozen=True)
class _Fragments:
    """The fragments as the bodies of :func:`kept_network` (a ``PairGraph``: one disc each)."""

    n_rods: int
    n_spheres: int
    pair_i: np.ndarray
    pair_j: np.ndarray
    pair_shift: np.ndarray
    cell_lengths: np.ndarray


def fragments(n_discs: int, g: np.ndarray, intact: np.ndarray) -> np.ndarray:
    """Label (M,) of the fragment of every disc: discs joined by intact bonds share a label."""
    joined = np.zeros(n_discs, dtype=bool)  # disc d joined to d − 1
    joined[g[intact] + 1] = True
    return np.cumsum(~joined) - 1


def bond_state(snapshot: NetworkSnapshot):
    """Geometry and forces of the intact bonds of a bonded snapshot, from the bond law of
    :func:`dem_taichi.physics.bonds.bond_forces` (no dashpots: a static state).

    Returns (h, g, axis a_m, tangent t_m, λ = (k_n e_n, k_t e_t, k_b e_b), the
    :class:`dem_taichi.physics.bonds.BondResult`; its ``separation`` is d = x_h − x_g).
    """
    bonds = snapshot.bonds
    if bonds is None:
        raise ValueError("bond_state needs a snapshot of bonded rods (snapshot.bonds)")
    g = bonds.g[bonds.intact]
    law = BondParameters(bonds.k_n, bonds.k_t, bonds.k_b, 0.0, 0.0, 0.0, bonds.rest_length)
    # the snapshot's chains are contiguous: the minimum image leaves every bond vector as it is
    result = bond_forces(snapshot.rod_position, snapshot.rod_angle, g, snapshot.cell_lengths, law)
    theta = snapshot.rod_angle
    theta_m = 0.5 * (theta[g] + theta[g + 1])
    axis = np.stack([np.cos(theta_m), np.sin(theta_m)], axis=-1)
    tangent = np.stack([-axis[:, 1], axis[:, 0]], axis=-1)
    lam = result.strain * np.array([bonds.k_n, bonds.k_t, bonds.k_b])
    return g + 1, g, axis, tangent, lam, result


def bonded_response(
    snapshot: NetworkSnapshot,
    sliding_contacts: Literal["free", "stuck"] = "free",
    include_geometric: bool = True,
    regularisation: float = 1e-10,
    variant: StiffnessVariant = ENGINE_STIFFNESS,
    stability: bool = False,
) -> LinearResponse:
    """Zero-amplitude stiffness dσ/dε of a bonded-rod network (arguments as
    :func:`dem_taichi.response.linear.linear_response`; ``solver.n_dof`` counts disc DOFs)."""
    if snapshot.bonds is None:
        raise ValueError("bonded_response needs a snapshot of bonded rods (snapshot.bonds)")
    if sliding_contacts not in ("free", "stuck"):
        raise ValueError(f"sliding_contacts = {sliding_contacts!r}: allowed 'free' or 'stuck'")
    if not (np.isfinite(regularisation) and regularisation > 0.0):
        raise ValueError(f"regularisation = {regularisation!r}: need a finite value > 0")
    start = time.perf_counter()
    bonds = snapshot.bonds
    n_discs = snapshot.n_rods
    area = float(np.prod(snapshot.cell_lengths))
    pairs = forcelaw.pair_forces(snapshot)
    active = pairs.in_contact | (pairs.normal_force != 0.0) | (pairs.normal_stiffness != 0.0)
    flagged = (snapshot.sliding | pairs.sliding) & pairs.in_contact
    sliding_free = flagged if sliding_contacts == "free" else np.zeros_like(flagged)
    zero = np.zeros((snapshot.n_pairs, 2))
    kappa, slope = rolling_terms(snapshot, pairs, sliding_contacts == "free", variant)
    k_pair, j_pair = pair_jacobians(
        pairs, zero, zero, pairs.separation, variant.normal_stiffness(snapshot, pairs),
        variant.k_t(snapshot), snapshot.mu, snapshot.k_n, sliding_free, include_geometric,
        kappa, slope,
    )  # fmt: skip

    # fragments (rods, or their pieces) are pruned as rigid rods are
    fragment = fragments(n_discs, bonds.g, bonds.intact)
    frag_i, frag_j = fragment[snapshot.pair_i], fragment[snapshot.pair_j]
    proxy = _Fragments(
        n_rods=int(fragment.max()) + 1 if n_discs else 0, n_spheres=1, pair_i=frag_i,
        pair_j=frag_j, pair_shift=snapshot.pair_shift, cell_lengths=snapshot.cell_lengths,
    )  # fmt: skip
    keep_fragment, _, labels = kept_network(proxy, active & (frag_i != frag_j))
    keep_disc = keep_fragment[fragment]
    used = active & keep_disc[snapshot.pair_i] & keep_disc[snapshot.pair_j]

    h, g, axis, tangent, lam, law = bond_state(snapshot)
    d = law.separation
    stiffness = BondStiffness(bonds.k_n, bonds.k_t, bonds.k_b)
    k_all, j_all, force_all = bond_jacobians(axis, tangent, d, lam, stiffness, include_geometric)
    kept = keep_disc[g]
    stress_all = (
        np.einsum("pa,pb->ab", pairs.force, pairs.separation) + np.einsum("pa,pb->ab", force_all, d)
    ) / area
    hessian, gamma, d_q, d_g = assemble(
        np.concatenate([k_pair[used], k_all[kept]]),
        np.concatenate([j_pair[used], j_all[kept]]),
        np.concatenate([pairs.separation[used], d[kept]]),
        np.concatenate([snapshot.pair_i[used], h[kept]]),
        np.concatenate([snapshot.pair_j[used], g[kept]]),
        n_discs, area, stress_all, include_geometric,
    )  # fmt: skip

    # pin the translations of one disc of the best-connected fragment of each cluster
    keep_dof = np.repeat(keep_disc, 3)
    count = np.bincount(frag_i[used], minlength=proxy.n_rods) + np.bincount(
        frag_j[used], minlength=proxy.n_rods
    )
    pinned = []
    for label in np.unique(labels[keep_fragment]):
        members = np.flatnonzero(labels == label)
        best = int(members[np.argmax(count[members])])
        discs = np.flatnonzero(fragment == best)
        disc = int(discs[len(discs) // 2])
        pinned.append(disc)
        keep_dof[3 * disc : 3 * disc + 2] = False
    residual = _residual_forces(snapshot, pairs, h, g, law)
    force_scale = np.mean(np.linalg.norm(pairs.force[active], axis=-1)) if np.any(active) else 0.0
    unbalanced = float(np.max(np.abs(residual[keep_disc])) / force_scale) if force_scale else 0.0
    return relaxed_response(
        hessian, gamma, d_q, d_g, stress_all, keep_dof, regularisation, start,
        n_pairs_used=int(np.count_nonzero(used)), pinned=pinned, keep_rod=keep_disc,
        unbalanced_force=unbalanced, sliding_contacts=sliding_contacts,
        include_geometric=include_geometric, stability=stability,
    )  # fmt: skip


def _residual_forces(snapshot, pairs, h, g, law):
    """Net force and torque (M, 3) on every disc from its pairs and bonds (0 in equilibrium);
    ``law`` the bonds' :class:`dem_taichi.physics.bonds.BondResult`."""
    n = snapshot.n_rods
    force, torque = disc_forces_and_torques(snapshot, pairs)
    for a in range(2):
        force[:, a] += np.bincount(h, law.force_h[:, a], n) - np.bincount(g, law.force_h[:, a], n)
    torque += np.bincount(h, law.torque_h, n) + np.bincount(g, law.torque_g, n)
    return np.column_stack([force, torque])
