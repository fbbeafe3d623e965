"""Identifiability: exact recovery within the profile intervals at the DEM's noise level, the
undetermined parameters reported as such, bounds and fixed parameters stated."""

import numpy as np
import pytest

from bridge.calibration import CalibrationOptions, calibrate
from bridge.calibration.identifiability import identifiability, replica_spread
from bridge.series import all_probe_series, history_series
from bridge.synthetic import DEM_NOISE, add_noise, synthetic_results

from .conftest import CONVENTION, TRUTH

CHEAP = ("compressibility", "elastic")


def assert_within(prof, value):
    """The truth inside the interval on each side where it closes (an open side only says the
    data allow at least that far)."""
    if prof.closed_lower:
        assert prof.lower <= value, (prof.symbol, prof.lower, value)
    if prof.closed_upper:
        assert value <= prof.upper, (prof.symbol, value, prof.upper)


def dem_like(synthetic, seed):
    """The synthetic results with the DEM's measured scatter (fabric noise in DEM units: the
    test convention's fabric scale is 2)."""
    noise = dict(DEM_NOISE, fabric=DEM_NOISE["fabric"] / CONVENTION.fabric_scale)
    history, probes = add_noise(synthetic.history, synthetic.probes, noise, seed=seed)
    return history_series(history, CONVENTION), all_probe_series(probes, CONVENTION)


@pytest.mark.parametrize("seed", [1, pytest.param(2, marks=pytest.mark.slow)])
def test_cheap_stages_recover_the_truth_within_the_profile_intervals(synthetic, seed):
    """99 % intervals: the 95 % ones held the truth in 78 of 84 cases over 12 seeds (seven
    parameters each; the scatter of the measured probe states is not in the model of the
    errors), so a 95 % test on two seeds would fail by chance (seed 1: ω 12.9, interval
    9.7–18.3, truth 20)."""
    series, probes = dem_like(synthetic, seed)
    result = calibrate(series, probes, CalibrationOptions(), CHEAP)
    ide = identifiability(result, series, probes, level=0.99)
    truth = TRUTH.as_symbols()
    assert set(ide.profiles) == {"N", "lambda_star", "k", "g", "n", "r", "omega"}
    for sym, prof in ide.profiles.items():
        assert_within(prof, truth[sym])
        assert prof.lower <= prof.value <= prof.upper
    for sym in ("N", "lambda_star", "k", "g"):
        assert ide.status(sym) == "determined", sym
    # the fabric parameters were not fitted here: stated as fixed at their starting values
    for sym in ("c", "s", "z", "M", "p_r"):
        assert ide.status(sym) == "fixed"
    text = ide.statement()
    assert "Determined by the data" in text and "Fixed, not fitted" in text
    assert ide.to_dict()["profiles"]["k"]["status"] == "determined"


def test_parameter_on_a_bound_is_flagged():
    truth = TRUTH.replace(r=0.0)
    data = synthetic_results(truth, convention=CONVENTION, increments=6, unloading_increments=3)
    series = history_series(data.history, CONVENTION)
    probes = all_probe_series(data.probes, CONVENTION)
    options = CalibrationOptions(initial=truth.replace(r=0.3))
    result = calibrate(series, probes, options, CHEAP)
    elastic = next(st for st in result.stages_ if st.name == "elastic")
    assert elastic.at_bound == {"r": "lower"}
    assert any("r = 0 is at the lower search bound" in w for w in result.warnings())
    assert result.to_dict()["stages"][1]["at_bound"] == {"r": "lower"}
    ide = identifiability(result, series, probes, symbols=("r",))
    assert ide.profiles["r"].at_bound == "lower"
    assert "At a search bound: r (lower)" in ide.statement()


def test_replica_spread(synthetic):
    results = []
    for seed in (1, 2, 3):
        series, probes = dem_like(synthetic, seed)
        results.append(calibrate(series, probes, CalibrationOptions(), ("compressibility",)))
    spread = replica_spread(results)
    assert spread["N"]["n"] == 3
    assert spread["N"]["min"] <= spread["N"]["mean"] <= spread["N"]["max"]
    assert 0 < spread["N"]["std"] < 0.05
    assert spread["k"]["std"] == 0.0  # not fitted: the same everywhere


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_all_stages_at_the_dem_noise_level(seed):
    """Every stage on synthetic paths of 8 increments with the DEM's scatter: every parameter
    the profiles call determined contains the truth, and each of c, s, z that is not is said
    so (≈ 15–40 s)."""
    data = synthetic_results(TRUTH, convention=CONVENTION, increments=8, unloading_increments=4)
    series, probes = dem_like(data, seed)
    result = calibrate(series, probes, CalibrationOptions(max_k0_increments=8))
    ide = identifiability(result, series, probes)
    truth = TRUTH.as_symbols()
    for sym, prof in ide.profiles.items():
        assert_within(prof, truth[sym])
    assert {"N", "lambda_star", "k", "g", "omega", "M"} <= set(ide.determined())
    for sym in ("c", "s", "z"):
        if ide.status(sym) != "determined":
            assert sym in ide.statement()


RADIAL_RATIOS = (0.3, 0.5, 0.7)


@pytest.fixture(scope="module")
def radial_synthetic():
    return synthetic_results(TRUTH, convention=CONVENTION, increments=6, unloading_increments=3,
                             radial_ratios=RADIAL_RATIOS)  # fmt: skip


def test_radial_paths_are_read_from_the_history(radial_synthetic):
    from bridge.series import radial_series

    paths = radial_series(radial_synthetic.history, CONVENTION)
    assert list(paths) == ["radial_1", "radial_2", "radial_3"]
    for (name, ds), eta in zip(paths.items(), RADIAL_RATIOS, strict=True):
        model = radial_synthetic.model[name]
        assert ds.sizes["point"] == model.sizes["step"]
        assert ds.attrs["stress_ratio"] == pytest.approx(eta, rel=1e-6)
        np.testing.assert_allclose(ds["fabric"].values, model["fabric"].values, atol=1e-12)
    assert radial_series(history_series_free_history(radial_synthetic), CONVENTION) == {}


def history_series_free_history(data):
    """The history without its radial records."""
    from bridge.series import RADIAL_STAGE
    from dem_taichi.io.schema import stage_code

    keep = data.history["stage"].values != stage_code(RADIAL_STAGE)
    return data.history.isel(time=np.flatnonzero(keep))


def test_fabric_stage_with_radial_paths_recovers_c_s_z_and_m(radial_synthetic):
    series = history_series(radial_synthetic.history, CONVENTION)
    from bridge.series import radial_series

    series.update(radial_series(radial_synthetic.history, CONVENTION))
    options = CalibrationOptions(initial=TRUTH.replace(c=1.2, s=14.0, z=5.4, M=1.1))
    result = calibrate(series, {}, options, ("fabric",))
    for sym in ("c", "s", "z", "M"):
        assert result.params_.as_symbols()[sym] == pytest.approx(TRUTH.as_symbols()[sym],
                                                                 rel=1e-5), sym  # fmt: skip
    assert ("radial_2", "fabric") in result.fitted_
    assert result.residual_rms_["radial_3:fabric"] < 1e-8


@pytest.mark.slow
def test_radial_paths_determine_the_fabric_law_at_the_dem_noise_level(radial_synthetic):
    """K0 alone leaves z undetermined and c, s bounded on one side; with radial paths at three
    η, c and z are determined and contain the truth (≈ 30 s)."""
    from bridge.series import radial_series

    series, _ = dem_like(radial_synthetic, 1)
    noise = dict(DEM_NOISE, fabric=DEM_NOISE["fabric"] / CONVENTION.fabric_scale)
    history, _ = add_noise(radial_synthetic.history, radial_synthetic.probes, noise, seed=1)
    series.update(radial_series(history, CONVENTION))
    start = TRUTH.replace(c=1.2, s=14.0, z=5.4, M=1.1)
    status = {}
    for paths in (("k0",), ("k0", "radial")):
        options = CalibrationOptions(initial=start, fabric_paths=paths)
        result = calibrate(series, {}, options, ("fabric",))
        ide = identifiability(result, series, {})
        for sym, prof in ide.profiles.items():
            assert_within(prof, TRUTH.as_symbols()[sym])
        status[paths] = {s: ide.status(s) for s in ("c", "s", "z", "M")}
    assert status[("k0",)]["z"] != "determined"
    assert status[("k0", "radial")]["c"] == status[("k0", "radial")]["z"] == "determined"


def test_pipeline_with_radial_paths(radial_synthetic, tmp_path):
    """The pipeline reads the radial paths, fits, predicts and draws them (the profiles are
    left out here for time: they are tested above)."""
    import json

    from bridge.pipeline import calibrate_from_results

    history, probes = tmp_path / "relaxed_states.nc", tmp_path / "probes.nc"
    radial_synthetic.history.to_netcdf(history)
    radial_synthetic.probes.to_netcdf(probes)
    outcome = calibrate_from_results(history, probes, tmp_path / "out",
                                     {"stress_scale_kpa": CONVENTION.stress_scale_kpa,
                                      "fabric_scale": CONVENTION.fabric_scale,
                                      "identifiability": False})  # fmt: skip
    assert ["radial_1", "fabric"] in outcome["fitted"]
    assert "prediction_radial_3" in outcome["files"]
    saved = json.loads((tmp_path / "out" / "calibration.json").read_text())
    assert "identifiability" not in saved
    assert saved["parameters"]["z"] == pytest.approx(TRUTH.z, rel=1e-4)
    report = (tmp_path / "out" / "report.md").read_text()
    assert "radial_2" in report and "## What the data determine" not in report


class _Held:
    """Stand-in parameters: only the held value matters to the fake refit."""

    def __init__(self, value: float) -> None:
        self.value = value

    def replace(self, **held):
        return _Held(*held.values())


def _fake_fit(value: float):
    from types import SimpleNamespace

    return SimpleNamespace(
        name="fabric", parameters=("s",), n_data=40, cost=1.0, values={"s": value},
        bounds={"s": (0.0, 1000.0)}, standard_errors={"s": 2.0}, at_bound={},
    )  # fmt: skip


@pytest.mark.parametrize("fails_above", [False, True])
def test_a_failed_refit_leaves_its_side_open(monkeypatch, fails_above):
    """A profile point where the model cannot be refitted (a limit point) is no evidence: the
    side stays open, the failing value is recorded and stated; the other side still closes
    where the data close it. (It used to count as Δ = ∞ and close both sides at θ̂: a
    zero-width "determined" interval.)"""
    from types import SimpleNamespace

    from bridge.calibration import identifiability as ide_module
    from tiv_model.errors import TivModelError

    value, curvature = 197.0, 1.0  # C(θ) = 1 + ½ curvature (θ − 197)²

    def fake_fit_stage(stage, held, others, options):
        theta = held.value
        if fails_above and theta > value:
            raise TivModelError("the model's K0 run reached a limit point")
        cost = 1.0 + 0.5 * curvature * (theta - value) ** 2
        return held, SimpleNamespace(cost=cost, success=True)

    monkeypatch.setattr(ide_module, "fit_stage", fake_fit_stage)
    prof = ide_module.profile_parameter(None, _Held(value), "s", _fake_fit(value), None)
    assert prof.closed_lower and prof.lower < value
    if fails_above:
        assert not prof.closed_upper and prof.status == "bounded below"
        assert value < prof.failed_upper <= value + 1.96 * 2.0
        assert prof.upper == value  # the last point profiled: the optimum itself
        holder = ide_module.Identifiability({"s": prof}, {}, [], 0.95, 0.0)
        assert "could not be evaluated or refitted" in holder.statement()
        assert f"s (above {prof.failed_upper:.4g})" in holder.statement()
        assert holder.to_dict()["profiles"]["s"]["failed_upper"] == prof.failed_upper
    else:
        assert prof.closed_upper and prof.status == "determined"
        assert prof.upper > value and prof.failed_upper != prof.failed_upper  # NaN: none
