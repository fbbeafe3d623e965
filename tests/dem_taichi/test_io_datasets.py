"""Schema consistency, probes and configuration files, CF attributes, no Taichi in dem_taichi.io."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import netCDF4
import numpy as np
import pytest

from dem_taichi.io import (
    CONFIGURATION_VARIABLES,
    HISTORY_VARIABLES,
    PROBE_VARIABLES,
    STAGE_CODES,
    HistoryWriter,
    Variable,
    make_dataset,
    open_configuration,
    open_probes,
    stage_code,
    stage_label,
    write_configuration,
    write_dataset,
)
from dem_taichi.io.schema import COMPRESSION_POSITIVE

ROOT = Path(__file__).resolve().parents[2]
ALL_VARIABLES = HISTORY_VARIABLES + PROBE_VARIABLES + CONFIGURATION_VARIABLES
SIZES = {"probe": 4, "amplitude": 6, "voigt_i": 3, "voigt_j": 3}


def probe_values(seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    values: dict[str, np.ndarray] = {}
    for var in PROBE_VARIABLES:
        shape = tuple(SIZES[dim] for dim in var.dims)
        if var.dtype == "str":
            values[var.name] = np.array(["A", "B", "C", "A_to_C_3"], dtype=object)
        elif var.dtype.startswith("i"):
            values[var.name] = rng.integers(0, 10**12, shape)
        else:
            values[var.name] = rng.normal(size=shape) * 10.0 ** rng.integers(-8, 8, shape)
    values["amplitude"] = np.logspace(-7, -3, SIZES["amplitude"])
    return values


# --- schema ---------------------------------------------------------------------------------


@pytest.mark.parametrize("var", ALL_VARIABLES, ids=lambda v: v.name)
def test_every_variable_is_fully_described(var):
    attrs = var.attrs()
    assert attrs["units"] in ("1", "radian")  # UDUNITS; DEM units are stated in dem_units
    assert len(attrs["long_name"]) > 3
    if var.units == "1" and var.dem_units:
        assert var.dem_units in ("length", "time", "1/time", "force/length", "energy")
    is_stress_like = var.name.startswith(("stress", "strain", "mean_stress", "deviatoric_stress"))
    if is_stress_like or var.dem_units == "force/length":
        assert var.sign_convention == COMPRESSION_POSITIVE, var.name
    several_definitions = ("mean_stress", "deviatoric_stress", "fabric", "strain", "coordination")
    if var.name.startswith(several_definitions) and var.dims != ("probe",):
        assert var.definition, var.name


def test_stage_flags_are_consistent_and_labels_map_both_ways():
    stage = next(var for var in HISTORY_VARIABLES if var.name == "stage")
    assert stage.flag_meanings == tuple(STAGE_CODES)
    assert stage.flag_values == tuple(STAGE_CODES.values())
    assert len(set(stage.flag_values)) == len(stage.flag_values)
    for label in ("gas", "isotropic_to_A", "A_to_B", "A_to_C", "C_to_B", "radial", "relax"):
        assert stage_label(stage_code(label)) == label
    assert "probe" in STAGE_CODES
    with pytest.raises(ValueError, match="allowed"):
        stage_code("K0")
    with pytest.raises(ValueError, match="allowed"):
        stage_label(-3)


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"name": "2bad"}, "identifier"),
        ({"dtype": "f2"}, "dtype"),
        ({"units": ""}, "units"),
        ({"flag_values": (0, 1), "flag_meanings": ("a",)}, "flag_meanings"),
        ({"flag_values": (0,), "flag_meanings": ("two words",)}, "one word"),
        ({"sign_convention": "tension"}, "sign_convention"),
    ],
)
def test_invalid_variable_definitions_fail(kwargs, words):
    args = {"name": "x", "dims": ("time",), "units": "1", "long_name": "x"}
    args.update(kwargs)
    with pytest.raises(ValueError, match=words):
        Variable(**args)


# --- probes -----------------------------------------------------------------------------------


def test_probes_round_trip_with_attributes_and_fill_values(tmp_path):
    values = probe_values()
    path = write_dataset(
        tmp_path / "probes.nc",
        make_dataset(values, attrs={"plateau_rule": "median of amplitudes <= 1e-5"}),
    )
    ds = open_probes(path)
    for var in PROBE_VARIABLES:
        stored = ds[var.name]
        assert stored.dims == var.dims
        if var.dtype == "str":
            assert stored.values.tolist() == values[var.name].tolist()
        else:
            assert stored.dtype == var.numpy_dtype
            np.testing.assert_array_equal(stored.values, values[var.name], err_msg=var.name)
        for key, value in var.attrs().items():
            np.testing.assert_array_equal(stored.attrs[key], value, err_msg=f"{var.name}.{key}")
    assert ds.attrs["plateau_rule"] == "median of amplitudes <= 1e-5"
    assert ds.attrs["Conventions"] == "CF-1.11"
    with netCDF4.Dataset(path) as raw:  # fill values in the file, typed like the variable (CF)
        assert np.isnan(raw["e_oed_v_linear"]._FillValue)
        assert raw["step"]._FillValue == np.iinfo(np.int64).min
        assert raw["step"].dtype == np.int64


def test_partial_probes_are_completed_with_fill_values(tmp_path):
    values = probe_values()
    given = {name: values[name] for name in ("state_label", "mean_stress", "e_oed_v_linear")}
    ds = open_probes(write_dataset(tmp_path / "p.nc", make_dataset(given)))
    assert ds["mean_stress"].values.tolist() == values["mean_stress"].tolist()
    assert np.isnan(ds["e_oed_h_linear"].values).all()
    assert (ds["step"].values == ds["step"].encoding["_FillValue"]).all()
    assert "e_oed_v_of_amplitude" not in ds  # its `amplitude` dimension was never given


def test_probes_with_unknown_names_or_wrong_shapes_fail():
    with pytest.raises(KeyError, match="e_oed_vertical"):
        make_dataset({"e_oed_vertical": np.zeros(3)})
    with pytest.raises(ValueError, match="axes"):
        make_dataset({"stiffness_tensor_linear": np.zeros((3, 3))})
    with pytest.raises(ValueError, match="'probe' has length 2"):
        make_dataset({"mean_stress": np.zeros(3), "specific_volume": np.zeros(2)})


def test_write_dataset_refuses_variables_outside_the_schema(tmp_path):
    ds = make_dataset({"mean_stress": np.zeros(3)})
    ds["typo_modulus"] = ("probe", np.zeros(3))
    with pytest.raises(KeyError, match="typo_modulus"):
        write_dataset(tmp_path / "p.nc", ds)
    assert list(tmp_path.iterdir()) == []


def test_write_dataset_applies_schema_attributes_over_stale_ones(tmp_path):
    ds = make_dataset({"mean_stress": np.ones(2)})
    ds["mean_stress"].attrs["units"] = "kPa"
    ds["mean_stress"].attrs["comment"] = "kept"
    back = open_probes(write_dataset(tmp_path / "p.nc", ds))
    assert back["mean_stress"].attrs["units"] == "1"
    assert back["mean_stress"].attrs["dem_units"] == "force/length"
    assert back["mean_stress"].attrs["comment"] == "kept"


# --- configurations -----------------------------------------------------------------------------


def test_configuration_round_trip(tmp_path):
    rng = np.random.default_rng(4)
    position = rng.random((25, 2)) * [10.0, 12.0]
    angle = rng.uniform(-np.pi, np.pi, 25)
    attrs = {"state_label": "A", "n_spheres": 5, "spacing": 1.0, "diameter": 1.0, "step": 10}
    path = write_configuration(tmp_path / "config_A.nc", position, angle, [10.0, 12.0], attrs)
    ds = open_configuration(path)
    np.testing.assert_array_equal(ds["rod_position"].values, position)
    np.testing.assert_array_equal(ds["rod_angle"].values, angle)
    np.testing.assert_array_equal(ds["cell_lengths"].values, [10.0, 12.0])
    assert ds["rod_position"].dims == ("rod", "xy")
    assert ds["rod_angle"].attrs["units"] == "radian"
    assert ds["rod_position"].attrs["dem_units"] == "length"
    assert ds.attrs["state_label"] == "A" and int(ds.attrs["n_spheres"]) == 5


@pytest.mark.parametrize(
    ("position", "angle", "lengths", "words"),
    [
        (np.zeros((3, 3)), np.zeros(3), [1.0, 1.0], "rod_position"),
        (np.zeros((3, 2)), np.zeros(4), [1.0, 1.0], "rod_angle"),
        (np.zeros((3, 2)), np.zeros(3), [1.0, -1.0], "cell_lengths"),
        (np.full((3, 2), np.nan), np.zeros(3), [1.0, 1.0], "non-finite"),
    ],
)
def test_configuration_rejects_bad_arrays(tmp_path, position, angle, lengths, words):
    with pytest.raises(ValueError, match=words):
        write_configuration(tmp_path / "c.nc", position, angle, lengths)


def test_attributes_that_netcdf_cannot_hold_fail_naming_the_key(tmp_path):
    with pytest.raises(TypeError, match="'scene'"):
        write_configuration(tmp_path / "c.nc", np.zeros((1, 2)), np.zeros(1), [1, 1], {"scene": {}})


# --- CF and dependencies ----------------------------------------------------------------------


def test_history_file_is_cf_shaped(tmp_path):
    path = tmp_path / "h.nc"
    with HistoryWriter(path) as writer:
        writer.append({"step": 0, "time": 0.0, "stage": "gas"})
    with netCDF4.Dataset(path) as raw:
        assert raw.getncattr("Conventions") == "CF-1.11"
        assert raw.dimensions["time"].isunlimited()
        assert raw.data_model == "NETCDF3_64BIT_DATA"  # crash-safe default, see writers.py
        for name, variable in raw.variables.items():
            assert "units" in variable.ncattrs() and "long_name" in variable.ncattrs(), name
            if name == "time":  # CF 2.5.1: a coordinate variable has no _FillValue
                assert "_FillValue" not in variable.ncattrs()
                continue
            assert np.asarray(variable._FillValue).dtype == variable.dtype, name
        stage = raw["stage"]
        assert stage.flag_values.dtype == stage.dtype  # CF 3.5: same type as the variable
        assert stage.flag_meanings.split() == list(STAGE_CODES)


def test_dem_taichi_io_never_imports_taichi():
    for path in sorted((ROOT / "dem_taichi" / "io").rglob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            assert not any(n == "taichi" or n.startswith("taichi.") for n in names), path
    code = (
        "import sys, importlib, pkgutil, dem_taichi.io as io\n"
        "for m in pkgutil.walk_packages(io.__path__, 'dem_taichi.io.'):\n"
        "    importlib.import_module(m.name)\n"
        "assert 'taichi' not in sys.modules, sorted(m for m in sys.modules if 'taichi' in m)\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)
