"""Cost estimates before a run (dem_taichi.protocol.cost): memory, steps, the refusal and the
warning."""

from __future__ import annotations

import math

import pytest

from dem_taichi.protocol.cost import LONG_RUN_SECONDS, check_cost, estimate_cost
from dem_taichi.protocol.run_schedule import builtin_schedule
from dem_taichi.scene.config import load_scene, scene_with_overrides
from dem_taichi.scene.options import with_preset


@pytest.mark.parametrize("execution", ["auto", "parallel", "gather"])
def test_memory_estimate_brackets_the_engine_allocation(execution):
    """The arrays' bytes summed from the device-array table for the scene are those the engine
    allocates, but for the neighbour capacity (taken at 1.5× its start value): on the serial
    path, the parallel one (block rows of the measure) and the gather one (the full list)."""
    from dem_taichi.engine.simulation import Simulation

    scene = load_scene("smoke").replace(integration={"execution": execution})
    sim = Simulation(scene)
    allocated = sum(
        math.prod(sim.a[name].shape) * (8 if "f64" in str(sim.a[name].dtype) else 4)
        for name in sim.a
    )
    estimated = estimate_cost(scene, "run").memory_bytes
    assert allocated <= estimated <= 2.0 * allocated


def test_run_steps_are_the_builtin_schedule_and_time_grows_with_size():
    scene = load_scene("default")
    cost = estimate_cost(scene, "run")
    assert cost.exact_steps and cost.steps == sum(n for _, n, _ in builtin_schedule(scene))
    bigger = scene.replace(particles={"n_rods": 3000})
    assert estimate_cost(bigger, "run").cpu_seconds > 2 * cost.cpu_seconds
    assert estimate_cost(bigger, "run").memory_bytes > 5 * cost.memory_bytes


def test_protocol_estimate_follows_the_knobs():
    scene = load_scene("default")
    base = estimate_cost(scene, "protocol")
    assert not base.exact_steps
    fast = estimate_cost(with_preset(scene, "fast"), "protocol")
    accurate = estimate_cost(with_preset(scene, "accurate"), "protocol")
    assert fast.steps < base.steps < accurate.steps
    stiff = scene.replace(contact={"k_n": 1.0e7, "k_t": 2.0e6})  # Δt 10× smaller
    assert estimate_cost(stiff, "protocol").steps == pytest.approx(10 * base.steps, rel=0.02)
    # the measured default protocol (serial, seed 2): 8.2 M path steps, 33 min; within ×3
    assert 8.2e6 / 3 < base.steps < 3 * 8.2e6
    assert 33 * 60 / 3 < base.cpu_seconds < 3 * 33 * 60
    # the paths at twice the Δt: their steps halve, the gas to A's do not
    coarse_scene = scene_with_overrides(scene, ["protocol.path_time_step_factor=2"])
    coarse = estimate_cost(coarse_scene, "protocol").steps
    assert base.steps / 2 < coarse < base.steps


def test_memory_beyond_the_machine_is_refused_with_what_to_change():
    scene = load_scene("paper")
    with pytest.raises(ValueError, match=r"n_rods = 1520: the engine's arrays need .* GiB.*f32"):
        check_cost(scene, "run", memory=1e6)


def test_long_runs_get_a_warning_line_and_short_ones_only_the_estimate():
    lines = []
    check_cost(load_scene("smoke"), "run", say=lines.append)
    assert len(lines) == 1 and lines[0].startswith("cost estimate: ")
    lines.clear()
    huge = load_scene("paper").replace(particles={"n_rods": 100_000})
    cost = check_cost(huge, "protocol", say=lines.append)
    assert cost.cpu_seconds > LONG_RUN_SECONDS
    assert len(lines) == 2 and "long run" in lines[1] and "--preset fast" in lines[1]


def test_protocol_estimate_counts_the_ageing_and_the_isotropic_path_past_B():
    """The ageing of an aggregation stage is counted exactly (time / Δt); an isotropic path
    continued past B costs more; the `study` scene's estimate is within ×3 of its measured run
    (seed 11, 1520 rods: 4.14 M steps, 1.55 M of them ageing; study_scene_sp05_replicas.md)."""
    from dem_taichi.scene.options import scene_from_options

    study = load_scene("study")
    longer = scene_from_options("study", overrides=["protocol.aggregation_time=3000"])
    extra = estimate_cost(longer, "protocol").steps - estimate_cost(study, "protocol").steps
    assert extra == pytest.approx(1000.0 / study.time_step, rel=1e-9)
    further = scene_from_options("study", overrides=["protocol.isotropic_end_stress=1000"])
    assert estimate_cost(further, "protocol").steps > estimate_cost(study, "protocol").steps
    assert 4.14e6 / 3 < estimate_cost(study, "protocol").steps < 3 * 4.14e6


def test_the_optional_arrays_are_sized_as_the_engine_sizes_them():
    """The rods' strengths and attraction partners take a row per rod only where the engine
    allocates one: keys set on a scene whose discs carry no charge (pattern neutral) cost
    nothing, as in the engine."""
    base = load_scene("study_demo")
    options = {"strength_spread": 0.5, "attraction_pairs": "bonded_at_A"}

    def memory(**long_range):
        return estimate_cost(base.replace(long_range=long_range), "run").memory_bytes

    assert memory(pattern="neutral", **options) == memory(pattern="neutral")
    rods = base.particles.n_rods
    extra = memory(**options) - memory()
    assert extra == (rods - 1) * 8 + (rods - 1) * 32 * 4  # f64 strengths, int32 partner rows
