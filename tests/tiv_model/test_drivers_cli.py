"""Element-test datasets (names, units, CF attributes) and the command line."""

import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

from tiv_model import drivers
from tiv_model.cli import main
from tiv_model.errors import ParameterError
from tiv_model.params import TABLE1, ModelOptions

REQUIRED = [
    "axial_stress", "radial_stress", "mean_stress", "deviatoric_stress", "specific_volume",
    "fabric", "e_oed_v", "e_oed_h",
]  # fmt: skip


def test_dataset_schema_and_consistency():
    ds = drivers.k0(40.0, increments=6)
    assert ds.attrs["Conventions"] == "CF-1.11"
    assert "tiv_model" in ds.attrs["source"]
    assert ds.attrs["parameter_omega"] == TABLE1.omega
    assert ds.attrs["option_anisotropy"] == "A"
    for name in REQUIRED:
        assert name in ds and ds[name].dims == ("step",)
        assert ds[name].attrs["units"] and ds[name].attrs["long_name"]
    for name in ds.data_vars:
        assert "units" in ds[name].attrs, name
    np.testing.assert_allclose(
        ds.mean_stress, (ds.axial_stress + 2 * ds.radial_stress) / 3, rtol=1e-12
    )
    np.testing.assert_allclose(ds.deviatoric_stress, ds.axial_stress - ds.radial_stress)
    np.testing.assert_allclose(ds.radial_strain, 0.0, atol=1e-15)
    assert ds.axial_stress.values[-1] == pytest.approx(40.0, rel=1e-9)
    assert np.all(np.diff(ds.fabric.values) > 0)  # rods lie down under vertical load
    assert np.all(np.diff(ds.specific_volume.values) < 0)


def test_k0_then_unload_has_stages():
    ds = drivers.k0_then_unload(60.0, increments=8, unload_increments=4)
    assert list(np.unique(ds.stage.values)) == [0, 1]
    assert ds.stage.attrs["flag_meanings"] == "k0 constant_p_unloading"
    assert ds.deviatoric_stress.values[-1] == pytest.approx(0.0, abs=1e-7)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: drivers.isotropic(-5.0), "p_max"),
        (lambda: drivers.k0(100.0, increments=0), "increments"),
        (lambda: drivers.radial(float("nan")), "eta"),
        (lambda: drivers.isotropic(100.0, p0=0.0), "p0"),
        (lambda: drivers.isotropic(100.0, on_error="ignore"), "on_error"),
    ],
)
def test_driver_arguments_are_validated(call, match):
    with pytest.raises(ParameterError, match=match):
        call()


def test_stop_on_error_returns_partial_dataset_with_the_reason():
    ds = drivers.isotropic(320.0, increments=4, on_error="stop")
    assert "SpecificVolumeBelowOneError" in ds.attrs["termination"]
    assert ds.specific_volume.values.min() >= 1.0


def test_cli_writes_netcdf(tmp_path, capsys):
    out = tmp_path / "k0.nc"
    assert main(["k0", "--sigma-v-max", "50", "--increments", "5", "--out", str(out),
                 "--anisotropy", "B", "--no-constraint-forces"]) == 0  # fmt: skip
    ds = xr.load_dataset(out)
    assert ds.attrs["option_anisotropy"] == "B"
    assert ds.attrs["option_constraint_forces"] == 0
    assert ds.sizes["step"] == 6
    assert "k0:" in capsys.readouterr().out


def test_cli_stops_clearly_at_v_equal_one(tmp_path, capsys):
    out = tmp_path / "iso.nc"
    assert main(["isotropic", "--p-max", "300", "--increments", "4", "--out", str(out)]) == 1
    assert "285.6 kPa" in capsys.readouterr().err
    assert xr.load_dataset(out).sizes["step"] >= 1


@pytest.mark.parametrize(
    "argv",
    [
        ["k0", "--sigma-v-max", "-1", "--out", "x.nc"],
        ["k0", "--sigma-v-max", "100", "--param", "n=1.0", "--out", "x.nc"],
        ["k0", "--sigma-v-max", "100", "--param", "z=0.9", "--out", "x.nc"],
        ["k0", "--sigma-v-max", "100", "--param", "bogus=1", "--out", "x.nc"],
        ["k0", "--sigma-v-max", "100", "--anisotropy", "C", "--out", "x.nc"],
        ["isotropic", "--p-max", "abc", "--out", "x.nc"],
    ],
)
def test_cli_bad_input_exits_with_code_2(argv, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2  # one error handler: an exit code, never a raised SystemExit
    err = capsys.readouterr().err
    assert "error" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_python_dash_m_entry_point():
    proc = subprocess.run(
        [sys.executable, "-m", "tiv_model", "probe", "--p", "100"],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "E_oed,v" in proc.stdout


def test_options_change_the_answer():
    base = drivers.k0(60.0, increments=6)
    b = drivers.k0(60.0, increments=6, options=ModelOptions(anisotropy="B"))
    assert base.stiffness_ratio.values[-1] > b.stiffness_ratio.values[-1] > 1.0
