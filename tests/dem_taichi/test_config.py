"""Scene loading: validation messages, derived quantities, TOML round trip, gas generation."""

import math

import numpy as np
import pytest

from dem_taichi.physics.restitution import discrete_restitution, gamma_for_discrete_restitution
from dem_taichi.scene.config import (
    SceneError,
    contact_duration,
    gamma_from_restitution,
    load_scene,
    restitution_from_gamma,
    scene_from_toml,
    scene_to_toml,
)
from dem_taichi.scene.geometry import generate_gas, lens_area, rod_geometry


@pytest.mark.parametrize("name", ["smoke", "default", "paper"])
def test_builtin_scenes_load_and_round_trip(name):
    scene = load_scene(name)
    assert scene.scene.name == name
    assert scene_from_toml(scene_to_toml(scene)) == scene


def test_a_retired_key_still_loads_and_is_dropped():
    """[control] servo_gain (the engine's former stress servo) is in older scenes and the
    checkpoints written from them: they load, the key is gone from the scene."""
    scene = scene_from_toml("[control]\nservo_gain = 2.0\ninertial_number_max = 0.01\n")
    assert scene.control.inertial_number_max == 0.01
    assert not hasattr(scene.control, "servo_gain")
    assert "servo_gain" not in scene_to_toml(scene)


def test_paper_scene_is_the_study_size():
    scene = load_scene("paper")
    assert (scene.particles.n_rods, scene.particles.n_spheres) == (1520, 5)


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("[contact]\nk_n = -1.0", "[contact] k_n = -1.0 is out of range: allowed (0.0, inf)"),
        ("[contact]\nkn = 1.0", "unknown key(s) kn; allowed keys:"),
        ("[long_range]\npattern = 'salty'", "allowed values are acidic | basic | neutral"),
        ("[integration]\ndt_safety = 0.9", "[integration] dt_safety = 0.9 is out of range"),
        ("[particles]\nn_rods = 2.5", "[particles] n_rods = 2.5: must be an integer"),
        ("[contact]\nfriction = 1", "[contact] friction = 1: must be true or false"),
        ("[gravity]\ng = 9.81", "unknown section(s) [gravity]"),
        ("[contact]\ne_n = 0.5\ngamma_n = 3.0", "either e_n or gamma_n"),
        ("[particles]\nspacing = 1.5", "spacing = 1.5 > diameter"),
        ("[particles]\nn_spheres = 2\n[long_range]\nenabled = true", "needs n_spheres >= 3"),
        ("[contact]\ngamma_n = 1e6", "overdamped"),
        (
            "[contact]\ne_n = 0.5\nrestitution_model = 'exact'",
            "[contact] restitution_model = 'exact': allowed values are discrete | continuous",
        ),
        (
            "[contact]\ne_n = 0.05\n[integration]\ndt_safety = 0.3",
            "[contact] e_n = 0.05 with restitution_model = 'discrete': e_n = 0.05 is not reached",
        ),
        ("[scene\nname='x'", "invalid TOML"),
    ],
)
def test_invalid_scenes_name_the_key_and_what_is_allowed(text, fragment):
    with pytest.raises(SceneError) as info:
        scene_from_toml(text)
    assert fragment in str(info.value)


def test_restitution_and_damping_are_inverse():
    k, m = 1.0e5, 1.0
    for e in (0.1, 0.5, 0.9):
        gamma = gamma_from_restitution(e, k, m)
        assert restitution_from_gamma(gamma, k, m) == pytest.approx(e, rel=1e-12)
    assert contact_duration(k, 0.0, m) == pytest.approx(math.pi / math.sqrt(2 * k / m))


def test_time_step_is_safety_times_contact_duration():
    scene = scene_from_toml("[contact]\nk_n = 4.0e4\ne_n = 0.7\n[integration]\ndt_safety = 0.1")
    gamma = gamma_from_restitution(0.7, 4.0e4, 1.0)
    assert scene.time_step == pytest.approx(0.1 * math.pi / math.sqrt(8.0e4 - gamma**2))


def test_discrete_model_solves_the_replica_and_keeps_the_time_step():
    text = "[contact]\nk_n = 4.0e4\ne_n = 0.3\n[integration]\ndt_safety = 0.15\n"
    discrete = scene_from_toml(text)
    continuous = scene_from_toml(
        text.replace("e_n = 0.3", "e_n = 0.3\nrestitution_model = 'continuous'")
    )
    assert discrete.contact.restitution_model == "discrete"  # the default
    assert continuous.gamma_n == gamma_from_restitution(0.3, 4.0e4, 1.0)
    assert discrete.time_step == continuous.time_step  # Δt from the continuous-model t_c
    assert discrete.time_step == pytest.approx(
        0.15 * contact_duration(4.0e4, continuous.gamma_n, 1.0)
    )
    dt = discrete.time_step
    assert discrete_restitution(discrete.gamma_n, 4.0e4, 1.0, dt) == pytest.approx(0.3, abs=2e-4)
    assert discrete_restitution(continuous.gamma_n, 4.0e4, 1.0, dt) < 0.3 * 0.9  # the old error
    assert scene_from_toml(scene_to_toml(discrete)) == discrete


def test_discrete_model_tends_to_the_continuous_formula_as_dt_vanishes():
    k, m = 1.0e5, 1.0
    for e in (0.3, 0.7):
        gamma = gamma_from_restitution(e, k, m)
        t_c = contact_duration(k, gamma, m)
        # O(Δt/t_c) convergence: 0.3 % at 0.005 t_c, 0.06 % at 0.001 t_c (measured)
        assert gamma_for_discrete_restitution(e, k, m, 0.001 * t_c) == pytest.approx(
            gamma, rel=1e-3
        )
        assert discrete_restitution(gamma, k, m, 0.001 * t_c) == pytest.approx(e, rel=1e-3)
        assert discrete_restitution(0.0, k, m, 0.001 * t_c) == pytest.approx(1.0, abs=1e-6)


def test_given_gamma_n_ignores_the_restitution_model():
    for model in ("discrete", "continuous"):
        scene = scene_from_toml(f"[contact]\ngamma_n = 30.0\nrestitution_model = '{model}'")
        assert scene.gamma_n == 30.0
        assert scene.time_step == pytest.approx(0.15 * contact_duration(1.0e5, 30.0, 1.0))


def test_rod_geometry_inertia_and_area():
    scene = scene_from_toml("[particles]\nn_spheres = 3\nspacing = 0.5\ndisc_mass = 2.0")
    geo = rod_geometry(scene)
    assert geo.mass == 6.0
    assert geo.inertia == pytest.approx(2.0 * (0.25 + 0.25) + 3 * 2.0 / 8.0)
    lens = 2 * 0.25 * math.acos(0.5) - 0.25 * math.sqrt(1 - 0.25)
    assert lens_area(0.5, 0.5) == pytest.approx(lens)
    assert geo.solid_area == pytest.approx(3 * math.pi / 4 - 2 * lens)


def test_gas_is_non_overlapping_seeded_and_at_the_area_fraction():
    scene = load_scene("smoke")
    gas = generate_gas(scene)
    again = generate_gas(scene)
    assert np.array_equal(gas.position, again.position)
    geo = rod_geometry(scene)
    n = scene.particles.n_rods
    area = gas.cell_lengths.prod()
    assert n * geo.solid_area / area == pytest.approx(scene.particles.initial_area_fraction)
    axis = np.stack([np.cos(gas.angle), np.sin(gas.angle)], axis=1)
    discs = gas.position[:, None, :] + geo.offsets[None, :, None] * axis[:, None, :]
    flat = discs.reshape(-1, 2)
    rod = np.repeat(np.arange(n), geo.n_spheres)
    diff = flat[:, None] - flat[None]
    diff -= np.round(diff / gas.cell_lengths) * gas.cell_lengths
    dist = np.linalg.norm(diff, axis=-1)
    assert dist[rod[:, None] != rod[None, :]].min() >= scene.particles.diameter
    assert np.abs(gas.velocity.mean(axis=0)).max() < 1e-12


def test_scene_overrides_are_validated_like_the_file():
    from dem_taichi.scene.config import scene_with_overrides

    base = load_scene("smoke")
    scene = scene_with_overrides(
        base, ["contact.mu=0.2", "scene.seed=4", "particles.rod_model=bonded", "bonds.bending=1"]
    )
    assert (scene.contact.mu, scene.scene.seed, scene.bonded, scene.bonds.bending) == (
        0.2, 4, True, 1.0,
    )  # fmt: skip
    assert scene_with_overrides(base, []) is base
    quoted = scene_with_overrides(base, ['protocol.radial_stress_ratios="0.2, 0.3"'])
    assert quoted.extensions["protocol"].radial_stress_ratios == "0.2, 0.3"
    # a bonded scene made rigid drops its [bonds]
    rigid = scene_with_overrides(load_scene("smoke_bonded"), ["particles.rod_model=rigid"])
    assert not rigid.bonded
    for bad, words in (
        (["contact.muu=1"], "unknown key(s) muu; allowed keys"),
        (["contact.mu=-1"], "mu = -1.0 is out of range"),
        (["mu=0.2"], "expected section.key=value"),
        (["nosection.x=1"], "unknown section(s) [nosection]"),
        (["bonds.bending=1"], "[bonds] is used only with"),
    ):
        with pytest.raises(SceneError) as error:
            scene_with_overrides(base, bad)
        assert words in str(error.value)


def test_tangential_stiffness_limit_is_the_leapfrog_bound_of_two_discs():
    """ω_t = sqrt(3 k_t/k_n) ω_n for two free discs, ω_n Δt = π dt_safety, leapfrog needs
    ω Δt < 2: the limit is where sqrt(3 k_t/k_n) π dt_safety = 2."""
    from dem_taichi.scene.config import SceneError, load_scene, tangential_stiffness_limit

    for dt_safety in (0.05, 0.15, 0.4):
        ratio = tangential_stiffness_limit(dt_safety)
        assert math.sqrt(3.0 * ratio) * math.pi * dt_safety == pytest.approx(2.0)
    smoke = load_scene("smoke")
    limit = tangential_stiffness_limit(smoke.integration.dt_safety) * smoke.contact.k_n
    scene_from_toml(f"[contact]\nk_t = {0.99 * limit}\n")  # just inside
    with pytest.raises(SceneError, match=r"\[contact\] k_t = .* × k_n = 100000.0: allowed k_t/k_n"):
        scene_from_toml(f"[contact]\nk_t = {1.01 * limit}\n")


@pytest.mark.parametrize(
    ("toml", "words"),
    [
        ("[contact]\nk_n = 1e13\n", "[contact] k_n = 10000000000000.0 is out of range"),
        ("[contact]\ngamma_t = 1e-13\n", "[contact] gamma_t = 1e-13 is out of range"),
        ("[output]\nevery = 2000000000000\n", "[output] every = 2000000000000"),
        ("[protocol]\nservo_time = 1e15\n", "[protocol] servo_time = 1000000000000000.0"),
    ],
)
def test_every_number_of_a_scene_lies_within_the_magnitude_bounds(toml, words):
    from dem_taichi.scene.config import SceneError

    with pytest.raises(SceneError) as raised:
        scene_from_toml(toml)
    assert words in str(raised.value) and "magnitudes 1e-12 to 1e+12 (or 0)" in str(raised.value)
    scene_from_toml("[contact]\ngamma_t = 0.0\nk_n = 1e12\nk_t = 1e-12\n")  # 0 and the bounds
