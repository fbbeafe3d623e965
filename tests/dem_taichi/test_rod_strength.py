"""A spread of the rods' long-range strengths (``[long_range] strength_spread``, issue 19).

- the draw: none when the rods are alike, a mean of exactly 1, the log-spread σ, deterministic
  per seed, a stream of its own (the gas is the same with and without a spread);
- two rods: the pair's F_max and k_a are the scene's times the harmonic mean of the two rods'
  strengths, so the range is kept, in force and energy, for both facing pairs;
- a jammed packing, rigid and bonded, on the serial, parallel and gather paths: the engine's
  forces and long-range energy equal the numpy reference (:mod:`dem_taichi.physics.forcelaw`)
  on the engine's snapshot, which carries the strengths; a spread of 0 allocates one unused
  entry and compiles the kernels without it.
"""

from __future__ import annotations

import numpy as np
import pytest

from dem_taichi.engine.parameters import resolve_scene
from dem_taichi.engine.simulation import Simulation
from dem_taichi.physics import forcelaw
from dem_taichi.scene.config import SceneError, scene_from_toml
from dem_taichi.scene.geometry import generate_gas, rod_strengths

from .test_two_body import (
    DENSE_NETWORK,
    assert_engine_matches_reference,
    facing_rods,
    jammed_network,
    rods_scene,
)


def two_rods(seed: int, spread: float):
    """The two 3-disc rods of test_two_body.py (acidic, F_max 10/30, k_a 50/150, no friction),
    with ``[scene] seed`` and ``[long_range] strength_spread``."""
    return rods_scene("acidic").replace(
        scene={"seed": seed}, long_range={"strength_spread": spread}
    )


def test_no_draw_when_the_rods_are_alike():
    assert rod_strengths(two_rods(1, 0.0)) is None
    off = scene_from_toml("[long_range]\nenabled = false\nstrength_spread = 0.8")
    assert rod_strengths(off) is None
    assert not resolve_scene(off).physics.strength
    alike = two_rods(1, 0.0)
    assert not resolve_scene(alike).physics.strength
    assert resolve_scene(two_rods(1, 0.5)).physics.strength


@pytest.mark.parametrize("sigma", [0.3, 1.0])
def test_the_draw_has_mean_one_the_log_spread_and_its_own_stream(sigma):
    scene = scene_from_toml(
        f"[scene]\nseed = 7\n[particles]\nn_rods = 20000\n[long_range]\nenabled = true\n"
        f"strength_spread = {sigma}"
    )
    s = rod_strengths(scene)
    assert s.shape == (20000,) and np.all(s > 0.0)
    assert s.mean() == pytest.approx(1.0, rel=1e-12)
    assert np.std(np.log(s)) == pytest.approx(sigma, rel=0.03)  # 20000 draws: ~0.5 % noise
    np.testing.assert_array_equal(s, rod_strengths(scene))  # deterministic
    other = rod_strengths(scene.replace(scene={"seed": 8}))
    assert not np.allclose(s, other)


def test_the_gas_does_not_depend_on_the_spread():
    base = "[scene]\nseed = 3\n[particles]\nn_rods = 40\n[long_range]\nenabled = true\n"
    alike = generate_gas(scene_from_toml(base))
    spread = generate_gas(scene_from_toml(base + "strength_spread = 1.0"))
    np.testing.assert_array_equal(alike.position, spread.position)
    np.testing.assert_array_equal(alike.angle, spread.angle)
    np.testing.assert_array_equal(alike.velocity, spread.velocity)


@pytest.mark.parametrize("face", ["edge", "inner"])
@pytest.mark.parametrize("gap", [-0.01, 0.05, 0.15, 0.2 + 1e-6])
def test_two_rods_feel_the_harmonic_mean_of_their_strengths(face, gap):
    gas, (_, sj) = facing_rods(gap, face)  # A's edge disc (species 2) faces B's species sj
    f_max = np.array([10.0, 30.0, 10.0])
    k_a = np.array([50.0, 150.0, 50.0])
    charge = np.array([1, -1, 1])
    spread = Simulation(two_rods(4, 1.0), initial=gas)
    s = spread.rod_strength
    assert s is not None and abs(s[0] - s[1]) > 0.1  # two different strengths
    m = 2 * s[0] * s[1] / (s[0] + s[1])
    f_pair = m * forcelaw.harmonic_mean(f_max[2], f_max[sj])
    k_pair = m * forcelaw.harmonic_mean(k_a[2], k_a[sj])
    sign = charge[2] * charge[sj]
    expected = float(forcelaw.long_range_force(gap, f_pair, k_pair, sign))
    expected += 1.0e5 * max(-gap, 0.0)
    force_a = spread.get_state()["force"][0]
    assert force_a[0] == pytest.approx(-expected, rel=1e-9, abs=1e-9)
    energy = float(forcelaw.long_range_potential(gap, f_pair, k_pair, sign))
    assert spread.measure()["long_range_energy"] == pytest.approx(energy, rel=1e-9, abs=1e-12)
    if gap > 0.2:  # the range g_max = F_max / k_a is kept: nothing beyond it, whatever s
        assert force_a[0] == 0.0


@pytest.mark.parametrize(
    "rod_model, execution",
    [("rigid", "serial"), ("bonded", "serial"), ("rigid", "parallel"), ("bonded", "gather")],
)
def test_engine_matches_the_numpy_reference_with_a_spread(rod_model, execution):
    scene = scene_from_toml(DENSE_NETWORK).replace(
        particles={"rod_model": rod_model},
        long_range={"strength_spread": 0.8},
        integration={"execution": execution},
    )
    sim = jammed_network(scene)
    snap = sim.snapshot()
    assert snap.rod_strength is not None and snap.rod_strength.shape == (30,)
    assert sim.measure()["n_long_range_pairs"] > 10
    energy = forcelaw.potential_energy(snap)
    assert sim.measure()["long_range_energy"] == pytest.approx(energy.long_range, rel=1e-9)
    alike = forcelaw.potential_energy(snap.__class__(**{**snap.__dict__, "rod_strength": None}))
    assert abs(alike.long_range - energy.long_range) > 1e-3 * abs(energy.long_range)
    if rod_model == "rigid":
        assert_engine_matches_reference(sim, snap)


def test_a_spread_of_zero_allocates_and_reads_nothing():
    """σ = 0: the strengths' array holds one unused entry and the kernels compile without the
    strength branch (the bitwise smoke references of test_protocol.py run this default)."""
    sim = Simulation(two_rods(4, 0.0), initial=facing_rods(0.1, "edge")[0])
    assert sim.rod_strength is None and not sim.physics.strength
    assert sim.a["rod_strength"].shape == (1,)
    spread = Simulation(two_rods(4, 0.5), initial=facing_rods(0.1, "edge")[0])
    assert spread.physics.strength and spread.a["rod_strength"].shape == (2,)
    np.testing.assert_allclose(spread.a["rod_strength"].to_numpy(), spread.rod_strength)


def test_the_spread_is_validated_at_load():
    with pytest.raises(SceneError, match="strength_spread"):
        scene_from_toml("[long_range]\nenabled = true\nstrength_spread = -0.1")
    with pytest.raises(SceneError, match="strength_spread"):
        scene_from_toml("[long_range]\nenabled = true\nstrength_spread = 3.0")
