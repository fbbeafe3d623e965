"""The built-in run's schedule (``python -m dem_taichi run``): its stages and their steps.

Plain Python (no Taichi): used by the command line (:mod:`dem_taichi.cli.commands`) to run the
stages and by the cost estimate (:mod:`dem_taichi.protocol.cost`) to count their steps.
"""

from __future__ import annotations

import math

__all__ = ["builtin_schedule"]


def builtin_schedule(scene) -> list[tuple[str, int, float]]:
    """Stages of the built-in run: (stage label, steps, strain rate of both axes).

    The compression lasts t = ln(v_0 / v_target) / (2 ε̇) (area A ∝ exp(−2 ε̇ t)).
    """
    v0 = 1.0 / scene.particles.initial_area_fraction
    target = scene.control.target_specific_volume
    rate = scene.control.compression_strain_rate
    stages = []
    if target < v0:
        duration = math.log(v0 / target) / (2.0 * rate)
        stages.append(("isotropic_to_A", int(math.ceil(duration / scene.time_step)), rate))
    stages.append(("relax", scene.control.relax_steps, 0.0))
    return stages
