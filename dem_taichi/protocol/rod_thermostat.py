"""A thermostat on the rods' rigid-body motion, for the aggregation stage of bonded rods.

``[protocol] aggregation_thermostat = "rods"``: at every check every ROD gets a fresh rigid-body
motion at the temperature of ``aggregation_speed``, drawn as
:func:`~dem_taichi.protocol.quasistatic.resample_speed` draws a rigid rod's: centre-of-mass
velocity components V ~ N(0, speed²), the mean over the rods removed (total momentum zero), and
angular velocity Ω ~ N(0, speed² M/I) (equipartition, ½ I Ω² = ½ M V_x² on average), M and I of
the whole rod about its centre of mass.

Rigid rods (a body is a rod): exactly :func:`resample_speed` (delegated to it: the same
numbers bit for bit as ``"resample"``). Bonded rods (a body is a disc): every disc i of rod r is
given the rigid-body velocity field of its rod, v_i = V_r + Ω_r × (x_i − X_r), and its own
angular velocity ω_i = Ω_r, with x_i the disc centres of the rod made contiguous across the
periodic cell (each bond vector at its minimum image, :func:`dem_taichi.physics.bonds.
unwrapped_chains`, as the engine measures the rod's axis), X_r = the mean of its discs (equal
masses) and I_r = Σ m |x_i − X_r|² + n_s I_disc of the rod as it is (bent or stretched: so that
½ I_r Ω_r² is the rotational energy of the discs' motion exactly). The bonds' stretch, shear and
bending rates are then zero: the rod's internal (bond) modes are left with no kinetic energy at
each draw, where ``"resample"`` on bonded rods draws every disc independently and heats them.
A rod with a broken bond is still moved as one rigid whole.

The temperature: the rods' centre-of-mass velocities have rms component ``speed``, as for rigid
rods (kT = M speed², M the rod's mass); ``"resample"`` on bonded rods gives each disc that rms,
kT = m speed² per disc, n_s times colder at the same ``aggregation_speed``.

The generator is PCG64 seeded by (seed, :data:`~dem_taichi.protocol.quasistatic.RESAMPLE_STREAM`,
step), as :func:`resample_speed`'s, with the draws in the same order (V of shape (N, 2), then
the N spins): a bonded scene draws at a step the rod motions a rigid scene of as many rods and the
same seed draws there (the spins scaled by each rod's own I). Deterministic and resumable.

Pure numpy: :func:`~dem_taichi.physics.bonds.rod_frames` (re-exported),
:func:`draw_rod_motion`, :func:`rigid_disc_velocities`; :func:`rod_speed` applies them to a
simulation.
"""

from __future__ import annotations

import numpy as np

from dem_taichi.engine.simulation import Simulation
from dem_taichi.physics.bonds import rod_frames, unwrapped_chains
from dem_taichi.protocol.quasistatic import (
    RESAMPLE_STREAM,
    resample_speed,
    rms_velocity_component,
)

__all__ = ["rod_frames", "draw_rod_motion", "rigid_disc_velocities", "rod_speed"]


def draw_rod_motion(
    rng: np.random.Generator, n_rods: int, speed: float, mass: float, inertia
) -> tuple[np.ndarray, np.ndarray]:
    """(V (N, 2), Ω (N,)) of ``n_rods`` rods of mass ``mass`` and moments of inertia ``inertia``
    (a number or (N,)): V ~ N(0, speed²) per component with the mean over the rods removed, then
    Ω ~ N(0, speed² M/I), in this order from ``rng`` (:func:`resample_speed`'s order)."""
    velocity = rng.normal(0.0, speed, size=(n_rods, 2))
    velocity -= velocity.mean(axis=0, keepdims=True)
    spin = speed * np.sqrt(mass / np.asarray(inertia, dtype=float))
    omega = rng.normal(0.0, spin, size=n_rods)
    return velocity, omega


def rigid_disc_velocities(
    discs: np.ndarray, centre: np.ndarray, velocity: np.ndarray, omega: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(disc velocities (N n_s, 2), disc angular velocities (N n_s,)), rod-major, of rods moving
    as rigid bodies: v_i = V + Ω × (x_i − X) = V + Ω (−(y_i − Y), x_i − X), ω_i = Ω, for discs at
    contiguous positions ``discs`` (N, n_s, 2), rod centres ``centre`` (N, 2), rod velocities
    ``velocity`` (N, 2) and angular velocities ``omega`` (N,)."""
    discs = np.asarray(discs, dtype=float)
    arm = discs - np.asarray(centre, dtype=float)[:, None, :]
    turn = np.stack([-arm[..., 1], arm[..., 0]], axis=-1)
    omega = np.asarray(omega, dtype=float)
    disc_velocity = np.asarray(velocity, dtype=float)[:, None, :] + omega[:, None, None] * turn
    chain = discs.shape[1]
    return disc_velocity.reshape(-1, 2), np.repeat(omega, chain)


def rod_speed(sim: Simulation, speed: float, seed: int) -> float:
    """Draw every rod's rigid-body motion afresh at the temperature of ``speed`` (module
    docstring); returns the rms velocity component of the bodies before (rods, or the discs of
    bonded rods). Rigid rods: :func:`resample_speed` itself."""
    if not sim.bonded:
        return resample_speed(sim, speed, seed)
    velocity_now, omega_now = sim.velocities()
    before = rms_velocity_component(velocity_now)
    chain = sim.geometry.n_spheres
    discs = unwrapped_chains(sim.body_positions(), chain, sim.cell_lengths)
    centre, inertia = rod_frames(discs, sim.body.mass, sim.body.inertia)
    rng = np.random.Generator(np.random.PCG64([int(seed), RESAMPLE_STREAM, int(sim.step)]))
    velocity, omega = draw_rod_motion(rng, sim.n_rods, speed, sim.geometry.mass, inertia)
    disc_velocity, disc_omega = rigid_disc_velocities(discs, centre, velocity, omega)
    sim.set_velocities(disc_velocity.astype(velocity_now.dtype), disc_omega.astype(omega_now.dtype))
    return before
