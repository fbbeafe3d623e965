"""The stress-servo keys of ``[protocol]``: their field metadata.

The keys are fields of :class:`dem_taichi.scene.protocol_sections.ProtocolConfig` (declared there,
in the order the scene's TOML and hash have, from the metadata here; what each means is in that
class's docstring); this module holds their metadata so that the ``[protocol]`` module stays under
the project's module length, as :mod:`dem_taichi.scene.aggregation_keys` does for the aggregation
keys. They are the tolerances of the relaxed states' stresses (``stress_tolerance``,
``path_stress_tolerance``), the servo's rate law and its hunting detection (``servo_*``), and the
caps of its loading rate (``unbalanced_force_max``, ``inertial_number_safety``,
``servo_inertial_number_safety``); the servo is
:mod:`dem_taichi.protocol.servo`.

Units: DEM units (d = 1, disc mass = 1); stresses in force/length. Every key's unit and a one-line
description are in its metadata (``unit=``, ``doc=``), from which the documentation's scene
reference is generated.
"""

from __future__ import annotations

from typing import Any

from dem_taichi.scene.base import field_choices as _choices
from dem_taichi.scene.base import field_range as _range

__all__ = ["SERVO_KEYS"]

#: key -> field metadata of each stress-servo key of ``[protocol]``, in the order of the section's
#: fields
SERVO_KEYS: dict[str, dict[str, Any]] = {
    "stress_tolerance": _range(
        0.0,
        0.1,
        lo_open=True,
        doc="|σ − σ_target| / σ_target allowed at relaxed states",
        unit="1",
    ),
    "path_stress_tolerance": {
        **_range(
            0.0,
            0.1,
            lo_open=True,
            doc=(
                "|σ − σ_target| / σ_target allowed at the relaxed states inside a path "
                "(unset: stress_tolerance; a path's end keeps stress_tolerance)"
            ),
            unit="1",
        ),
        "optional": True,
    },
    "servo_time": _range(
        0.0,
        None,
        lo_open=True,
        doc="time constant T of the stress servo, ε̇ = C⁻¹ (σ_target − σ) / T",
        unit="time",
    ),
    "servo_near_target": _range(
        0.0,
        1.0,
        lo_open=True,
        doc=("hunting detection: the residual counts as near within this fraction of the target"),
        unit="1",
    ),
    "servo_stall_times": _range(
        0.0,
        None,
        lo_open=True,
        doc="servo times T without settling after which T is doubled",
        unit="1",
    ),
    "servo_time_max_factor": _range(
        1.0, doc="largest servo time, as a multiple of servo_time", unit="1"
    ),
    "servo_stiffness": _choices(
        "elastic",
        "secant",
        doc=(
            "stiffness of the servo's rate law: 'elastic' the linear response C of "
            "the relaxed network, 'secant' s C with s the measured secant/elastic "
            "ratio"
        ),
    ),
    "servo_softening_min": _range(
        0.0,
        1.0,
        lo_open=True,
        doc="smallest secant/elastic ratio s of the secant servo",
        unit="1",
    ),
    "servo_check_steps": _range(1, doc="steps between servo updates", unit="steps"),
    "servo_max_steps": _range(
        1, doc="most steps to reach one stress target (then an error)", unit="steps"
    ),
    "unbalanced_force_max": _range(
        0.0,
        None,
        lo_open=True,
        doc=("unbalanced-force ratio limit while loading; above it the servo rate is halved"),
        unit="1",
    ),
    "inertial_number_safety": _range(
        0.0,
        1.0,
        lo_open=True,
        doc="the rates are capped at this fraction of [control] inertial_number_max",
        unit="1",
    ),
    "servo_inertial_number_safety": {
        **_range(
            0.0,
            1.0,
            lo_open=True,
            doc=(
                "the stress servo's rates are capped at this fraction of [control] "
                "inertial_number_max (unset: inertial_number_safety, which the compression to "
                "A keeps)"
            ),
            unit="1",
        ),
        "optional": True,
    },
}
