"""The findings on the mapped stress window (dem_taichi.analysis.mapped_window, issue 19 item 3):
every function against values computed by hand on constructed histories, the NaN cases, and
run_findings / open_sweep on a synthetic run folder (no Taichi, no simulation)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import xarray as xr
from scipy import stats

from dem_taichi.analysis.findings import run_findings, stress_scale_interval
from dem_taichi.analysis.mapped_window import (
    densification_sensitivity,
    local_compressibility,
    moduli_exponent,
    rod_disc_union_area,
    rod_rectangle_area,
    specific_volume_at,
    specific_volume_rectangle,
    stress_scale_from_stiffness,
    windowed_compressibility,
)
from dem_taichi.io.schema import stage_code
from dem_taichi.scene.config import load_scene, scene_to_toml, scene_with_overrides
from dem_taichi.scene.geometry import rod_geometry

# --- the stress scale -------------------------------------------------------------------------


def test_stress_scale_of_a_power_law_is_exact():
    """E_v/p = 125 (p/4)^−0.2: E_v/p = 125 at p* = 4 DEM units, so 100/4 = 25 kPa per unit;
    the bracketing states are p = 2 and 8 (log-log interpolation is exact for a power law)."""
    p = np.array([0.5, 1.0, 2.0, 8.0, 16.0])
    e_v = 125.0 * p * (p / 4.0) ** -0.2
    s = stress_scale_from_stiffness(p, e_v)
    assert s.method == "interpolated" and s.reason == ""
    assert s.p_star == pytest.approx(4.0, rel=1e-12)
    assert s.kpa_per_unit == pytest.approx(25.0, rel=1e-12)


def test_stress_scale_interpolates_in_log_log_between_the_bracketing_pair():
    """States (1, E_v/p = 250) and (4, 62.5): ln(E_v/p) falls by ln 4 over ln 4, slope −1, so
    E_v/p = 125 at p* = 2 → 50 kPa per unit. Shuffled input: ordered by p first."""
    s = stress_scale_from_stiffness([4.0, 1.0], [4.0 * 62.5, 250.0])
    assert s.p_star == pytest.approx(2.0, rel=1e-12)
    assert s.kpa_per_unit == pytest.approx(50.0, rel=1e-12)


def test_stress_scale_takes_the_last_crossing_by_rising_p():
    """E_v/p = 200, 100, 200, 100 at p = 1, 2, 3, 4: the crossing at the highest p is on (3, 4),
    at ln p* = ln 3 + ln(4/3) · ln(200/125)/ln(200/100) (the one near A, on (1, 2), is the
    forming gel's, not the loaded material's)."""
    p = np.array([1.0, 2.0, 3.0, 4.0])
    s = stress_scale_from_stiffness(p, p * np.array([200.0, 100.0, 200.0, 100.0]))
    expected = 3.0 * (4.0 / 3.0) ** (math.log(1.6) / math.log(2.0))
    assert s.p_star == pytest.approx(expected, rel=1e-12)
    assert s.kpa_per_unit == pytest.approx(100.0 / expected, rel=1e-12)


def test_stress_scale_ignores_a_rising_crossing_near_a():
    """A forming gel (a 300-rod K70 run): E_v/p = 120, 124.7, 221, 179, 125.8 at rising p rises
    through 125 near A and stays above it: no scale (it would be 29 kPa per unit), and the
    reason says E_v/p does not fall through 125."""
    p = np.array([0.63, 3.39, 7.91, 42.9, 99.96])
    s = stress_scale_from_stiffness(p, p * np.array([120.2, 124.7, 221.2, 179.4, 125.8]))
    assert math.isnan(s.kpa_per_unit) and math.isnan(s.p_star)
    assert "does not fall through 125" in s.reason


def test_stress_scale_on_a_state_exactly_at_the_target():
    s = stress_scale_from_stiffness([1.0, 5.0, 10.0], [300.0, 625.0, 1000.0])
    assert s.p_star == 5.0 and s.kpa_per_unit == 20.0


def test_stress_scale_without_a_bracketing_state_is_nan_unless_extrapolation_is_allowed():
    """E_v/p = 125 (p/4)^−0.2 measured at p = 8, 16, 32 only (all below 125): NaN with a reason;
    allowed, the log-log line (exact here) is solved: p* = 4, 25 kPa per unit."""
    p = np.array([8.0, 16.0, 32.0])
    e_v = 125.0 * p * (p / 4.0) ** -0.2
    s = stress_scale_from_stiffness(p, e_v)
    assert math.isnan(s.kpa_per_unit) and math.isnan(s.p_star) and s.method == "none"
    assert "does not fall through 125" in s.reason and "3 states" in s.reason
    x = stress_scale_from_stiffness(p, e_v, allow_extrapolation=True)
    assert x.method == "extrapolated"
    assert x.p_star == pytest.approx(4.0, rel=1e-12)
    assert x.kpa_per_unit == pytest.approx(25.0, rel=1e-12)


def test_stress_scale_nan_cases():
    assert "no state" in stress_scale_from_stiffness([], []).reason
    assert "no state" in stress_scale_from_stiffness([-1.0, np.nan], [1.0, 2.0]).reason
    one = stress_scale_from_stiffness([2.0], [1000.0])
    assert math.isnan(one.kpa_per_unit) and "does not fall through" in one.reason
    flat = stress_scale_from_stiffness([1.0, 2.0], [200.0, 400.0], allow_extrapolation=True)
    assert math.isnan(flat.kpa_per_unit) and "does not vary" in flat.reason
    far = stress_scale_from_stiffness([1.0, 2.0], [200.0, 400.0 * (1 + 1e-12)],
                                      allow_extrapolation=True)  # fmt: skip
    assert math.isnan(far.kpa_per_unit) and "misses the target" in far.reason
    single = stress_scale_from_stiffness([2.0], [1000.0], allow_extrapolation=True)
    assert math.isnan(single.kpa_per_unit) and "too few" in single.reason
    with pytest.raises(ValueError, match="one length"):
        stress_scale_from_stiffness([1.0, 2.0], [1.0])


def test_stress_scale_interval_is_taken_in_log_space():
    """Scales 10 and 40: ln-mean ln 20 (geometric mean 20); ln-values ±ln 2 about it, so
    s = √2 ln 2 and the half-width t(0.975, 1) s/√2 = t ln 2: interval 20 · 2^(∓t)."""
    mean, low, high, n = stress_scale_interval([10.0, 40.0, np.nan, -3.0])
    t = stats.t.ppf(0.975, 1)
    assert n == 2
    assert mean == pytest.approx(20.0, rel=1e-12)
    assert low == pytest.approx(20.0 * 2.0**-t, rel=1e-12)
    assert high == pytest.approx(20.0 * 2.0**t, rel=1e-12)
    one = stress_scale_interval([7.0])
    assert one[0] == pytest.approx(7.0) and math.isnan(one[1]) and one[3] == 1
    assert math.isnan(stress_scale_interval([])[0]) and stress_scale_interval([])[3] == 0


# --- λ* on the window, the local curve, the moduli exponent -----------------------------------


def test_windowed_compressibility_recovers_lambda_and_selects_the_window():
    """v = 1.30 (p/100)^−0.25 on 1 ≤ p ≤ 200 kPa (7 states, both ends included); states
    outside the window follow another line and must not enter."""
    inside = np.array([1.0, 2.0, 5.0, 10.0, 50.0, 100.0, 200.0])
    outside = np.array([0.5, 0.99, 201.0, 400.0])
    p = np.r_[outside[:2], inside, outside[2:]]
    v = np.where((p >= 1.0) & (p <= 200.0), 1.30 * (p / 100.0) ** -0.25, 3.0 * p**-0.6)
    fit = windowed_compressibility(p, v)
    assert fit.n == 7
    assert fit.slope == pytest.approx(0.25, abs=1e-12)
    assert fit.se < 1e-12
    assert fit.intercept == pytest.approx(math.log(1.30) + 0.25 * math.log(100.0), abs=1e-12)
    wide = windowed_compressibility(p, v, window=(0.1, 1000.0))
    assert wide.n == 11 and abs(wide.slope - 0.25) > 0.01


def test_windowed_compressibility_standard_error_by_hand():
    """ln p = 0, 1, 2 and ln v = 0, −1, −1: slope −1/2 (λ* = 1/2), intercept −1/6, residuals
    1/6, −1/3, 1/6, s² = (1/6)/(3 − 2), Sxx = 2: se = √(1/12)."""
    fit = windowed_compressibility(np.exp([0.0, 1.0, 2.0]), np.exp([0.0, -1.0, -1.0]),
                                   window=(0.5, 10.0))  # fmt: skip
    assert fit.slope == pytest.approx(0.5, abs=1e-12)
    assert fit.intercept == pytest.approx(-1.0 / 6.0, abs=1e-12)
    assert fit.se == pytest.approx(math.sqrt(1.0 / 12.0), abs=1e-12)
    assert fit.n == 3


def test_windowed_compressibility_is_nan_below_three_points():
    p = np.array([0.5, 10.0, 100.0, 300.0])
    fit = windowed_compressibility(p, 2.0 * p**-0.1)
    assert fit.n == 2 and math.isnan(fit.slope) and math.isnan(fit.se)
    none = windowed_compressibility([np.nan, -1.0], [1.0, 1.0])
    assert none.n == 0 and math.isnan(none.slope)
    same = windowed_compressibility([5.0, 5.0, 5.0], [1.0, 1.1, 1.2])
    assert same.n == 3 and math.isnan(same.slope)


def test_local_compressibility_of_a_piecewise_power_law():
    """v = (p/10)^−0.1 below p = 10, (p/10)^−0.3 above. States p = 1, 4, 25, 100: the pairs
    (1, 4) and (25, 100) lie on one branch (λ 0.1 and 0.3, mid-points 2 and 50); (4, 25)
    straddles the break: Δln v = −0.1 ln 2.5 − 0.3 ln 2.5 over Δln p = 2 ln 2.5, λ = 0.2 at
    √(4 · 25) = 10."""
    p = np.array([1.0, 4.0, 25.0, 100.0])
    v = np.where(p <= 10.0, (p / 10.0) ** -0.1, (p / 10.0) ** -0.3)
    mid, lam = local_compressibility(p, v)
    np.testing.assert_allclose(mid, [2.0, 10.0, 50.0], rtol=1e-12)
    np.testing.assert_allclose(lam, [0.1, 0.2, 0.3], rtol=1e-12)


def test_local_compressibility_leaves_out_bad_pairs():
    """A repeated p and a state with NaN v drop the pairs they are in, nothing else."""
    p = np.array([1.0, 1.0, 4.0, 8.0, 16.0])
    v = np.array([2.0, 2.0, 2.0 * 4.0**-0.5, np.nan, 2.0 * 16.0**-0.5])
    mid, lam = local_compressibility(p, v)
    np.testing.assert_allclose(mid, [2.0], rtol=1e-12)
    np.testing.assert_allclose(lam, [0.5], rtol=1e-12)
    with pytest.raises(ValueError, match="one length"):
        local_compressibility([1.0], [1.0, 2.0])


def test_moduli_exponent_on_the_window():
    """E = 3 p^0.8 inside 1–200 kPa (4 states), p^2 outside: n = 0.8 from the 4 only."""
    p = np.array([0.1, 1.0, 20.0, 150.0, 200.0, 500.0])
    e = np.where((p >= 1.0) & (p <= 200.0), 3.0 * p**0.8, p**2)
    fit = moduli_exponent(p, e)
    assert fit.n == 4 and fit.slope == pytest.approx(0.8, abs=1e-12)
    assert math.isnan(moduli_exponent(p, e, window=(10.0, 100.0)).slope)


# --- specific volume under two rod areas, N ---------------------------------------------------


def test_rectangle_and_disc_union_areas_by_hand():
    """5 discs, s_p = d = 1: touching discs, no lens, union 5π/4; L = 4 + 1 = 5, L d = 5; the
    ratio π/4. 3 discs, s_p = 0.5, d = 1: lens of radius 1/2 at distance 1/2 is
    2 r² acos(s/2r) − (s/2)√(4r² − s²) = π/6 − √3/8, union 3π/4 − 2 lens = 5π/12 + √3/4,
    L = 2, L d = 2."""
    assert rod_disc_union_area(5, 1.0, 1.0) == pytest.approx(5.0 * math.pi / 4.0, rel=1e-14)
    assert rod_rectangle_area(5, 1.0, 1.0) == 5.0
    assert specific_volume_rectangle(2.0, 5, 1.0, 1.0) == pytest.approx(math.pi / 2.0, rel=1e-14)
    union = 5.0 * math.pi / 12.0 + math.sqrt(3.0) / 4.0
    assert rod_disc_union_area(3, 0.5, 1.0) == pytest.approx(union, rel=1e-14)
    assert rod_rectangle_area(3, 0.5, 1.0) == 2.0
    v = specific_volume_rectangle(np.array([1.5, 3.0]), 3, 0.5, 1.0)
    np.testing.assert_allclose(v, np.array([1.5, 3.0]) * union / 2.0, rtol=1e-14)


@pytest.mark.parametrize("overrides", [[], ["particles.spacing=0.5"], ["particles.n_spheres=3"]])
def test_disc_union_area_is_the_one_the_dem_uses(overrides):
    """The area the DEM's v divides by (rod_geometry(scene).solid_area, engine/measures.py)."""
    scene = scene_with_overrides(load_scene("smoke"), overrides)
    p = scene.particles
    area = rod_disc_union_area(p.n_spheres, p.spacing, p.diameter)
    assert area == pytest.approx(rod_geometry(scene).solid_area, rel=1e-14)
    assert rod_rectangle_area(p.n_spheres, p.spacing, p.diameter) == pytest.approx(
        rod_geometry(scene).length * p.diameter, rel=1e-14
    )


def test_specific_volume_at_100_kpa():
    """v = 1.30 (p/100)^−0.25: 1.30 at 100 kPa, interpolated between 80 and 200 (exact in
    ln v – ln p), taken as is when a state sits at 100, NaN when 100 is not bracketed."""
    p = np.array([200.0, 8.0, 80.0, 20.0])
    v = 1.30 * (p / 100.0) ** -0.25
    assert specific_volume_at(p, v) == pytest.approx(1.30, rel=1e-12)
    assert specific_volume_at([50.0, 100.0, 200.0], [1.5, 1.4, 1.3]) == 1.4
    assert specific_volume_at([100.0], [1.4]) == 1.4
    assert math.isnan(specific_volume_at([10.0, 50.0], [1.5, 1.4]))
    assert math.isnan(specific_volume_at([], []))
    assert specific_volume_at(p, v, p_ref=20.0) == pytest.approx(1.30 * 5.0**0.25, rel=1e-12)


def test_specific_volume_at_a_path_end_within_the_servo_tolerance():
    """B stops within the servo's stress tolerance of 100 kPa (p = 99.95): it still gives N, as
    its own v; beyond the tolerance nothing is extrapolated."""
    p, v = [1.0, 10.0, 99.95], [2.0, 1.8, 1.6]
    assert specific_volume_at(p, v) == 1.6
    assert specific_volume_at([100.1, 300.0], [1.6, 1.5]) == 1.6
    assert math.isnan(specific_volume_at([1.0, 10.0, 99.7], [2.0, 1.8, 1.6]))
    assert math.isnan(specific_volume_at(p, v, rel_tol=1e-4))


def test_densification_sensitivity():
    """E_B = 100, E_B' = 400, v_B = 2, v_B' = 1: ln 4/ln(1/2) = −2; the study's −2.5 from
    E_B'/E_B = 0.95^−2.5 at v_B'/v_B = 0.95."""
    assert densification_sensitivity(100.0, 400.0, 2.0, 1.0) == pytest.approx(-2.0, rel=1e-14)
    e = 100.0 * 0.95**-2.5
    assert densification_sensitivity(100.0, e, 2.0, 1.9) == pytest.approx(-2.5, rel=1e-12)
    assert math.isnan(densification_sensitivity(100.0, 400.0, 2.0, 2.0))
    assert math.isnan(densification_sensitivity(-1.0, 400.0, 2.0, 1.0))
    assert math.isnan(densification_sensitivity(100.0, float("nan"), 2.0, 1.0))


# --- run_findings on a synthetic run folder ---------------------------------------------------

#: DEM mean stress of A and of the relaxed states of A→B; E_v/p = 125 at p* = 0.5 DEM, so the
#: measured scale is 100/0.5 = 200 kPa per unit: A at 4 kPa, A→B at 8 ... 800 kPa (none on
#: the window's edges, where rounding of the measured scale would decide).
P_A = 0.02
P_AB = np.array([0.04, 0.1, 0.2, 0.4, 0.9, 2.0, 4.0])
P_STAR = 0.5
V_B_PRIME_OVER_B = 0.95


def _ev(p):
    return 125.0 * p * (p / P_STAR) ** -0.2  # E_v ∝ p^0.8, E_v/p = 125 at p*


def _eh(p):
    return 110.0 * p * (p / P_STAR) ** -0.3  # E_h ∝ p^0.7


def _v(p, scale=100.0 / P_STAR):
    return 1.30 * (p * scale / 100.0) ** -0.25  # λ* = 0.25, N = 1.30 at 100 kPa


def write_run(folder, with_probes=True, scene_scale=1.0):
    """A run folder as run_protocol leaves it, reduced to what run_findings reads."""
    folder.mkdir(parents=True)
    p_c, v_c = 2.0, 1.2
    stages = [stage_code("isotropic_to_A")] + [stage_code("A_to_B")] * len(P_AB)
    stages += [stage_code("A_to_C")] * 2 + [stage_code("C_to_B")]
    p_all = np.r_[P_A, P_AB, 1.0, p_c, 4.0]
    v_all = np.r_[_v(np.r_[P_A, P_AB]), 1.25, v_c, V_B_PRIME_OVER_B * _v(4.0)]
    n = len(p_all)
    relaxed = xr.Dataset(
        {
            "stage": ("time", np.array(stages, dtype=float)),
            "mean_stress": ("time", p_all),
            "specific_volume": ("time", v_all),
            "fabric_deviator": ("time", np.linspace(0.01, 0.2, n)),
        },
        coords={"time": np.arange(n, dtype=float)},
        attrs={"scene_toml_effective": scene_to_toml(load_scene("smoke")),
               "stress_scale_kpa": scene_scale},
    )  # fmt: skip
    relaxed.to_netcdf(folder / "relaxed_states.nc")

    def state(p, v, ratio=1.0):
        return {"mean_stress": p, "specific_volume": v, "fabric_deviator": 0.05,
                "stress_xx": p * ratio, "stress_yy": p}  # fmt: skip

    v_b = float(_v(4.0))
    summary = {
        "n_rods": 40,
        "stress_scale_kpa": scene_scale,
        "states": {"A": state(P_A, float(_v(P_A))), "B": state(4.0, v_b),
                   "C": state(p_c, v_c, 0.6), "B'": state(4.0, V_B_PRIME_OVER_B * v_b)},
        "stages": {"isotropic_to_A": {"max_inertial_number": 1e-3},
                   "A_to_B": {"max_inertial_number": 1e-4}},
        "total_seconds": 1.0,
    }  # fmt: skip
    (folder / "summary.json").write_text(json.dumps(summary))
    if not with_probes:
        return folder
    p_probe = np.r_[P_A, P_AB, 4.0]
    e_v = np.r_[_ev(np.r_[P_A, P_AB]), _ev(4.0) * V_B_PRIME_OVER_B**-2.5]
    e_h = np.r_[_eh(np.r_[P_A, P_AB]), _eh(4.0) * V_B_PRIME_OVER_B**-1.5]
    paths = ["isotropic_to_A"] + ["A_to_B"] * len(P_AB) + ["C_to_B"]
    labels = ["A"] + [""] * (len(P_AB) - 1) + ["B", "B'"]
    probes = xr.Dataset(
        {
            "path": ("probe", np.array(paths)),
            "state_label": ("probe", np.array(labels)),
            "mean_stress": ("probe", p_probe),
            "e_oed_v_linear": ("probe", e_v),
            "e_oed_h_linear": ("probe", e_h),
        }
    )
    probes.to_netcdf(folder / "probes.nc")
    return folder


def test_run_findings_on_the_mapped_window(tmp_path):
    """Measured scale 200 kPa/unit: A and A→B at 4, 8, 20, 40, 80, 180, 400, 800 kPa; in the
    1–200 kPa window A and five A→B states (6); λ* 0.25, n_v 0.8, n_h 0.7 (probes in the
    window: the same 6); N_disc = 1.30 (100 kPa between 80 and 180), N_rectangle = 1.30 π/4
    (5 discs, s_p = d = 1); densification −2.5 and −1.5 by construction."""
    row = run_findings(write_run(tmp_path / "run"))
    assert row["stress_scale_source"] == "measured" and row["stress_scale_reason"] == ""
    assert row["stress_scale_kpa_measured"] == pytest.approx(200.0, rel=1e-12)
    assert row["stress_scale_kpa_used"] == row["stress_scale_kpa_measured"]
    assert row["p_star"] == pytest.approx(P_STAR, rel=1e-12)
    assert row["n_window_points"] == 6 and row["n_exponent_points"] == 6
    assert row["lambda_window"] == pytest.approx(0.25, abs=1e-12)
    assert row["lambda_window_se"] < 1e-12
    assert row["exponent_window_v"] == pytest.approx(0.8, abs=1e-12)
    assert row["exponent_window_h"] == pytest.approx(0.7, abs=1e-12)
    assert row["N_disc"] == pytest.approx(1.30, rel=1e-12)
    assert row["N_rectangle"] == pytest.approx(1.30 * math.pi / 4.0, rel=1e-12)
    assert row["densification_sensitivity_v"] == pytest.approx(-2.5, rel=1e-12)
    assert row["densification_sensitivity_h"] == pytest.approx(-1.5, rel=1e-12)
    kpa = np.r_[P_A, P_AB] * 200.0
    np.testing.assert_allclose(row["local_lambda_p_kpa"], np.sqrt(kpa[:-1] * kpa[1:]), rtol=1e-12)
    np.testing.assert_allclose(row["local_lambda"], 0.25, rtol=1e-12)
    # the keys from before are still there
    assert row["lambda_star"] == pytest.approx(0.25, abs=1e-12)
    assert row["modulus_exponent"] == pytest.approx(0.8, abs=1e-12)
    assert row["ev_over_p_B"] == pytest.approx(125.0 * (4.0 / P_STAR) ** -0.2, rel=1e-12)
    json.dumps(row)  # the row stays JSON: lists, numbers, strings


def test_run_findings_falls_back_to_the_scene_scale(tmp_path):
    """No probes: no measured scale, the scene's 50 kPa/unit maps p: A and A→B at 1, 2, 5, 10,
    20, 45, 100, 200 kPa, all 8 in the window (both ends included); v at 100 kPa is the state
    at DEM p = 2, whose v = 1.30 (2 · 200/100)^−0.25 = 1.30/√2 (the history was made with
    200 kPa/unit)."""
    row = run_findings(write_run(tmp_path / "run", with_probes=False, scene_scale=50.0))
    assert row["stress_scale_source"] == "scene"
    assert math.isnan(row["stress_scale_kpa_measured"]) and "no state" in row["stress_scale_reason"]
    assert row["stress_scale_kpa_used"] == 50.0
    assert row["n_window_points"] == 8
    assert row["lambda_window"] == pytest.approx(0.25, abs=1e-12)
    assert row["N_disc"] == pytest.approx(1.30 / math.sqrt(2.0), rel=1e-12)
    assert row["N_rectangle"] == pytest.approx(row["N_disc"] * math.pi / 4.0, rel=1e-12)
    for key in ("exponent_window_v", "exponent_window_h", "densification_sensitivity_v",
                "densification_sensitivity_h"):  # fmt: skip
        assert math.isnan(row[key]), key


def test_findings_from_arrays_are_run_findings_without_the_run_record(tmp_path):
    """run_findings reads the folder, then assembles with findings_from_arrays (issue 21): given
    the same arrays, the scene's scale and the rod shape of the scene (as a run in memory has
    them, not read from the folder's TOML), it gives every finding of the folder's row."""
    from dem_taichi.analysis.findings import findings_from_arrays, path_arrays, probe_arrays
    from dem_taichi.io import open_history, open_probes

    folder = write_run(tmp_path / "run")
    summary = json.loads((folder / "summary.json").read_text())
    path = path_arrays(summary, open_history(folder / "relaxed_states.nc"))
    probes = probe_arrays(open_probes(folder / "probes.nc"))
    rods = load_scene("smoke").particles
    shape = (rods.n_spheres, rods.spacing, rods.diameter)
    found = findings_from_arrays(path, probes, 40, 1.0, shape)
    row = run_findings(folder)
    assert set(row) - set(found) == {"run", "max_i", "seconds", "workers", "max_overlap"}
    assert math.isnan(row["max_overlap"])  # the folder has no configurations
    np.testing.assert_equal(found, {key: row[key] for key in found})  # NaN equals NaN
    assert found["N_rectangle"] == pytest.approx(1.30 * math.pi / 4.0, rel=1e-12)
    assert math.isnan(findings_from_arrays(path, probes, 40)["N_rectangle"])  # no rod shape


def test_sweep_dataset_and_summary_carry_the_new_findings(tmp_path):
    """open_sweep takes the new scalars of each finished member; the table shows them."""
    from dem_taichi.sweep.results import (
        open_sweep,
        replica_statistics,
        summarise_sweep,
        summary_table,
    )

    out = tmp_path / "sweep"
    members = []
    for seed in (1, 2):
        name = f"seed-{seed}"
        write_run(out / "members" / name)
        (out / "members" / name / "member.json").write_text(
            json.dumps({"status": "done", "scene_sha256": "x"})
        )
        members.append({"name": name, "parameters": {"scene.seed": seed}, "scene_sha256": "x"})
    (out / "sweep.json").write_text(json.dumps({"sweep": "s", "scene": "smoke",
                                                "members": members}))  # fmt: skip
    ds = open_sweep(out)
    np.testing.assert_allclose(ds["lambda_window"].values, 0.25, atol=1e-12)
    np.testing.assert_allclose(ds["stress_scale_kpa_measured"].values, 200.0, rtol=1e-12)
    np.testing.assert_allclose(ds["N_rectangle"].values, 1.30 * math.pi / 4.0, rtol=1e-12)
    np.testing.assert_allclose(ds["densification_sensitivity_v"].values, -2.5, rtol=1e-12)
    np.testing.assert_array_equal(ds["n_window_points"].values, 6.0)
    stats_ = replica_statistics(ds)
    found = stats_["all members"]["findings"]
    assert found["λ* (1–200 kPa)"]["mean"] == pytest.approx(0.25, abs=1e-12)
    assert "N: v at 100 kPa (rectangle L×d)" in summary_table(ds, stats_)
    files = summarise_sweep(out)
    numbers = json.loads(open(files["statistics"]).read())["all members"]["findings"]
    assert numbers["ln(E_v B′/B)/ln(v B′/B)"]["mean"] == pytest.approx(-2.5, rel=1e-12)
    with xr.open_dataset(files["dataset"]) as saved:
        assert float(saved["N_disc"][0]) == pytest.approx(1.30, rel=1e-12)


def test_headline_findings_pair_the_labelled_states_of_one_run(tmp_path):
    """The anisotropy at B and B′ (their probes), B′ − B paired within the run, C NaN without a
    K0 probe, the wall time in minutes, and every numeric finding of run_findings."""
    from dem_taichi.analysis.findings import headline_findings

    folder = write_run(tmp_path / "run")
    row = headline_findings(folder)
    ratio_b = _eh(4.0) / _ev(4.0)
    ratio_bp = ratio_b * V_B_PRIME_OVER_B  # E_h × V^-1.5 over E_v × V^-2.5
    assert row["ratio_B"] == pytest.approx(ratio_b, rel=1e-12)
    assert row["ratio_Bp"] == pytest.approx(ratio_bp, rel=1e-12)
    assert row["ratio_Bp_minus_B"] == pytest.approx(ratio_bp - ratio_b, rel=1e-9)
    assert math.isnan(row["ratio_C"]) and math.isnan(row["ratio_C_minus_B"])
    assert row["minutes"] == pytest.approx(1.0 / 60.0)
    found = run_findings(folder)
    for key, value in found.items():
        if isinstance(value, int | float) and not (isinstance(value, float) and math.isnan(value)):
            assert row[key] == value, key


def test_headline_findings_read_b_at_its_label_when_the_isotropic_path_goes_on(tmp_path):
    """With ``isotropic_end_stress`` A→B has probes past B: E_h/E_v at B is still B's probe."""
    from dem_taichi.analysis.findings import headline_findings

    folder = write_run(tmp_path / "run")
    probes = xr.load_dataset(folder / "probes.nc")
    beyond = probes.isel(probe=[len(P_AB)])  # a copy of B's probe, moved on to p = 8, unlabelled
    beyond["state_label"] = ("probe", np.array([""]))
    beyond["mean_stress"] = ("probe", np.array([8.0]))
    beyond["e_oed_h_linear"] = ("probe", np.array([3.0 * _eh(8.0)]))
    beyond["e_oed_v_linear"] = ("probe", np.array([_ev(8.0)]))
    order = list(range(len(P_AB) + 1)) + [probes.sizes["probe"]] + [len(P_AB) + 1]
    extended = xr.concat([probes, beyond], dim="probe").isel(probe=order)
    extended.to_netcdf(folder / "probes.nc")
    row = headline_findings(folder)
    assert row["ratio_B"] == pytest.approx(_eh(4.0) / _ev(4.0), rel=1e-12)
