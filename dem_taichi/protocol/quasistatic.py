"""Quasi-static building blocks on a :class:`dem_taichi.engine.simulation.Simulation`
(docs/science/dem-model.md §1.6).

The loading paths (:mod:`dem_taichi.protocol.runner`) and the probes
(:mod:`dem_taichi.protocol.probing`) are built from these three: the strain-rate cap of the inertial
number, a relaxation at fixed cell to a static state, and a strain increment applied at constant
rates. The ageing of the gas before the compression to A
(:meth:`dem_taichi.protocol.paths.ProtocolRunner.aggregate`) adds two: a run at fixed cell
(:func:`hold`) and a rescale or a fresh draw of the bodies' velocities (:func:`rescale_speed`,
:func:`resample_speed`).

Symbols: I = ε̇ d sqrt(ρ/p) inertial number (ρ = rod mass / rod solid area, 2D density; d disc
diameter; p mean stress), UFR unbalanced-force ratio, KE kinetic energy, ε logarithmic strain
(compression positive).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, cast

import numpy as np

from dem_taichi.engine.failures import PERIOD_TWO_SHARE, period_two_error
from dem_taichi.engine.measures import Measures
from dem_taichi.engine.simulation import CellControl, Simulation
from dem_taichi.engine.work_profile import doing

__all__ = [
    "strain_rate_cap",
    "relax",
    "apply_strain",
    "hold",
    "rms_velocity_component",
    "equipartition_spin",
    "rescale_speed",
    "resample_speed",
    "refresh_speed",
    "RESAMPLE_STREAM",
]

#: the generator's stream tag of :func:`resample_speed` ("AGGT"), beside the seed and the step
RESAMPLE_STREAM = 0x41474754


def strain_rate_cap(
    sim: Simulation, mean_stress: float, floor_stress: float, safety: float = 1.0
) -> float:
    """Largest strain rate keeping I = ε̇ d sqrt(ρ/p) ≤ safety · I_max ([control]
    inertial_number_max).

    ρ = rod mass / rod solid area (2D density); p = max(mean_stress, floor_stress) (DEM units).
    """
    geo = sim.geometry
    rho = geo.mass / geo.solid_area
    p = max(float(mean_stress), float(floor_stress))
    i_max = safety * sim.scene.control.inertial_number_max
    return i_max * math.sqrt(p / rho) / geo.diameter


def _control(stage: str, rate_x: float, rate_y: float) -> CellControl:
    return CellControl.strain_rate(rate_x, rate_y, stage=stage)


@doing("relax")
def relax(
    sim: Simulation,
    stage: str,
    unbalanced_force: float,
    kinetic_energy_per_rod: float,
    check_steps: int,
    max_steps: int,
    give_up: Callable[[Measures, int], bool] | None = None,
) -> tuple[Measures, bool, int]:
    """Run at fixed cell until UFR < ``unbalanced_force`` and KE/N < ``kinetic_energy_per_rod``.

    Checks every ``check_steps`` steps, stops after ``max_steps``; ``give_up(measures, steps)``
    may end it early (returns not relaxed). When ``max_steps`` ran out and most of the
    unbalanced force is in bodies oscillating with a period of two steps (the time step beyond
    their local stability limit; :func:`dem_taichi.engine.failures.period_two_bodies`), raises
    :class:`~dem_taichi.engine.failures.BlowUpError` saying so: more steps relax them slowly if
    at all (the damped relaxation; FIRE's kick is another). Returns (measures, relaxed, steps run).
    Each chunk is a minimising call (``CellControl.relaxation``): the scene's
    ``[integration] relaxation`` integrates it with the damped dynamics (the default) or with FIRE.
    """
    steps = 0
    measures = cast(Measures, {})  # returned as is only when max_steps <= 0
    control = CellControl.relaxation(stage)  # a minimisation: FIRE on "fire" scenes
    while steps < max_steps:
        n = min(check_steps, max_steps - steps)
        measures = sim.run(n, control, output_every=n)
        steps += n
        ufr = measures["unbalanced_force_ratio"]
        ke = measures["kinetic_energy"] / sim.n_rods
        if math.isfinite(ufr) and ufr < unbalanced_force and ke < kinetic_energy_per_rod:
            return measures, True, steps
        if give_up is not None and give_up(measures, steps):
            return measures, False, steps
    if max_steps > 0 and sim.scene.integration.relaxation_method != "fire":
        found = sim.period_two()  # a bounded blow-up: more steps barely relax it
        if found.share >= PERIOD_TWO_SHARE:
            raise period_two_error(
                found, stage, sim.step, sim.time_step, sim.scene.time_step, sim.scene.integration
            )
    return measures, False, steps


@doing("strain")
def apply_strain(
    sim: Simulation,
    strain: tuple[float, float],
    stage: str,
    max_rate: float,
    min_steps: int,
    writer: Any = None,
    output_every: int | None = None,
) -> Measures:
    """Apply the logarithmic strain increments (Δε_xx, Δε_yy) (compression positive) at constant
    rates, over n = max(min_steps, ceil(max|Δε| / (max_rate dt))) steps; returns the measures.

    The cell then has L = L_0 exp(−Δε) on each axis (the engine integrates L̇ = −ε̇ L exactly).
    """
    dt = sim.time_step
    biggest = max(abs(strain[0]), abs(strain[1]))
    n = max(int(min_steps), int(math.ceil(biggest / (max_rate * dt))) if biggest > 0 else 0, 1)
    rates = (strain[0] / (n * dt), strain[1] / (n * dt))
    control = _control(stage, rates[0], rates[1])
    return sim.run(n, control, output_every=output_every or n, writer=writer)


@doing("hold")
def hold(sim: Simulation, stage: str, n_steps: int) -> Measures:
    """Run ``n_steps`` steps at fixed cell (strain rates 0) under the stage label ``stage``;
    returns the measures at the end (no history records: the caller writes them)."""
    return sim.run(n_steps, _control(stage, 0.0, 0.0), output_every=n_steps)


def rms_velocity_component(velocity) -> float:
    """sqrt(<v_x² + v_y²>/2) of the bodies' velocities (0 for none): the measure of
    ``[particles] initial_speed`` and of ``[protocol] aggregation_speed``."""
    return float(math.sqrt(float((velocity * velocity).mean()))) if velocity.size else 0.0


def equipartition_spin(sim: Simulation, speed: float) -> float:
    """The rms angular velocity at the kinetic temperature of ``speed``: speed sqrt(M/I), so
    that ½ I ω² = ½ M v_x² (M and I of a rod, or of a disc for bonded rods)."""
    return speed * math.sqrt(sim.body.mass / sim.body.inertia)


def rescale_speed(sim: Simulation, speed: float) -> float:
    """Scale every body's velocity and angular velocity by s = ``speed`` / (rms velocity
    component, sqrt(<v_x² + v_y²>/2), the measure of ``[particles] initial_speed``) so that it
    becomes ``speed``; returns the rms velocity component before (rods, or the discs of bonded
    rods).

    A gas at rest (rms 0) is left as it is. The scaled velocities are written back alone
    (:meth:`Simulation.set_velocities`), so the run continues deterministically from them.
    """
    velocity, omega = sim.velocities()
    before = rms_velocity_component(velocity)
    if before > 0.0:
        factor = speed / before
        sim.set_velocities(velocity * velocity.dtype.type(factor), omega * omega.dtype.type(factor))
    return before


def resample_speed(sim: Simulation, speed: float, seed: int) -> float:
    """Draw every body's velocity afresh at the kinetic temperature of ``speed`` (an Andersen
    thermostat, all bodies at once); returns the rms velocity component before.

    Velocity components ~ N(0, speed²), then the mean velocity removed (the gas's momentum stays
    zero); angular velocities ~ N(0, speed² M/I), the rotational share of equipartition
    (½ I ω² = ½ M v_x²; M and I of a rod, or of a disc for bonded rods). The generator is
    PCG64 seeded by (``seed``, the current step), so the draw is deterministic and a resumed run
    draws what the uninterrupted one drew. Unlike :func:`rescale_speed` it has no memory: a body
    that loses no energy between draws cannot be pumped (docs/science/dem-model.md §1.6).
    On bonded rods every disc is drawn on its own (the bonds are heated);
    :func:`dem_taichi.protocol.rod_thermostat.rod_speed` draws whole rods' rigid-body motions.
    """
    velocity, omega = sim.velocities()
    before = rms_velocity_component(velocity)
    rng = np.random.Generator(np.random.PCG64([int(seed), RESAMPLE_STREAM, int(sim.step)]))
    drawn = rng.normal(0.0, speed, size=velocity.shape)
    drawn -= drawn.mean(axis=0, keepdims=True)
    spin = equipartition_spin(sim, speed)
    spun = rng.normal(0.0, spin, size=omega.shape)
    sim.set_velocities(drawn.astype(velocity.dtype), spun.astype(omega.dtype))
    return before


def refresh_speed(sim: Simulation, speed: float, seed: int, keep: float) -> float:
    """Refresh every body's velocity partly towards the kinetic temperature of ``speed`` (a
    Langevin thermostat applied at intervals: the Ornstein–Uhlenbeck update of the velocities
    over one interval); returns the rms velocity component before.

    v ← a v + sqrt(1 − a²) ξ and ω ← a ω + sqrt(1 − a²) ζ, with a = ``keep`` = exp(−Δt/τ)
    (Δt the interval, τ the velocities' correlation time), ξ ~ N(0, speed²) per component with
    its mean over the bodies removed (the momentum kept) and ζ ~ N(0, speed² M/I)
    (equipartition). A gas that loses no energy between refreshes stays at the temperature on
    average (a² + 1 − a² = 1); one that dissipates does not: each refresh puts back only 1 − a²
    of the target energy (measured on an ageing gel, ``benchmarks/results/
    study_clay_agitated.md``: kinetic energy per rod 0.004 at a = 0.947, against ≈ 1.4 at the
    temperature).
    a = 0 is :func:`resample_speed`, a → 1 no thermostat. Unlike a fresh draw, a body's velocity and
    a cluster's collective motion last ~τ; unlike :func:`rescale_speed`, no mode is pumped
    beyond the temperature. Seeded as :func:`resample_speed` (deterministic, resumable).
    """
    if not 0.0 <= keep < 1.0:
        raise ValueError(f"keep = {keep!r}: allowed values are 0 <= keep < 1")
    velocity, omega = sim.velocities()
    before = rms_velocity_component(velocity)
    rng = np.random.Generator(np.random.PCG64([int(seed), 0x4C414E47, int(sim.step)]))
    noise = rng.normal(0.0, speed, size=velocity.shape)
    noise -= noise.mean(axis=0, keepdims=True)
    spin = equipartition_spin(sim, speed)
    fresh = math.sqrt(1.0 - keep * keep)
    spun = rng.normal(0.0, spin, size=omega.shape)
    sim.set_velocities(
        (keep * velocity + fresh * noise).astype(velocity.dtype),
        (keep * omega + fresh * spun).astype(omega.dtype),
    )
    return before
