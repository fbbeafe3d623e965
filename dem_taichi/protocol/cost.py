"""What a scene will cost before it runs: device memory, steps and CPU time (no Taichi).

- **Memory** (exact but for the neighbour-list capacity): the sum over the engine's device
  arrays (:data:`dem_taichi.engine.device_arrays.DEVICE_ARRAYS`) of their shapes for this scene, the
  neighbour capacity taken at 1.5× its start value (it grows as the sample is compressed), and
  the cell grid of the starting gas (its largest box).
- **Steps**: the built-in run's schedule exactly
  (:func:`dem_taichi.protocol.run_schedule.builtin_schedule`); for the protocol a rough estimate
  scaled from the measured default-scene protocol (serial, seed 2: gas → A 0.30 M steps, A→B 1.16 M,
  A→C 1.80 M, C→B 0.07 M, each radial path 1.63 M, at dt_safety 0.15, inertial-number cap 1e-3,
  elastic servo; ``benchmarks/sweeps/default_seeds.toml``): each path's steps × (Δt_ref / Δt) ×
  (I_ref / I) (the loading is rate-capped; the servo's fraction of that cap is left out: doubling
  it halved the steps on the `study` scene and multiplied them by 2.5 on `paper`,
  ``benchmarks/results/study_servo.md``) × ln(p_end / p_A) / ln(100 / 0.6) (p_A ≈ 1.2 ×
  ``pressure_tolerance``; the isotropic path's p_end is ``isotropic_end_stress`` when set) ×
  sqrt(path_increments / 6) × 0.5 for the secant servo (measured:
  ``servo_trade_default_acidic.md``), plus 2e5 steps per dynamic probe sweep, plus the ageing of
  an aggregation stage, exactly (its time / its Δt; ``aggregation_max_time`` for "coordination").
  Good to a factor ~3 (chaotic packings, the servo): the `study` scene's seed-11 run took 4.14 M
  steps, of which 1.55 M of ageing (``benchmarks/results/study_scene_sp05_replicas.md``; 3.12 M
  and 0.78 M before the sparser gas, ``study_servo.md``).
- **CPU time**: steps × (a + b · discs), a = 1.2e-4 s per step and b = 3.3e-8 s per
  disc-step, fitted to two measured serial protocol runs with long-range forces on the
  development machine (default: 1.68e-4 s per step at 1500 discs; paper: 3.7e-4 s at 7600,
  which is also the kernel benchmark's 2530 steps/s, ``benchmarks/results/
  dem_bench_commits.md``); b × 0.64 without long-range forces (3970 steps/s contact only),
  b × 2.5 for bonded rods (``benchmarks/results/bonded_paper.md``).

:func:`check_cost` is what the command lines call before a run: one line with the estimate
(unless quiet), a warning line past :data:`LONG_RUN_SECONDS`, and a refusal when the memory
exceeds the machine's (with what to change).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

__all__ = ["CostEstimate", "estimate_cost", "check_cost", "cost_lines", "LONG_RUN_SECONDS"]

#: Serial CPU seconds per step: fixed part and per disc (see the module docstring).
SECONDS_PER_STEP = 1.2e-4
SECONDS_PER_DISC_STEP = 3.3e-8
CONTACT_ONLY_FACTOR = 0.64
BONDED_FACTOR = 2.5
#: Steps of each stage of the measured default protocol (see the module docstring).
REFERENCE_STEPS = {
    "gas_to_A": 0.30e6,
    "isotropic": 1.16e6,
    "k0": 1.80e6,
    "unloading": 0.07e6,
    "radial": 1.63e6,
}
REFERENCE_DT_SAFETY = 0.15
REFERENCE_INERTIAL_NUMBER = 1e-3
SECANT_FACTOR = 0.5
DYNAMIC_PROBE_STEPS = 2e5
#: A run estimated longer than this gets a warning line (2 h of CPU time).
LONG_RUN_SECONDS = 7200.0


@dataclass(frozen=True)
class CostEstimate:
    """``steps`` (exact for the built-in run, rough for the protocol), ``cpu_seconds`` (one
    core), ``memory_bytes`` (device arrays), ``exact_steps`` whether the steps are exact."""

    steps: float
    cpu_seconds: float
    memory_bytes: float
    exact_steps: bool

    def describe(self) -> str:
        from dem_taichi.protocol.progress import format_seconds

        approx = "" if self.exact_steps else "~"
        spread = "" if self.exact_steps else " (rough: ±×3)"
        return (
            f"{approx}{self.steps:.3g} steps, ~{format_seconds(self.cpu_seconds)} on one CPU "
            f"core{spread}, {self.memory_bytes / 2**20:.0f} MiB of arrays"
        )


def _memory_bytes(scene, precision: str) -> float:
    from dem_taichi.engine.device_arrays import DEVICE_ARRAYS
    from dem_taichi.engine.parameters import resolve_physics
    from dem_taichi.kernels.layout import measure_block_rows
    from dem_taichi.scene.geometry import species_parameters

    p = scene.particles
    # the engine's own switches (charged discs included), so the sizes are those it allocates
    physics = resolve_physics(scene, species_parameters(scene)[0], p.n_spheres)
    bonded = p.rod_model == "bonded"
    discs = p.n_rods * p.n_spheres
    bodies = discs if bonded else p.n_rods
    d = p.diameter
    reach = d  # contact; long-range forces reach further
    lr = scene.long_range
    if lr.enabled:
        reach += max(lr.f_max_edge / lr.k_a_edge, lr.f_max_inner / lr.k_a_inner)
    radius = (reach + scene.integration.skin) / d
    # "auto" on a CPU: serial; the gather path keeps the full list (each pair twice)
    parallel = scene.integration.execution in ("parallel", "gather")
    full = scene.integration.execution == "gather"
    capacity = 1.5 * (2 if full else 1) * (int(2.2 * radius * radius) + 6)  # grown once
    rod_area = (p.n_spheres - 1) * p.spacing * d + math.pi * d * d / 4
    box = math.sqrt(p.n_rods * rod_area / p.initial_area_fraction)
    cells = int(box / (reach + scene.integration.skin)) + 2
    sizes = {
        "rods": bodies,
        "discs": discs,
        "spheres": 1 if bonded else p.n_spheres,
        "species": p.n_spheres,
        "capacity": capacity,
        "cells": cells,
        "rolling_discs": discs if physics.rolling else 1,
        "strength_rods": p.n_rods if physics.strength else 1,
        "partner_rods": p.n_rods if physics.partners else 1,
        # the parallel paths' block sums of the measure (one row on the serial path)
        "measure_blocks": measure_block_rows(bodies, discs, bonded) if parallel else 1,
    }
    real = 8 if precision == "f64" else 4
    total = 0.0
    for spec in DEVICE_ARRAYS:
        total += math.prod(spec.shape_for(sizes)) * (real if spec.dtype == "real" else 4)
    return total


def _reference_time_step() -> float:
    """Δt of the reference run: dt_safety 0.15 × t_c of k_n = 1e5, e_n = 0.5, m = 1."""
    from dem_taichi.scene.config import contact_duration, gamma_from_restitution

    gamma = gamma_from_restitution(0.5, 1.0e5, 1.0)
    return REFERENCE_DT_SAFETY * contact_duration(1.0e5, gamma, 1.0)


def _protocol_steps(scene) -> tuple[float, float]:
    """(steps of the whole protocol, of which on a rigid twin: the ageing of bonded rods with
    ``aggregation_rod_model = "rigid"``)."""
    from dem_taichi.scene.probing_sections import probing_settings
    from dem_taichi.scene.protocol_sections import protocol_settings

    c = protocol_settings(scene)
    probing = probing_settings(scene)
    paths = 0.0
    p_a = 1.2 * c.pressure_tolerance
    if c.run_isotropic:
        beyond = 1.0
        if c.isotropic_end_stress is not None and c.isotropic_end_stress > c.target_mean_stress:
            beyond = math.log(c.isotropic_end_stress / p_a) / math.log(c.target_mean_stress / p_a)
        paths += REFERENCE_STEPS["isotropic"] * beyond
    if c.run_k0:
        paths += REFERENCE_STEPS["k0"]
    if c.run_unloading:
        paths += REFERENCE_STEPS["unloading"]
    paths += REFERENCE_STEPS["radial"] * len(c.radial_ratios)
    paths *= (c.path_increments / 6) ** 0.5  # more increments: more relaxations, same strain
    # the strain to apply grows with ln(p_end / p_A); p_A ≈ 1.2 × the pressure tolerance
    span = math.log(max(c.target_mean_stress / p_a, 1.01))
    paths *= span / math.log(100.0 / 0.6)
    paths /= c.path_time_step_factor or 1.0  # the same loading in fewer, longer steps
    rate = REFERENCE_INERTIAL_NUMBER / scene.control.inertial_number_max
    servo = SECANT_FACTOR if c.servo_stiffness == "secant" else 1.0
    dt = _reference_time_step() / scene.time_step  # the loading takes a time, not steps
    probes = 0
    if probing.enabled and probing.dynamic:
        n_states = len(probing.state_labels)
        every = probing.every_n_increments
        n_paths = c.run_isotropic + c.run_k0 + c.run_unloading + len(c.radial_ratios)
        per_path = c.path_increments // every if every else 0
        probes = n_states + n_paths * per_path
        if probing.dynamic_states.strip() != "all":
            probes = len([s for s in probing.dynamic_states.split(",") if s.strip()])
    ageing, rigid = 0.0, 0.0
    if c.aggregates:
        ageing_time = c.aggregation_time if c.aggregation == "time" else c.aggregation_max_time
        factor = c.aggregation_time_step_factor or 1.0  # the ageing's Δt, a multiple
        ageing_scene = scene  # bonded rods aged as rigid: the rigid twin's Δt and bodies
        if c.ages_rigid(scene):
            ageing_scene = scene.replace(particles={"rod_model": "rigid"})
        ageing = (ageing_time or 0.0) / (ageing_scene.time_step * factor)  # exact: a hold
        rigid = ageing if ageing_scene is not scene else 0.0
    steps = REFERENCE_STEPS["gas_to_A"] + rate * servo * paths + probes * DYNAMIC_PROBE_STEPS
    return dt * steps + ageing, rigid


def estimate_cost(scene, command: str = "protocol", precision: str = "f64") -> CostEstimate:
    """The estimate for ``command`` = ``"run"`` (the built-in schedule) or ``"protocol"``."""
    if command not in ("run", "protocol"):
        raise ValueError(f"command = {command!r}: allowed values are run | protocol")
    p = scene.particles
    discs = p.n_rods * p.n_spheres
    if command == "run":
        from dem_taichi.protocol.run_schedule import builtin_schedule

        steps, rigid, exact = float(sum(n for _, n, _ in builtin_schedule(scene))), 0.0, True
    else:
        (steps, rigid), exact = _protocol_steps(scene), False
    per_disc = SECONDS_PER_DISC_STEP
    if not scene.long_range.enabled:
        per_disc *= CONTACT_ONLY_FACTOR
    rigid_seconds = rigid * (SECONDS_PER_STEP + per_disc * discs)  # a rigid twin's ageing
    if p.rod_model == "bonded":
        per_disc *= BONDED_FACTOR
    seconds = (steps - rigid) * (SECONDS_PER_STEP + per_disc * discs) + rigid_seconds
    return CostEstimate(steps, seconds, _memory_bytes(scene, precision), exact)


def _machine_memory() -> float:
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
        return math.inf


def check_cost(scene, command: str, precision: str = "f64", say=None, memory=None) -> CostEstimate:
    """Estimate, say it (``say(line)``, e.g. print to stderr; None: silent), warn past
    :data:`LONG_RUN_SECONDS`, and refuse (``ValueError``, one line) a scene whose arrays need
    more memory than the machine has (``memory`` bytes; default: the physical memory)."""
    cost = estimate_cost(scene, command, precision)
    available = _machine_memory() if memory is None else memory
    if cost.memory_bytes > available:
        f32 = _memory_bytes(scene, "f32") / 2**30
        raise ValueError(
            f"[particles] n_rods = {scene.particles.n_rods}: the engine's arrays need "
            f"~{cost.memory_bytes / 2**30:.1f} GiB, this machine has {available / 2**30:.1f} "
            "GiB: lower n_rods (memory grows in proportion), use --precision f32 "
            f"(~{f32:.1f} GiB), or run on a machine with more memory"
        )
    if say is not None:
        for line in cost_lines(cost):
            say(line)
    return cost


def cost_lines(cost: CostEstimate) -> list[str]:
    """The estimate in one line, and a warning line when the run is long."""
    lines = [f"cost estimate: {cost.describe()}"]
    if cost.cpu_seconds > LONG_RUN_SECONDS:
        lines.append(
            "this is a long run: fewer rods, --preset fast, --workers N (protocol) or the "
            "GPU (--arch gpu) shorten it; progress and checkpoints let it be stopped and "
            "resumed"
        )
    return lines
