"""Units of the DEM results files are read and checked (issue 11): physical pressure units are
converted, DEM units take the stress scale, anything else is refused naming the variable."""

import numpy as np
import pytest

from bridge.calibration import CalibrationOptions
from bridge.pipeline import PipelineOptions, calibrate_from_results, main
from bridge.series import Convention, SeriesError, all_probe_series, history_series, path_series
from bridge.units import UnitsError, checked, kind_of

from .conftest import CONVENTION, TRUTH

#: kPa per unit of the physical units written below.
KPA_PER = {"Pa": 1e-3, "kPa": 1.0, "MPa": 1e3, "GPa": 1e6}


def in_physical_units(ds, scale_kpa, stress="MPa", modulus="GPa", file_scale=None):
    """The same data with every DEM-unit stress and modulus written in a pressure unit
    (MPa: the kPa values divided by 1000; GPa: by 10^6); ``file_scale`` replaces the global
    ``stress_scale_kpa`` (the physical values must not depend on it)."""
    out = ds.copy(deep=True)
    for name in ds.variables:
        kind = kind_of(str(name))
        if kind in ("stress", "modulus") and ds[name].attrs.get("dem_units"):
            unit = stress if kind == "stress" else modulus
            attrs = {k: v for k, v in ds[name].attrs.items() if k != "dem_units"}
            attrs["units"] = unit
            out[name] = ds[name].copy(data=ds[name].values * scale_kpa / KPA_PER[unit])
            out[name].attrs = attrs
    if file_scale is not None:
        out.attrs["stress_scale_kpa"] = file_scale
    return out


def _assert_same_series(a, b):
    assert set(a) == set(b)
    for path in a:
        for name in a[path].data_vars:
            np.testing.assert_allclose(
                a[path][name].values, b[path][name].values, rtol=1e-12, atol=1e-12,
                err_msg=f"{path} {name}",
            )  # fmt: skip


@pytest.mark.parametrize(("stress", "modulus"), [("MPa", "GPa"), ("Pa", "kPa"), ("kPa", "MPa")])
def test_physical_units_give_the_same_series(synthetic, stress, modulus):
    scale = CONVENTION.stress_scale_kpa
    history = in_physical_units(synthetic.history, scale, stress, modulus)
    probes = in_physical_units(synthetic.probes, scale, stress, modulus)
    assert history["stress_yy"].attrs["units"] == stress
    np.testing.assert_allclose(
        history["stress_yy"].values * KPA_PER[stress], synthetic.history["stress_yy"] * scale
    )
    _assert_same_series(
        history_series(history, CONVENTION), history_series(synthetic.history, CONVENTION)
    )
    _assert_same_series(all_probe_series(probes, CONVENTION),
                        all_probe_series(synthetic.probes, CONVENTION))  # fmt: skip
    # physical units do not depend on the stress scale of the convention
    other = Convention(7.0, CONVENTION.name, CONVENTION.fabric_scale)
    for name in ("mean_stress", "deviatoric_stress", "fabric", "specific_volume"):
        np.testing.assert_allclose(
            path_series(history, "k0", other)[name].values,
            path_series(synthetic.history, "k0", CONVENTION)[name].values, rtol=1e-12,
        )  # fmt: skip


def test_dem_units_use_the_stress_scale(synthetic):
    k0 = path_series(synthetic.history, "k0", CONVENTION)
    doubled = Convention(2 * CONVENTION.stress_scale_kpa, CONVENTION.name, CONVENTION.fabric_scale)
    np.testing.assert_allclose(
        path_series(synthetic.history, "k0", doubled)["mean_stress"].values,
        2 * k0["mean_stress"].values, rtol=1e-14,
    )  # fmt: skip
    same = checked(synthetic.history, ("stress_xx",), 50.0, "history")
    assert same["stress_xx"].attrs["dem_units"] == "force/length"
    np.testing.assert_array_equal(same["stress_xx"].values, synthetic.history["stress_xx"].values)


def _with(ds, name, **attrs):
    out = ds.copy(deep=False)
    out[name] = ds[name].copy()
    new = dict(ds[name].attrs)
    for key, value in attrs.items():
        if value is None:
            new.pop(key, None)
        else:
            new[key] = value
    out[name].attrs = new
    return out


BAD_UNITS = [
    ("history", "stress_yy", {"units": "m", "dem_units": None}, r"'stress_yy'.*'m'.*\[length\]"),
    ("history", "stress_xx", {"units": "kpa"}, r"'stress_xx'.*'kpa', not a unit pint can read"),
    ("history", "stress_xx", {"units": "N/m"}, r"'stress_xx'.*'N/m'.*\[mass\]"),
    ("history", "stress_yy", {"dem_units": None}, r"'stress_yy'.*'1' with dem_units None"),
    ("history", "stress_yy", {"dem_units": "energy"}, r"'stress_yy'.*dem_units 'energy'"),
    ("history", "specific_volume", {"units": "kPa"}, r"'specific_volume'.*dimensionless"),
    ("history", "fabric_deviator", {"units": "m"}, r"'fabric_deviator'.*'m'"),
    ("history", "stress_xx", {"units": None}, r"'stress_xx'.*no units attribute"),
    ("history", "stress_xx", {"units": " "}, r"'stress_xx'.*no units attribute"),
    ("probes", "e_oed_v_linear", {"units": "kg"}, r"'e_oed_v_linear' \(modulus\).*'kg'.*\[mass\]"),
    ("probes", "stiffness_tensor_linear", {"units": "s"}, r"'stiffness_tensor_linear'.*'s'"),
    ("probes", "stress_yy", {"units": None}, r"probes variable 'stress_yy'.*no units"),
]


@pytest.mark.parametrize(("kind", "name", "attrs", "message"), BAD_UNITS)
def test_incompatible_unknown_or_missing_units_are_refused(synthetic, kind, name, attrs, message):
    if kind == "history":
        bad = _with(synthetic.history, name, **attrs)
        call = lambda: history_series(bad, CONVENTION)  # noqa: E731
    else:
        bad = _with(synthetic.probes, name, **attrs)
        call = lambda: all_probe_series(bad, CONVENTION)  # noqa: E731
    with pytest.raises(UnitsError, match=message) as info:
        call()
    text = str(info.value)
    assert "\n" not in text and "allowed:" in text


def test_percent_is_a_dimensionless_unit(synthetic):
    history = synthetic.history.copy(deep=True)
    history["specific_volume"] = history["specific_volume"] * 100.0
    history["specific_volume"].attrs = {"units": "%"}
    np.testing.assert_allclose(
        path_series(history, "k0", CONVENTION)["specific_volume"].values,
        path_series(synthetic.history, "k0", CONVENTION)["specific_volume"].values, rtol=1e-14,
    )  # fmt: skip


FAST = CalibrationOptions(initial=TRUTH.replace(c=1.3), fixed=("s", "z", "M"), max_k0_increments=6)


def _write(history, probes, folder):
    """Both files as given (``dem_taichi.io.write_dataset`` would put the schema's units back)."""
    folder.mkdir(parents=True, exist_ok=True)
    history.to_netcdf(folder / "relaxed_states.nc")
    probes.to_netcdf(folder / "probes.nc")
    return folder / "relaxed_states.nc", folder / "probes.nc"


def test_files_in_mpa_and_gpa_calibrate_to_the_same_parameters(synthetic, tmp_path):
    scale = CONVENTION.stress_scale_kpa
    options = PipelineOptions(fabric_scale=CONVENTION.fabric_scale, calibration=FAST,
                              figures=False, identifiability=False)  # fmt: skip
    dem = _write(synthetic.history, synthetic.probes, tmp_path / "dem")
    history = in_physical_units(synthetic.history, scale)
    del history.attrs["stress_scale_kpa"]  # not needed: every stress has a pressure unit
    physical = _write(history, in_physical_units(synthetic.probes, scale), tmp_path / "mpa")
    want = calibrate_from_results(*dem, tmp_path / "out_dem", options)["parameters"]
    outcome = calibrate_from_results(*physical, tmp_path / "out_mpa", options)
    assert "not needed" in outcome["data"]["stress scale"]
    got = outcome["parameters"]
    assert want["k"] == pytest.approx(TRUTH.k, rel=1e-6)
    for sym, value in want.items():
        assert got[sym] == pytest.approx(value, rel=1e-9, abs=1e-12), sym


def test_dem_units_without_a_stress_scale_are_refused_naming_them(synthetic, tmp_path):
    history = in_physical_units(synthetic.history, CONVENTION.stress_scale_kpa)
    history["stress_xx"] = synthetic.history["stress_xx"]  # DEM units: needs the scale
    del history.attrs["stress_scale_kpa"]
    files = _write(history, synthetic.probes, tmp_path / "dem")
    with pytest.raises(
        SeriesError,
        match="pressure unit: history stress_xx; probes stress_xx, stress_yy, e_oed_v_linear",
    ):
        calibrate_from_results(*files, tmp_path / "out")


def test_command_line_refuses_a_bad_unit_in_one_line(synthetic, tmp_path, capsys):
    history, probes = _write(_with(synthetic.history, "stress_yy", units="m"), synthetic.probes,
                             tmp_path / "dem")  # fmt: skip
    code = main(["--history", str(history), "--probes", str(probes), "--out",
                 str(tmp_path / "out"), "--no-figures"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2
    assert "Traceback" not in err
    assert "history variable 'stress_yy' (stress) has units 'm'" in err
    assert len(err.strip().splitlines()) == 1
