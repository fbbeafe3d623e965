"""The study's findings as functions over arrays (dem_taichi.analysis.arrays, issue 21): the one
implementation that the report of a run in memory and the reader of a run folder both call.
Exact values on synthetic arrays; no Taichi, no simulation. That the two callers agree on a
real run is tested on the smoke protocol (tests/dem_taichi/test_protocol.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dem_taichi.analysis.arrays import (
    FABRIC_NOISE_MULTIPLE,
    PathArrays,
    ProbeArrays,
    compressibility_slope,
    fabric_isotropy,
    max_change,
    methods_relative_difference,
    modulus_over_p_at,
    power_law_exponent,
    stiffness_ratio,
    stress_ratio_at,
)

NAN = math.nan


def _path() -> PathArrays:
    states = {
        "A": {"mean_stress": 1.0, "specific_volume": 2.0, "fabric_deviator": 0.01},
        "C": {"mean_stress": 5.0, "stress_xx": 3.0, "stress_yy": 6.0},
    }
    stage = np.array(["isotropic_to_A", "A_to_B", "A_to_C", "A_to_B", "A_to_C"])
    p = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    return PathArrays(states, stage, {"mean_stress": p, "specific_volume": 2.0 * p**-0.25})


def _probes() -> ProbeArrays:
    return ProbeArrays(
        label=np.array(["A", "", "B", "", "C", "B"]),
        path=np.array(["isotropic_to_A", "A_to_B", "A_to_B", "A_to_C", "A_to_C", "A_to_B"]),
        mean_stress=np.array([1.0, 2.0, 4.0, 6.0, 5.0, 4.0]),
        e_oed_v=np.array([100.0, 0.0, 400.0, 10.0, 20.0, 500.0]),
        e_oed_h=np.array([90.0, 1.0, 300.0, 12.0, NAN, 450.0]),
        e_oed_v_dynamic=np.array([110.0, NAN, NAN, NAN, NAN, NAN]),
        e_oed_h_dynamic=np.array([NAN, NAN, NAN, NAN, NAN, 400.0]),
    )


def test_path_from_a_is_state_a_then_the_stage_in_path_order():
    path = _path()
    np.testing.assert_array_equal(path.from_a("A_to_B", "mean_stress"), [1.0, 2.0, 4.0])
    np.testing.assert_array_equal(path.on("A_to_C", "mean_stress"), [3.0, 5.0])
    assert math.isnan(path.at("B", "mean_stress"))
    assert path.on("A_to_B", "no_such_measure").size == 0
    without_a = PathArrays({}, path.stage, path.measures)
    np.testing.assert_array_equal(without_a.from_a("A_to_B", "mean_stress"), [2.0, 4.0])


def test_compressibility_slope_of_a_normal_compression_line():
    path = _path()
    fit = compressibility_slope(
        path.from_a("A_to_B", "mean_stress"), path.from_a("A_to_B", "specific_volume")
    )
    assert fit["lambda_star"] == pytest.approx(0.25, rel=1e-12)
    assert fit["r2"] == pytest.approx(1.0, abs=1e-12) and fit["n"] == 3
    assert math.isnan(compressibility_slope([1.0, 2.0], [2.0, 1.9])["lambda_star"])


def test_fabric_isotropy_against_the_sampling_noise():
    noise = math.sqrt(0.5 / 50)
    inside = fabric_isotropy([0.0, -FABRIC_NOISE_MULTIPLE * noise, 0.5 * noise], 50)
    assert inside.noise == noise and inside.within_noise
    assert inside.max_abs == FABRIC_NOISE_MULTIPLE * noise
    outside = fabric_isotropy([0.0, 2.01 * noise], 50)
    assert not outside.within_noise
    empty = fabric_isotropy([], 50)
    assert math.isnan(empty.max_abs) and not empty.within_noise


def test_stiffness_ratio_is_nan_where_a_modulus_is_missing_or_e_v_zero():
    probes = _probes()
    ratio = stiffness_ratio(probes.e_oed_h, probes.e_oed_v)
    np.testing.assert_array_equal(ratio, [0.9, NAN, 0.75, 1.2, NAN, 0.9])
    assert float(stiffness_ratio(3.0, 2.0)) == 1.5


def test_probe_selections():
    probes = _probes()
    np.testing.assert_array_equal(probes.isotropic(), [True, True, True, False, False, True])
    np.testing.assert_array_equal(probes.along_k0(), [4, 3])  # by rising p
    assert probes.last("B") == 5 and probes.last("B'") == -1
    assert probes.moduli_at("B") == (500.0, 450.0)
    assert all(math.isnan(x) for x in probes.moduli_at("B'"))
    assert modulus_over_p_at(probes, "B") == 125.0
    assert math.isnan(modulus_over_p_at(probes, "B'"))
    assert len(ProbeArrays.empty()) == 0 and len(probes) == 6


def test_power_law_exponent():
    p = np.array([1.0, 2.0, 4.0, 8.0])
    assert power_law_exponent(p, 3.0 * p**0.8) == pytest.approx(0.8, rel=1e-12)
    # two states are enough: the exponent of the power law through them
    assert power_law_exponent(p[:2], 3.0 * p[:2] ** 0.5) == pytest.approx(0.5, rel=1e-12)
    # non-positive or missing moduli (an unstable or failed probe) are left out
    e = np.r_[3.0 * p**0.8, -1.0, NAN]
    assert power_law_exponent(np.r_[p, 16.0, 32.0], e) == pytest.approx(0.8, rel=1e-12)
    assert math.isnan(power_law_exponent([1.0], [1.0]))
    assert math.isnan(power_law_exponent([2.0, 2.0], [1.0, 3.0]))


def test_k0_and_changes():
    path = _path()
    assert stress_ratio_at(path, "C") == 0.5
    assert math.isnan(stress_ratio_at(path, "B"))
    assert max_change([1.0, 3.0, -2.0], 1.0) == 3.0
    assert math.isnan(max_change([], 1.0))


def test_methods_relative_difference_where_both_methods_measured():
    diff = methods_relative_difference(_probes())
    # E_oed,v at A (110 against 100) and E_oed,h at the second B (400 against 450)
    np.testing.assert_allclose(diff, [0.1, 50.0 / 450.0], rtol=1e-15)
