"""Writers of the DEM results files (netCDF, CF-1.11), spelled by :mod:`.schema`.

- :class:`HistoryWriter` appends one record per output step along the unlimited ``time``
  dimension and syncs the file to disk as it goes (every ``sync_every`` appends), so that a run
  killed half-way leaves a valid file holding every synced record. ``resume=True`` reopens a file
  for an exact resume from a checkpoint, dropping the records written after the checkpoint.
- :func:`write_dataset` writes a whole dataset (the probes) atomically, with the schema's
  attributes and fill values.
- :func:`write_configuration` writes a saved configuration (rods and cell) atomically.

Formats (all written by the ``netCDF4`` library, all read by xarray's ``netcdf4`` engine):

- the history is appended in place in the classic 64-bit-data format ``NETCDF3_64BIT_DATA``
  (CDF5: int64 allowed, no strings) by default. Measured here (SIGKILL at random moments of a
  writer that does nothing but append, 29 variables, sync every record): 0 unreadable or
  inconsistent files out of 150 in CDF5, against 2 out of 100 with the HDF5-based ``NETCDF4``
  format (one unreadable "HDF error", one record half-written although ``step`` was stored last):
  HDF5 is not crash-consistent when killed inside a write or a flush. ``file_format="NETCDF4"``
  remains available. CDF5 files also carry no HDF5 lock, so a running history can be read.
- probes and configurations are whole datasets, written once, atomically (temporary file +
  ``os.replace``), in ``NETCDF4`` (variable-length strings for the state labels).
"""

from __future__ import annotations

import contextlib
import math
import os
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from types import TracebackType
from typing import Any, Final, Literal, TypeGuard

import netCDF4
import numpy as np
import xarray as xr

from .provenance import CONVENTIONS, history_line
from .schema import (
    CONFIGURATION_VARIABLES,
    DEM_UNIT_SYSTEM,
    HISTORY_VARIABLES,
    PROBE_VARIABLES,
    Variable,
    variables_by_name,
)

#: Format of whole datasets (probes, configurations).
FILE_FORMAT: Final = "NETCDF4"
HistoryFormat = Literal["NETCDF3_64BIT_DATA", "NETCDF4"]
#: Default format of the history (see the module docstring for why not HDF5).
HISTORY_FILE_FORMAT: Final = "NETCDF3_64BIT_DATA"
HISTORY_FILE_FORMATS: tuple[HistoryFormat, ...] = ("NETCDF3_64BIT_DATA", "NETCDF4")
#: Records per HDF5 chunk along ``time`` (``NETCDF4`` only).
DEFAULT_CHUNK_RECORDS = 256


# ---------------------------------------------------------------------------------------------
# Attributes
# ---------------------------------------------------------------------------------------------


def clean_attribute(key: str, value: Any) -> Any:
    """A value netCDF can store as an attribute (bool → int, numpy scalars → Python / arrays).

    Fails naming the key for values netCDF cannot hold (None, dicts, nested lists...).
    """
    if isinstance(value, bool | np.bool_):
        return int(value)
    if isinstance(value, str | int | float | np.integer | np.floating):
        return value
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, list | tuple | np.ndarray):
        array = np.asarray(value)
        if array.ndim == 1 and array.dtype.kind in "iuf":
            return array
    raise TypeError(
        f"attribute {key!r}: value {value!r} of type {type(value).__name__} cannot be stored; "
        "use str, int, float or a 1D numeric sequence (join strings into one str)"
    )


def global_attrs(attrs: Mapping[str, Any] | None) -> dict[str, Any]:
    """``attrs`` cleaned for netCDF, with ``Conventions`` and the DEM unit system always present."""
    out: dict[str, Any] = {"Conventions": CONVENTIONS, "dem_unit_system": DEM_UNIT_SYSTEM}
    for key, value in (attrs or {}).items():
        if not isinstance(key, str) or not key.isidentifier():
            raise ValueError(f"global attribute name {key!r} must be an identifier")
        out[key] = clean_attribute(key, value)
    return out


# ---------------------------------------------------------------------------------------------
# History
# ---------------------------------------------------------------------------------------------


def _is_coordinate(var: Variable) -> bool:
    """A CF coordinate variable: one dimension of its own name (``time``, ``amplitude``)."""
    return var.dims == (var.name,)


def _check_history_variables(variables: Iterable[Variable]) -> dict[str, Variable]:
    by_name = variables_by_name(tuple(variables))
    for var in by_name.values():
        if var.dims != ("time",):
            raise ValueError(
                f"history variable {var.name!r} has dims {var.dims}; history variables must have "
                "dims ('time',)"
            )
        if var.dtype == "str":
            raise ValueError(f"history variable {var.name!r}: strings are not allowed in history")
    return by_name


@contextlib.contextmanager
def _full_disk_reported(path: Path) -> Iterator[None]:
    """netCDF4 (HDF5) reports a full disk as ``RuntimeError('NetCDF: HDF error')``: raise it
    again as ``OSError`` ENOSPC naming ``path`` when the disk is full, so that the command lines
    give their disk-full exit code (:mod:`clay_cli`)."""
    try:
        yield
    except RuntimeError as error:
        from clay_cli import disk_full_while_writing

        full = disk_full_while_writing(error, path)
        if full is None:
            raise
        raise full from error


def _is_history_format(name: str) -> TypeGuard[HistoryFormat]:
    return name in HISTORY_FILE_FORMATS


def _create_history_file(
    path: Path,
    variables: Mapping[str, Variable],
    attrs: Mapping[str, Any],
    file_format: HistoryFormat,
    chunk_records: int,
) -> netCDF4.Dataset:
    with _full_disk_reported(path):
        dataset = netCDF4.Dataset(path, "w", format=file_format)
    chunking = {"chunksizes": (chunk_records,)} if file_format == "NETCDF4" else {}
    try:
        with _full_disk_reported(path):
            _define_history(dataset, variables, attrs, chunking)
    except BaseException:
        dataset.close()
        raise
    return dataset


def _define_history(
    dataset: netCDF4.Dataset,
    variables: Mapping[str, Variable],
    attrs: Mapping[str, Any],
    chunking: Mapping[str, Any],
) -> None:
    """The dimension, variables and attributes of a new history file, synced."""
    dataset.createDimension("time", None)
    for var in variables.values():
        # CF 2.5.1: no _FillValue on a coordinate variable (``time``, always given); the
        # netCDF default fill still pre-fills it, without the attribute.
        fill = None if _is_coordinate(var) else var.fill_value
        ncvar = dataset.createVariable(
            var.name, var.numpy_dtype, var.dims, fill_value=fill, **chunking
        )
        ncvar.setncatts(var.attrs())
    dataset.setncatts(dict(attrs))
    dataset.sync()


def _coerce(var: Variable, value: Any) -> Any:
    """The value of one record of ``var``; fails with the name and the allowed values."""
    if value is None:
        return var.fill_value
    if isinstance(value, str):
        if var.flag_meanings and value in var.flag_meanings:
            return var.flag_values[var.flag_meanings.index(value)]
        allowed = f"one of {var.flag_meanings}" if var.flag_meanings else "a number"
        raise ValueError(f"{var.name!r}: got the string {value!r}; allowed: {allowed}")
    array = np.asarray(value)
    if array.shape != ():
        raise ValueError(f"{var.name!r}: expected a scalar per record, got shape {array.shape}")
    if array.dtype.kind not in "biuf":
        raise TypeError(f"{var.name!r}: expected a number, got {value!r} ({type(value).__name__})")
    if var.dtype.startswith("i"):
        number = float(array)
        if not math.isfinite(number) or number != round(number):
            raise ValueError(f"{var.name!r}: expected an integer, got {value!r}")
        integer = int(array)
        info = np.iinfo(var.numpy_dtype)
        if not info.min < integer <= info.max:
            raise ValueError(f"{var.name!r}: {integer} outside the range of {var.dtype}")
        if var.flag_values and integer not in var.flag_values:
            raise ValueError(
                f"{var.name!r}: code {integer} not among flag_values {var.flag_values} "
                f"({' '.join(var.flag_meanings)})"
            )
        return integer
    return float(array)


def _is_finite_number(value: Any) -> bool:
    return isinstance(value, int | float) and math.isfinite(value)


def _read_records(path: Path) -> tuple[dict[str, np.ndarray], dict[str, Any], str]:
    """Raw arrays (no masking), global attributes and format of a history file."""
    with netCDF4.Dataset(path, "r") as dataset:
        dataset.set_auto_mask(False)
        arrays = {name: np.asarray(var[:]) for name, var in dataset.variables.items()}
        attrs = {key: dataset.getncattr(key) for key in dataset.ncattrs()}
        file_format = str(dataset.data_model)
    return arrays, attrs, file_format


class HistoryWriter:
    """Append-only netCDF history of a run, one record per :meth:`append`.

    Parameters
    ----------
    path: the ``.nc`` file (created, or with ``resume=True`` reopened).
    variables: the schema of the records (default :data:`~.schema.HISTORY_VARIABLES`).
    attrs: global attributes (e.g. from :func:`~.provenance.provenance_attrs`).
    resume: reopen an existing file and append after its last kept record.
    resume_after_step: with ``resume=True``, drop the records whose ``step`` is greater than this
        (the step of the checkpoint the run resumes from); ``None`` keeps every record.
    sync_every: write and sync the file every this many appends (1: every append); records
        appended since the last sync are lost if the process is killed.
    file_format: ``"NETCDF3_64BIT_DATA"`` (default, crash-safe) or ``"NETCDF4"``; a resumed
        file keeps its own format.
    chunk_records: HDF5 chunk length along ``time`` (``NETCDF4`` only).

    Usage::

        with HistoryWriter(out / "history.nc", attrs=provenance_attrs(...)) as history:
            history.append(simulation.measure() | {"stage": "A_to_C"})
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        variables: Iterable[Variable] | Mapping[str, Variable] = HISTORY_VARIABLES,
        attrs: Mapping[str, Any] | None = None,
        resume: bool = False,
        *,
        resume_after_step: int | None = None,
        sync_every: int = 1,
        file_format: str = HISTORY_FILE_FORMAT,
        chunk_records: int = DEFAULT_CHUNK_RECORDS,
    ) -> None:
        if not _is_history_format(file_format):
            raise ValueError(
                f"file_format {file_format!r} not allowed; use one of {HISTORY_FILE_FORMATS}"
            )
        if isinstance(sync_every, bool) or not isinstance(sync_every, int) or sync_every < 1:
            raise ValueError(f"sync_every must be an int >= 1, got {sync_every!r}")
        if not isinstance(chunk_records, int) or chunk_records < 1:
            raise ValueError(f"chunk_records must be an int >= 1, got {chunk_records!r}")
        if resume_after_step is not None and not resume:
            raise ValueError("resume_after_step is only meaningful with resume=True")
        values = variables.values() if isinstance(variables, Mapping) else variables
        self.variables = _check_history_variables(values)
        self.path = Path(path)
        self.sync_every = sync_every
        self._buffer: list[dict[str, Any]] = []
        self._closed = False
        if resume:
            self._dataset = self._reopen(attrs, resume_after_step, chunk_records)
        else:
            if self.path.exists():
                self.path.unlink()
            self._dataset = _create_history_file(
                self.path, self.variables, global_attrs(attrs), file_format, chunk_records
            )
        self.n_records = len(self._dataset.dimensions["time"])

    def _reopen(
        self, attrs: Mapping[str, Any] | None, after_step: int | None, chunk_records: int
    ) -> netCDF4.Dataset:
        if not self.path.exists():
            raise FileNotFoundError(f"cannot resume: history file {self.path} does not exist")
        arrays, old_attrs, file_format = _read_records(self.path)
        if not _is_history_format(file_format):
            raise ValueError(
                f"cannot resume {self.path}: format {file_format}, not one of "
                f"{HISTORY_FILE_FORMATS}"
            )
        missing = sorted(set(self.variables) - set(arrays))
        extra = sorted(set(arrays) - set(self.variables))
        if missing or extra:
            raise ValueError(
                f"cannot resume {self.path}: its variables differ from the schema "
                f"(missing in file: {missing}; not in schema: {extra})"
            )
        n_keep = len(next(iter(arrays.values()))) if arrays else 0
        if "step" in arrays:
            steps = arrays["step"]
            given = np.flatnonzero(steps != self.variables["step"].fill_value)
            if given.size:  # drop a last record cut short by a kill (its `step` is written last)
                n_keep = int(given[-1]) + 1
        if after_step is not None:
            if "step" not in arrays:
                raise ValueError("resume_after_step needs a 'step' variable in the history")
            beyond = np.flatnonzero(arrays["step"][:n_keep] > after_step)
            n_keep = int(beyond[0]) if beyond.size else n_keep
        merged = dict(old_attrs)
        new = global_attrs(attrs)
        old_history = str(old_attrs.get("history", ""))
        merged.update(new)
        note = history_line(f"resumed after step {after_step}, {n_keep} records kept")
        lines = [line for line in (old_history, str(new.get("history", "")), note) if line]
        merged["history"] = "\n".join(dict.fromkeys(lines))
        # netCDF cannot shrink an unlimited dimension: rebuild the file with the kept records
        # in a temporary file, then swap it in atomically.
        handle, temp_name = tempfile.mkstemp(
            dir=self.path.parent, prefix=f".{self.path.name}.", suffix=".tmp"
        )
        os.close(handle)
        temp = Path(temp_name)
        try:
            dataset = _create_history_file(temp, self.variables, merged, file_format, chunk_records)
            try:
                with _full_disk_reported(self.path):
                    for name, values in arrays.items():
                        if n_keep:
                            dataset.variables[name][:n_keep] = values[:n_keep]
                    dataset.sync()
            finally:
                dataset.close()
            os.chmod(temp, self.path.stat().st_mode & 0o777)
            os.replace(temp, self.path)
        except BaseException:
            temp.unlink(missing_ok=True)
            raise
        return netCDF4.Dataset(self.path, "a")

    def append(self, frame: Mapping[str, Any]) -> int:
        """Append one record; returns its index along ``time``.

        Unknown names fail (listing them and the known ones); names left out get the fill value
        (NaN for floats), except ``time``, the coordinate, which every record must give. Flag
        variables (``stage``) take the code or the label.
        """
        if self._closed:
            raise RuntimeError(f"history {self.path} is closed")
        unknown = sorted(set(frame) - set(self.variables))
        if unknown:
            raise KeyError(
                f"unknown history variable(s) {unknown}; known: {sorted(self.variables)}"
            )
        record = {name: _coerce(self.variables[name], value) for name, value in frame.items()}
        if "time" in self.variables and not _is_finite_number(record.get("time")):
            raise ValueError(
                "every history record needs a finite 'time': it is the coordinate of the file "
                f"(CF: no missing coordinate values); got {frame.get('time')!r}"
            )
        index = self.n_records
        self._buffer.append(record)
        self.n_records = index + 1
        if len(self._buffer) >= self.sync_every:
            self.sync()
        return index

    def sync(self) -> None:
        """Write the buffered records to the file and the file to disk.

        Records are buffered in memory between syncs because each netCDF write costs about
        0.15 ms per variable whatever its length: one block write per variable per sync.
        """
        if self._closed:
            return
        with _full_disk_reported(self.path):
            self._write_buffer()

    def _write_buffer(self) -> None:
        """The body of :meth:`sync`."""
        if self._buffer:
            start = self.n_records - len(self._buffer)
            stop = self.n_records
            # `step` goes last: a record whose `step` is still the fill value was cut short by
            # a kill during this loop, and open_history drops it.
            names = sorted(self.variables, key=lambda name: name == "step")
            for name in names:
                var = self.variables[name]
                block = np.array(
                    [record.get(name, var.fill_value) for record in self._buffer],
                    dtype=var.numpy_dtype,
                )
                self._dataset.variables[name][start:stop] = block
            self._buffer.clear()
        self._dataset.sync()

    def close(self) -> None:
        """Sync and close the file (idempotent)."""
        if not self._closed:
            try:
                self.sync()
            finally:
                self._dataset.close()
                self._closed = True

    def __enter__(self) -> HistoryWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else "open"
        return f"HistoryWriter({str(self.path)!r}, {self.n_records} records, {state})"


# ---------------------------------------------------------------------------------------------
# Whole datasets (probes) and configurations
# ---------------------------------------------------------------------------------------------


def make_dataset(
    values: Mapping[str, Any],
    variables: Iterable[Variable] | Mapping[str, Variable] = PROBE_VARIABLES,
    attrs: Mapping[str, Any] | None = None,
) -> xr.Dataset:
    """An :class:`xarray.Dataset` of ``values`` laid out and annotated by the schema.

    Every name must be in the schema; each array must have as many axes as the variable's dims,
    and a dimension must have the same length everywhere. Schema variables left out are filled
    with their fill value when all their dimensions are known from the given ones.
    """
    schema = variables_by_name(
        tuple(variables.values() if isinstance(variables, Mapping) else variables)
    )
    unknown = sorted(set(values) - set(schema))
    if unknown:
        raise KeyError(f"unknown variable(s) {unknown}; known: {sorted(schema)}")
    sizes: dict[str, int] = {}
    data_vars: dict[str, xr.Variable] = {}
    for name, value in values.items():
        var = schema[name]
        array = np.asarray(value, dtype=var.numpy_dtype)
        if array.ndim != len(var.dims):
            raise ValueError(
                f"{name!r}: expected {len(var.dims)} axes {var.dims}, got shape {array.shape}"
            )
        for dim, size in zip(var.dims, array.shape, strict=True):
            if sizes.setdefault(dim, size) != size:
                raise ValueError(
                    f"{name!r}: dimension {dim!r} has length {size} here but {sizes[dim]} elsewhere"
                )
        data_vars[name] = xr.Variable(var.dims, array, attrs=var.attrs())
    for name, var in schema.items():
        if name not in data_vars and all(dim in sizes for dim in var.dims):
            shape = tuple(sizes[dim] for dim in var.dims)
            array = np.full(shape, var.fill_value, dtype=var.numpy_dtype)
            data_vars[name] = xr.Variable(var.dims, array, attrs=var.attrs())
    return xr.Dataset(data_vars, attrs=global_attrs(attrs))


def _encoding(ds: xr.Dataset, schema: Mapping[str, Variable]) -> dict[str, dict[str, Any]]:
    encoding: dict[str, dict[str, Any]] = {}
    for name in ds.variables:
        var = schema.get(str(name))
        if var is None:
            continue
        if var.dtype == "str":
            encoding[str(name)] = {"dtype": str}
        elif _is_coordinate(var):  # CF 2.5.1: no _FillValue on a coordinate variable
            encoding[str(name)] = {"dtype": var.numpy_dtype, "_FillValue": None}
        else:
            encoding[str(name)] = {"dtype": var.numpy_dtype, "_FillValue": var.fill_value}
    return encoding


def _give_default_permissions(path: Path) -> None:
    """mkstemp makes files readable by their owner only; results are ordinary files (umask)."""
    mask = os.umask(0)
    os.umask(mask)
    os.chmod(path, 0o666 & ~mask)


def _atomic_to_netcdf(path: Path, ds: xr.Dataset, encoding: Mapping[str, Any]) -> None:
    handle, temp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(handle)
    temp = Path(temp_name)
    try:
        with _full_disk_reported(path):
            ds.to_netcdf(temp, format=FILE_FORMAT, engine="netcdf4", encoding=dict(encoding))
        _give_default_permissions(temp)
        os.replace(temp, path)
    except BaseException:
        temp.unlink(missing_ok=True)
        raise


def write_dataset(
    path: str | os.PathLike[str],
    ds: xr.Dataset,
    variables: Iterable[Variable] | Mapping[str, Variable] = PROBE_VARIABLES,
    attrs: Mapping[str, Any] | None = None,
) -> Path:
    """Write a whole dataset (the probes) atomically, annotated by the schema.

    Schema variables get their units, long names, definitions and fill values (the schema wins
    over attributes already on ``ds``); variables the schema does not know are refused, so a
    misspelled name fails here rather than in the bridge. ``attrs`` are added to the global
    attributes of ``ds``. Returns the path written.
    """
    schema = variables_by_name(
        tuple(variables.values() if isinstance(variables, Mapping) else variables)
    )
    unknown = sorted(str(name) for name in ds.variables if str(name) not in schema)
    if unknown:
        raise KeyError(f"variable(s) {unknown} are not in the schema; known: {sorted(schema)}")
    out = ds.copy()
    for name in out.variables:
        var = schema[str(name)]
        if out[name].dims != var.dims:
            raise ValueError(f"{name!r}: dims {out[name].dims}, the schema says {var.dims}")
        attrs_here = {k: v for k, v in out[name].attrs.items() if k != "_FillValue"}
        attrs_here.update(var.attrs())
        out[name].attrs = attrs_here
        out[name].encoding = {}
    merged = dict(ds.attrs)
    merged.update(attrs or {})
    out.attrs = global_attrs(merged)
    target = Path(path)
    _atomic_to_netcdf(target, out, _encoding(out, schema))
    return target


def write_configuration(
    path: str | os.PathLike[str],
    rod_position: np.ndarray,
    rod_angle: np.ndarray,
    cell_lengths: np.ndarray,
    attrs: Mapping[str, Any] | None = None,
) -> Path:
    """Write a saved configuration (e.g. at state A, B or C) atomically.

    ``rod_position`` (N, 2) centroids, ``rod_angle`` (N,) in radians, ``cell_lengths`` (2,).
    Put what is needed to draw the rods (``n_spheres``, ``spacing``, ``diameter``, the state
    label, step, p and q...) in ``attrs``.
    """
    position = np.asarray(rod_position, dtype=np.float64)
    angle = np.asarray(rod_angle, dtype=np.float64)
    lengths = np.asarray(cell_lengths, dtype=np.float64)
    if position.ndim != 2 or position.shape[1] != 2:
        raise ValueError(f"rod_position must have shape (N, 2), got {position.shape}")
    if angle.shape != (position.shape[0],):
        raise ValueError(
            f"rod_angle must have shape ({position.shape[0]},) like rod_position, got {angle.shape}"
        )
    if lengths.shape != (2,) or not np.all(lengths > 0):
        raise ValueError(f"cell_lengths must be two positive lengths, got {cell_lengths!r}")
    for name, array in (("rod_position", position), ("rod_angle", angle)):
        if not np.all(np.isfinite(array)):
            raise ValueError(f"{name} has non-finite values")
    ds = make_dataset(
        {"rod_position": position, "rod_angle": angle, "cell_lengths": lengths},
        CONFIGURATION_VARIABLES,
        attrs,
    )
    schema = variables_by_name(CONFIGURATION_VARIABLES)
    target = Path(path)
    _atomic_to_netcdf(target, ds, _encoding(ds, schema))
    return target
