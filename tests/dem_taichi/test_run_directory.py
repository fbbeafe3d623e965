"""Run directories (issue 11): one run per --out, resume of the same scene only, per-run
checkpoint rotation, and Ctrl-C writing a checkpoint that a resume continues bit for bit."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from dem_taichi.io import checkpoint_meta, latest_checkpoint, load_checkpoint, open_history
from dem_taichi.io.checkpoint import checkpoint_path, save_checkpoint
from dem_taichi.io.run_directory import (
    RUN_RECORD,
    RunDirectoryError,
    resume_run,
    scene_sha256,
    start_run,
)
from dem_taichi.scene.config import load_scene, scene_to_toml

ROOT = Path(__file__).resolve().parents[2]
SMOKE = scene_to_toml(load_scene("smoke"))
OTHER = scene_to_toml(load_scene("smoke").replace(scene={"seed": 2}))


def fake_checkpoint(folder: Path, step: int, scene_toml: str = SMOKE) -> Path:
    arrays = {"angle": np.zeros(3)}
    return save_checkpoint(checkpoint_path(folder, step), arrays, {"scene_toml": scene_toml})


def scene_of(path: Path) -> str:
    return checkpoint_meta(path)["scene_toml"]


# ---- the rules, on the run-directory layer alone (no engine) -----------------------------------


def test_a_fresh_run_writes_its_record(tmp_path):
    run = start_run(tmp_path / "out", "run", "smoke", SMOKE)
    record = json.loads((tmp_path / "out" / RUN_RECORD).read_text())
    assert record["run_id"] == run.run_id and len(run.run_id) == 32
    assert record["scene_sha256"] == scene_sha256(SMOKE)
    assert record["checkpoints"] == []


def test_a_directory_with_other_files_is_not_used(tmp_path):
    (tmp_path / "my_scene.toml").write_text(SMOKE)
    start_run(tmp_path, "protocol", "smoke", SMOKE)  # a scene file beside the outputs is fine


@pytest.mark.parametrize("marker", [RUN_RECORD, "history.nc", "checkpoints"])
def test_a_used_directory_is_refused(tmp_path, marker):
    (tmp_path / marker).mkdir() if marker == "checkpoints" else (tmp_path / marker).write_text("x")
    with pytest.raises(RunDirectoryError, match="already holds .* --overwrite"):
        start_run(tmp_path, "protocol", "smoke", SMOKE)


def test_overwrite_removes_the_old_run_and_keeps_other_files(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    old = start_run(tmp_path, "run", "smoke", SMOKE)
    old.add_checkpoint(fake_checkpoint(old.checkpoint_dir, 9000))
    (tmp_path / "history.nc").write_text("old")
    (tmp_path / "configuration_A.nc").write_text("old")
    old.close()  # lists what the run wrote without registering it, releases the lock
    with pytest.raises(RunDirectoryError, match="or --resume to continue it"):
        start_run(tmp_path, "run", "smoke", SMOKE, resume_hint=True)
    new = start_run(tmp_path, "run", "smoke", SMOKE, overwrite=True)
    assert new.run_id != old.run_id
    assert not (tmp_path / "checkpoints").exists() and not (tmp_path / "history.nc").exists()
    assert not (tmp_path / "configuration_A.nc").exists()
    assert (tmp_path / "notes.txt").read_text() == "mine"


def test_rotation_touches_only_the_runs_own_checkpoints(tmp_path):
    run = start_run(tmp_path, "run", "smoke", SMOKE)
    stranger = fake_checkpoint(run.checkpoint_dir, 99_000)  # not written by this run
    for step in (1000, 2000, 3000):
        run.add_checkpoint(fake_checkpoint(run.checkpoint_dir, step))
    assert stranger.exists()
    assert not checkpoint_path(run.checkpoint_dir, 1000).exists()
    assert run.record.checkpoints == [p.name for p in map(
        lambda s: checkpoint_path(run.checkpoint_dir, s), (2000, 3000))]  # fmt: skip
    assert run.latest_checkpoint() == checkpoint_path(run.checkpoint_dir, 3000)
    # the record on disk lists the same checkpoints
    on_disk = json.loads((tmp_path / RUN_RECORD).read_text())["checkpoints"]
    assert on_disk == run.record.checkpoints


def test_resume_refuses_another_scene(tmp_path):
    run = start_run(tmp_path, "run", "smoke", SMOKE)
    run.add_checkpoint(fake_checkpoint(run.checkpoint_dir, 1000))
    run.close()
    with pytest.raises(RunDirectoryError, match="is not the scene of run"):
        resume_run(tmp_path, "other", OTHER, scene_of)
    again, latest = resume_run(tmp_path, "smoke", SMOKE, scene_of)
    assert again.run_id == run.run_id and latest.name.endswith("1000.npz")


def test_resume_refuses_a_checkpoint_of_another_scene(tmp_path):
    run = start_run(tmp_path, "run", "smoke", SMOKE)
    run.add_checkpoint(fake_checkpoint(run.checkpoint_dir, 1000, scene_toml=OTHER))
    run.close()
    with pytest.raises(RunDirectoryError, match="holds another scene"):
        resume_run(tmp_path, "smoke", SMOKE, scene_of)


def test_resume_of_nothing_is_refused(tmp_path):
    with pytest.raises(RunDirectoryError, match="no run to continue"):
        resume_run(tmp_path / "empty", "smoke", SMOKE, scene_of)
    start_run(tmp_path / "new", "run", "smoke", SMOKE).close()
    with pytest.raises(RunDirectoryError, match="has no checkpoint yet"):
        resume_run(tmp_path / "new", "smoke", SMOKE, scene_of)


def test_a_directory_from_before_run_records_is_adopted_for_its_own_scene(tmp_path):
    fake_checkpoint(tmp_path / "checkpoints", 500)
    with pytest.raises(RunDirectoryError, match="is not the scene"):
        resume_run(tmp_path, "other", OTHER, scene_of)
    run, latest = resume_run(tmp_path, "smoke", SMOKE, scene_of)
    assert (tmp_path / RUN_RECORD).exists() and latest.name.endswith("500.npz")


# ---- the command line ----------------------------------------------------------------------


def test_cli_refuses_a_used_directory_and_another_scene(tmp_path, capsys):
    from dem_taichi.cli.commands import main

    out = tmp_path / "run"
    assert main(["run", "smoke", "--out", str(out), "--steps", "600", "--no-progress"]) == 0
    first = json.loads((out / RUN_RECORD).read_text())["run_id"]
    capsys.readouterr()
    assert main(["run", "smoke", "--out", str(out), "--steps", "600"]) == 2
    err = capsys.readouterr().err
    assert "already holds run" in err and "--overwrite" in err and "--resume" in err
    other = tmp_path / "other.toml"
    other.write_text(OTHER)
    assert main(["run", str(other), "--out", str(out), "--steps", "900", "--resume"]) == 2
    assert "is not the scene of run" in capsys.readouterr().err
    assert main(["run", "smoke", "--out", str(out), "--resume", "--overwrite"]) == 2
    assert "exclude each other" in capsys.readouterr().err
    assert main(["run", "smoke", "--out", str(out), "--steps", "500", "--overwrite"]) == 0
    record = json.loads((out / RUN_RECORD).read_text())
    assert record["run_id"] != first
    assert record["checkpoints"] == ["checkpoint_000000000500.npz"]
    assert open_history(out / "history.nc").attrs["run_id"] == record["run_id"]


def _slow_smoke(tmp_path: Path) -> Path:
    """The smoke scene compressed 50x slower (~260,000 steps), checkpoints every 2000 steps."""
    scene = load_scene("smoke").replace(
        control={"compression_strain_rate": 0.002}, output={"checkpoint_every": 2000}
    )
    path = tmp_path / "slow_smoke.toml"
    path.write_text(scene_to_toml(scene))
    return path


def test_interrupt_writes_a_checkpoint_and_resume_continues_bitwise(tmp_path):
    from dem_taichi.cli.commands import main

    scene = _slow_smoke(tmp_path)
    out = tmp_path / "interrupted"
    command = [sys.executable, "-m", "dem_taichi", "run", str(scene), "--out", str(out)]
    proc = subprocess.Popen(
        [*command, "--no-progress"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
    )
    try:
        deadline = time.monotonic() + 600
        while latest_checkpoint(out / "checkpoints") is None:
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no checkpoint within 600 s"
            time.sleep(0.2)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert not (out / "run.lock").exists()  # released on SIGINT (issue 22)
    last = err.strip().splitlines()[-1]
    assert "interrupted by SIGINT at step" in last and "--resume" in last, err
    stopped = int(checkpoint_meta(latest_checkpoint(out / "checkpoints"))["step"])
    # a checkpoint at the output step after the signal (2000 itself when it came right there)
    assert stopped >= 2000 and stopped % 500 == 0, err
    assert f"at step {stopped}:" in last
    end = str(stopped + 1500)
    assert main(["run", str(scene), "--out", str(out), "--steps", end, "--resume"]) == 0
    straight = tmp_path / "straight"
    assert main(["run", str(scene), "--out", str(straight), "--steps", end, "--no-progress"]) == 0
    a, _ = load_checkpoint(latest_checkpoint(straight / "checkpoints"))
    b, _ = load_checkpoint(latest_checkpoint(out / "checkpoints"))
    assert a.keys() == b.keys()
    for key in a:
        assert np.array_equal(a[key], b[key]), key
    resumed, reference = open_history(out / "history.nc"), open_history(straight / "history.nc")
    common = np.intersect1d(resumed["step"].values, reference["step"].values)
    assert common[-1] == stopped + 1500
    r = resumed.set_index(time="step").sel(time=common)
    s = reference.set_index(time="step").sel(time=common)
    for name in ("mean_stress", "specific_volume", "coordination_number"):
        assert np.array_equal(r[name].values, s[name].values), name


def test_cli_resume_falls_back_past_a_damaged_newest_checkpoint(tmp_path, capsys):
    """Issue 22: a damaged newest checkpoint (a flipped byte) does not stop ``run --resume``:
    it continues from the older intact one and says so in one line naming both."""
    from dem_taichi.cli.commands import main

    scene = tmp_path / "smoke.toml"
    scene.write_text(scene_to_toml(load_scene("smoke").replace(output={"checkpoint_every": 200})))
    out = tmp_path / "run"
    assert main(["run", str(scene), "--out", str(out), "--steps", "600", "--no-progress"]) == 0
    record = json.loads((out / RUN_RECORD).read_text())
    older, newest = (out / "checkpoints" / name for name in record["checkpoints"])
    assert older.name.endswith("400.npz") and newest.name.endswith("600.npz")
    data = bytearray(newest.read_bytes())
    data[len(data) // 2] ^= 0xFF  # inside an array's data: its CRC fails
    newest.write_bytes(bytes(data))
    capsys.readouterr()
    argv = ["run", str(scene), "--out", str(out), "--steps", "800", "--resume", "--no-progress"]
    assert main(argv) == 0
    captured = capsys.readouterr()
    notes = [line for line in captured.err.splitlines() if str(newest) in line]
    assert len(notes) == 1 and f"falling back to {older}" in notes[0], captured.err
    assert f"resuming from {older} at step 400" in captured.out
    assert load_checkpoint(latest_checkpoint(out / "checkpoints"))[1]["step"] == 800


# ---- run_protocol holds its folder's lock only while it runs ------------------------------


def test_run_protocol_releases_its_lock_when_it_raises_and_when_it_returns(tmp_path, monkeypatch):
    """Issue 22: the protocol's run folder was released only at garbage collection (a caught
    error's traceback kept it locked); now when run_protocol raises or returns, without
    gc.collect() (the collector is off here)."""
    import gc

    from dem_taichi.protocol.paths import ProtocolRunner
    from dem_taichi.protocol.runner import run_protocol

    from .test_protocol import smoke_protocol_scene

    def stop(runner):
        raise RuntimeError("made to fail")

    # only the compression to A: a run that returns is all this needs (the paths from A add
    # nothing to how the folder is released)
    scene = smoke_protocol_scene(
        run_isotropic=False, run_k0=False, run_unloading=False, radial_stress_ratios=""
    )
    enabled = gc.isenabled()
    gc.disable()
    try:
        with monkeypatch.context() as patch:
            patch.setattr(ProtocolRunner, "compress_to_transition", stop)
            with pytest.raises(RuntimeError, match="made to fail") as raised:
                run_protocol(scene, tmp_path / "raises")
        assert raised.value is not None  # the traceback (and its frames) still alive
        assert (tmp_path / "raises" / RUN_RECORD).exists()
        assert not (tmp_path / "raises" / "run.lock").exists()
        result = run_protocol(scene, tmp_path / "returns")
        assert result.states and (tmp_path / "returns" / "summary.json").exists()
        assert not (tmp_path / "returns" / "run.lock").exists()
        listed = json.loads((tmp_path / "returns" / RUN_RECORD).read_text())["files"]
        assert {"summary.json", "history.nc", "report.md"} <= set(listed)
    finally:
        if enabled:
            gc.enable()
