"""History writer/reader: round trip of the schema, kill-safety, resume truncation."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import netCDF4
import numpy as np
import pytest

from dem_taichi.io import HistoryWriter, open_history, provenance_attrs
from dem_taichi.io.schema import HISTORY_VARIABLES, STAGE_CODES, Variable

ROOT = Path(__file__).resolve().parents[2]


def frame_for(index: int) -> dict[str, float | int]:
    """A distinct, exactly representable value for every history variable of record ``index``."""
    frame: dict[str, float | int] = {}
    for position, var in enumerate(HISTORY_VARIABLES):
        if var.name == "stage":
            frame[var.name] = list(STAGE_CODES.values())[index % len(STAGE_CODES)]
        elif var.dtype.startswith("i"):
            frame[var.name] = 1000 * index + position
        else:
            frame[var.name] = 0.5 * index + position / 64.0 - 3.25
    return frame


FORMATS = ["NETCDF3_64BIT_DATA", "NETCDF4"]


@pytest.mark.parametrize("file_format", FORMATS)
def test_every_history_variable_round_trips_with_its_attributes(tmp_path, file_format):
    path = tmp_path / "history.nc"
    frames = [frame_for(i) for i in range(7)]
    with HistoryWriter(path, attrs={"title": "round trip"}, file_format=file_format) as writer:
        for frame in frames:
            writer.append(frame)
    ds = open_history(path)
    assert ds.sizes["time"] == len(frames)
    for var in HISTORY_VARIABLES:
        stored = ds[var.name]
        expected = np.array([frame[var.name] for frame in frames], dtype=var.numpy_dtype)
        assert stored.dtype == var.numpy_dtype, var.name
        np.testing.assert_array_equal(stored.values, expected, err_msg=var.name)
        assert stored.attrs["units"] == var.units
        assert stored.attrs["long_name"] == var.long_name
        for key, value in var.attrs().items():
            np.testing.assert_array_equal(stored.attrs[key], value, err_msg=f"{var.name}.{key}")
        assert stored.dims == ("time",)
    assert list(ds["stage_label"].values) == [
        list(STAGE_CODES)[i % len(STAGE_CODES)] for i in range(len(frames))
    ]
    assert ds.attrs["Conventions"] == "CF-1.11"
    assert ds.attrs["title"] == "round trip"


def test_missing_names_get_fill_values_and_stage_labels_are_accepted(tmp_path):
    path = tmp_path / "history.nc"
    with HistoryWriter(path) as writer:
        writer.append({"step": 3, "time": 0.5, "stage": "A_to_C", "mean_stress": 2.0})
        writer.append({"step": 4, "time": 0.75, "stage": "relax", "n_contacts": 12})
    ds = open_history(path)
    assert np.isnan(ds["mean_stress"].values[1]) and ds["mean_stress"].values[0] == 2.0
    fill = ds["n_contacts"].encoding["_FillValue"]
    assert ds["n_contacts"].values.tolist() == [fill, 12]
    assert ds["stage"].values.tolist() == [STAGE_CODES["A_to_C"], STAGE_CODES["relax"]]
    assert ds["stage_label"].values.tolist() == ["A_to_C", "relax"]


@pytest.mark.parametrize(
    ("frame", "error", "words"),
    [
        ({"step": 1, "mean_stres": 1.0}, KeyError, "mean_stres"),
        ({"step": 1.5}, ValueError, "integer"),
        ({"stage": "K0"}, ValueError, "A_to_C"),
        ({"stage": 99}, ValueError, "flag_values"),
        ({"mean_stress": [1.0, 2.0]}, ValueError, "scalar"),
        ({"mean_stress": "high"}, ValueError, "mean_stress"),
    ],
)
def test_bad_records_fail_naming_the_variable(tmp_path, frame, error, words):
    with HistoryWriter(tmp_path / "h.nc") as writer:
        with pytest.raises(error, match=words):
            writer.append(frame)
        assert writer.n_records == 0


def test_provenance_attributes_are_stored(tmp_path):
    scene = '[scene]\nname = "smoke"\nn_rods = 40\n'
    attrs = provenance_attrs(
        scene, "cpu", "f64", 7, "python -m dem_taichi run smoke.toml", taichi_version="1.7.4"
    )
    with HistoryWriter(tmp_path / "h.nc", attrs=attrs) as writer:
        writer.append({"step": 0, "time": 0.0})
    ds = open_history(tmp_path / "h.nc")
    for key in ("Conventions", "title", "institution", "source", "history", "dem_unit_system"):
        assert ds.attrs[key], key
    assert ds.attrs["Conventions"] == "CF-1.11"
    assert ds.attrs["scene_toml"] == scene
    assert ds.attrs["taichi_version"] == "1.7.4"
    assert (ds.attrs["arch"], ds.attrs["precision"], int(ds.attrs["seed"])) == ("cpu", "f64", 7)
    assert ds.attrs["source"].startswith("dem_taichi ")
    assert ds.attrs["history"].endswith(": python -m dem_taichi run smoke.toml")


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"arch": "tpu"}, "arch"),
        ({"precision": "f16"}, "precision"),
        ({"seed": -1}, "seed"),
        ({"command": ""}, "command"),
    ],
)
def test_provenance_rejects_invalid_input(kwargs, words):
    args = {"scene_toml": "", "arch": "cpu", "precision": "f64", "seed": 0, "command": "x"}
    args.update(kwargs)
    with pytest.raises(ValueError, match=words):
        provenance_attrs(**args)


WRITER_SCRIPT = textwrap.dedent(
    """
    import sys
    from dem_taichi.io import HistoryWriter
    with HistoryWriter(sys.argv[1], sync_every=int(sys.argv[2]), file_format=sys.argv[3]) as writer:
        step = 0
        while True:
            writer.append({"step": step, "time": 0.25 * step, "mean_stress": 2.0 * step,
                           "stage": step % 3, "n_contacts": step + 1})
            if writer.n_records % int(sys.argv[2]) == 0:
                print(writer.n_records, flush=True)
            step += 1
    """
)


@pytest.mark.parametrize(
    ("sync_every", "wanted", "file_format"),
    [(1, 40, "NETCDF3_64BIT_DATA"), (5, 60, "NETCDF3_64BIT_DATA")],
)
def test_a_killed_writer_leaves_a_readable_file_with_the_synced_records(
    tmp_path, sync_every, wanted, file_format
):
    """One kill per case of the default format (NETCDF4 fails about 1 kill in 50, see writers.py,
    so a test of it would be flaky)."""
    path = tmp_path / "killed.nc"
    child = subprocess.Popen(
        [sys.executable, "-c", WRITER_SCRIPT, str(path), str(sync_every), file_format],
        stdout=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    try:
        synced = 0
        while synced < wanted:
            line = child.stdout.readline()
            assert line, "writer process died early"
            synced = int(line)
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
        child.stdout.close()
    assert child.returncode == -signal.SIGKILL
    ds = open_history(path)
    n = ds.sizes["time"]
    assert n >= synced
    steps = np.arange(n)
    np.testing.assert_array_equal(ds["step"].values, steps)
    np.testing.assert_array_equal(ds["time"].values, 0.25 * steps)
    np.testing.assert_array_equal(ds["mean_stress"].values, 2.0 * steps)
    np.testing.assert_array_equal(ds["n_contacts"].values, steps + 1)
    np.testing.assert_array_equal(ds["stage"].values, steps % 3)


def record(step: int) -> dict[str, float | int | str]:
    return {"step": step, "time": step / 4, "mean_stress": step / 8, "stage": "A_to_B"}


def write_steps(path: Path, steps, **kwargs) -> None:
    with HistoryWriter(path, **kwargs) as writer:
        for step in steps:
            writer.append(record(step))


@pytest.mark.parametrize("file_format", FORMATS)
def test_resume_truncates_records_after_the_checkpoint_step(tmp_path, file_format):
    path = tmp_path / "h.nc"
    write_steps(
        path,
        range(0, 100, 10),
        attrs={"history": "2026-01-01T00:00:00Z: first run"},
        file_format=file_format,
    )
    with HistoryWriter(path, resume=True, resume_after_step=45) as writer:
        assert writer.n_records == 5  # steps 0..40 kept
        for step in range(50, 80, 10):
            writer.append(record(step))
    ds = open_history(path)
    np.testing.assert_array_equal(ds["step"].values, np.arange(0, 80, 10))
    np.testing.assert_array_equal(ds["mean_stress"].values, np.arange(0, 80, 10) / 8)
    assert ds.attrs["history"].startswith("2026-01-01T00:00:00Z: first run\n")
    assert "resumed after step 45, 5 records kept" in ds.attrs["history"]
    assert ds["mean_stress"].attrs["units"] == "1"
    assert not list(tmp_path.glob(".*.tmp"))
    with netCDF4.Dataset(path) as raw:
        assert raw.data_model == file_format


def test_resume_without_a_step_keeps_every_record_and_appends(tmp_path):
    path = tmp_path / "h.nc"
    write_steps(path, range(4))
    with HistoryWriter(path, resume=True) as writer:
        writer.append(record(4))
    assert open_history(path)["step"].values.tolist() == [0, 1, 2, 3, 4]


def test_resume_needs_an_existing_file_with_the_same_variables(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        HistoryWriter(tmp_path / "none.nc", resume=True)
    path = tmp_path / "h.nc"
    write_steps(path, range(3))
    other = (Variable("step", ("time",), "1", "step", dtype="i8"),)
    with pytest.raises(ValueError, match="not in schema"):
        HistoryWriter(path, variables=other, resume=True)


def test_an_incomplete_last_record_is_dropped_by_the_reader(tmp_path):
    """Simulates a kill in the middle of a sync: every variable but `step` was written."""
    path = tmp_path / "h.nc"
    write_steps(path, range(3))
    with netCDF4.Dataset(path, "a") as dataset:
        dataset["mean_stress"][3] = 99.0
    assert open_history(path, drop_incomplete=False).sizes["time"] == 4
    ds = open_history(path)
    assert ds["step"].values.tolist() == [0, 1, 2]


def test_resume_drops_an_incomplete_last_record(tmp_path):
    path = tmp_path / "h.nc"
    write_steps(path, range(3))
    with netCDF4.Dataset(path, "a") as dataset:  # a kill in the middle of the 4th record
        dataset["mean_stress"][3] = 99.0
    with HistoryWriter(path, resume=True, resume_after_step=7) as writer:
        assert writer.n_records == 3
        writer.append(record(8))
    ds = open_history(path, drop_incomplete=False)
    assert ds["step"].values.tolist() == [0, 1, 2, 8]
    assert ds["mean_stress"].values.tolist() == [0, 1 / 8, 2 / 8, 1]


def test_history_variables_must_be_along_time_only():
    bad = (Variable("rod_angle", ("rod",), "radian", "angle"),)
    with pytest.raises(ValueError, match="dims"):
        HistoryWriter("unused.nc", variables=bad)


def test_every_record_needs_a_finite_time(tmp_path):
    with HistoryWriter(tmp_path / "h.nc") as writer:
        with pytest.raises(ValueError, match="'time'"):
            writer.append({"step": 1})
        with pytest.raises(ValueError, match="'time'"):
            writer.append({"step": 1, "time": float("nan")})
        assert writer.n_records == 0


LIVE_WRITER = textwrap.dedent(
    """
    import sys, time
    from dem_taichi.io import HistoryWriter
    with HistoryWriter(sys.argv[1], file_format=sys.argv[2]) as writer:
        for step in range(10**6):
            writer.append({"step": step, "time": 0.5 * step})
            if step == 30:
                print("go", flush=True)
    """
)


@pytest.mark.parametrize("file_format", FORMATS)
def test_a_history_can_be_read_while_its_writer_runs(tmp_path, file_format):
    path = tmp_path / "live.nc"
    child = subprocess.Popen(
        [sys.executable, "-c", LIVE_WRITER, str(path), file_format],
        stdout=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    try:
        assert child.stdout.readline().strip() == "go"
        ds = open_history(path)
        assert child.poll() is None  # the writer was still running
    finally:
        child.kill()
        child.wait()
        child.stdout.close()
    n = ds.sizes["time"]
    assert n >= 31
    np.testing.assert_array_equal(ds["step"].values, np.arange(n))
    np.testing.assert_array_equal(ds["time"].values, 0.5 * np.arange(n))


def test_history_names_match_the_interfaces_note():
    names = [var.name for var in HISTORY_VARIABLES]
    assert names == [
        "step", "time", "stage", "cell_length_x", "cell_length_y", "strain_xx", "strain_yy",
        "strain_rate_xx", "strain_rate_yy", "stress_xx", "stress_yy", "stress_xy", "mean_stress",
        "deviatoric_stress", "specific_volume", "void_ratio", "fabric_xx", "fabric_yy",
        "fabric_xy", "fabric_deviator", "coordination_number", "mechanical_coordination_number",
        "n_contacts", "n_long_range_pairs", "kinetic_energy", "contact_energy",
        "long_range_energy", "unbalanced_force_ratio", "inertial_number",
    ]  # fmt: skip
