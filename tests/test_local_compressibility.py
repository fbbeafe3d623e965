"""benchmarks/local_compressibility.py: the decade-by-decade slopes of ln v on ln p recover a
straight normal compression line, a kinked one segment by segment, and start at p_A in the
segment that holds A."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.scripts import load_script


def test_a_straight_line_gives_its_slope_on_every_segment():
    script = load_script("benchmarks/local_compressibility.py")
    p = np.geomspace(0.5, 250.0, 12)
    v = 3.0 * p**-0.25
    assert script.segment_slopes(p, v) == pytest.approx([0.25] * 5, rel=1e-12)


def test_a_kinked_line_gives_each_part_its_own_slope():
    """λ 0.05 up to 3 kPa, 0.2 beyond (a yield at 3 kPa): the first segment holds the first
    slope, the others the second; the 1–200 fit lies between."""
    script = load_script("benchmarks/local_compressibility.py")
    p = np.array([0.8, 1.5, 3.0, 6.0, 10.0, 20.0, 30.0, 60.0, 100.0, 150.0, 200.0])
    ln_v = np.where(p <= 3.0, -0.05 * np.log(p), -0.05 * math.log(3.0) - 0.2 * np.log(p / 3.0))
    slopes = script.segment_slopes(p, np.exp(ln_v))
    assert slopes == pytest.approx([0.05, 0.2, 0.2, 0.2, 0.2], rel=1e-12)


def test_the_segment_holding_a_starts_there_and_those_below_it_are_nan():
    script = load_script("benchmarks/local_compressibility.py")
    p = np.array([1.6, 4.0, 12.0, 40.0, 120.0, 210.0])
    slopes = script.segment_slopes(p, 2.0 * p**-0.2)
    assert slopes == pytest.approx([0.2] * 5, rel=1e-12)  # 1–3 read from p_A = 1.6
    late = np.array([3.5, 12.0, 40.0, 120.0, 210.0])
    slopes = script.segment_slopes(late, 2.0 * late**-0.2)
    assert math.isnan(slopes[0])  # 1–3 kPa: below A
    assert slopes[1:] == pytest.approx([0.2] * 4, rel=1e-12)  # 3–10 read from p_A = 3.5


def test_the_cell_table_gives_mean_and_interval_over_seeds():
    script = load_script("benchmarks/local_compressibility.py")
    keys = [key for key, _ in script._columns()]
    rows = [
        {"cell": "X", "seed": seed, **{key: value for key in keys}}
        for seed, value in ((11, 0.1), (2, 0.2), (12, 0.3))
    ]
    text = script.markdown(rows)
    # mean 0.2, half-width t(0.975, 2) · 0.1/√3 = 4.303 · 0.0577 = 0.25
    assert "| X (11,2,12) | 0.2 ± 0.25 |" in text
    assert "| X_s2 | 0.2 |" in text


def test_the_elastic_slope_is_read_at_each_segments_geometric_middle():
    """κ = p/K interpolated linearly in ln p between the probed states: κ = 0.01 + 0.002 ln p
    gives 0.01 + 0.002 ln √(lo·hi) on each segment inside them, NaN outside."""
    script = load_script("benchmarks/local_compressibility.py")
    p = np.geomspace(2.0, 120.0, 7)
    kappa = 0.01 + 0.002 * np.log(p)
    slopes = script.segment_elastic_slopes(p, kappa)
    middles = [math.sqrt(lo * hi) for lo, hi in script._segments()]
    assert math.isnan(slopes[0])  # √3 = 1.73 kPa: below the first probe (2 kPa)
    assert slopes[1:4] == pytest.approx([0.01 + 0.002 * math.log(m) for m in middles[1:4]])
    assert math.isnan(slopes[4])  # √20000 = 141 kPa: above the last probe (120 kPa)


def test_the_compliance_is_read_at_a_and_along_a_to_b_only(tmp_path):
    """From a probes.nc: state A and the A→B states (B and past it included), ordered by p and
    scaled to kPa; the K0 and unloading probes are left out."""
    import xarray as xr

    script = load_script("benchmarks/local_compressibility.py")
    labels = ["A", "A_to_B_1", "B", "A_to_B_3", "A_to_C_1", "C"]
    paths = ["isotropic_to_A", "A_to_B", "A_to_B", "A_to_B", "A_to_C", "A_to_C"]
    p = np.array([0.5, 5.0, 100.0, 50.0, 3.0, 100.0])
    bulk = np.array([50.0, 400.0, 8000.0, 5000.0, 1.0, 1.0])
    xr.Dataset(
        {
            "state_label": ("probe", np.array(labels)),
            "path": ("probe", np.array(paths)),
            "mean_stress": ("probe", p),
            "bulk_modulus_linear": ("probe", bulk),
        }
    ).to_netcdf(tmp_path / "probes.nc")
    p_kpa, kappa = script.isotropic_bulk_compliance(script.run_probes(tmp_path), 2.0)
    assert p_kpa == pytest.approx([1.0, 10.0, 100.0, 200.0])
    assert kappa == pytest.approx([0.01, 0.0125, 0.01, 0.0125])
    assert script.isotropic_bulk_compliance(script.run_probes(tmp_path / "none"), 1.0)[0].size == 0
    older = tmp_path / "older"  # probes written before the bulk modulus was: no κ, no error
    older.mkdir()
    xr.Dataset({"state_label": ("probe", np.array(labels))}).to_netcdf(older / "probes.nc")
    assert script.isotropic_bulk_compliance(script.run_probes(older), 1.0)[0].size == 0
    assert all(math.isnan(k) for k in script.segment_elastic_slopes(np.empty(0), np.empty(0)))
