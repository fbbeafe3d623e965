"""Speed–accuracy presets: named groups of the scene keys that trade run time for accuracy.

A preset sets the numerical knobs only, never the physics or the sample: the time step, the
loading rate, the servo's stiffness and the relaxation tolerances. Selecting one:

- in a scene file, ``[scene] preset = "fast" | "balanced" | "accurate"``: the preset fills
  every one of its keys that the file does not give; keys written in the file win;
- on the command line, ``--preset NAME`` (``run``, ``protocol``): the preset's keys replace the
  scene's (a built-in scene states them all), and ``--set section.key=value`` still wins over
  both;
- in Python, :func:`dem_taichi.scene.options.with_preset` (the command line's rule) or a
  scene dict with ``scene.preset`` (the file's rule).

The measured cost and error of each preset (wall time and the error of each finding against a
converged reference run of the same sample, isotropic and K0 paths of the ``default`` scene)
are in ``benchmarks/results/speed_accuracy.md`` (``benchmarks/speed_accuracy.py``) and in the
README; at the study's size (the ``study`` scene's branches from A, 1520 rods, five seeds),
``fast`` against ``balanced`` in ``benchmarks/results/study_fast_preset.md``. ``balanced`` is
the built-in scenes' own integration and loading (dt_safety 0.15, inertial number 1e-3, UFR
1e-4) with the secant servo, the paper scene's (``paper_bonded`` integrates at dt_safety 0.30,
measured in ``benchmarks/results/bonded_time_step.md``: a preset sets it back to the preset's
value); ``fast`` and ``accurate`` move every knob one step each way.

Keys (``section.key``) and why each is a knob (units: DEM, time in units of sqrt(m/k_n)·…):

- ``integration.dt_safety``: Δt / t_c. Stable to 0.35 on jammed packings
  (``benchmarks/results/dem_stability.csv``); ``fast`` stays below it with a margin. A scene
  whose paths step at a multiple of it (``[protocol] path_time_step_factor``: ``study``'s 5/3)
  multiplies the preset's value too; past 0.35 on rigid rods the scene is refused at load
  (``fast`` on ``study``: ``--set protocol.path_time_step_factor=1`` mends it).
- ``control.inertial_number_max``: the quasi-static loading-rate cap I = ε̇ d sqrt(ρ/p).
- ``protocol.servo_stiffness``: "secant" reaches each stress target near the rate cap,
  "elastic" approaches it slower on plastic paths (servo_trade results: 2× the wall time).
- ``protocol.relax_unbalanced_force``: UFR at which a state along a path counts as static.
- ``protocol.stress_tolerance``: |σ − σ_target| / σ_target accepted at a relaxed state.
- ``probing.relax_unbalanced_force``: UFR of the dynamic probes' relaxation.
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Any

__all__ = [
    "PRESETS",
    "PRESET_NAMES",
    "preset_keys",
    "fill_preset",
]

PRESETS: MappingProxyType = MappingProxyType(
    {
        "fast": MappingProxyType(
            {
                "integration.dt_safety": 0.25,
                "control.inertial_number_max": 3.0e-3,
                "protocol.servo_stiffness": "secant",
                "protocol.relax_unbalanced_force": 1.0e-3,
                "protocol.stress_tolerance": 3.0e-3,
                "probing.relax_unbalanced_force": 1.0e-6,
            }
        ),
        "balanced": MappingProxyType(
            {
                "integration.dt_safety": 0.15,
                "control.inertial_number_max": 1.0e-3,
                "protocol.servo_stiffness": "secant",
                "protocol.relax_unbalanced_force": 1.0e-4,
                "protocol.stress_tolerance": 1.0e-3,
                "probing.relax_unbalanced_force": 1.0e-7,
            }
        ),
        "accurate": MappingProxyType(
            {
                "integration.dt_safety": 0.075,
                "control.inertial_number_max": 2.5e-4,
                "protocol.servo_stiffness": "elastic",
                "protocol.relax_unbalanced_force": 1.0e-5,
                "protocol.stress_tolerance": 5.0e-4,
                "probing.relax_unbalanced_force": 1.0e-8,
            }
        ),
    }
)

#: The allowed values of ``[scene] preset`` ("" = none).
PRESET_NAMES = ("", *PRESETS)


def preset_keys(name: str, where: str = "[scene] preset") -> dict[str, Any]:
    """The ``section.key`` → value map of the preset ``name``; a clear error for another name."""
    from dem_taichi.scene.base import SceneError

    if name not in PRESETS:
        raise SceneError(
            f"{where} = {name!r}: allowed values are {', '.join(PRESETS)} "
            "(or leave it out for the scene's own keys)"
        )
    return dict(PRESETS[name])


def fill_preset(data: dict) -> dict:
    """A scene dict (as read from TOML) with its ``[scene] preset`` filled in: every key of the
    preset that the dict does not give is added; keys present win. No preset: unchanged."""
    name = data.get("scene", {}).get("preset", "") if isinstance(data.get("scene"), dict) else ""
    if not name:
        return data
    if not isinstance(name, str):
        from dem_taichi.scene.base import SceneError

        raise SceneError(f"[scene] preset = {name!r}: must be a string, one of {PRESET_NAMES}")
    out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in data.items()}
    for key, value in preset_keys(name).items():
        section, field_name = key.split(".")
        table = out.setdefault(section, {})
        if isinstance(table, dict):
            table.setdefault(field_name, value)
    return out


def set_keys(data: dict, overrides: dict[str, Any], where: str = "--set") -> dict:
    """``data`` (a scene dict) with ``section.key`` → value ``overrides`` written in, in place.

    An override of ``scene.preset`` first writes that preset's keys (replacing the scene's:
    the command line's rule), then every override, so that the other overrides win over it.
    Used by ``--set`` (:func:`dem_taichi.scene.config.scene_with_overrides`) and by the sweeps."""
    preset = overrides.get("scene.preset", "")
    items = dict(preset_keys(preset, f"{where} scene.preset")) if preset else {}
    items.update(overrides)
    for key, value in items.items():
        section, _, name = key.partition(".")
        table = data.setdefault(section, {})
        if not isinstance(table, dict):
            from dem_taichi.scene.base import SceneError

            raise SceneError(f"[{section}] must be a table")
        table[name] = value
    return data
