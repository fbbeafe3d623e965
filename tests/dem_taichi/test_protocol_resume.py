"""Resuming an interrupted protocol run (dem_taichi.protocol.resume): bitwise, and refusals."""

from __future__ import annotations

import subprocess
import sys

import pytest

from dem_taichi.io.run_directory import RunDirectoryError
from dem_taichi.scene.config import load_scene, scene_to_toml

from .test_protocol import REFERENCE_SECANT, _assert_bitwise_equal, _outputs, smoke_protocol_scene


@pytest.fixture(scope="module")
def interrupted(tmp_path_factory):
    """The smoke protocol of test_protocol stopped by a KeyboardInterrupt at the start of its
    second branch (A→C), as Ctrl-C would: state A and the first branch (A→B) are saved."""
    import dem_taichi.protocol.branches as branches
    from dem_taichi.protocol.runner import run_protocol

    out = tmp_path_factory.mktemp("interrupted")
    original = branches.run_branch_on

    def stop_at_k0(runner, branch):
        if branch.kind == "k0":
            raise KeyboardInterrupt
        return original(runner, branch)

    branches.run_branch_on = stop_at_k0
    try:
        with pytest.raises(KeyboardInterrupt):
            run_protocol(smoke_protocol_scene(), out)
    finally:
        branches.run_branch_on = original
    _release_runs()
    return out


def _release_runs() -> None:
    """Free the run directories held by the frames of caught exceptions, as the end of a
    process would: their locks (if the run directory takes one) are released."""
    import gc

    gc.collect()


def test_interrupted_run_saved_state_a_and_the_finished_branch(interrupted):
    from dem_taichi.protocol.records import Branch
    from dem_taichi.protocol.resume import saved_summary

    assert (interrupted / "resume" / "A.npz").exists()
    assert (interrupted / "resume" / "branch_0.npz").exists()
    assert not (interrupted / "resume" / "branch_1.npz").exists()
    branches = [Branch("isotropic"), Branch("k0"), Branch("radial", 1, 0.4)]
    text = saved_summary(interrupted, branches)
    assert text == "state A and 1 of 3 branches from A are saved"
    assert not (interrupted / "summary.json").exists()


def test_resumed_run_equals_the_uninterrupted_run_bitwise(interrupted):
    """The resume runs A→C, C→B and the radial path from the saved A, writes the history files
    again from the saved records: every output equals the reference run's bit for bit."""
    from dem_taichi.protocol.runner import run_protocol

    result = run_protocol(smoke_protocol_scene(), interrupted, resume=True)
    _release_runs()
    assert (interrupted / "summary.json").exists()
    assert list(result.states) == ["A", "B", "C", "B'", "R1_end"]
    _assert_bitwise_equal(_outputs(result, history=True), REFERENCE_SECANT)


def test_resume_refuses_another_scene_and_a_directory_without_a_run(tmp_path, interrupted):
    from dem_taichi.protocol.runner import run_protocol

    _release_runs()
    other = smoke_protocol_scene(path_increments=3)
    with pytest.raises(RunDirectoryError, match="is not the scene of run"):
        run_protocol(other, interrupted, resume=True)
    with pytest.raises(RunDirectoryError, match="holds no run to continue"):
        run_protocol(smoke_protocol_scene(), tmp_path / "empty", resume=True)
    with pytest.raises(ValueError, match="exclude each other"):
        run_protocol(smoke_protocol_scene(), interrupted, resume=True, overwrite=True)


def test_resume_refuses_a_run_of_another_command(tmp_path):
    from dem_taichi.io.run_directory import reopen_run, start_run

    toml = scene_to_toml(load_scene("smoke"))
    start_run(tmp_path, "run", "smoke", toml)
    with pytest.raises(RunDirectoryError, match="not a protocol run"):
        reopen_run(tmp_path, "protocol", "smoke", toml)


def test_command_line_resume_of_nothing_is_one_line(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "dem_taichi", "protocol", "smoke", "--out", str(tmp_path / "x")]
        + ["--resume"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert "holds no run to continue" in proc.stderr and "Traceback" not in proc.stderr


def test_a_moved_run_folder_resumes_in_worker_processes(interrupted, tmp_path):
    """The run folder moved elsewhere, a decoy left where it was (a reused folder whose
    ``state_A.npz`` is not this run's), and the missing branches run in spawned processes: they
    read state A inside the moved folder, merge in their place among the saved ones, and the
    outputs again equal the reference bit for bit.

    The two short branches (A→B, the radial path) are the missing ones, one per process, and
    the long one (A→C→B', saved by the resume above) merges between them; run alone, this test
    finds it unsaved and runs all three."""
    import shutil

    from dem_taichi.protocol.runner import run_protocol

    for index in (0, 2):
        (interrupted / "resume" / f"branch_{index}.npz").unlink(missing_ok=True)
    _release_runs()
    moved = tmp_path / "moved"
    shutil.copytree(interrupted, moved)
    shutil.rmtree(interrupted)
    interrupted.mkdir()
    (interrupted / "state_A.npz").write_bytes(b"a file of another run, not a checkpoint")
    result = run_protocol(smoke_protocol_scene(), moved, resume=True, workers=2)
    assert (moved / "resume" / "branch_0.npz").exists()
    assert (moved / "resume" / "branch_2.npz").exists()
    assert result.files["state_A"] == str(moved / "state_A.npz")
    assert all(str(interrupted) not in path for path in result.files.values())
    _assert_bitwise_equal(_outputs(result, history=True), REFERENCE_SECANT)


# The two command-line signal tests run real protocol processes (~50 s each): `make test-slow`
# runs them; the in-process resume tests above keep the bitwise check in the default suite.
@pytest.mark.slow
def test_sigint_on_the_command_line_then_resume(tmp_path):
    """Ctrl-C (SIGINT) once state A is saved: exit code 130, one line that says what is saved
    and the command that resumes; that command then finishes the run."""
    import signal
    import time

    out = tmp_path / "run"
    args = [sys.executable, "-m", "dem_taichi", "protocol", "smoke", "--out", str(out), "--quiet"]
    args += ["--set", "probing.dynamic=false", "--set", "protocol.path_increments=1"]
    proc = subprocess.Popen(args, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 600
    while not (out / "resume" / "A.npz").exists() and proc.poll() is None:
        assert time.monotonic() < deadline, "state A not reached in 10 min"
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=600)
    if proc.returncode == 0:
        pytest.skip("the run finished before the signal arrived")
    assert proc.returncode == 130, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert "SIGINT: stopped; state A and" in lines[0] and "--resume" in lines[0]
    assert f"continue with: python -m dem_taichi protocol smoke --out {out}" in lines[0]
    assert lines[0].endswith("--resume")
    resumed = subprocess.run(args + ["--resume"], capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    assert (out / "summary.json").exists()


@pytest.mark.slow
def test_sigterm_with_worker_processes_stops_them(tmp_path):
    """SIGTERM to a run whose branches are in worker processes: exit code 143 and the one line;
    no worker process is left behind; the resume finishes the run."""
    import os
    import signal
    import time

    out = tmp_path / "run"
    args = [sys.executable, "-m", "dem_taichi", "protocol", "smoke", "--out", str(out), "--quiet"]
    args += [
        "--set",
        "probing.dynamic=false",
        "--set",
        "protocol.path_increments=1",
        "--workers",
        "2",
    ]
    proc = subprocess.Popen(args, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 600
    while not (out / "resume" / "A.npz").exists() and proc.poll() is None:
        assert time.monotonic() < deadline, "state A not reached in 10 min"
        time.sleep(0.2)
    time.sleep(3.0)  # the branch processes have started
    children = _children(proc.pid)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    if proc.returncode == 0:
        pytest.skip("the run finished before the signal arrived")
    assert proc.returncode == 143, err
    assert "SIGTERM: stopped; state A and" in err and "Traceback" not in err
    left = [c for c in children if os.path.exists(f"/proc/{c}")]
    for _ in range(50):  # up to 5 s for the terminated processes to be reaped
        left = [c for c in left if _alive(c)]
        if not left:
            break
        time.sleep(0.1)
    assert not left, f"processes left: {[_cmdline(c) for c in left]}"
    resumed = subprocess.run(args + ["--resume"], capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    assert (out / "summary.json").exists()


def _children(pid: int) -> list[int]:
    """The process ids of ``pid``'s descendants (Linux /proc)."""
    import os

    found, todo = [], [pid]
    while todo:
        parent = todo.pop()
        for entry in os.listdir("/proc"):
            if not entry.isdigit():
                continue
            try:
                with open(f"/proc/{entry}/stat") as fh:
                    ppid = int(fh.read().rsplit(")", 1)[1].split()[1])
            except (OSError, ValueError, IndexError):
                continue
            if ppid == parent:
                found.append(int(entry))
                todo.append(int(entry))
    return found


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _cmdline(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/cmdline") as fh:
            return fh.read().replace("\0", " ")[:120]
    except OSError:
        return "?"
