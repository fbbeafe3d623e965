"""Speed–accuracy presets (dem_taichi.scene.presets): the file rule, the command-line rule,
sweeps."""

from __future__ import annotations

import subprocess
import sys

import pytest

from dem_taichi.scene.config import (
    SceneError,
    load_scene,
    scene_from_dict,
    scene_from_toml,
    scene_to_toml,
    scene_with_overrides,
)
from dem_taichi.scene.options import scene_from_options, with_preset
from dem_taichi.scene.presets import PRESETS, preset_keys
from dem_taichi.scene.probing_sections import probing_settings
from dem_taichi.scene.protocol_sections import protocol_settings
from dem_taichi.sweep.spec import sweep_from_toml

BUILTIN = (
    "smoke", "demo", "default", "paper", "smoke_bonded", "paper_bonded", "study", "study_demo",
)  # fmt: skip
NUMERICAL_KEYS = {
    "integration.dt_safety",
    "control.inertial_number_max",
    "protocol.servo_stiffness",
    "protocol.relax_unbalanced_force",
    "protocol.stress_tolerance",
    "probing.relax_unbalanced_force",
}


def value(scene, key: str):
    section, name = key.split(".")
    if section == "protocol":
        return getattr(protocol_settings(scene), name)
    if section == "probing":
        return getattr(probing_settings(scene), name)
    return getattr(getattr(scene, section), name)


@pytest.mark.parametrize("name", sorted(PRESETS))
@pytest.mark.parametrize("scene_name", BUILTIN)
def test_every_preset_loads_on_every_builtin_scene(name, scene_name):
    if (name, scene_name) == ("fast", "study"):  # its paths at 5/3 Δt: see the test below
        with pytest.raises(SceneError, match="path_time_step_factor"):
            with_preset(load_scene(scene_name), name)
        return
    scene = with_preset(load_scene(scene_name), name)
    assert scene.scene.preset == name
    for key, expected in preset_keys(name).items():
        assert value(scene, key) == expected
    assert scene_from_toml(scene_to_toml(scene)) == scene


def test_fast_on_the_study_scene_needs_its_paths_at_the_presets_step():
    """`study` steps its paths at 5/3 of dt_safety; under `fast` (0.25) that is 0.42, past rigid
    rods' measured limit on jammed packings (0.35): refused at load, naming the key and the
    mend, which loads (the paths at 0.25: what study_fast_preset.md measured as `fast`)."""
    with pytest.raises(SceneError, match=r"path_time_step_factor = 1.66.* 0.417, beyond .* rigid "
                       r"rods on jammed packings, 0.35: allowed .* <= 1.4 \(e.g. --set "
                       r"protocol.path_time_step_factor=1\)"):  # fmt: skip
        with_preset(load_scene("study"), "fast")
    scene = scene_from_options("study", "fast", ["protocol.path_time_step_factor=1"])
    assert scene.integration.dt_safety == 0.25
    assert protocol_settings(scene).path_time_step(1.0) == 1.0
    # balanced and accurate keep the scene's factor: 0.25 and 0.125 on the paths
    for name, dt in (("balanced", 0.25), ("accurate", 0.125)):
        scene = scene_from_options("study", name)
        path_safety = protocol_settings(scene).path_time_step(scene.integration.dt_safety)
        assert path_safety == pytest.approx(dt)


def test_presets_set_only_numerical_keys_and_are_ordered_by_cost():
    for name in PRESETS:
        assert set(preset_keys(name)) == NUMERICAL_KEYS
    fast, balanced, accurate = (preset_keys(n) for n in ("fast", "balanced", "accurate"))
    for key in NUMERICAL_KEYS - {"protocol.servo_stiffness"}:
        assert fast[key] > balanced[key] > accurate[key], key


def test_file_rule_keys_written_in_the_file_win():
    scene = scene_from_dict(
        {"scene": {"preset": "accurate"}, "integration": {"dt_safety": 0.1}, "particles": {}}
    )
    assert scene.integration.dt_safety == 0.1
    assert (
        scene.control.inertial_number_max == preset_keys("accurate")["control.inertial_number_max"]
    )
    assert protocol_settings(scene).servo_stiffness == "elastic"


def test_command_line_rule_preset_replaces_and_set_wins():
    base = load_scene("default")
    scene = scene_from_options("default", "fast", ["integration.dt_safety=0.2"])
    assert scene.integration.dt_safety == 0.2
    assert scene.control.inertial_number_max == 3.0e-3
    assert base.integration.dt_safety == 0.15
    # --set scene.preset=NAME is the same as --preset NAME
    same = scene_with_overrides(base, ["scene.preset=fast", "integration.dt_safety=0.2"])
    assert same == scene


def test_no_preset_keeps_the_scene_toml_unchanged():
    text = scene_to_toml(load_scene("default"))
    assert "preset" not in text
    assert with_preset(load_scene("default"), "") == load_scene("default")


def test_unknown_preset_refused_with_the_allowed_names():
    with pytest.raises(SceneError, match=r"\[scene\] preset = 'fastest'.*fast, balanced"):
        scene_from_dict({"scene": {"preset": "fastest"}})
    with pytest.raises(SceneError, match="fast, balanced, accurate"):
        scene_with_overrides(load_scene("smoke"), ["scene.preset=quick"])


def test_sweep_preset_replaces_the_scene_keys_and_member_keys_win():
    spec = sweep_from_toml(
        """
[sweep]
scene = "default"
[sweep.set]
"scene.preset" = "accurate"
[[sweep.members]]
name = "a"
[[sweep.members]]
name = "b"
"integration.dt_safety" = 0.1
"""
    )
    a, b = (scene_from_toml(m.scene_toml) for m in spec.members)
    assert a.integration.dt_safety == 0.075 and b.integration.dt_safety == 0.1
    assert a.control.inertial_number_max == b.control.inertial_number_max == 2.5e-4


def test_command_line_refuses_an_unknown_preset(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "dem_taichi", "run", "smoke", "--out", str(tmp_path / "r")]
        + ["--preset", "fastest"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert "invalid choice: 'fastest'" in proc.stderr and "Traceback" not in proc.stderr


def test_builtin_scene_names_are_the_shipped_scenes():
    """The scene names the command lines list in their help and errors are the scenes shipped
    (a new scene is listed without editing a help string)."""
    from dem_taichi.scene.config import builtin_scene_names

    assert builtin_scene_names() == sorted(BUILTIN)
