"""[protocol] and [probing] scene sections: defaults, validation messages, TOML round trip."""

from __future__ import annotations

import pytest

from dem_taichi.scene.config import SceneError, load_scene, scene_from_toml, scene_to_toml
from dem_taichi.scene.probing_sections import ProbingConfig, probing_settings
from dem_taichi.scene.protocol_sections import ProtocolConfig, parse_number_list, protocol_settings


def test_sections_load_from_a_scene_and_round_trip():
    scene = scene_from_toml(
        '[protocol]\ntarget_mean_stress = 50.0\nradial_stress_ratios = "0.5, -0.25"\n'
        '[probing]\nstates = "A, C"\namplitude_min = 1e-8\n'
    )
    protocol, probing = protocol_settings(scene), probing_settings(scene)
    assert protocol.target_mean_stress == 50.0
    assert protocol.radial_ratios == (0.5, -0.25)
    assert probing.state_labels == ("A", "C")
    again = scene_from_toml(scene_to_toml(scene))
    assert again.extensions["protocol"] == protocol
    assert again.extensions["probing"] == probing


def test_defaults_when_the_scene_has_no_section():
    scene = scene_from_toml("[scene]\nname = 'x'\n")
    assert protocol_settings(scene) == ProtocolConfig()
    assert probing_settings(scene) == ProbingConfig()
    assert ProtocolConfig().stress_tolerance == 1e-3


def test_the_probing_names_still_import_from_protocol_sections():
    """[probing] moved to its own module (issue 21); the old import path gives the same names."""
    from dem_taichi.scene import protocol_sections

    assert protocol_sections.ProbingConfig is ProbingConfig
    assert protocol_sections.probing_settings is probing_settings


def test_builtin_scenes_with_sections_load():
    for name in ("smoke", "default", "paper"):
        scene = load_scene(name)
        assert isinstance(protocol_settings(scene), ProtocolConfig)


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("[protocol]\nbogus = 1\n", ["[protocol]", "bogus", "allowed keys"]),
        ("[protocol]\ntarget_mean_stress = -1.0\n", ["target_mean_stress", "out of range"]),
        ("[protocol]\nstress_tolerance = 0.5\n", ["stress_tolerance", "allowed"]),
        (
            "[protocol]\ncompression_increment = 0.01\nmin_compression_increment = 0.02\n",
            ["min_compression_increment", "allowed"],
        ),
        ('[protocol]\nradial_stress_ratios = "0.5, x"\n', ["radial_stress_ratios", "numbers"]),
        ('[protocol]\nradial_stress_ratios = "2.5"\n', ["radial_stress_ratios", "(-2, 2)"]),
        ("[protocol]\nrun_k0 = false\n", ["run_unloading", "run_k0"]),
        ('[probing]\nsliding_contacts = "maybe"\n', ["sliding_contacts", "stuck | free"]),
        ("[probing]\namplitude_min = 1e-2\namplitude_max = 1e-3\n", ["amplitude_min"]),
        ("[probing]\nevery_n_increments = 1.5\n", ["every_n_increments", "integer"]),
    ],
)
def test_invalid_values_fail_naming_the_key(text, words):
    with pytest.raises(SceneError) as info:
        scene_from_toml(text)
    for word in words:
        assert word in str(info.value)


def test_amplitudes_are_log_spaced_and_inclusive():
    amps = ProbingConfig(amplitude_min=1e-8, amplitude_max=1e-4, amplitudes_per_decade=2).amplitudes
    assert len(amps) == 9
    assert amps[0] == pytest.approx(1e-8) and amps[-1] == pytest.approx(1e-4)
    assert all(b / a == pytest.approx(10**0.5) for a, b in zip(amps, amps[1:], strict=False))
    assert ProbingConfig(amplitude_min=1e-5, amplitude_max=1e-5).amplitudes == (1e-5,)


def test_parse_number_list():
    assert parse_number_list("", "k") == ()
    assert parse_number_list(" 1, 2.5 ,-3", "k") == (1.0, 2.5, -3.0)
    with pytest.raises(SceneError, match="k = "):
        parse_number_list("1, nan", "k")


def test_scene_lists_may_be_toml_arrays():
    text = (
        "[protocol]\nradial_stress_ratios = [0.2, 0.35, 0.5]\n"
        '[probing]\nstates = ["A", "C", "R1_end"]\ndynamic_states = ["C"]\n'
    )
    scene = scene_from_toml(text)
    protocol, probing = scene.extensions["protocol"], scene.extensions["probing"]
    assert protocol.radial_stress_ratios == "0.2, 0.35, 0.5"
    assert probing.states == "A, C, R1_end" and probing.dynamic_states == "C"
    # the same scene as the comma-separated strings, and it round-trips
    same = scene_from_toml(
        '[protocol]\nradial_stress_ratios = "0.2, 0.35, 0.5"\n'
        '[probing]\nstates = "A, C, R1_end"\ndynamic_states = "C"\n'
    )
    assert scene_to_toml(scene) == scene_to_toml(same)
    assert scene_from_toml(scene_to_toml(scene)) == scene
    with pytest.raises(SceneError, match="a list of numbers or strings"):
        scene_from_toml("[protocol]\nradial_stress_ratios = [true]\n")


def test_a_path_time_step_factor_is_held_to_the_scenes_stability_bounds():
    """``path_time_step_factor`` × dt_safety: bonded rods refused past their measured limit
    (0.4: 0.15 × 2 loads, 0.15 × 3 does not), a tangential spring refused past the leapfrog
    bound at the coarser step; the ageing's factor is held to the same bounds, except the bonded
    one where the bonded rods age as rigid rods (their rigid twin has no bonds)."""
    from dem_taichi.scene.config import scene_with_overrides

    bonded = scene_with_overrides(load_scene("paper_bonded"), ["integration.dt_safety=0.15"])
    assert protocol_settings(
        scene_with_overrides(bonded, ["protocol.path_time_step_factor=2"])
    ).path_time_step(1.0) == pytest.approx(2.0)
    with pytest.raises(SceneError, match=r"path_time_step_factor = 3.0 × .* allowed .* <= 2.67"):
        scene_with_overrides(bonded, ["protocol.path_time_step_factor=3"])
    # k_t/k_n 3: within the bound at 0.15 (6.0), beyond it at 0.3 (1.5)
    stiff = scene_with_overrides(load_scene("smoke"), ["contact.k_t=3e5"])
    with pytest.raises(SceneError, match="path_time_step_factor = 2.0: .* leapfrog bound"):
        scene_with_overrides(stiff, ["protocol.path_time_step_factor=2"])
    with pytest.raises(SceneError, match="aggregation_time_step_factor = 2.0: .* leapfrog"):
        scene_with_overrides(
            stiff, ['protocol.aggregation="time"', "protocol.aggregation_time=10",
                    "protocol.aggregation_time_step_factor=2"],
        )  # fmt: skip
    aged = ['protocol.aggregation="time"', "protocol.aggregation_time=10",
            "protocol.aggregation_time_step_factor=3"]  # fmt: skip
    with pytest.raises(SceneError, match="aggregation_time_step_factor = 3.0 × "):
        scene_with_overrides(bonded, aged)
    scene_with_overrides(bonded, [*aged, 'protocol.aggregation_rod_model="rigid"'])
    assert protocol_settings(load_scene("smoke")).path_time_step(0.25) == 0.25  # unset: 1
    # rigid rods' paths held to their measured limit on jammed packings (0.35), not the ageing
    rigid = scene_with_overrides(load_scene("smoke"), ["integration.dt_safety=0.2"])
    scene_with_overrides(rigid, ["protocol.path_time_step_factor=1.7"])  # 0.34: loads
    with pytest.raises(SceneError, match=r"= 1.8 × .* is 0.36, beyond .* rigid rods on jammed "):
        scene_with_overrides(rigid, ["protocol.path_time_step_factor=1.8"])
    scene_with_overrides(
        rigid, ['protocol.aggregation="time"', "protocol.aggregation_time=10",
                "protocol.aggregation_time_step_factor=2"],
    )  # fmt: skip
