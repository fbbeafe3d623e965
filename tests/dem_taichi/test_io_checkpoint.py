"""Checkpoints: exact round trip, atomic saves, clear errors, rotation."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest

from dem_taichi.io import checkpoint
from dem_taichi.io.checkpoint import (
    CheckpointError,
    checkpoint_path,
    latest_checkpoint,
    list_checkpoints,
    load_checkpoint,
    rotate_checkpoints,
    save_checkpoint,
)

ROOT = Path(__file__).resolve().parents[2]


def state_arrays(seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {
        "rod_position": rng.random((37, 2)),
        "rod_angle": rng.random(37).astype(np.float32),
        "velocity": np.array([[np.nan, np.inf], [-0.0, 5e-324]]),
        "pair_i": rng.integers(0, 2**40, 11, dtype=np.int64),
        "pair_j": rng.integers(0, 200, 11).astype(np.int32),
        "sliding": rng.random(11) > 0.5,
        "charge": np.array([1, -1, -1, -1, 1], dtype=np.int8),
        "counter": np.uint64(2**63 + 5),
        "empty": np.zeros((0, 2)),
        "labels": np.array(["A", "B_long"]),
    }


def assert_same(loaded: dict[str, np.ndarray], original: dict[str, np.ndarray]) -> None:
    assert set(loaded) == set(original)
    for name, value in original.items():
        expected = np.asarray(value)
        assert loaded[name].dtype == expected.dtype, name
        assert loaded[name].shape == expected.shape, name
        assert loaded[name].tobytes() == expected.tobytes(), name  # bit for bit (NaN, -0.0)


def test_round_trip_is_bit_exact_with_dtypes_and_meta(tmp_path):
    arrays = state_arrays(1)
    meta = {"step": 123456, "dt": 1.0e-3 / 3, "stage": "A_to_C", "nested": {"a": [1, 2.5, None]}}
    path = save_checkpoint(tmp_path / "checkpoint_000000123456.npz", arrays, meta)
    loaded, meta_back = load_checkpoint(path)
    assert_same(loaded, arrays)
    assert meta_back == meta
    assert meta_back["dt"] == 1.0e-3 / 3
    with zipfile.ZipFile(path) as archive:
        header = json.loads(np.load(archive.open("__meta__.npy")).item())
    assert header["format"] == "dem_taichi.checkpoint"
    assert header["format_version"] == checkpoint.FORMAT_VERSION


def test_a_failed_save_leaves_the_previous_checkpoint_and_no_temporary_file(tmp_path, monkeypatch):
    path = tmp_path / "checkpoint.npz"
    first = state_arrays(1)
    save_checkpoint(path, first, {"step": 1})

    def broken_savez(stream, **arrays):
        stream.write(b"PK\x03\x04 half a zip")
        raise OSError("disk full")

    monkeypatch.setattr(checkpoint.np, "savez", broken_savez)
    with pytest.raises(OSError, match="disk full"):
        save_checkpoint(path, state_arrays(2), {"step": 2})
    loaded, meta = load_checkpoint(path)
    assert_same(loaded, first)
    assert meta == {"step": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["checkpoint.npz"]


KILLED_SAVE = textwrap.dedent(
    """
    import sys, time
    import numpy as np
    from dem_taichi.io import checkpoint
    real_savez = np.savez
    def slow_savez(stream, **arrays):
        real_savez(stream, **arrays)          # the new checkpoint is written to the temp file ...
        stream.flush()
        print("writing", flush=True)          # ... and the process dies before the rename
        time.sleep(60)
    checkpoint.np.savez = slow_savez
    checkpoint.save_checkpoint(sys.argv[1], {"x": np.full(1000, 2.0)}, {"step": 2})
    """
)


def test_a_process_killed_during_a_save_leaves_the_previous_checkpoint(tmp_path):
    path = tmp_path / "checkpoint_000000000001.npz"
    save_checkpoint(path, {"x": np.full(1000, 1.0)}, {"step": 1})
    child = subprocess.Popen(
        [sys.executable, "-c", KILLED_SAVE, str(path)], stdout=subprocess.PIPE, text=True, cwd=ROOT
    )
    try:
        assert child.stdout.readline().strip() == "writing"
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
        child.stdout.close()
    arrays, meta = load_checkpoint(path)
    np.testing.assert_array_equal(arrays["x"], np.full(1000, 1.0))
    assert meta == {"step": 1}
    leftovers = [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
    assert len(leftovers) == 1  # the half-done save; rotation cleans it up
    rotate_checkpoints(tmp_path, keep=2)
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def test_missing_file_fails_clearly(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_checkpoint(tmp_path / "nope.npz")


def test_truncated_file_is_reported_as_corrupt(tmp_path):
    path = save_checkpoint(tmp_path / "c.npz", state_arrays(3), {"step": 3})
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="corrupt"):
        load_checkpoint(path)


def test_flipped_byte_is_reported_as_corrupt(tmp_path):
    path = save_checkpoint(tmp_path / "c.npz", {"x": np.arange(4096, dtype=np.float64)}, {})
    data = bytearray(path.read_bytes())
    data[len(data) // 3] ^= 0xFF  # inside the array's data: the zip CRC-32 catches it
    path.write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match="corrupt"):
        load_checkpoint(path)


def test_a_plain_npz_is_not_a_checkpoint(tmp_path):
    path = tmp_path / "plain.npz"
    np.savez(path, x=np.zeros(3))
    with pytest.raises(CheckpointError, match="not a dem_taichi checkpoint"):
        load_checkpoint(path)


def test_a_newer_format_version_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(checkpoint, "FORMAT_VERSION", checkpoint.FORMAT_VERSION + 1)
    path = save_checkpoint(tmp_path / "c.npz", {"x": np.zeros(2)}, {})
    monkeypatch.setattr(checkpoint, "FORMAT_VERSION", checkpoint.FORMAT_VERSION - 1)
    with pytest.raises(CheckpointError, match="format version"):
        load_checkpoint(path)


@pytest.mark.parametrize(
    ("arrays", "meta", "error", "words"),
    [
        ({"x": np.array([object()])}, {}, TypeError, "no pickles"),
        ({"__meta__": np.zeros(1)}, {}, ValueError, "not allowed"),
        ({"a b": np.zeros(1)}, {}, ValueError, "not allowed"),
        ({"allow_pickle": np.zeros(1)}, {}, ValueError, "not allowed"),  # np.savez's keywords
        ({"file": np.zeros(1)}, {}, ValueError, "not allowed"),
        ({"x": np.zeros(1)}, {"bad": object()}, TypeError, "JSON"),
    ],
)
def test_invalid_input_fails_before_writing(tmp_path, arrays, meta, error, words):
    with pytest.raises(error, match=words):
        save_checkpoint(tmp_path / "c.npz", arrays, meta)
    assert list(tmp_path.iterdir()) == []


def test_rotation_keeps_the_latest_steps(tmp_path):
    for step in (5, 100, 20, 1000):
        save_checkpoint(checkpoint_path(tmp_path, step), {"x": np.array([step])}, {"step": step})
    (tmp_path / "history.nc").write_text("not a checkpoint")
    assert [p.name for p in list_checkpoints(tmp_path)] == [
        "checkpoint_000000000005.npz",
        "checkpoint_000000000020.npz",
        "checkpoint_000000000100.npz",
        "checkpoint_000000001000.npz",
    ]
    removed = rotate_checkpoints(tmp_path, keep=2)
    assert sorted(p.name for p in removed) == [
        "checkpoint_000000000005.npz",
        "checkpoint_000000000020.npz",
    ]
    assert latest_checkpoint(tmp_path) == checkpoint_path(tmp_path, 1000)
    assert load_checkpoint(latest_checkpoint(tmp_path))[1] == {"step": 1000}
    assert (tmp_path / "history.nc").exists()
    assert latest_checkpoint(tmp_path / "missing") is None
    with pytest.raises(ValueError, match="keep"):
        rotate_checkpoints(tmp_path, keep=0)


def _write_header(path: Path, header) -> None:
    """An archive shaped like a checkpoint whose JSON header is ``header``."""
    with open(path, "wb") as stream:
        np.savez(stream, x=np.zeros(2), __meta__=np.array(json.dumps(header)))


@pytest.mark.parametrize(
    "header",
    [
        {"format": "dem_taichi.checkpoint", "format_version": 1, "arrays": [], "meta": {}},
        {"format": "dem_taichi.checkpoint", "format_version": 1, "arrays": {"x": 3}, "meta": {}},
        {"format": "dem_taichi.checkpoint", "format_version": 1, "arrays": {}, "meta": []},
        ["a", "list"],
    ],
    ids=["arrays a list", "array spec a number", "meta a list", "header a list"],
)
def test_a_malformed_header_is_reported_as_corrupt(tmp_path, header):
    """Headers that are JSON but not a checkpoint's: CheckpointError, never a TypeError or
    AttributeError (which the command line would report as an internal error)."""
    path = tmp_path / "c.npz"
    _write_header(path, header)
    with pytest.raises(CheckpointError, match=str(path)):
        load_checkpoint(path)


def test_an_npy_file_is_not_a_checkpoint(tmp_path):
    path = tmp_path / "c.npz"
    with open(path, "wb") as stream:
        np.save(stream, np.arange(3))
    with pytest.raises(CheckpointError, match="not an .npz archive"):
        load_checkpoint(path)
    with pytest.raises(CheckpointError, match="not an .npz archive"):
        checkpoint.checkpoint_meta(path)


def _damage_middle(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[len(data) // 3] ^= 0xFF  # inside the array's data: the CRC-32 no longer fits
    path.write_bytes(bytes(data))


@pytest.mark.parametrize(
    "damage",
    [
        _damage_middle,
        lambda p: p.write_bytes(p.read_bytes()[:100]),
        lambda p: p.write_bytes(b""),
    ],
    ids=["flipped byte", "truncated", "empty"],
)
def test_a_damaged_newest_checkpoint_falls_back_to_the_older_one(tmp_path, damage):
    older, newest = (
        save_checkpoint(checkpoint_path(tmp_path, step), {"x": np.arange(4096.0) + step}, {})
        for step in (100, 200)
    )
    damage(newest)
    said: list[str] = []
    assert checkpoint.latest_intact_checkpoint(list_checkpoints(tmp_path), said.append) == older
    assert len(said) == 1 and "\n" not in said[0]
    assert str(newest) in said[0] and f"falling back to {older}" in said[0]
    assert load_checkpoint(older)[0]["x"][0] == 100.0


def test_no_intact_checkpoint_gives_none_and_names_each_damaged_one(tmp_path):
    paths = [save_checkpoint(checkpoint_path(tmp_path, s), {"x": np.zeros(9)}, {}) for s in (1, 2)]
    for path in paths:
        path.write_bytes(b"garbage")
    said: list[str] = []
    assert checkpoint.latest_intact_checkpoint(paths, said.append) is None
    assert [str(p) in line for p, line in zip(reversed(paths), said, strict=True)] == [True, True]
    assert said[-1].endswith("no older checkpoint to use")
    assert checkpoint.latest_intact_checkpoint([], said.append) is None


def test_an_intact_newest_checkpoint_is_used_without_a_word(tmp_path):
    paths = [save_checkpoint(checkpoint_path(tmp_path, s), {"x": np.zeros(9)}, {}) for s in (1, 2)]
    said: list[str] = []
    assert checkpoint.latest_intact_checkpoint(paths, said.append) == paths[-1]
    assert said == []
