"""Run folders that are safe to share and to reuse (issue 22): the manifest, --overwrite deleting
exactly what a run wrote, the lock, no writing through links, existing outputs refused, and a
full disk as its own exit code.

Every deletion case puts a SENTINEL file where it must survive. DEM runs are the smoke scene cut
to a few hundred steps (a few seconds each); the bridge's cases are in
tests/bridge/test_outputs_safety.py.
"""

from __future__ import annotations

import errno
import gc
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from clay_cli import EXIT_DISK_FULL, EXIT_USAGE, run_command
from dem_taichi.io.run_directory import (
    RUN_LOCK,
    RUN_RECORD,
    RunDirectoryError,
    RunLockedError,
    start_run,
)
from dem_taichi.scene.config import load_scene, scene_to_toml
from tests.sentinels import one_line, sentinel, survived

ROOT = Path(__file__).resolve().parents[1]
SMOKE = scene_to_toml(load_scene("smoke"))


def dem(*args: str) -> int:
    """``python -m dem_taichi ARGS`` in this process."""
    from dem_taichi.cli.commands import main

    return main(list(args))


def smoke_run(out: Path, *extra: str, steps: str = "500") -> int:
    return dem("run", "smoke", "--out", str(out), "--steps", steps, "--no-progress", "--quiet",
               *extra)  # fmt: skip


def manifest(out: Path) -> dict:
    return json.loads((out / RUN_RECORD).read_text())


def every_entry(out: Path) -> set[str]:
    found = set()
    for root, dirs, names in os.walk(out):
        for name in [*dirs, *names]:
            found.add((Path(root) / name).relative_to(out).as_posix())
    return found


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    """A finished smoke run (500 steps, with ParaView files) to copy from and snapshot."""
    out = tmp_path_factory.mktemp("finished") / "run"
    assert smoke_run(out, "--paraview") == 0
    return out


# ---- the manifest and what --overwrite deletes ------------------------------------------------


def test_the_manifest_lists_every_file_the_run_wrote_and_nothing_else(tmp_path):
    out = tmp_path / "run"
    mine = sentinel(out / "notes.txt")
    assert smoke_run(out, "--paraview") == 0
    record = manifest(out)
    listed = set(record["files"]) | set(record["folders"])
    assert listed == every_entry(out) - {"notes.txt"}
    assert "scene.toml" in listed and "history.nc" in listed and "paraview/run.pvd" in listed
    assert not (out / RUN_LOCK).exists()
    assert survived(mine)


def test_a_run_folder_named_like_a_run_subfolder_lists_true_paths(tmp_path):
    out = tmp_path / "checkpoints"  # the run's folder has the name of one of its subfolders
    assert smoke_run(out, "--paraview") == 0
    record = manifest(out)
    assert set(record["files"]) | set(record["folders"]) == every_entry(out)
    assert "checkpoints/checkpoint_000000000500.npz" in record["files"]


def test_overwrite_deletes_the_manifest_only(tmp_path):
    out = tmp_path / "run"
    assert smoke_run(out, "--paraview") == 0
    outside = sentinel(tmp_path / "outside.txt")
    inside = sentinel(out / "notes.txt")
    named_like_a_run = sentinel(out / "figure_mine.png")  # a run's name, not the run's file
    in_a_run_folder = sentinel(out / "paraview" / "my_view.pvsm")
    old_id = manifest(out)["run_id"]
    assert smoke_run(out, "--overwrite", steps="400") == 0
    assert manifest(out)["run_id"] != old_id
    assert not list((out / "paraview").glob("*.vtu"))  # the old run's ParaView files went
    assert survived(outside, inside, named_like_a_run, in_a_run_folder)
    assert "figure_mine.png" not in manifest(out)["files"]


def test_overwrite_of_a_foreign_folder_with_checkpoints_is_refused(tmp_path, capsys):
    out = tmp_path / "foreign"
    kept = [sentinel(out / "checkpoints" / "mine.txt"), sentinel(out / "report.md"),
            sentinel(out / "paraview" / "x.vtu")]  # fmt: skip
    assert smoke_run(out, "--overwrite") == EXIT_USAGE
    line = one_line(capsys.readouterr().err)
    assert "no run.json" in line and "nothing is deleted" in line
    assert survived(*kept)


@pytest.mark.parametrize("command", ["run", "protocol"])
def test_a_fresh_run_never_replaces_a_file_with_a_run_name(tmp_path, capsys, command):
    out = tmp_path / "mine"
    report = sentinel(out / "report.md")  # e.g. the user's own notes, in a folder without a run
    assert dem(command, "smoke", "--out", str(out), "--quiet") == EXIT_USAGE
    line = one_line(capsys.readouterr().err)
    assert "already holds files with the names a run writes (report.md) but no run.json" in line
    assert survived(report) and not (out / RUN_RECORD).exists()


def test_overwrite_of_a_record_from_before_manifests_is_refused(tmp_path, capsys):
    out = tmp_path / "old"
    run = start_run(out, "run", "smoke", SMOKE)
    run.close()
    record = manifest(out)
    del record["files"]
    (out / RUN_RECORD).write_text(json.dumps(record))
    kept = sentinel(out / "history.nc")
    assert smoke_run(out, "--overwrite") == EXIT_USAGE
    assert "from before runs listed their files" in one_line(capsys.readouterr().err)
    assert survived(kept)


def test_a_manifest_naming_a_path_outside_the_run_is_refused(tmp_path, capsys):
    out = tmp_path / "run"
    start_run(out, "run", "smoke", SMOKE).close()
    outside = sentinel(tmp_path / "outside.txt")
    record = manifest(out)
    record["files"].append("../outside.txt")
    (out / RUN_RECORD).write_text(json.dumps(record))
    assert smoke_run(out, "--overwrite") == EXIT_USAGE
    assert "not a path inside" in one_line(capsys.readouterr().err)
    assert survived(outside)


@pytest.mark.parametrize("command", ["run", "protocol"])
def test_an_empty_out_is_refused(tmp_path, monkeypatch, capsys, command):
    monkeypatch.chdir(tmp_path)
    here = sentinel(tmp_path / "report.md")
    sentinel(tmp_path / "checkpoints" / "x.npz")
    assert dem(command, "smoke", "--out", "", "--overwrite", "--quiet") == EXIT_USAGE
    assert "--out is empty" in one_line(capsys.readouterr().err)
    assert survived(here)


@pytest.mark.parametrize("command", ["run", "protocol"])
def test_overwrite_of_the_current_folder_is_refused(tmp_path, monkeypatch, capsys, command):
    monkeypatch.chdir(tmp_path)
    start_run(tmp_path, "run", "smoke", SMOKE).close()  # even a real run folder
    here = sentinel(tmp_path / "notes.txt")
    assert dem(command, "smoke", "--out", ".", "--overwrite", "--quiet") == EXIT_USAGE
    assert "is the current folder" in one_line(capsys.readouterr().err)
    assert survived(here) and (tmp_path / RUN_RECORD).exists()


def test_overwrite_of_the_home_folder_and_above_is_refused(tmp_path, monkeypatch, capsys):
    home = tmp_path / "home"
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(tmp_path.parent)
    start_run(home, "run", "smoke", SMOKE).close()
    mine = sentinel(home / "thesis.tex")
    assert smoke_run(home, "--overwrite") == EXIT_USAGE
    assert "is your home folder" in one_line(capsys.readouterr().err)
    with pytest.raises(RunDirectoryError, match="above"):
        start_run(tmp_path, "run", "smoke", SMOKE, overwrite=True)  # a folder above home
    with pytest.raises(RunDirectoryError, match="refused"):
        start_run("/", "run", "smoke", SMOKE, overwrite=True)
    assert survived(mine)


def test_a_run_dropped_without_closing_lists_what_it_wrote(tmp_path, capsys):
    """The protocol's writers do not register their files: the run lists them when it is
    closed (here by garbage collection, the last resort of a run never closed; run_protocol
    closes its run when it returns or raises)."""
    out = tmp_path / "run"
    run = start_run(out, "protocol", "smoke", SMOKE)
    (out / "configuration_A.nc").write_text("written by the run")
    (out / "resume").mkdir()
    (out / "resume" / "A.npz").write_text("written by the run")
    del run
    gc.collect()
    assert not (out / RUN_LOCK).exists()
    record = manifest(out)
    assert {"configuration_A.nc", "resume/A.npz"} <= set(record["files"])
    kept = sentinel(out / "resume" / "my_notes.txt")  # put there after the run
    start_run(out, "protocol", "smoke", SMOKE, overwrite=True).close()
    assert not (out / "configuration_A.nc").exists() and not (out / "resume" / "A.npz").exists()
    assert survived(kept)
    assert "kept resume" in capsys.readouterr().err


# ---- links ----------------------------------------------------------------------------------


def test_a_link_where_the_run_writes_is_refused_and_its_target_unchanged(tmp_path, capsys):
    target = sentinel(tmp_path / "elsewhere" / "precious.toml")
    out = tmp_path / "run"
    out.mkdir()
    (out / "scene.toml").symlink_to(target)
    assert smoke_run(out) == EXIT_USAGE
    line = one_line(capsys.readouterr().err)
    assert "scene.toml is a symbolic link" in line and "remove the link" in line
    assert survived(target) and (out / "scene.toml").is_symlink()
    assert not (out / RUN_LOCK).exists()


def test_a_linked_output_folder_is_refused(tmp_path, capsys):
    elsewhere = tmp_path / "elsewhere"
    kept = sentinel(elsewhere / "checkpoint_000000000500.npz")
    out = tmp_path / "run"
    start_run(out, "run", "smoke", SMOKE).close()
    (out / "checkpoints").symlink_to(elsewhere, target_is_directory=True)
    assert smoke_run(out, "--overwrite") == EXIT_USAGE
    assert "checkpoints is a symbolic link" in one_line(capsys.readouterr().err)
    assert survived(kept)


def test_a_linked_lock_is_refused(tmp_path):
    target = sentinel(tmp_path / "precious.txt")
    out = tmp_path / "run"
    out.mkdir()
    (out / RUN_LOCK).symlink_to(target)
    with pytest.raises(RunDirectoryError, match="run.lock is a symbolic link"):
        start_run(out, "run", "smoke", SMOKE)
    assert survived(target)


# ---- the lock -------------------------------------------------------------------------------


def fake_lock(out: Path, pid: int, host: str | None = None) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    data = {"pid": pid, "host": host or socket.gethostname(), "started": "2026-01-01T00:00:00Z",
            "command": "run", "token": "fake"}  # fmt: skip
    path = out / RUN_LOCK
    path.write_text(json.dumps(data))
    return path


def dead_pid() -> int:
    done = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)  # fmt: skip
    return int(done.stdout)


def test_a_lock_of_a_live_process_refuses_a_run_and_overwrite(tmp_path, capsys):
    out = tmp_path / "run"
    start_run(out, "run", "smoke", SMOKE).close()
    history = sentinel(out / "history.nc")
    fake_lock(out, os.getpid())
    for extra in ((), ("--overwrite",), ("--resume",)):
        assert smoke_run(out, *extra) == EXIT_USAGE
        line = one_line(capsys.readouterr().err)
        assert f"PID {os.getpid()}" in line and str(out / RUN_LOCK) in line and "in use" in line
    assert survived(history)
    assert json.loads((out / RUN_LOCK).read_text())["token"] == "fake"  # left alone


def test_a_second_claim_of_an_open_run_is_refused(tmp_path):
    out = tmp_path / "run"
    run = start_run(out, "run", "smoke", SMOKE)
    with pytest.raises(RunLockedError, match=f"held by running PID {os.getpid()}"):
        start_run(out, "run", "smoke", SMOKE, overwrite=True)
    assert (out / RUN_RECORD).exists() and manifest(out)["run_id"] == run.run_id
    run.close()
    assert not (out / RUN_LOCK).exists()


def test_a_lock_of_another_host_or_unreadable_is_refused(tmp_path):
    fake_lock(tmp_path / "a", 1, host="another-machine.example")
    with pytest.raises(RunLockedError, match="another-machine.example.*, not this host"):
        start_run(tmp_path / "a", "run", "smoke", SMOKE)
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / RUN_LOCK).write_text("{half a lock")
    with pytest.raises(RunLockedError, match="not a readable lock"):
        start_run(tmp_path / "b", "run", "smoke", SMOKE)


def test_a_stale_lock_is_taken_over_with_a_note(tmp_path, capsys):
    out = tmp_path / "run"
    run = start_run(out, "protocol", "smoke", SMOKE)
    run.lock.release()  # as if the process had been killed: no close, the lock left behind
    run._finalizer.detach()
    (out / "configuration_A.nc").write_text("written by the dead run")
    kept = sentinel(out / "notes.txt")
    pid = dead_pid()
    fake_lock(out, pid)
    start_run(out, "protocol", "smoke", SMOKE, overwrite=True).close()
    err = capsys.readouterr().err
    assert f"took over the stale lock {out / RUN_LOCK}" in err and f"PID {pid}" in err
    assert not (out / "configuration_A.nc").exists()  # the dead run's manifest was completed
    assert survived(kept) and not (out / RUN_LOCK).exists()


def test_a_live_second_process_is_refused_until_it_ends(tmp_path, capsys):
    out = tmp_path / "run"
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys\nfrom dem_taichi.io.run_directory import start_run\n"
         f"run = start_run(sys.argv[1], 'run', 'smoke', {SMOKE!r})\nprint('ready', flush=True)\n"
         "sys.stdin.read()\n", str(out)],
        cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "ready"
        assert smoke_run(out, "--overwrite") == EXIT_USAGE
        assert f"held by running PID {holder.pid}" in one_line(capsys.readouterr().err)
        holder.stdin.close()  # the holder ends normally: its lock is released at exit
        assert holder.wait(timeout=60) == 0
    finally:
        if holder.poll() is None:
            holder.kill()
    assert not (out / RUN_LOCK).exists()
    assert smoke_run(out, "--overwrite") == 0


def test_the_lock_is_released_after_an_error(tmp_path, monkeypatch, capsys):
    import dem_taichi.cli.commands as cli

    def broken(*args, **kwargs):
        raise ValueError("a writer failed")

    monkeypatch.setattr(cli, "replace_file", broken)
    out = tmp_path / "run"
    assert smoke_run(out) == EXIT_USAGE
    assert "a writer failed" in one_line(capsys.readouterr().err)
    assert not (out / RUN_LOCK).exists() and (out / RUN_RECORD).exists()


def test_sigterm_stops_the_run_and_releases_the_lock(tmp_path):
    scene = load_scene("smoke").replace(
        control={"compression_strain_rate": 0.002}, output={"checkpoint_every": 500}
    )
    path = tmp_path / "slow.toml"
    path.write_text(scene_to_toml(scene))
    out = tmp_path / "run"
    proc = subprocess.Popen(
        [sys.executable, "-m", "dem_taichi", "run", str(path), "--out", str(out), "--quiet"],
        cwd=ROOT, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 300
        while not list((out / "checkpoints").glob("*.npz")):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no checkpoint within 300 s"
            time.sleep(0.2)
        assert json.loads((out / RUN_LOCK).read_text())["pid"] == proc.pid
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert not (out / RUN_LOCK).exists()
    assert set(manifest(out)["files"]) >= {"history.nc", "scene.toml", RUN_RECORD}


# ---- existing outputs of the one-file commands ---------------------------------------------


def test_snapshot_refuses_an_existing_file_unless_overwrite(tmp_path, finished_run, capsys):
    checkpoint = next((finished_run / "checkpoints").glob("*.npz"))
    target = sentinel(tmp_path / "discs.vtu")
    assert dem("snapshot", str(checkpoint), "--out", str(target), "--quiet") == EXIT_USAGE
    assert "exists; add --overwrite" in one_line(capsys.readouterr().err)
    assert survived(target)
    assert dem("snapshot", str(checkpoint), "--out", str(target), "--overwrite", "--quiet") == 0
    assert "<VTKFile" in target.read_text()
    assert [p.name for p in tmp_path.iterdir()] == ["discs.vtu"]  # no temporary left


def test_snapshot_overwrite_replaces_a_link_not_its_target(tmp_path, finished_run):
    checkpoint = next((finished_run / "checkpoints").glob("*.npz"))
    precious = sentinel(tmp_path / "elsewhere" / "precious.vtu")
    link = tmp_path / "discs.vtu"
    link.symlink_to(precious)
    assert dem("snapshot", str(checkpoint), "--out", str(link), "--overwrite", "--quiet") == 0
    assert survived(precious) and not link.is_symlink()


def tiv(*args: str) -> int:
    from tiv_model.cli import main

    return main(list(args))


def test_tiv_model_refuses_an_existing_out_unless_overwrite(tmp_path, capsys):
    target = sentinel(tmp_path / "iso.nc")
    path = ("isotropic", "--p-max", "50", "--increments", "3", "--quiet", "--out", str(target))
    assert tiv(*path) == EXIT_USAGE
    assert "iso.nc exists; add --overwrite" in one_line(capsys.readouterr().err)
    assert survived(target)
    assert tiv(*path, "--overwrite") == 0
    import xarray as xr

    with xr.open_dataset(target) as ds:
        assert ds.sizes["step"] == 4


def test_tiv_model_overwrite_replaces_a_link_not_its_target(tmp_path):
    precious = sentinel(tmp_path / "elsewhere" / "precious.nc")
    link = tmp_path / "iso.nc"
    link.symlink_to(precious)
    assert tiv("isotropic", "--p-max", "50", "--increments", "3", "--quiet", "--out", str(link),
               "--overwrite") == 0  # fmt: skip
    assert survived(precious) and not link.is_symlink()


# ---- a full disk ----------------------------------------------------------------------------


def no_space(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device", "history.nc")


def test_a_full_disk_in_a_dem_run_is_exit_code_4(tmp_path, monkeypatch, capsys):
    import dem_taichi.cli.commands as cli

    monkeypatch.setattr(cli, "replace_file", no_space)
    out = tmp_path / "run"
    assert smoke_run(out) == EXIT_DISK_FULL == 4
    line = one_line(capsys.readouterr().err)
    assert line.startswith("python -m dem_taichi: error: disk full: history.nc: No space left")
    assert not (out / RUN_LOCK).exists()


def test_a_full_disk_in_tiv_model_is_exit_code_4_and_leaves_no_file(tmp_path, monkeypatch,
                                                                    capsys):  # fmt: skip
    import xarray as xr

    monkeypatch.setattr(xr.Dataset, "to_netcdf", no_space)
    target = tmp_path / "iso.nc"
    assert tiv("isotropic", "--p-max", "50", "--increments", "3", "--out", str(target)) == 4
    assert "tiv-model: error: disk full:" in one_line(capsys.readouterr().err)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("error", "code"),
    [
        (OSError(errno.ENOSPC, "No space left on device", "f.nc"), 4),
        (OSError(errno.EDQUOT, "Disk quota exceeded", "f.nc"), 4),
        (RuntimeError("NetCDF: HDF error"), 1),
        (OSError(errno.ENOENT, "No such file or directory", "f.nc"), EXIT_USAGE),
    ],
)
def test_run_command_tells_a_full_disk_from_bad_input(error, code, capsys):
    def body(argv):
        raise error

    assert run_command("prog", body, []) == code
    one_line(capsys.readouterr().err)


def test_a_full_disk_behind_another_error_is_still_exit_code_4(capsys):
    def body(argv):
        try:
            raise OSError(errno.ENOSPC, "No space left on device", "h.nc")
        except OSError as full:
            raise RuntimeError("NetCDF: HDF error") from full

    assert run_command("prog", body, []) == 4
    assert "disk full: h.nc" in one_line(capsys.readouterr().err)


@pytest.mark.parametrize(("available", "code"), [(0, 4), (10 << 30, 1)])
def test_a_netcdf_hdf_error_on_a_full_disk_is_exit_code_4(tmp_path, monkeypatch, capsys,
                                                          available, code):  # fmt: skip
    """netCDF4 reports a full disk as "NetCDF: HDF error" without an errno: it counts as a full
    disk only when the file system has (almost) no space left."""
    import types

    import xarray as xr

    def hdf_error(*args, **kwargs):
        raise RuntimeError("NetCDF: HDF error")

    space = types.SimpleNamespace(f_bavail=available // 4096, f_frsize=4096)
    monkeypatch.setattr(xr.Dataset, "to_netcdf", hdf_error)
    monkeypatch.setattr(os, "statvfs", lambda path: space)
    target = tmp_path / "iso.nc"
    assert tiv("isotropic", "--p-max", "50", "--increments", "3", "--out", str(target)) == code
    line = one_line(capsys.readouterr().err)
    assert ("disk full" in line) == (code == 4) and "HDF error" in line
    assert not target.exists()


@pytest.mark.slow
def test_the_protocol_lists_its_files_and_overwrite_deletes_them(tmp_path, capsys):
    """The protocol's writers do not register their files: the run lists them when it closes
    (≈ 40 s of CPU: the smoke protocol with one increment per path, no dynamic probes)."""
    out = tmp_path / "protocol"
    mine = sentinel(out / "notes.txt")
    quick = ("--set", "probing.dynamic=false", "--set", "protocol.path_increments=1", "--quiet")
    assert dem("protocol", "smoke", "--out", str(out), *quick) == 0
    record = manifest(out)
    assert set(record["files"]) | set(record["folders"]) == every_entry(out) - {"notes.txt"}
    assert {"summary.json", "report.md", "resume/A.npz", "probes.nc"} <= set(record["files"])
    assert not (out / RUN_LOCK).exists()
    assert dem("protocol", "smoke", "--out", str(out), *quick) == EXIT_USAGE
    assert "already holds run" in one_line(capsys.readouterr().err)
    start_run(out, "protocol", "smoke", SMOKE, overwrite=True).close()
    assert every_entry(out) == {"notes.txt", RUN_RECORD} and survived(mine)


def test_the_lock_is_taken_where_hard_links_are_not_supported(tmp_path, monkeypatch):
    def no_links(source, target):
        raise OSError(errno.EPERM, "Operation not permitted", str(target))

    monkeypatch.setattr(os, "link", no_links)
    run = start_run(tmp_path / "run", "run", "smoke", SMOKE)
    assert json.loads((tmp_path / "run" / RUN_LOCK).read_text())["pid"] == os.getpid()
    with pytest.raises(RunLockedError, match="in use"):
        start_run(tmp_path / "run", "run", "smoke", SMOKE, overwrite=True)
    run.close()
    assert not (tmp_path / "run" / RUN_LOCK).exists()
    assert [p.name for p in (tmp_path / "run").iterdir()] == [RUN_RECORD]  # no temporary left
