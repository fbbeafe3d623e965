"""DEM ↔ model conventions: round trips, stated definitions, clear errors."""

import numpy as np
import pytest
import xarray as xr

from bridge.series import (
    CONVENTIONS,
    Convention,
    SeriesError,
    all_probe_series,
    dem_state_values,
    history_series,
    path_series,
    probe_series,
)

from .conftest import CONVENTION


@pytest.mark.parametrize("name", CONVENTIONS)
def test_stress_and_fabric_round_trip(name):
    conv = Convention(stress_scale_kpa=37.5, name=name, fabric_scale=1.7)
    rng = np.random.default_rng(1)
    sv, sh = rng.uniform(0.1, 3.0, 50), rng.uniform(0.1, 3.0, 50)
    sa, sr = conv.model_stress(sv, sh)
    back_v, back_h = conv.dem_stress(sa, sr)
    np.testing.assert_allclose(back_v, sv, rtol=1e-14)
    np.testing.assert_allclose(back_h, sh, rtol=1e-14)
    dev = rng.uniform(-0.5, 0.5, 50)
    np.testing.assert_allclose(conv.dem_fabric(conv.model_fabric(dev)), dev, rtol=1e-14)
    np.testing.assert_allclose(conv.dem_modulus(conv.model_modulus(sv)), sv, rtol=1e-14)


def test_triaxial_convention_definitions():
    conv = Convention(stress_scale_kpa=10.0)
    sa, sr = conv.model_stress(3.0, 1.0)
    assert (sa, sr) == (30.0, 10.0)
    assert (sa + 2 * sr) / 3 == pytest.approx(50.0 / 3)  # p = (σ_v + 2σ_h)/3
    assert sa - sr == pytest.approx(20.0)  # q = σ_v − σ_h


def test_plane_convention_keeps_the_2d_invariants():
    conv = Convention(stress_scale_kpa=10.0, name="plane")
    sa, sr = conv.model_stress(3.0, 1.0)
    assert (sa + 2 * sr) / 3 == pytest.approx(20.0)  # p = S (σ_v + σ_h)/2
    assert sa - sr == pytest.approx(20.0)  # q = S (σ_v − σ_h)


def test_fabric_sign_rods_lying_down_give_positive_beta():
    conv = Convention(stress_scale_kpa=1.0, fabric_scale=2.0)
    # rods lying down: β_yy < β_xx, DEM deviator negative; model β positive like q under K0
    assert conv.model_fabric(-0.1) == pytest.approx(0.2)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"stress_scale_kpa": 0.0},
        {"stress_scale_kpa": -1.0},
        {"stress_scale_kpa": 1.0, "name": "biaxial"},
        {"stress_scale_kpa": 1.0, "fabric_scale": 0.0},
        {"stress_scale_kpa": True},
    ],
)
def test_invalid_convention_fails_naming_the_value(kwargs):
    with pytest.raises(SeriesError, match="stress_scale_kpa|convention|fabric_scale"):
        Convention(**kwargs)


def test_history_series_recover_the_model_paths(synthetic):
    series = history_series(synthetic.history, CONVENTION)
    for path, ds in series.items():
        model = synthetic.model[path]
        for name in (
            "axial_stress",
            "radial_stress",
            "mean_stress",
            "deviatoric_stress",
            "specific_volume",
            "fabric",
        ):
            np.testing.assert_allclose(
                ds[name].values,
                model[name].values,
                rtol=1e-12,
                atol=1e-12,
                err_msg=f"{path} {name}",
            )
        assert ds.attrs["convention"] == "triaxial"
        assert ds.attrs["stress_scale_kpa"] == 50.0
        assert ds.attrs["fabric_scale"] == 2.0


def test_probe_series_start_states_and_moduli(synthetic):
    probes = all_probe_series(synthetic.probes, CONVENTION)
    assert probes["isotropic"].attrs["state_labels"].split()[0] == "A"
    assert probes["k0"].attrs["state_labels"].split()[0] == "A"
    assert probes["k0"].attrs["state_labels"].split()[-1] == "C"
    assert probes["unloading"].attrs["state_labels"].split()[0] == "C"
    assert probes["unloading"].attrs["state_labels"].split()[-1] == "B'"
    k0 = synthetic.model["k0"]
    np.testing.assert_allclose(probes["k0"]["e_oed_v"].values, k0["e_oed_v"].values, rtol=1e-10)
    np.testing.assert_allclose(probes["k0"]["e_oed_h"].values, k0["e_oed_h"].values, rtol=1e-10)
    assert "e_cross" in probes["k0"]
    dyn = probe_series(synthetic.probes, "k0", CONVENTION, method="dynamic")
    assert "e_cross" not in dyn


def test_dem_state_values_fabric_components_have_unit_trace():
    vals = dem_state_values([2.0], [1.0], [1.5], [0.3], CONVENTION)
    assert vals["fabric_xx"][0] + vals["fabric_yy"][0] == pytest.approx(1.0)
    assert vals["fabric_yy"][0] - vals["fabric_xx"][0] == pytest.approx(-0.15)


def test_missing_variable_is_named(synthetic):
    broken = synthetic.history.drop_vars("fabric_deviator")
    with pytest.raises(SeriesError, match="fabric_deviator"):
        path_series(broken, "k0", CONVENTION)
    with pytest.raises(SeriesError, match="e_oed_v_linear"):
        probe_series(synthetic.probes.drop_vars("e_oed_v_linear"), "k0", CONVENTION)


def test_missing_path_is_named(synthetic):
    stage = synthetic.history["stage"]
    only_iso = synthetic.history.isel(time=np.flatnonzero(stage.values <= 2))
    with pytest.raises(SeriesError, match="A_to_C.*stages present"):
        path_series(only_iso, "k0", CONVENTION)
    with pytest.raises(SeriesError, match="unknown path"):
        path_series(synthetic.history, "triaxial", CONVENTION)
    no_start = synthetic.history.isel(time=np.flatnonzero(stage.values != 1))
    with pytest.raises(SeriesError, match="start state is unknown"):
        path_series(no_start, "isotropic", CONVENTION)


def test_non_positive_pressure_is_rejected(synthetic):
    bad = synthetic.history.copy(deep=True)
    bad["stress_xx"].values[2] = -1.0
    bad["stress_yy"].values[2] = -1.0
    with pytest.raises(SeriesError, match="non-positive"):
        path_series(bad, "isotropic", CONVENTION)


def test_reads_files_written_with_the_dem_schema(synthetic, tmp_path):
    from dem_taichi.io import open_history, open_probes, write_dataset

    probes_file = write_dataset(tmp_path / "probes.nc", synthetic.probes)
    synthetic.history.to_netcdf(tmp_path / "history.nc")
    history = open_history(tmp_path / "history.nc")
    probes = open_probes(probes_file)
    assert isinstance(history, xr.Dataset)
    series = history_series(history, CONVENTION)
    np.testing.assert_allclose(
        series["k0"]["fabric"].values, synthetic.model["k0"]["fabric"].values, atol=1e-12
    )
    assert set(all_probe_series(probes, CONVENTION)) == {"isotropic", "k0", "unloading"}
