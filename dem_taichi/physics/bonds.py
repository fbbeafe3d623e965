"""The intra-rod bond law of the bonded-rod model in numpy (docs/science/dem-model.md §1.7; no
Taichi).

The independent reference of :mod:`dem_taichi.kernels.bonds` (same symbols, see there): bond
g—h = g + 1 between neighbouring discs of a rod, d = x_h − x_g (minimum image), θ_m the mean
angle, e_n = d·a_m − s_0, e_t = d·t_m, e_b = θ_h − θ_g, Λ_e = k_e e + γ_e ė,
F_h = −(Λ_n a_m + Λ_t t_m) = −F_g, τ_h = −(½Λ_n e_t − ½Λ_t d·a_m + Λ_b),
τ_g = −(½Λ_n e_t − ½Λ_t d·a_m − Λ_b), U = ½ Σ k_e e².

Also: the bond parameters of a scene (:func:`bond_parameters`), the stiffness matrix of one free
straight chain and its highest angular frequency (:func:`chain_max_frequency`), which sets the
bonded time step Δt = dt_safety · min(t_c, π/ω_max)
(:attr:`dem_taichi.scene.config.Scene.time_step`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "rod_frames",
    "BondParameters",
    "BondResult",
    "bond_forces",
    "chain_bonds",
    "chain_hessian",
    "chain_max_frequency",
    "disc_inertia",
]


def disc_inertia(disc_mass: float, diameter: float) -> float:
    """Moment of inertia of a uniform disc about its centre, m d²/8."""
    return disc_mass * diameter * diameter / 8.0


@dataclass(frozen=True)
class BondParameters:
    """Springs, dashpots and strength of the bonds (DEM units).

    k_n [force/length] stretch, k_t [force/length] shear, k_b [force·length/rad] bending;
    gamma_n, gamma_t [force·time/length], gamma_b [force·length·time/rad]; rest length s_0;
    breakage tension F_b (0 = unbreakable).
    """

    k_n: float
    k_t: float
    k_b: float
    gamma_n: float
    gamma_t: float
    gamma_b: float
    rest_length: float
    breakage_force: float = 0.0

    @classmethod
    def from_ratios(
        cls, k_n_contact: float, diameter: float, spacing: float, disc_mass: float,
        normal: float, shear: float, bending: float, damping_ratio: float,
        breakage_force: float = 0.0,
    ) -> BondParameters:  # fmt: skip
        """Bonds from ratios to the contact stiffness: k_bn = normal k_n, k_bt = shear k_n,
        κ_b = bending k_n d²; each mode damped at ``damping_ratio`` ζ of its two-body
        oscillator: γ = 2ζ sqrt(k μ) with μ = m/2 (stretch, shear) or I/2 (bending)."""
        k_n = normal * k_n_contact
        k_t = shear * k_n_contact
        k_b = bending * k_n_contact * diameter * diameter
        inertia = disc_inertia(disc_mass, diameter)
        zeta = damping_ratio
        return cls(
            k_n=k_n,
            k_t=k_t,
            k_b=k_b,
            gamma_n=2.0 * zeta * math.sqrt(k_n * disc_mass / 2.0),
            gamma_t=2.0 * zeta * math.sqrt(k_t * disc_mass / 2.0),
            gamma_b=2.0 * zeta * math.sqrt(k_b * inertia / 2.0),
            rest_length=spacing,
            breakage_force=breakage_force,
        )


@dataclass(frozen=True)
class BondResult:
    """Per bond: force on h (B, 2), torques on h and g (B,), bond vector d (B, 2), elastic
    energy (B,) and the measures e = (e_n, e_t, e_b) (B, 3)."""

    force_h: np.ndarray
    torque_h: np.ndarray
    torque_g: np.ndarray
    separation: np.ndarray
    energy: np.ndarray
    strain: np.ndarray


def chain_bonds(n_rods: int, chain: int) -> np.ndarray:
    """Index g (disc of the lower index) of every bond, rod-major: (N (chain − 1),)."""
    return (np.arange(n_rods)[:, None] * chain + np.arange(chain - 1)[None, :]).ravel()


def bond_forces(
    position: np.ndarray,
    angle: np.ndarray,
    g: np.ndarray,
    cell_lengths: np.ndarray,
    bonds: BondParameters,
    velocity: np.ndarray | None = None,
    angular_velocity: np.ndarray | None = None,
    rates: np.ndarray | None = None,
) -> BondResult:
    """Forces of the bonds g—g+1 between discs at ``position`` (M, 2), ``angle`` (M,), with the
    velocities (relative to the affine flow, cell strain ``rates`` ε̇, compression positive)
    entering the dashpots when given."""
    h = g + 1
    lengths = np.asarray(cell_lengths, dtype=float)
    d = position[h] - position[g]
    d = d - np.round(d / lengths) * lengths
    theta_m = 0.5 * (angle[g] + angle[h])
    a = np.stack([np.cos(theta_m), np.sin(theta_m)], axis=-1)
    t = np.stack([-a[:, 1], a[:, 0]], axis=-1)
    d_a = np.sum(d * a, axis=-1)
    e_n = d_a - bonds.rest_length
    e_t = np.sum(d * t, axis=-1)
    e_b = angle[h] - angle[g]
    lam_n, lam_t, lam_b = bonds.k_n * e_n, bonds.k_t * e_t, bonds.k_b * e_b
    if velocity is not None:
        omega = np.zeros_like(angle) if angular_velocity is None else angular_velocity
        rate = np.zeros(2) if rates is None else np.asarray(rates, dtype=float)
        d_dot = velocity[h] - velocity[g] - rate * d
        w_m = 0.5 * (omega[g] + omega[h])
        lam_n = lam_n + bonds.gamma_n * (np.sum(d_dot * a, axis=-1) + e_t * w_m)
        lam_t = lam_t + bonds.gamma_t * (np.sum(d_dot * t, axis=-1) - d_a * w_m)
        lam_b = lam_b + bonds.gamma_b * (omega[h] - omega[g])
    force_h = -(lam_n[:, None] * a + lam_t[:, None] * t)
    common = 0.5 * lam_n * e_t - 0.5 * lam_t * d_a
    energy = 0.5 * (bonds.k_n * e_n**2 + bonds.k_t * e_t**2 + bonds.k_b * e_b**2)
    return BondResult(
        force_h=force_h,
        torque_h=-(common + lam_b),
        torque_g=-(common - lam_b),
        separation=d,
        energy=energy,
        strain=np.stack([e_n, e_t, e_b], axis=-1),
    )


def chain_hessian(chain: int, spacing: float, k_n: float, k_t: float, k_b: float) -> np.ndarray:
    """Stiffness matrix (3n, 3n) of a free straight chain along x at rest, DOFs (x, y, θ) per
    disc: Σ_bonds Gᵀ diag(k_n, k_t, k_b) G with G = ∂(e_n, e_t, e_b)/∂q."""
    n_dof = 3 * chain
    hessian = np.zeros((n_dof, n_dof))
    k = np.diag([k_n, k_t, k_b])
    for g in range(chain - 1):
        grad = np.zeros((3, n_dof))
        x_g, x_h = 3 * g, 3 * (g + 1)
        grad[0, x_g], grad[0, x_h] = -1.0, 1.0  # e_n = d·a − s_0, a = x̂
        grad[1, x_g + 1], grad[1, x_h + 1] = -1.0, 1.0  # e_t = d·t, t = ŷ
        grad[1, x_g + 2] = grad[1, x_h + 2] = -0.5 * spacing  # ∂(d·t_m)/∂θ = −½ d·a
        grad[2, x_g + 2], grad[2, x_h + 2] = -1.0, 1.0
        hessian += grad.T @ k @ grad
    return hessian


def chain_max_frequency(
    chain: int, spacing: float, disc_mass: float, diameter: float, k_n: float, k_t: float,
    k_b: float,
) -> float:  # fmt: skip
    """Highest angular frequency ω_max of one free bonded chain (rad/time): the eigenvalues of
    M^{-1/2} K M^{-1/2} with M = diag(m, m, m d²/8) per disc."""
    if chain < 2:
        return 0.0
    hessian = chain_hessian(chain, spacing, k_n, k_t, k_b)
    inv_sqrt_mass = np.tile(
        1.0 / np.sqrt([disc_mass, disc_mass, disc_inertia(disc_mass, diameter)]), chain
    )
    scaled = hessian * inv_sqrt_mass[:, None] * inv_sqrt_mass[None, :]
    return float(math.sqrt(max(np.linalg.eigvalsh(scaled).max(), 0.0)))


def unwrapped_chains(position: np.ndarray, chain: int, cell_lengths: np.ndarray) -> np.ndarray:
    """Disc positions (N, chain, 2) of every rod made contiguous: disc 0 as stored, each next
    disc at the minimum image of its bond vector (bonds shorter than half the cell)."""
    lengths = np.asarray(cell_lengths, dtype=float)
    discs = np.asarray(position, dtype=float).reshape(-1, chain, 2)
    step = np.diff(discs, axis=1)
    step -= np.round(step / lengths) * lengths
    start = discs[:, :1]
    return np.concatenate([start, start + np.cumsum(step, axis=1)], axis=1)


def rod_frames(
    discs: np.ndarray, disc_mass: float, disc_inertia: float
) -> tuple[np.ndarray, np.ndarray]:
    """(centres of mass X (N, 2), moments of inertia I (N,) about them) of rods of equal discs
    at contiguous positions ``discs`` (N, n_s, 2): X = mean of the discs,
    I = Σ m |x_i − X|² + n_s I_disc."""
    discs = np.asarray(discs, dtype=float)
    centre = discs.mean(axis=1)
    arm = discs - centre[:, None, :]
    inertia = disc_mass * np.sum(arm * arm, axis=(1, 2)) + discs.shape[1] * disc_inertia
    return centre, inertia


def rod_axes(position: np.ndarray, chain: int, cell_lengths: np.ndarray):
    """Centroids (N, 2), wrapped into [0, L), and end-to-end angles (N,) in (−π, π] of bonded
    rods: the rod fabric of a bonded rod is that of its end-to-end vector
    (docs/science/dem-model.md §1.7)."""
    lengths = np.asarray(cell_lengths, dtype=float)
    discs = unwrapped_chains(position, chain, lengths)
    centroid = discs.mean(axis=1)
    end_to_end = discs[:, -1] - discs[:, 0]
    angle = np.arctan2(end_to_end[:, 1], end_to_end[:, 0])
    return np.mod(centroid, lengths), angle
