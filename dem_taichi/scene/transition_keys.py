"""The keys of ``[protocol]`` for the compression to A and the relaxations: their field metadata.

The keys are fields of :class:`dem_taichi.scene.protocol_sections.ProtocolConfig` (declared there,
in the order the scene's TOML and hash have, from the metadata here; what each means is in that
class's docstring), as :mod:`dem_taichi.scene.servo_keys` and
:mod:`dem_taichi.scene.aggregation_keys` hold theirs. They are the compression's increments and
their halving, the A criterion (``pressure_tolerance``, ``coordination_min``, the confirmation)
and the relaxations to a static state (``relax_*``); the stages are
:mod:`dem_taichi.protocol.transition` and :func:`dem_taichi.protocol.quasistatic.relax`.

Units: DEM units (d = 1, disc mass = 1); stresses in force/length. Every key's unit and a one-line
description are in its metadata (``unit=``, ``doc=``), from which the documentation's scene
reference is generated.
"""

from __future__ import annotations

from typing import Any

from dem_taichi.scene.base import field_range as _range

__all__ = ["TRANSITION_KEYS"]

#: key -> field metadata of each compression and relaxation key of ``[protocol]``, in the order of
#: the section's fields
TRANSITION_KEYS: dict[str, dict[str, Any]] = {
    "compression_increment": _range(
        0.0,
        0.2,
        lo_open=True,
        doc=("per-axis logarithmic strain of a (coarse) compression increment towards A"),
        unit="1",
    ),
    "min_compression_increment": _range(
        0.0,
        0.2,
        lo_open=True,
        doc="smallest increment of the halving that resolves A",
        unit="1",
    ),
    "transition_pressure_factor": _range(
        1.0, doc="halving stops once a candidate A has p ≤ this × pressure_tolerance", unit="1"
    ),
    "gas_strain_rate": _range(
        0.0,
        None,
        lo_open=True,
        doc="strain-rate cap of the compression while p ≤ pressure_tolerance",
        unit="1/time",
    ),
    "pressure_tolerance": _range(
        0.0,
        None,
        lo_open=True,
        doc=(
            "relaxed static p above which a state carries load (the A criterion; "
            "the floor stress of the rate caps)"
        ),
        unit="force/length",
    ),
    "coordination_min": _range(
        0.0, doc="Z_m at or above which the contact network is taken as percolating", unit="1"
    ),
    "confirm_increments": _range(
        0,
        100,
        doc=("relaxed increments after a candidate A over which p must stay above the tolerance"),
        unit="1",
    ),
    "confirm_increment": {
        **_range(
            0.0,
            0.2,
            lo_open=True,
            doc=(
                "per-axis logarithmic strain of each confirmation increment after a "
                "candidate A (unset: the candidate's own increment)"
            ),
            unit="1",
        ),
        "optional": True,
    },
    "max_compression_increments": _range(
        1, doc="give up (error) after this many compression increments", unit="1"
    ),
    "relax_unbalanced_force": _range(
        0.0,
        1.0,
        lo_open=True,
        doc="unbalanced-force ratio below which a state is relaxed (static)",
        unit="1",
    ),
    "relax_kinetic_energy_per_rod": _range(
        0.0,
        None,
        lo_open=True,
        doc="kinetic energy per rod below which a state is relaxed (with the UFR)",
        unit="energy",
    ),
    "relax_check_steps": _range(1, doc="steps between relaxation checks", unit="steps"),
    "relax_max_steps": _range(
        1,
        doc=(
            "most steps of one relaxation (then it continues, recorded as not relaxed; a "
            "period-two oscillation, a time step past the local stability limit, stops the run)"
        ),
        unit="steps",
    ),
}
