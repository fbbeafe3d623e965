"""Reference pair laws of the rod DEM, in plain vectorised numpy (no Taichi).

This module is the independent reference against which the Taichi kernels are tested, and the
force evaluator of :mod:`dem_taichi.response.linear`. Every formula is from
docs/science/dem-model.md §1.2/§1.4 (cited below as [M]) and §1.8 (cited below as [I]).

Symbols (dimensionless DEM units: disc diameter d = 1, disc mass m = 1)
    x_i         disc centre; X_P, θ_P rod centroid and angle; a_P = (cos θ_P, sin θ_P)
    o_s         body-frame offset of disc s: (s - (n_s-1)/2) * spacing            [I]
    r_ij        x_i - x_j - shift, minimum-image pair vector; ρ = |r_ij|           [I]
    n           r_ij/ρ, unit normal pointing from j to i; t = (-n_y, n_x) its tangent
    δ           overlap d - ρ (contact when δ > 0); g = -δ surface gap             [M §1.2]
    f           scalar normal force on i along n, positive = repulsive             [M §1.2]
    k_n, γ_n    contact normal stiffness [force/length] and damping [force·time/length]
    ξ           tangential spring (a vector in the tangent plane) [length]
    k_t, γ_t, μ tangential stiffness, damping, Coulomb friction coefficient
    c           disc charge in {-1, 0, +1}; s = c_i c_j charge product
    F_max, k_a  long-range maximum force [force] and stiffness [force/length];
                pair values are the harmonic mean 2ab/(a+b) of the discs' species values [I]
    g_max       long-range range F_max/k_a [length]
    F_W, k_W    van der Waals-like maximum force and stiffness (global), g_W = F_W/k_W
    l_PQ        centroid branch vector X_P - X_Q - shift (same image as the disc pair) [I]
    σ           stress (force/length), compression positive: (1/A) Σ f_ij ⊗ l_PQ  [I, M §1.4]
    A           cell area L_x L_y

Conventions fixed here (the notes leave them open; the engine must match them):
    * The contact point of a disc pair is the midpoint x_c = x_i - r_ij/2 (for equal discs this is
      MercuryDPM's x_i - (R - δ/2) n). The tangential force acts there: torque on rod P is
      (x_c - X_P) × F_ij, on rod Q (image) (x_c - X_Q - shift) × (-F_ij).
    * The contact normal force is not clipped at zero: f_c = k_n δ - γ_n v_n as written in [M].
    * The Coulomb cap uses the contact normal force only: |F_t| <= μ |f_c| [M]. On slip the spring
      is reset so that the spring-dashpot force equals the capped force:
      ξ = -(F_t,capped + γ_t v_t)/k_t (= -F_t,capped/k_t without tangential damping).
    * "Kept in the tangent plane" is a projection ξ <- ξ - (ξ·n) n at the current normal, done
      before adding the increment v_t Δt.
    * Long-range and vdW forces act along the line of centres; branches use δ >= 0 (touching),
      0 < g <= g_max (linear decay, cut-off included), g > g_max (zero).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from dem_taichi.physics.attraction import are_partners
from dem_taichi.physics.rolling import rolling_moment
from dem_taichi.physics.snapshot import NetworkSnapshot

__all__ = [
    "PairForces",
    "PairParameters",
    "PotentialEnergy",
    "attracting_rod_pairs",
    "branch_vectors",
    "cap_force",
    "contact_normal_force",
    "contact_normal_stiffness",
    "contact_potential",
    "cross",
    "disc_offsets",
    "disc_positions",
    "harmonic_mean",
    "long_range_force",
    "long_range_potential",
    "long_range_stiffness",
    "pair_forces",
    "pair_parameters",
    "pair_separation",
    "potential_energy",
    "rod_forces_and_torques",
    "rod_inertia",
    "stress_from_forces",
    "tangential_force",
    "tangential_spring_step",
    "van_der_waals_force",
    "van_der_waals_potential",
    "van_der_waals_stiffness",
]


# --------------------------------------------------------------------------------------------
# Small pure laws (scalars or arrays, broadcast elementwise)
# --------------------------------------------------------------------------------------------


def harmonic_mean(a, b) -> np.ndarray:
    """Pair value 2ab/(a+b) of two species values [I]; 0 where a + b = 0 (equal values -> a)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    total = a + b
    safe = np.where(total > 0.0, total, 1.0)
    return np.where(total > 0.0, 2.0 * a * b / safe, 0.0)


def cross(a, b) -> np.ndarray:
    """2D cross product a_x b_y - a_y b_x of (..., 2) arrays."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def contact_normal_force(overlap, k_n: float, normal_velocity=0.0, gamma_n: float = 0.0):
    """Contact normal force f_c = k_n δ - γ_n v_n for δ > 0, else 0 [M §1.2].

    Args:
        overlap: δ = d - ρ [length].
        k_n: normal stiffness [force/length].
        normal_velocity: v_n = (v_i - v_j)·n at the contact [length/time], negative approaching.
        gamma_n: normal damping coefficient [force·time/length].
    Returns: f_c [force], positive repulsive, not clipped at zero.
    """
    overlap = np.asarray(overlap, dtype=float)
    force = k_n * overlap - gamma_n * np.asarray(normal_velocity, dtype=float)
    return np.where(overlap > 0.0, force, 0.0)


def contact_normal_stiffness(overlap, k_n: float):
    """-df_c/dρ = k_n for δ > 0, else 0 [force/length]."""
    return np.where(np.asarray(overlap, dtype=float) > 0.0, float(k_n), 0.0)


def contact_potential(overlap, k_n: float):
    """Contact energy ½ k_n δ² for δ > 0, else 0 [force·length] [I]."""
    overlap = np.asarray(overlap, dtype=float)
    return np.where(overlap > 0.0, 0.5 * k_n * overlap**2, 0.0)


def long_range_force(gap, f_max, k_a, charge_product):
    """Charged long-range normal force (three branches, sign by s = c_i c_j) [M §1.2 table].

    f = s F_max for g <= 0 (touching, δ >= 0); f = s F_max (1 - g/g_max) for 0 < g <= g_max;
    f = 0 for g > g_max, with g_max = F_max/k_a. Zero where F_max = 0 or s = 0.

    Args: gap g = ρ - d [length]; pair F_max [force]; pair k_a [force/length]; s in {-1, 0, 1}.
    Returns: f [force], positive repulsive.
    """
    gap, f_max, k_a, s = np.broadcast_arrays(
        np.asarray(gap, float), np.asarray(f_max, float), np.asarray(k_a, float),
        np.asarray(charge_product, float),
    )  # fmt: skip
    on = (f_max > 0.0) & (k_a > 0.0) & (s != 0.0)
    g_max = np.where(on, f_max / np.where(k_a > 0.0, k_a, 1.0), 0.0)
    decay = np.where(gap <= 0.0, 1.0, 1.0 - gap / np.where(on, g_max, 1.0))
    inside = on & (gap <= g_max)
    return np.where(inside, s * f_max * decay, 0.0)


def long_range_stiffness(gap, f_max, k_a, charge_product):
    """-df/dρ of the long-range force: s k_a for 0 < g <= g_max, else 0 [force/length].

    Positive (+k_a) for repulsive pairs, negative (-k_a) for attractive pairs within range.
    """
    gap, f_max, k_a, s = np.broadcast_arrays(
        np.asarray(gap, float), np.asarray(f_max, float), np.asarray(k_a, float),
        np.asarray(charge_product, float),
    )  # fmt: skip
    on = (f_max > 0.0) & (k_a > 0.0) & (s != 0.0)
    g_max = np.where(on, f_max / np.where(k_a > 0.0, k_a, 1.0), 0.0)
    return np.where(on & (gap > 0.0) & (gap <= g_max), s * k_a, 0.0)


def long_range_potential(gap, f_max, k_a, charge_product):
    """Long-range energy with f = -dU/dg on every branch [I].

    U = s [½ k_a g_max² - F_max g] for g <= 0 (i.e. s[½ k_a g_max² + F_max δ]);
    U = s ½ k_a (g_max - g)² for 0 < g <= g_max; U = 0 beyond. Continuous at g = 0 and g_max.
    """
    gap, f_max, k_a, s = np.broadcast_arrays(
        np.asarray(gap, float), np.asarray(f_max, float), np.asarray(k_a, float),
        np.asarray(charge_product, float),
    )  # fmt: skip
    on = (f_max > 0.0) & (k_a > 0.0) & (s != 0.0)
    safe_k = np.where(on, k_a, 1.0)
    g_max = np.where(on, f_max / safe_k, 0.0)
    touching = s * (0.5 * safe_k * g_max**2 - f_max * gap)
    decaying = s * 0.5 * safe_k * (g_max - gap) ** 2
    energy = np.where(gap <= 0.0, touching, decaying)
    return np.where(on & (gap <= g_max), energy, 0.0)


def van_der_waals_force(gap, f_w: float, k_w: float, both_charged):
    """van der Waals-like force: the long-range shape with s = -1 between charged discs [M §1.2]."""
    return long_range_force(gap, f_w, k_w, -np.asarray(both_charged, dtype=float))


def van_der_waals_stiffness(gap, f_w: float, k_w: float, both_charged):
    """-df/dρ of the vdW term: -k_W within 0 < g <= g_W, else 0 [force/length]."""
    return long_range_stiffness(gap, f_w, k_w, -np.asarray(both_charged, dtype=float))


def van_der_waals_potential(gap, f_w: float, k_w: float, both_charged):
    """vdW energy (the long-range potential with s = -1), f = -dU/dg."""
    return long_range_potential(gap, f_w, k_w, -np.asarray(both_charged, dtype=float))


def cap_force(law: str, contact_force, long_range_force=0.0, van_der_waals_force=0.0):
    """The normal force behind the sliding cap μ|f| and the rolling cap μ_r d_eff |f| [M §1.2]:
    ``law`` "contact": |f_c|, the contact spring's force, which an attraction loads (MercuryDPM's
    laws, the study's); "net": max(|f_c| − F_att, 0) with F_att = −min(f_LR, 0) − min(f_W, 0)
    the pair's attraction, so an attraction holds a contact shut but adds no strength (a
    departure from the study's laws: [contact] cap_force). Repulsion leaves the caps as they are.
    """
    contact = np.abs(np.asarray(contact_force, dtype=float))
    if law == "contact":
        return contact
    if law != "net":
        raise ValueError(f"cap_force law {law!r}: allowed 'contact' or 'net'")
    attraction = np.minimum(long_range_force, 0.0) + np.minimum(van_der_waals_force, 0.0)
    return np.maximum(contact + attraction, 0.0)


def tangential_force(spring, normal, k_t: float, mu: float, contact_force, tangential_velocity=0.0,
                     gamma_t: float = 0.0):  # fmt: skip
    """Tangential spring-dashpot force with Coulomb cap, for a given spring ξ [M §1.2].

    F_t = -k_t ξ_t - γ_t v_t with ξ_t = ξ - (ξ·n) n (tangent-plane part); if |F_t| > μ |f_c| the
    force is scaled down to μ |f_c| (sliding).

    Args:
        spring: (..., 2) ξ [length]; normal: (..., 2) unit n; contact_force: f_c [force];
        tangential_velocity: (..., 2) or 0, v_t of the contact points [length/time].
    Returns: (F_t (..., 2) [force], sliding (...,) bool).
    """
    spring = np.asarray(spring, dtype=float)
    normal = np.asarray(normal, dtype=float)
    spring_t = spring - np.sum(spring * normal, axis=-1, keepdims=True) * normal
    force = -k_t * spring_t - gamma_t * np.asarray(tangential_velocity, dtype=float)
    magnitude = np.linalg.norm(force, axis=-1)
    cap = mu * np.abs(np.asarray(contact_force, dtype=float))
    sliding = magnitude > cap
    scale = np.where(sliding, cap / np.where(magnitude > 0.0, magnitude, 1.0), 1.0)
    return force * scale[..., None], sliding


def tangential_spring_step(spring, normal, relative_velocity, dt: float, k_t: float, mu: float,
                           contact_force, gamma_t: float = 0.0):  # fmt: skip
    """One time step of the tangential spring with history [M §1.2].

    1. keep ξ in the tangent plane of the current normal: ξ <- ξ - (ξ·n) n;
    2. v_t = v_rel - (v_rel·n) n; ξ <- ξ + v_t Δt;
    3. F_t = -k_t ξ - γ_t v_t; if |F_t| > μ|f_c|: F_t <- μ|f_c| F_t/|F_t| and
       ξ <- -(F_t + γ_t v_t)/k_t (reset to the capped value).

    Args:
        spring: (..., 2) ξ; normal: (..., 2) unit n (from j to i);
        relative_velocity: (..., 2) velocity of i's contact point minus j's (image) contact point.
    Returns: (new spring (..., 2), F_t (..., 2), sliding (...,) bool).
    """
    spring = np.asarray(spring, dtype=float)
    normal = np.asarray(normal, dtype=float)
    velocity = np.asarray(relative_velocity, dtype=float)
    spring = spring - np.sum(spring * normal, axis=-1, keepdims=True) * normal
    v_t = velocity - np.sum(velocity * normal, axis=-1, keepdims=True) * normal
    spring = spring + v_t * dt
    force = -k_t * spring - gamma_t * v_t
    magnitude = np.linalg.norm(force, axis=-1)
    cap = mu * np.abs(np.asarray(contact_force, dtype=float))
    sliding = magnitude > cap
    scale = np.where(sliding, cap / np.where(magnitude > 0.0, magnitude, 1.0), 1.0)
    force = force * scale[..., None]
    reset = -(force + gamma_t * v_t) / (k_t if k_t > 0.0 else 1.0)
    spring = np.where(sliding[..., None], reset, spring)
    return spring, force, sliding


# --------------------------------------------------------------------------------------------
# Geometry
# --------------------------------------------------------------------------------------------


def disc_offsets(n_spheres: int, spacing: float) -> np.ndarray:
    """Body-frame offsets o_s = (s - (n_s-1)/2) spacing along the rod axis, s = 0..n_s-1 [I]."""
    return (np.arange(n_spheres, dtype=float) - 0.5 * (n_spheres - 1)) * spacing


def rod_inertia(n_spheres: int, spacing: float, diameter: float, disc_mass: float) -> float:
    """Moment of inertia of a rigid rod of n_s uniform discs about its centroid,
    I = Σ m o_s² + n_s m d²/8 (one disc, n_s = 1: m d²/8)."""
    offsets = disc_offsets(n_spheres, spacing)
    m, d = disc_mass, diameter
    return float(m * np.sum(offsets**2) + n_spheres * m * d * d / 8.0)


def disc_positions(rod_position, rod_angle, n_spheres: int, spacing: float) -> np.ndarray:
    """Disc centres x_g = X_r + o_s a_r, global index g = r n_s + s [I]; returns (N n_s, 2)."""
    rod_position = np.asarray(rod_position, dtype=float)
    rod_angle = np.asarray(rod_angle, dtype=float)
    axis = np.stack([np.cos(rod_angle), np.sin(rod_angle)], axis=-1)
    offsets = disc_offsets(n_spheres, spacing)
    discs = rod_position[:, None, :] + offsets[None, :, None] * axis[:, None, :]
    return discs.reshape(-1, 2)


def pair_separation(snapshot: NetworkSnapshot) -> np.ndarray:
    """r_ij = x_i - x_j - shift for every listed pair, (P, 2) [I]."""
    discs = disc_positions(
        snapshot.rod_position, snapshot.rod_angle, snapshot.n_spheres, snapshot.spacing
    )
    return discs[snapshot.pair_i] - discs[snapshot.pair_j] - snapshot.pair_shift


def branch_vectors(snapshot: NetworkSnapshot) -> np.ndarray:
    """Centroid branch vectors l_PQ = X_P - X_Q - shift of every pair, (P, 2) [I]."""
    rod_i = snapshot.pair_i // snapshot.n_spheres
    rod_j = snapshot.pair_j // snapshot.n_spheres
    return snapshot.rod_position[rod_i] - snapshot.rod_position[rod_j] - snapshot.pair_shift


# --------------------------------------------------------------------------------------------
# Pair parameters and pair forces of a snapshot
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PairParameters:
    """Mixed parameters of every listed pair (harmonic means of the discs' species values) [I].

    Attributes: f_max, k_a, g_max (P,) long-range; charge_product (P,) s = c_i c_j;
    both_charged (P,) bool, pairs feeling the vdW term.
    """

    f_max: np.ndarray
    k_a: np.ndarray
    g_max: np.ndarray
    charge_product: np.ndarray
    both_charged: np.ndarray


def pair_parameters(snapshot: NetworkSnapshot) -> PairParameters:
    """Pair F_max, k_a (harmonic mean; times the harmonic mean of the two rods' strengths when the
    snapshot has them), g_max = F_max/k_a and charge product of listed pairs. With attraction
    partners (:attr:`NetworkSnapshot.attraction_partners`), an attractive pair (s < 0) of two
    rods that are not partners has F_max = k_a = g_max = 0 (:mod:`dem_taichi.physics.attraction`).
    """
    mixed = _mixed_parameters(snapshot)
    if snapshot.attraction_partners is None:
        return mixed
    chain = snapshot.charge.shape[0]
    partners = are_partners(
        snapshot.attraction_partners, snapshot.pair_i // chain, snapshot.pair_j // chain
    )
    cut = (mixed.charge_product < 0.0) & ~partners
    return dataclasses.replace(
        mixed,
        f_max=np.where(cut, 0.0, mixed.f_max),
        k_a=np.where(cut, 0.0, mixed.k_a),
        g_max=np.where(cut, 0.0, mixed.g_max),
    )


def attracting_rod_pairs(snapshot: NetworkSnapshot) -> np.ndarray:
    """The rod pairs (a, b), a < b, once each, of the snapshot that attract under the
    unrestricted law: at least one listed pair of their discs of opposite charge (s < 0) with
    F_max > 0 within the range (gap <= g_max), (P, 2) int. What
    :func:`dem_taichi.physics.attraction.partner_table` takes at state A."""
    mixed = _mixed_parameters(snapshot)
    gap = np.hypot(*pair_separation(snapshot).T) - snapshot.diameter
    on = (mixed.charge_product < 0.0) & (mixed.f_max > 0.0) & (gap <= mixed.g_max)
    chain = snapshot.charge.shape[0]
    rods = np.sort(
        np.stack([snapshot.pair_i[on] // chain, snapshot.pair_j[on] // chain], axis=1), axis=1
    )
    return np.unique(rods, axis=0).reshape(-1, 2)


def _mixed_parameters(snapshot: NetworkSnapshot) -> PairParameters:
    """:func:`pair_parameters` without the attraction partners."""
    species_i = snapshot.species(snapshot.pair_i)
    species_j = snapshot.species(snapshot.pair_j)
    f_max = harmonic_mean(snapshot.f_max[species_i], snapshot.f_max[species_j])
    k_a = harmonic_mean(snapshot.k_a[species_i], snapshot.k_a[species_j])
    if snapshot.rod_strength is not None:  # the rods' strengths: the range g_max is kept
        chain = snapshot.charge.shape[0]
        s = snapshot.rod_strength
        m = harmonic_mean(s[snapshot.pair_i // chain], s[snapshot.pair_j // chain])
        f_max = f_max * m
        k_a = k_a * m
    g_max = np.where(k_a > 0.0, f_max / np.where(k_a > 0.0, k_a, 1.0), 0.0)
    charge_i = snapshot.charge[species_i]
    charge_j = snapshot.charge[species_j]
    return PairParameters(
        f_max=f_max,
        k_a=k_a,
        g_max=g_max,
        charge_product=(charge_i * charge_j).astype(float),
        both_charged=(charge_i != 0) & (charge_j != 0),
    )


@dataclass(frozen=True)
class PairForces:
    """Static pair forces of a snapshot (velocities zero, so no damping terms).

    Attributes (P pairs):
        separation (P, 2) r_ij; distance (P,) ρ; normal (P, 2) n; tangent (P, 2) t = (-n_y, n_x);
        overlap (P,) δ = d - ρ; in_contact (P,) bool δ > 0;
        contact_force (P,) f_c = k_n δ; long_range_force (P,); van_der_waals_force (P,);
        normal_force (P,) total scalar f (positive repulsive);
        normal_stiffness (P,) -df/dρ (contact + long-range + vdW);
        tangential_force (P, 2) F_t (capped, zero for non-contacts); sliding (P,) bool at the cap;
        force (P, 2) total force on disc i from disc j, f n + F_t;
        contact_point (P, 2) x_c = x_i - r_ij/2; branch (P, 2) l_PQ;
        rolling_moment (P,) the couple M on rod P (−M on Q) of the rolling spring
        (:mod:`dem_taichi.physics.rolling`; 0 without rolling resistance); rolling_sliding (P,) bool
        at the rolling cap.
    """

    separation: np.ndarray
    distance: np.ndarray
    normal: np.ndarray
    tangent: np.ndarray
    overlap: np.ndarray
    in_contact: np.ndarray
    contact_force: np.ndarray
    long_range_force: np.ndarray
    van_der_waals_force: np.ndarray
    normal_force: np.ndarray
    normal_stiffness: np.ndarray
    tangential_force: np.ndarray
    sliding: np.ndarray
    force: np.ndarray
    contact_point: np.ndarray
    branch: np.ndarray
    rolling_moment: np.ndarray
    rolling_sliding: np.ndarray


def pair_forces(snapshot: NetworkSnapshot) -> PairForces:
    """Normal and tangential force of every listed pair of a static snapshot [M §1.2, I].

    f = f_c + f_LR + f_W along n; F_t = -k_t ξ_t capped at μ f_c for contacts (ξ_t: the snapshot's
    spring projected on the tangent plane), zero for non-contacts; the rolling couple
    M = −κ_r ψ capped at μ_r d_eff f_c at contacts (at the cap within 1e-6: ``rolling_sliding``).
    With ``snapshot.cap_force == "net"`` both caps use :func:`cap_force`'s load instead of f_c.
    """
    separation = pair_separation(snapshot)
    distance = np.linalg.norm(separation, axis=-1)
    if np.any(distance <= 0.0):
        bad = int(np.flatnonzero(distance <= 0.0)[0])
        raise ValueError(f"pair {bad}: coincident disc centres (distance 0), normal undefined")
    normal = separation / distance[:, None]
    tangent = np.stack([-normal[:, 1], normal[:, 0]], axis=-1)
    overlap = snapshot.diameter - distance
    gap = -overlap
    in_contact = overlap > 0.0
    params = pair_parameters(snapshot)
    f_contact = contact_normal_force(overlap, snapshot.k_n)
    f_long = long_range_force(gap, params.f_max, params.k_a, params.charge_product)
    f_vdw = van_der_waals_force(gap, snapshot.vdw_f_max, snapshot.vdw_k, params.both_charged)
    stiffness = (
        contact_normal_stiffness(overlap, snapshot.k_n)
        + long_range_stiffness(gap, params.f_max, params.k_a, params.charge_product)
        + van_der_waals_stiffness(gap, snapshot.vdw_f_max, snapshot.vdw_k, params.both_charged)
    )
    cap_load = cap_force(snapshot.cap_force, f_contact, f_long, f_vdw)
    f_tangential, sliding = tangential_force(
        snapshot.tangential_spring, normal, snapshot.k_t, snapshot.mu, cap_load
    )
    f_tangential = np.where(in_contact[:, None], f_tangential, 0.0)
    sliding = sliding & in_contact
    normal_force = f_contact + f_long + f_vdw
    force = normal_force[:, None] * normal + f_tangential
    discs = disc_positions(
        snapshot.rod_position, snapshot.rod_angle, snapshot.n_spheres, snapshot.spacing
    )
    kappa, cap = snapshot.rolling_stiffness, snapshot.rolling_cap
    moment, _, _ = rolling_moment(snapshot.pair_rolling_spring, 0.0, kappa, 0.0, cap, cap_load)
    moment = np.where(in_contact, moment, 0.0)
    limit = cap * np.abs(cap_load)
    rolling_sliding = in_contact & (kappa > 0.0) & (np.abs(moment) >= limit * (1.0 - 1e-6))
    return PairForces(
        separation=separation,
        distance=distance,
        normal=normal,
        tangent=tangent,
        overlap=overlap,
        in_contact=in_contact,
        contact_force=f_contact,
        long_range_force=f_long,
        van_der_waals_force=f_vdw,
        normal_force=normal_force,
        normal_stiffness=stiffness,
        tangential_force=f_tangential,
        sliding=sliding,
        force=force,
        contact_point=discs[snapshot.pair_i] - 0.5 * separation,
        branch=branch_vectors(snapshot),
        rolling_moment=moment,
        rolling_sliding=rolling_sliding,
    )


def rod_forces_and_torques(snapshot: NetworkSnapshot) -> tuple[np.ndarray, np.ndarray]:
    """Total force (N, 2) and torque (N,) on every rod from all listed pairs.

    Rod P (disc i) receives F_ij and torque (x_c - X_P) × F_ij; rod Q (disc j, image at
    X_Q + shift) receives -F_ij and torque (x_c - X_Q - shift) × (-F_ij); the rolling couple
    adds M to P and −M to Q.
    """
    pairs = pair_forces(snapshot)
    n_rods = snapshot.n_rods
    rod_i = snapshot.pair_i // snapshot.n_spheres
    rod_j = snapshot.pair_j // snapshot.n_spheres
    lever_i = pairs.contact_point - snapshot.rod_position[rod_i]
    lever_j = pairs.contact_point - snapshot.rod_position[rod_j] - snapshot.pair_shift
    rods = np.concatenate([rod_i, rod_j])
    force = np.stack(
        [
            np.bincount(rods, np.concatenate([pairs.force[:, a], -pairs.force[:, a]]), n_rods)
            for a in range(2)
        ],
        axis=1,
    )
    moments = np.concatenate(
        [
            cross(lever_i, pairs.force) + pairs.rolling_moment,
            -cross(lever_j, pairs.force) - pairs.rolling_moment,
        ]
    )
    torque = np.bincount(rods, moments, n_rods)
    return force, torque


def stress_from_forces(snapshot: NetworkSnapshot) -> np.ndarray:
    """Stress σ_ab = (1/A) Σ_pairs F_ij,a l_PQ,b, compression positive, (2, 2) [I, M §1.4].

    F_ij is the total force on disc i (rod P) from disc j (rod Q) and l_PQ = X_P - X_Q - shift.
    The first index is the force component. In force and torque equilibrium σ is symmetric.
    """
    pairs = pair_forces(snapshot)
    area = float(np.prod(snapshot.cell_lengths))
    return np.einsum("pa,pb->ab", pairs.force, pairs.branch) / area


@dataclass(frozen=True)
class PotentialEnergy:
    """Stored energy of a snapshot [force·length], by interaction.

    contact: Σ ½ k_n δ²; tangential: Σ ½ k_t |ξ_t|² over contacts (ξ_t capped, |k_t ξ_t| <= μ f_c);
    long_range: Σ U_LR; van_der_waals: Σ U_W; rolling: Σ ½ κ_r ψ² over contacts (ψ capped);
    total: their sum.
    """

    contact: float
    tangential: float
    long_range: float
    van_der_waals: float
    rolling: float = 0.0

    @property
    def total(self) -> float:
        return self.contact + self.tangential + self.long_range + self.van_der_waals + self.rolling


def potential_energy(snapshot: NetworkSnapshot) -> PotentialEnergy:
    """Potential energy of all listed pairs; the normal part is conservative (f = -dU/dρ)."""
    pairs = pair_forces(snapshot)
    params = pair_parameters(snapshot)
    gap = -pairs.overlap
    tangential = 0.0
    if snapshot.k_t > 0.0:
        spring_t = -pairs.tangential_force / snapshot.k_t
        tangential = float(0.5 * snapshot.k_t * np.sum(spring_t**2))
    rolling = 0.0
    if snapshot.rolling_stiffness > 0.0:
        rolling = float(0.5 * np.sum(pairs.rolling_moment**2) / snapshot.rolling_stiffness)
    return PotentialEnergy(
        rolling=rolling,
        contact=float(np.sum(contact_potential(pairs.overlap, snapshot.k_n))),
        tangential=tangential,
        long_range=float(
            np.sum(long_range_potential(gap, params.f_max, params.k_a, params.charge_product))
        ),
        van_der_waals=float(
            np.sum(
                van_der_waals_potential(
                    gap, snapshot.vdw_f_max, snapshot.vdw_k, params.both_charged
                )
            )
        ),
    )
