"""Transition detection, plateau picking and fabric statistics (numpy only, exact cases)."""

import numpy as np
import pytest

from dem_taichi.analysis.arrays import (
    detect_transition,
    elastic_plateau,
    fabric_sampling_noise,
    fabric_tensor,
)


def test_transition_is_first_state_that_stays_loaded_and_connected():
    p = np.array([0.0, 1e-9, 5e-3, 0.0, 2e-3, 4e-3, 8e-3])
    z = np.array([0.5, 1.0, 3.2, 1.5, 3.1, 3.4, 3.6])
    t = detect_transition(p, z, pressure_tolerance=1e-3, coordination_min=3.0)
    # index 2 is loaded but the pressure relaxes away at index 3: not a solid yet.
    assert t.found and t.index == 4
    assert t.pressure == pytest.approx(2e-3)
    assert t.coordination_jump == pytest.approx(3.1 - 1.5)


def test_transition_not_found_is_reported_not_invented():
    t = detect_transition(np.zeros(5), np.ones(5), pressure_tolerance=1e-3, coordination_min=3.0)
    assert not t.found and np.isnan(t.pressure)


def test_transition_rejects_bad_input():
    with pytest.raises(ValueError, match="pressure_tolerance"):
        detect_transition(np.ones(3), np.ones(3), pressure_tolerance=0.0, coordination_min=3.0)
    with pytest.raises(ValueError, match="equal length"):
        detect_transition(np.ones(3), np.ones(4), pressure_tolerance=1.0, coordination_min=3.0)


def test_plateau_of_a_degradation_curve():
    amplitude = np.logspace(-7, -3, 9)
    modulus = 100.0 / (1.0 + (amplitude / 1e-5) ** 2)  # flat below ~1e-6, degrades above
    plateau = elastic_plateau(amplitude[::-1], modulus[::-1], relative_tolerance=0.02)
    assert plateau.modulus == pytest.approx(100.0, rel=0.02)
    assert 1e-7 <= plateau.elastic_limit < 1e-5
    flat = elastic_plateau(amplitude, np.full(9, 7.0))
    assert flat.n_points == 9 and flat.modulus == 7.0


def test_plateau_rejects_non_finite():
    with pytest.raises(ValueError):
        elastic_plateau(np.array([1e-6, 1e-5]), np.array([1.0, np.nan]))


def test_fabric_of_known_orientations_is_exact():
    beta = fabric_tensor(np.array([0.0, np.pi / 2]))
    np.testing.assert_allclose(beta, 0.5 * np.eye(2), atol=1e-15)
    beta = fabric_tensor(np.zeros(10))
    np.testing.assert_allclose(beta, [[1.0, 0.0], [0.0, 0.0]], atol=1e-15)
    assert np.trace(fabric_tensor(np.random.default_rng(0).uniform(0, np.pi, 50))) == (
        pytest.approx(1.0)
    )


def test_fabric_sampling_noise_matches_monte_carlo():
    rng = np.random.default_rng(1)
    n = 1520
    samples = [np.diff(np.diag(fabric_tensor(rng.uniform(0, np.pi, n))))[0] for _ in range(2000)]
    assert np.std(samples) == pytest.approx(fabric_sampling_noise(n), rel=0.05)
    assert fabric_sampling_noise(1520) == pytest.approx(0.018, abs=5e-4)
