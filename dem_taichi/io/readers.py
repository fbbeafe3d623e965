"""Readers of the DEM results files: whole datasets loaded into memory, files closed.

Integer variables keep their integer dtype (a missing integer is the schema's fill value, kept in
``encoding["_FillValue"]``); float variables hold NaN where a record lacked them. The history's
``stage`` codes are also given as labels in the coordinate ``stage_label``.

A running history can be read at any time: the default (CDF5) history has no lock; an HDF5
(``NETCDF4``) file still open in its writer is locked by HDF5, and the readers then load a copy of
it (the records synced so far).
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import xarray as xr


def _load(path: Path) -> xr.Dataset:
    with xr.open_dataset(
        path, engine="netcdf4", mask_and_scale=False, decode_times=False, cache=False
    ) as opened:
        return opened.load()


def _load_snapshot(path: Path, attempts: int = 3) -> xr.Dataset:
    """Load a copy of ``path``: HDF5 locks a file its writer still holds open.

    A copy taken while the writer is in the middle of a sync may be inconsistent, hence the
    retries.
    """
    last_error: OSError | None = None
    for _ in range(attempts):
        with tempfile.TemporaryDirectory(prefix="dem_taichi_io_") as folder:
            copy = Path(folder) / path.name
            shutil.copyfile(path, copy)
            try:
                return _load(copy)
            except OSError as error:
                last_error = error
        time.sleep(0.05)
    assert last_error is not None
    raise last_error


def _open(path: str | os.PathLike[str], kind: str) -> xr.Dataset:
    target = Path(path)
    if not target.exists():
        raise FileNotFoundError(f"{kind} file {target} does not exist")
    try:
        ds = _load(target)
    except OSError as error:
        try:
            ds = _load_snapshot(target)
        except OSError:
            raise OSError(
                f"cannot read {kind} file {target}: {error} (not a netCDF file, or corrupt)"
            ) from error
    for name in list(ds.variables):
        variable = ds[name]
        fill = variable.attrs.pop("_FillValue", None)
        if fill is None:
            continue
        if variable.dtype.kind == "f" and not np.isnan(fill):
            ds[name] = variable.where(variable != fill)
        ds[name].encoding["_FillValue"] = fill
    return ds


def decode_flags(variable: xr.DataArray) -> xr.DataArray:
    """Labels (strings) of a CF flag variable from its ``flag_values``/``flag_meanings``.

    Codes that are not among the flags (e.g. the fill value) become ``""``.
    """
    values = np.atleast_1d(variable.attrs["flag_values"])
    meanings = str(variable.attrs["flag_meanings"]).split()
    lookup = dict(zip((int(v) for v in values), meanings, strict=True))
    labels = np.array([lookup.get(int(code), "") for code in variable.values.ravel()], dtype=object)
    return xr.DataArray(labels.reshape(variable.shape), dims=variable.dims)


def open_history(path: str | os.PathLike[str], drop_incomplete: bool = True) -> xr.Dataset:
    """The history of a run (also of a killed run: every record synced before the kill).

    Adds the coordinate ``stage_label`` (the stage names of the ``stage`` codes). The writer
    stores ``step`` last in each record, so trailing records whose ``step`` is the fill value were
    cut short by a kill during a write; ``drop_incomplete`` drops them.
    """
    ds = _open(path, "history")
    if drop_incomplete and "step" in ds and "_FillValue" in ds["step"].encoding:
        complete = np.flatnonzero(ds["step"].values != ds["step"].encoding["_FillValue"])
        # no step anywhere: the writer's caller never gave one, nothing to judge by
        n_complete = int(complete[-1]) + 1 if complete.size else ds.sizes["time"]
        if n_complete < ds.sizes["time"]:
            ds = ds.isel(time=slice(0, n_complete))
    if "stage" in ds and "flag_values" in ds["stage"].attrs:
        ds = ds.assign_coords(stage_label=decode_flags(ds["stage"]))
        ds["stage_label"].attrs["long_name"] = "stage of the virtual experiment (label)"
    return ds


def open_probes(path: str | os.PathLike[str]) -> xr.Dataset:
    """The probes dataset of a run (states, moduli from both methods, degradation curves)."""
    return _open(path, "probes")


def open_configuration(path: str | os.PathLike[str]) -> xr.Dataset:
    """A saved configuration: ``rod_position`` (rod, xy), ``rod_angle`` (rod), ``cell_lengths``."""
    return _open(path, "configuration")
