"""The netCDF files the project writes, checked against the CF conventions they claim (CF-1.11).

One small file of each kind is made without Taichi and without a simulation (seconds):

- ``tiv_k0``, ``tiv_k0_then_unload``: :mod:`tiv_model.drivers` datasets (``tiv-model`` CLI,
  ``scripts/demo.py``);
- ``dem_history`` (CDF5, the default) and ``dem_history_netcdf4``: :class:`HistoryWriter`, which
  writes ``history.nc`` and ``relaxed_states.nc`` of a protocol run, on synthetic records;
- ``dem_probes``: :func:`write_dataset` (``probes.nc``); ``dem_configuration``:
  :func:`write_configuration` (``configuration_<state>.nc``), with the attributes the protocol
  gives them;
- ``bridge_synthetic_relaxed_states``, ``bridge_synthetic_probes``:
  :func:`bridge.pipeline.synthetic_inputs` (DEM-schema files written by the TIV model).

Two layers of checks:

1. :func:`test_cf_checker_finds_no_error`: the IOOS ``compliance-checker`` (its ``cf:1.11``
   suite), when it is installed (``make cf-check``, i.e. ``pip install -e '.[cf]'``); skipped
   otherwise. It runs offline: it ships the CF standard-name table
   (``compliance_checker/data/cf-standard-name-table.xml``) and its ``cf-units`` wheel bundles
   UDUNITS-2; nothing is downloaded unless a file names another table version in a global
   ``standard_name_vocabulary`` (ours do not). With ``CF_CHECK_REQUIRED=1`` (``make cf-check``) a
   missing checker fails instead of skipping. No finding of high priority (the checker's
   "Errors") is allowed, except the one listed in :data:`CHECKER_FALSE_POSITIVES`.
2. :func:`test_own_cf_rules`, always (numpy, netCDF4 and pint only): the rules listed in
   :func:`cf_violations`; :func:`test_own_rules_catch_a_bad_file` shows each rule fires.
"""

from __future__ import annotations

import importlib.util
import math
import os
import re
import warnings
import xml.etree.ElementTree as ET
from functools import cache
from pathlib import Path

import netCDF4
import numpy as np
import pytest

CHECKER = "cf:1.11"

#: Files whose writer is known not to follow CF yet (strict xfail: fixing it fails the mark).
KNOWN_NOT_CF: dict[str, str] = {}

KINDS = (
    "tiv_k0",
    "tiv_k0_then_unload",
    "dem_history",
    "dem_history_netcdf4",
    "dem_probes",
    "dem_configuration",
    "bridge_synthetic_relaxed_states",
    "bridge_synthetic_probes",
)

#: Findings of high priority that are not CF errors in our files: message -> why.
CHECKER_FALSE_POSITIVES = {
    "Coordinate variable 'time' should have standard_name='time', found: 'None'": (
        "compliance-checker's 5.1 check takes any dimension named 'time' for a CF time axis; "
        "the DEM's 'time' is in DEM units (units '1', dem_units 'time'), not a CF time "
        "coordinate (CF 4.4 needs '<unit> since <epoch>'); with standard_name 'time' the "
        "checker reports 3.1 and 4.4 errors instead"
    ),
}

#: CF Appendix C: the standard-name modifiers.
STANDARD_NAME_MODIFIERS = (
    "detection_minimum",
    "number_of_observations",
    "standard_error",
    "status_flag",
)
#: Numeric attributes that must hold finite numbers (a NaN there has no meaning in CF 2.5.1,
#: 3.5 and 8.1: NaN compares unequal to every value). ``_FillValue`` and ``missing_value`` may
#: be NaN for floating-point variables.
FINITE_ATTRIBUTES = (
    "valid_min",
    "valid_max",
    "valid_range",
    "actual_range",
    "scale_factor",
    "add_offset",
    "flag_values",
    "flag_masks",
)
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
_STANDARD_NAME = re.compile(r"[a-z][a-z0-9_]*")
_CONVENTIONS = re.compile(r"CF-\d+\.\d+")


#: ``make cf-check`` sets this: there a missing checker fails instead of skipping.
CHECKER_REQUIRED = os.environ.get("CF_CHECK_REQUIRED", "") not in ("", "0")


def _checker_missing() -> str | None:
    for module, what in (
        ("compliance_checker", "the IOOS compliance-checker"),
        ("cf_units", "cf-units (UDUNITS-2)"),
    ):
        if importlib.util.find_spec(module) is None:
            return (
                f"{what} is not installed: `make cf-check` installs it (pip install -e '.[cf]') "
                "and runs this file"
            )
    return None


#: Skip the checker's tests where it is absent (the default suite), unless it is required.
needs_checker = pytest.mark.skipif(
    _checker_missing() is not None and not CHECKER_REQUIRED, reason=str(_checker_missing())
)


# ---------------------------------------------------------------------------------------------
# The files
# ---------------------------------------------------------------------------------------------


def _write_files(out: Path) -> dict[str, Path]:
    from bridge.pipeline import synthetic_inputs
    from dem_taichi.io import (
        HistoryWriter,
        make_dataset,
        provenance_attrs,
        write_configuration,
        write_dataset,
    )
    from tiv_model import drivers

    files = {name: out / f"{name}.nc" for name in KINDS}
    drivers.k0(250.0, increments=10).to_netcdf(files["tiv_k0"])
    drivers.k0_then_unload(250.0, increments=6, unload_increments=3).to_netcdf(
        files["tiv_k0_then_unload"]
    )
    attrs = provenance_attrs("[scene]\nname = 'cf'\n", "cpu", "f64", 0, "test_cf_conventions")
    for name, file_format in (
        ("dem_history", "NETCDF3_64BIT_DATA"),
        ("dem_history_netcdf4", "NETCDF4"),
    ):
        with HistoryWriter(files[name], attrs=attrs, file_format=file_format) as history:
            for i, stage in enumerate(("gas", "isotropic_to_A", "isotropic_to_A", "A_to_B")):
                # some variables left out: they get their fill values
                history.append(
                    {"step": 10 * i, "time": 0.5 * i, "stage": stage, "stress_xx": 1.0 + i}
                    | ({"n_contacts": 3 * i, "inertial_number": 1e-4} if i else {})
                )
    probes = make_dataset(
        {
            "state_label": np.array(["A", "B"], dtype=object),
            "path": np.array(["isotropic_to_A", "A_to_B"], dtype=object),
            "step": np.array([40, 80]),
            "mean_stress": np.array([1.0, 2.0]),
            "amplitude": np.array([1e-5, 1e-4, 1e-3]),
            "e_oed_v_of_amplitude": np.full((2, 3), 50.0),
            "stiffness_tensor_linear": np.ones((2, 3, 3)),
        }
    )
    write_dataset(files["dem_probes"], probes, attrs=dict(attrs, title="DEM elastic probes"))
    rng = np.random.default_rng(0)
    write_configuration(
        files["dem_configuration"],
        rng.random((6, 2)) * 4.0,
        rng.random(6) * np.pi,
        np.array([4.0, 4.0]),
        attrs={"title": "DEM configuration at state A", "state_label": "A", "n_spheres": 3},
    )
    history, probes_path, _ = synthetic_inputs(out / "bridge", increments=4)
    history.rename(files["bridge_synthetic_relaxed_states"])
    probes_path.rename(files["bridge_synthetic_probes"])
    return files


@pytest.fixture(scope="module")
def cf_files(tmp_path_factory) -> dict[str, Path]:
    return _write_files(tmp_path_factory.mktemp("cf"))


def _kinds():
    return [
        pytest.param(kind, marks=pytest.mark.xfail(strict=True, reason=KNOWN_NOT_CF[kind]))
        if kind in KNOWN_NOT_CF
        else kind
        for kind in KINDS
    ]


# ---------------------------------------------------------------------------------------------
# 1. The real checker
# ---------------------------------------------------------------------------------------------


@cache
def checker_findings(path: Path) -> tuple[list[tuple[int, str, str]], dict]:
    """(priority, section, message) of every failed check of compliance-checker's cf:1.11
    suite on ``path`` (priority 3 = "Errors", 2 = "Warnings"), and the checks that crashed."""
    missing = _checker_missing()
    if missing:
        pytest.fail(f"CF_CHECK_REQUIRED is set but {missing}")
    from compliance_checker.runner import CheckSuite

    suite = CheckSuite()
    suite.load_all_available_checkers()
    dataset = suite.load_dataset(str(path))
    try:
        groups, crashed = suite.run_all(dataset, [CHECKER], skip_checks=[])[CHECKER]
    finally:
        dataset.close()
    found: list[tuple[int, str, str]] = []

    def walk(results):
        for result in results:
            if result.children:
                walk(result.children)
            elif result.value[0] != result.value[1]:
                found.extend((result.weight, result.name, msg) for msg in result.msgs)

    walk(groups)
    return sorted(set(found)), crashed


@needs_checker
@pytest.mark.parametrize("kind", _kinds())
def test_cf_checker_finds_no_error(cf_files, kind):
    found, crashed = checker_findings(cf_files[kind])
    assert not crashed, f"{kind}: checks that crashed: {crashed}"
    errors = [
        f"{section}: {msg}"
        for weight, section, msg in found
        if weight >= 3 and msg not in CHECKER_FALSE_POSITIVES
    ]
    assert not errors, f"{kind}: compliance-checker {CHECKER} errors:\n" + "\n".join(errors)


@needs_checker
def test_checker_false_positive_is_only_on_dimensionless_time(cf_files):
    """The one allowed finding appears only where 'time' is the DEM's dimensionless time."""
    for kind, path in cf_files.items():
        found, _ = checker_findings(path)
        if any(msg in CHECKER_FALSE_POSITIVES for _, _, msg in found):
            with netCDF4.Dataset(path) as ds:
                assert kind in KNOWN_NOT_CF or ds["time"].getncattr("units") == "1", kind


# ---------------------------------------------------------------------------------------------
# 2. Our own rules
# ---------------------------------------------------------------------------------------------


@cache
def standard_name_table() -> frozenset[str] | None:
    """The CF standard names (and aliases) of a table found offline, else None: the file named
    by the environment variable CF_STANDARD_NAMES (as cfchecker reads it), else the copy that
    compliance-checker ships."""
    path = os.environ.get("CF_STANDARD_NAMES")
    if not path:
        spec = importlib.util.find_spec("compliance_checker")
        if spec is None or spec.origin is None:
            return None
        path = str(Path(spec.origin).parent / "data" / "cf-standard-name-table.xml")
    if not Path(path).is_file():
        return None
    root = ET.parse(path).getroot()
    return frozenset(
        str(element.get("id")) for element in root.iter() if element.tag in ("entry", "alias")
    )


@cache
def _pint_registry():
    from bridge.units import registry

    return registry()


def udunits_to_pint(units: str) -> str:
    """UDUNITS powers (``m2``, ``kPa-1``, ``s^-1``) in pint's spelling (``m**2``...)."""
    return re.sub(r"(?<=[A-Za-z])\^?(-?\d+)\b", r"**\1", units.strip())


def units_problem(units: object) -> str | None:
    """Why ``units`` is not a unit pint can read (after :func:`udunits_to_pint`), or None."""
    if not isinstance(units, str) or not units.strip():
        return f"units {units!r} is not a non-empty string"
    try:
        _pint_registry().Quantity(1.0, udunits_to_pint(units))
    except Exception as error:  # pint raises several types for text it cannot read
        return f"units {units!r} not readable by pint ({type(error).__name__})"
    return None


def standard_name_problem(value: object, table: frozenset[str] | None) -> str | None:
    """CF 3.3: ``name [modifier]``, the name in the table when one was found."""
    words = value.split() if isinstance(value, str) else []
    if not 1 <= len(words) <= 2 or not _STANDARD_NAME.fullmatch(words[0]):
        return f"standard_name {value!r} is not 'name [modifier]' in lower case"
    if len(words) == 2 and words[1] not in STANDARD_NAME_MODIFIERS:
        return f"standard_name {value!r}: modifier not one of {STANDARD_NAME_MODIFIERS}"
    if table is not None and words[0] not in table:
        return f"standard_name {words[0]!r} is not in the CF standard-name table"
    return None


def _same_type(value: object, dtype: np.dtype) -> bool:
    return np.asarray(value).dtype == dtype


def _item(value: object) -> object:
    return np.asarray(value).ravel()[0].item()


def _contains(values: np.ndarray, value: object) -> bool:
    values = np.asarray(values).ravel()
    if isinstance(value, float | np.floating) and math.isnan(value):
        return bool(np.isnan(values.astype(float)).any())
    return bool((values == value).any())


def cf_violations(path: Path) -> list[str]:
    """The CF rules we check ourselves, each violation as '§section what':

    - 2.6.1 the global ``Conventions`` is a string whose first item is ``CF-<n>.<m>``;
    - 2.3 variable, dimension and attribute names start with a letter and hold letters, digits
      and underscores (attributes may also start with '_', e.g. ``_FillValue``);
    - 2.4 the dimensions of a variable are all different;
    - 3.2 every variable has a non-empty string ``long_name``;
    - 3.1 every numeric variable that is not a flag variable has ``units``, and any ``units``
      is read by pint (UDUNITS powers translated; ``"1"`` is dimensionless);
    - 3.3 any ``standard_name`` is ``name [modifier]`` (lower case, Appendix C modifiers), the
      name in the standard-name table when one is found offline (:func:`standard_name_table`);
    - 2.5.1 ``_FillValue`` and ``missing_value`` have the variable's type, ``_FillValue`` is one
      value, and is among ``missing_value`` when both are given; no ``_FillValue`` among the
      ``flag_values``;
    - 3.5 ``flag_values`` have the variable's type, are distinct, and match ``flag_meanings``
      (blank-separated words) one to one;
    - 5 / 2.5.1 coordinate variables (one dimension of their own name) have no ``_FillValue``
      nor ``missing_value``, finite values, strictly monotonic;
    - no NaN in the attributes of :data:`FINITE_ATTRIBUTES`.
    """
    table = standard_name_table()
    out: list[str] = []
    with netCDF4.Dataset(path) as ds:
        ds.set_auto_maskandscale(False)
        conventions = ds.getncattr("Conventions") if "Conventions" in ds.ncattrs() else None
        first = conventions.replace(",", " ").split()[:1] if isinstance(conventions, str) else []
        if not first or not _CONVENTIONS.fullmatch(first[0]):
            out.append(f"§2.6.1 global Conventions {conventions!r} does not name CF-<n>.<m>")
        for key in ds.ncattrs():
            if not _NAME.fullmatch(key):
                out.append(f"§2.3 global attribute name {key!r}")
        for dim in ds.dimensions:
            if not _NAME.fullmatch(dim):
                out.append(f"§2.3 dimension name {dim!r}")
        for name, var in ds.variables.items():
            attrs = {key: var.getncattr(key) for key in var.ncattrs()}
            where = f"variable {name!r}"
            if not _NAME.fullmatch(name):
                out.append(f"§2.3 variable name {name!r}")
            for key in attrs:
                if not _NAME.fullmatch(key.lstrip("_")):
                    out.append(f"§2.3 {where}: attribute name {key!r}")
            if len(set(var.dimensions)) != len(var.dimensions):
                out.append(f"§2.4 {where}: repeated dimensions {var.dimensions}")
            is_string = var.dtype is str or np.dtype(var.dtype).kind in "SUO"
            is_flag = "flag_values" in attrs or "flag_masks" in attrs
            long_name = attrs.get("long_name")
            if not isinstance(long_name, str) or not long_name.strip():
                out.append(f"§3.2 {where}: no long_name")
            if "units" in attrs:
                problem = units_problem(attrs["units"])
                if problem:
                    out.append(f"§3.1 {where}: {problem}")
            elif not is_string and not is_flag:
                out.append(f"§3.1 {where}: no units")
            if "standard_name" in attrs:
                problem = standard_name_problem(attrs["standard_name"], table)
                if problem:
                    out.append(f"§3.3 {where}: {problem}")
            for key in FINITE_ATTRIBUTES:
                if key in attrs:
                    values = np.asarray(attrs[key])
                    if values.dtype.kind == "f" and not np.isfinite(values).all():
                        out.append(f"{where}: attribute {key} holds NaN or inf")
            if not is_string:
                dtype = np.dtype(var.dtype)
                fill = attrs.get("_FillValue")
                for key in ("_FillValue", "missing_value"):
                    if key in attrs and not _same_type(attrs[key], dtype):
                        out.append(
                            f"§2.5.1 {where}: {key} of type {np.asarray(attrs[key]).dtype}, "
                            f"the variable is {dtype}"
                        )
                if fill is not None and np.asarray(fill).size != 1:
                    out.append(f"§2.5.1 {where}: _FillValue is not a single value")
                if (
                    fill is not None
                    and "missing_value" in attrs
                    and not _contains(attrs["missing_value"], fill)
                ):
                    out.append(f"§2.5.1 {where}: _FillValue {_item(fill)} not among missing_value")
                if "flag_values" in attrs:
                    flags = np.asarray(attrs["flag_values"]).ravel()
                    meanings = str(attrs.get("flag_meanings", "")).split()
                    if flags.dtype != dtype:
                        out.append(f"§3.5 {where}: flag_values of type {flags.dtype}, not {dtype}")
                    if len(set(flags.tolist())) != flags.size or flags.size != len(meanings):
                        out.append(
                            f"§3.5 {where}: {flags.size} flag_values (distinct: "
                            f"{len(set(flags.tolist()))}) for {len(meanings)} flag_meanings"
                        )
                    if fill is not None and _contains(flags, fill):
                        out.append(f"§2.5.1 {where}: _FillValue {_item(fill)} is a flag value")
            if var.dimensions == (name,):
                for key in ("_FillValue", "missing_value"):
                    if key in attrs:
                        out.append(f"§2.5.1 coordinate {name!r} has {key}")
                values = np.asarray(var[:])
                if values.dtype.kind in "iuf":
                    steps = np.diff(values.astype(float))
                    if not np.isfinite(values.astype(float)).all():
                        out.append(f"§5 coordinate {name!r} has missing or non-finite values")
                    elif not ((steps > 0).all() or (steps < 0).all()):
                        out.append(f"§5 coordinate {name!r} is not strictly monotonic")
    return out


@pytest.mark.parametrize("kind", _kinds())
def test_own_cf_rules(cf_files, kind):
    problems = cf_violations(cf_files[kind])
    assert not problems, f"{kind} ({cf_files[kind].name}):\n" + "\n".join(problems)


def test_files_claim_cf_1_11(cf_files):
    for kind, path in cf_files.items():
        with netCDF4.Dataset(path) as ds:
            if kind not in KNOWN_NOT_CF:
                assert ds.getncattr("Conventions") == "CF-1.11", kind


def test_own_rules_catch_a_bad_file(tmp_path):
    path = tmp_path / "bad.nc"
    with netCDF4.Dataset(path, "w") as ds:
        ds.setncattr("Conventions", "COARDS")
        ds.createDimension("x", 3)
        x = ds.createVariable("x", "f8", ("x",), fill_value=-1.0)
        x[:] = [0.0, 2.0, 1.0]  # not monotonic, and a _FillValue on a coordinate
        x.units = "1"
        x.long_name = "x"
        a = ds.createVariable("a", "f8", ("x",), fill_value=0.0)
        a.units = "kpa_per_furlong"
        a.standard_name = "Air_Temperature"
        a.valid_min = np.nan
        a.missing_value = 5.0  # not the fill value
        b = ds.createVariable("b", "i4", ("x",), fill_value=np.int32(1))
        b.long_name = "flags"
        b.flag_values = np.array([0, 1], dtype=np.int64)
        b.flag_meanings = "off on maybe"
        with warnings.catch_warnings():  # netCDF4 warns that it cannot cast 2.5 to int32
            warnings.simplefilter("ignore", UserWarning)
            b.missing_value = 2.5
        c = ds.createVariable("c", "f8", ("x",))
        c.long_name = "air temperature"
        c.units = "kPa-1"  # UDUNITS power: fine
        c.standard_name = "air_temperature standard_deviation"
    problems = "\n".join(cf_violations(path))
    for expected in (
        "§2.6.1 global Conventions 'COARDS'",
        "§2.5.1 coordinate 'x' has _FillValue",
        "§5 coordinate 'x' is not strictly monotonic",
        "§3.2 variable 'a': no long_name",
        "§3.1 variable 'a': units 'kpa_per_furlong' not readable by pint",
        "§3.3 variable 'a': standard_name 'Air_Temperature'",
        "variable 'a': attribute valid_min holds NaN",
        "§2.5.1 variable 'b': missing_value of type float64, the variable is int32",
        "§2.5.1 variable 'a': _FillValue 0.0 not among missing_value",
        "§3.5 variable 'b': flag_values of type int64",
        "§3.5 variable 'b': 2 flag_values (distinct: 2) for 3 flag_meanings",
        "§2.5.1 variable 'b': _FillValue 1 is a flag value",
        "§3.3 variable 'c': standard_name 'air_temperature standard_deviation': modifier",
    ):
        assert expected in problems, f"{expected!r} not found in:\n{problems}"
    assert "variable 'c': units" not in problems
    assert "variable 'b': no units" not in problems  # a flag variable needs no units


def test_udunits_powers_read_by_pint():
    for units in ("1", "kPa", "kPa-1", "m2", "N m-2", "s^-1", "radian"):
        assert units_problem(units) is None, units
    assert units_problem("") is not None
    assert units_problem("kpa") is not None


def test_standard_name_table_found_offline_is_read():
    table = standard_name_table()
    if table is None:
        pytest.skip("no CF standard-name table offline (set CF_STANDARD_NAMES or make cf-check)")
    assert {"air_temperature", "time", "sea_water_pressure"} <= table
    assert standard_name_problem("air_temperature", table) is None
    assert standard_name_problem("dem_time", table) is not None


def test_standard_name_syntax_without_table():
    assert standard_name_problem("air_temperature", None) is None
    assert standard_name_problem("air_temperature status_flag", None) is None
    assert standard_name_problem("air temperature now", None) is not None
    assert standard_name_problem("Time", None) is not None
    assert standard_name_problem("time", frozenset({"time"})) is None
    assert standard_name_problem("dem_time", frozenset({"time"})) is not None
