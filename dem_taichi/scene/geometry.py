"""Rod geometry and the initial gas (numpy only, no Taichi).

Symbols: N rods of n_s discs of diameter d and centre spacing s_p; disc mass m. Disc s of a rod sits
at body-frame offset o_s = (s − (n_s − 1)/2) s_p along the axis a = (cos θ, sin θ)
(docs/science/dem-model.md §1.8). Rod mass M = n_s m; moment of inertia
I = Σ_s m o_s² + n_s m d²/8 (docs/science/dem-model.md §1.1). Solid area of a rod: n_s π d²/4 minus
the lens overlaps of neighbouring discs when s_p < d.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dem_taichi.physics.bonds import rod_frames
from dem_taichi.physics.forcelaw import disc_offsets, rod_inertia
from dem_taichi.scene.config import Scene, SceneError
from dem_taichi.scene.gas_placement import PlacementError, place_rods

__all__ = [
    "RodGeometry",
    "rod_geometry",
    "body_geometry",
    "bodies_from_rods",
    "rods_from_bodies",
    "species_parameters",
    "GasState",
    "generate_gas",
    "lens_area",
]


def lens_area(radius: float, distance: float) -> float:
    """Area of the intersection of two discs of ``radius`` whose centres are ``distance`` apart."""
    if distance >= 2 * radius:
        return 0.0
    r, s = radius, distance
    return 2 * r * r * math.acos(s / (2 * r)) - 0.5 * s * math.sqrt(4 * r * r - s * s)


@dataclass(frozen=True)
class RodGeometry:
    n_spheres: int
    diameter: float
    spacing: float
    disc_mass: float
    offsets: np.ndarray  # (n_s,) body-frame offset o_s along the axis
    mass: float  # rod mass M = n_s m
    inertia: float  # I = Σ m o_s² + n_s m d²/8
    solid_area: float  # disc-union area of one rod
    length: float  # tip to tip: (n_s − 1) s_p + d
    max_offset: float  # max |o_s|


def rod_geometry(scene: Scene) -> RodGeometry:
    p = scene.particles
    n, d, sp, m = p.n_spheres, p.diameter, p.spacing, p.disc_mass
    offsets = disc_offsets(n, sp)
    inertia = rod_inertia(n, sp, d, m)
    area = n * math.pi * d * d / 4.0 - (n - 1) * lens_area(d / 2.0, sp)
    return RodGeometry(
        n_spheres=n,
        diameter=d,
        spacing=sp,
        disc_mass=m,
        offsets=offsets,
        mass=n * m,
        inertia=inertia,
        solid_area=area,
        length=(n - 1) * sp + d,
        max_offset=float(np.max(np.abs(offsets))),
    )


def body_geometry(scene: Scene) -> RodGeometry:
    """The geometry of the engine's bodies: the rod itself for rigid rods; one disc (mass m,
    inertia m d²/8, no offset) for bonded rods, where every disc is a body
    (docs/science/dem-model.md §1.7)."""
    if not scene.bonded:
        return rod_geometry(scene)
    p = scene.particles
    d, m = p.diameter, p.disc_mass
    return RodGeometry(
        n_spheres=1,
        diameter=d,
        spacing=p.spacing,
        disc_mass=m,
        offsets=np.zeros(1),
        mass=m,
        inertia=rod_inertia(1, p.spacing, d, m),
        solid_area=math.pi * d * d / 4.0,
        length=d,
        max_offset=0.0,
    )


def bodies_from_rods(gas: GasState, geometry: RodGeometry) -> GasState:
    """The disc bodies (N n_s, rod-major) of a gas of rods: each disc at its place in the rod,
    with the rod's angle, the rigid-body velocity v + ω × o_s a and the rod's ω (so a straight
    bonded chain starts in its reference state, moving as the rigid rod did)."""
    n_s = geometry.n_spheres
    axis = np.stack([np.cos(gas.angle), np.sin(gas.angle)], axis=-1)
    offset = geometry.offsets[None, :, None] * axis[:, None, :]  # (N, n_s, 2)
    position = gas.position[:, None, :] + offset
    position = np.mod(position, gas.cell_lengths)
    spin = gas.angular_velocity[:, None, None]
    velocity = gas.velocity[:, None, :] + spin * np.stack([-offset[..., 1], offset[..., 0]], -1)
    return GasState(
        np.asarray(gas.cell_lengths, dtype=float),
        position.reshape(-1, 2),
        np.repeat(gas.angle, n_s),
        velocity.reshape(-1, 2),
        np.repeat(gas.angular_velocity, n_s),
    )


def rods_from_bodies(
    discs: np.ndarray,
    velocity: np.ndarray,
    angular_velocity: np.ndarray,
    geometry: RodGeometry,
    cell_lengths: np.ndarray,
) -> GasState:
    """The gas of rigid rods closest to bonded rods' discs: the inverse of
    :func:`bodies_from_rods` for a straight chain moving rigidly, and the rigid-body part of the
    motion of any chain.

    ``discs`` (N, n_s, 2): each rod's disc centres made contiguous across the periodic cell
    (:func:`dem_taichi.physics.bonds.unwrapped_chains`), rod-major; ``velocity`` (N n_s, 2) and
    ``angular_velocity`` (N n_s,) the discs'. Each rod: centre X = the mean of its discs (equal
    masses), wrapped into [0, L); angle θ of its end-to-end vector, in (−π, π]; velocity
    V = the mean of the disc velocities (momentum); angular velocity Ω = L / I with the angular
    momentum about X, L = Σ m (x_i − X) × (v_i − V) + I_d Σ ω_i, and I = Σ m |x_i − X|² + n_s I_d
    (I_d = m d²/8, the disc's own; X and I from :func:`dem_taichi.physics.bonds.rod_frames`),
    so that a rigidly moving chain keeps its Ω exactly.
    """
    discs = np.asarray(discs, dtype=float)
    n_rods, n_s = discs.shape[0], discs.shape[1]
    if n_s != geometry.n_spheres:
        raise ValueError(f"chains of {n_s} discs do not fit rods of {geometry.n_spheres}")
    m = geometry.disc_mass
    disc_inertia = m * geometry.diameter**2 / 8.0
    v = np.asarray(velocity, dtype=float).reshape(n_rods, n_s, 2)
    w = np.asarray(angular_velocity, dtype=float).reshape(n_rods, n_s)
    centre, inertia = rod_frames(discs, m, disc_inertia)
    end_to_end = discs[:, -1] - discs[:, 0]
    angle = np.arctan2(end_to_end[:, 1], end_to_end[:, 0])
    rod_velocity = v.mean(axis=1)
    arm = discs - centre[:, None, :]
    rel = v - rod_velocity[:, None, :]
    momentum = m * np.sum(arm[..., 0] * rel[..., 1] - arm[..., 1] * rel[..., 0], axis=1)
    momentum += disc_inertia * w.sum(axis=1)
    lengths = np.asarray(cell_lengths, dtype=float)
    return GasState(
        lengths.copy(), np.mod(centre, lengths), angle, rod_velocity, momentum / inertia
    )


def species_parameters(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-disc-position charge c_s ∈ {−1, 0, 1}, F_max and k_a (docs/science/dem-model.md §1.8).

    acidic: edge +1, inner −1; basic: all −1; neutral: all 0 (also when long range is disabled).
    """
    n = scene.particles.n_spheres
    lr = scene.long_range
    edge = np.zeros(n, dtype=bool)
    edge[0] = edge[-1] = True
    charge = np.zeros(n, dtype=np.int32)
    if lr.enabled:
        if lr.pattern == "acidic":
            charge = np.where(edge, 1, -1).astype(np.int32)
        elif lr.pattern == "basic":
            charge = -np.ones(n, dtype=np.int32)
    f_max = np.where(edge, lr.f_max_edge, lr.f_max_inner).astype(float)
    k_a = np.where(edge, lr.k_a_edge, lr.k_a_inner).astype(float)
    return charge, f_max, k_a


#: the second entry of the seed of the rods' strengths (:func:`rod_strengths`): a stream of its
#: own, so that a scene with a spread draws the same gas as the scene without it
STRENGTH_STREAM = 0x5157


def rod_strengths(scene: Scene) -> np.ndarray | None:
    """(N,) strength s_r of every rod, or None when the rods are alike (no long range, or
    ``[long_range] strength_spread`` = 0).

    s_r = exp(σ z_r) with z_r ~ N(0, 1) drawn from ``default_rng([seed, STRENGTH_STREAM])``,
    divided by the mean over the rods (so the mean strength is exactly 1 at any N: the spread
    changes the distribution, not the level). Deterministic for a given ``[scene] seed``.
    """
    lr = scene.long_range
    if not lr.enabled or lr.strength_spread == 0.0:
        return None
    rng = np.random.default_rng([scene.scene.seed, STRENGTH_STREAM])
    s = np.exp(lr.strength_spread * rng.standard_normal(scene.particles.n_rods))
    return s / s.mean()


@dataclass(frozen=True)
class GasState:
    cell_lengths: np.ndarray  # (2,)
    position: np.ndarray  # (N, 2) centroids in [0, L)
    angle: np.ndarray  # (N,)
    velocity: np.ndarray  # (N, 2)
    angular_velocity: np.ndarray  # (N,)


def generate_gas(scene: Scene, max_attempts_per_rod: int = 10_000) -> GasState:
    """Random non-overlapping rods in a square periodic cell at the scene's area fraction.

    Orientations are uniform in [0, π); a candidate is rejected when any of its discs lies closer
    than d (plus the long-range range when it is on, so the gas starts force-free) to a disc of
    another rod (minimum image). Velocities are Gaussian with rms ``initial_speed`` per component,
    with the mean removed; angular velocities have the matching rms ``initial_speed / radius of
    gyration``. Deterministic for a given ``[scene] seed``.

    The placement is random sequential (:func:`dem_taichi.scene.gas_placement.place_rods`: batches
    checked with periodic k-d trees, 1e5 rods in seconds); it accepts the same rods from the
    same random numbers as the rod-by-rod loop it replaced, so the gas is bitwise unchanged.
    """
    p = scene.particles
    geo = rod_geometry(scene)
    rng = np.random.default_rng(scene.scene.seed)
    n = p.n_rods
    side = math.sqrt(n * geo.solid_area / p.initial_area_fraction)
    cell = np.array([side, side])
    clearance = geo.diameter
    if scene.long_range.enabled:
        _, f_max, k_a = species_parameters(scene)
        clearance += float(np.max(f_max / k_a))
    if side < 2 * (geo.length + clearance):
        raise SceneError(
            f"[particles] n_rods = {n} gives a cell of side {side:.3g} < 2 x (rod length + range) "
            f"= {2 * (geo.length + clearance):.3g}; use more rods or a lower initial_area_fraction"
        )
    try:
        positions, angles, _ = place_rods(
            rng, n, side, geo.offsets, clearance, max_attempts_per_rod
        )
    except PlacementError as error:
        raise SceneError(
            f"could not place rod {error.rod} of {n} without overlap after "
            f"{max_attempts_per_rod} attempts; lower [particles] initial_area_fraction = "
            f"{p.initial_area_fraction}"
        ) from None
    velocity = rng.normal(0.0, p.initial_speed, size=(n, 2))
    if n > 1:
        velocity -= velocity.mean(axis=0)
    gyration = math.sqrt(geo.inertia / geo.mass)
    omega = rng.normal(0.0, p.initial_speed / gyration, size=n)
    return GasState(cell, positions, angles, velocity, omega)


def pair_table(scene: Scene) -> np.ndarray:
    """(n_s, n_s, 3): signed F_max, signed k_a and range g_max of each species pair.

    Pair values are harmonic means 2ab/(a+b) of the two discs' species values; s = c_i c_j.
    """
    charge, f_max, k_a = species_parameters(scene)
    n = len(charge)
    table = np.zeros((n, n, 3))
    for a in range(n):
        for b in range(n):
            s = charge[a] * charge[b]
            f = 2 * f_max[a] * f_max[b] / (f_max[a] + f_max[b])
            k = 2 * k_a[a] * k_a[b] / (k_a[a] + k_a[b])
            table[a, b] = (s * f, s * k, f / k) if s != 0 else (0.0, 0.0, f / k)
    return table
