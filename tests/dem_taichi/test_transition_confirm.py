"""The confirmation of state A with its own increment (``[protocol] confirm_increment``, issue
20): the confirmation only decides whether a candidate is A, so a cheaper confirmation that
reaches the same decision leaves A, and everything after it, bit for bit the same.

Scene: the smoke scene (40 rods), run to A alone (a few seconds each).
"""

from __future__ import annotations

import dataclasses
from types import MappingProxyType

import pytest

from dem_taichi.scene.config import SceneError, load_scene, scene_from_toml
from dem_taichi.scene.probing_sections import ProbingConfig
from dem_taichi.scene.protocol_sections import ProtocolConfig, protocol_settings


def smoke_with(**protocol):
    base = load_scene("smoke")
    config = dataclasses.replace(protocol_settings(base), **protocol)
    extensions = {"protocol": config, "probing": ProbingConfig(enabled=False)}
    return dataclasses.replace(base, extensions=MappingProxyType(extensions), source_text="")


def run_to_a(scene):
    """(state at A, the transition's details, steps of the confirmation) of a fresh run."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.protocol.paths import ProtocolRunner

    sim = Simulation(scene)
    runner = ProtocolRunner(sim, protocol_settings(scene), ProbingConfig(enabled=False))
    runner.compress_to_transition()
    work = runner.log.work["isotropic_to_A"]
    confirm_steps = sum(int(entry[0]) for kind, entry in work.items() if kind.startswith("confirm"))
    return runner.state_A, runner.log.transition_details, confirm_steps


def confirmation_increments(details: dict) -> list[float]:
    """h of the increments after the last candidate A of the recorded sequence."""
    sequence = details["sequence"]
    last = max(i for i, entry in enumerate(sequence) if entry.get("candidate"))
    return [entry["h"] for entry in sequence[last + 1 :]]


def test_increment_h_only_changes_the_confirmation():
    from dem_taichi.protocol.transition import increment_h

    unset = ProtocolConfig()
    small = ProtocolConfig(confirm_increment=1e-3)
    assert increment_h(unset, 0.02, confirming=True) == 0.02
    assert increment_h(small, 0.02, confirming=False) == 0.02
    assert increment_h(small, 0.02, confirming=True) == 1e-3
    assert increment_h(small, 2.5e-4, confirming=True) == 2.5e-4  # never above the candidate's


def test_a_smaller_confirmation_reaches_the_same_a_in_fewer_steps():
    from dem_taichi.engine.state import states_equal

    state_1, details_1, steps_1 = run_to_a(smoke_with())
    state_2, details_2, steps_2 = run_to_a(smoke_with(confirm_increment=1e-4))
    assert states_equal(state_1, state_2)
    assert details_1["protocol_index"] == details_2["protocol_index"]
    assert details_1["mean_stress"] == details_2["mean_stress"]
    # the increments after the (last) candidate are the confirmation's
    after_1, after_2 = confirmation_increments(details_1), confirmation_increments(details_2)
    assert len(after_1) == len(after_2) == 2
    assert max(after_2) <= 1e-4 < min(after_1)
    assert 0 < steps_2 < steps_1


@pytest.mark.parametrize("value", ["0.0", "-1e-3", "0.5"])
def test_a_confirm_increment_out_of_range_is_refused_at_load(value):
    with pytest.raises(SceneError, match="confirm_increment"):
        scene_from_toml(f"[protocol]\nconfirm_increment = {value}\n")
