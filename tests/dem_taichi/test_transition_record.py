"""The record of the fluid–solid transition, a pure function of the compression's relaxed
sequence (:func:`dem_taichi.protocol.transition.transition_record`): no engine needed."""

from __future__ import annotations

import math
from typing import cast

import pytest

from dem_taichi.engine.measures import Measures
from dem_taichi.protocol.transition import transition_record
from dem_taichi.scene.protocol_sections import ProtocolConfig


def _entry(p: float, z: float, **flags) -> dict:
    return {"mean_stress": p, "mechanical_coordination_number": z, "relaxed": True, **flags}


def _measures(p: float, z: float) -> Measures:
    """The measures at A that the record reads (the others are not read)."""
    record = {"mean_stress": p, "mechanical_coordination_number": z, "specific_volume": 1.3}
    return cast(Measures, {**record, "step": 1234})


def test_the_record_skips_restored_increments_and_finds_the_jump():
    sequence = [
        _entry(0.0, 1.0),
        _entry(50.0, 3.6, restored=True),  # overshot: restored, the increment halved
        _entry(0.2, 2.0),
        _entry(1.0, 3.2, candidate=True),
        _entry(1.5, 3.3),
        _entry(2.0, 3.4),
    ]
    at_a = _measures(1.0, 3.2)
    transition, details = transition_record(sequence, at_a, ProtocolConfig(), 0.5)
    assert transition.index == 2  # of the relaxed states without the restored one
    assert details["protocol_index"] == details["detector_index"] == 2
    assert details["detector_agrees"] and details["first_candidate_index"] == 2
    assert details["coordination_jump"] == pytest.approx(1.2)
    assert details["mean_stress_before"] == 0.2
    assert details["n_increments"] == 6 and details["sequence"] is sequence
    assert "pressure_tolerance_reduced" not in details


def test_the_record_names_a_reduced_tolerance_and_a_first_state_a():
    sequence = [_entry(3.0, 3.5, candidate=True), _entry(4.0, 3.6)]
    at_a = _measures(3.0, 3.5)
    config = ProtocolConfig(pressure_tolerance_reduced=0.01)
    _, details = transition_record(sequence, at_a, config, 0.5)
    assert details["pressure_tolerance_reduced"] == 0.01
    assert details["coordination_jump"] == 3.5 and math.isnan(details["mean_stress_before"])
