"""The protocol's resume files are data, checked against the run, and never run code
(issue 22); branch worker processes die with the run that started them.

Most tests write small genuine resume files (:mod:`dem_taichi.protocol.resume`) into a run
folder claimed for the smoke protocol scene and then damage, swap or replace them: a resume must
refuse each bad file with one line naming it and what to do, before any simulation starts.
The bitwise resume of a real interrupted run and the moved run folder are tested in
``test_protocol_resume.py``.
"""

from __future__ import annotations

import gc
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from dem_taichi.io.checkpoint import load_checkpoint, save_checkpoint
from dem_taichi.io.run_directory import start_run
from dem_taichi.protocol.records import Branch, RelaxedState, RunLog, StageRecord
from dem_taichi.protocol.resume import (
    AgeingPoint,
    ResumeFileError,
    RunIdentity,
    StageA,
    ageing_file,
    branch_file,
    load_ageing,
    load_branches,
    load_stage_a,
    save_ageing,
    save_branch,
    save_stage_a,
    stage_a_file,
)
from dem_taichi.scene.config import scene_to_toml

from .test_protocol import smoke_protocol_scene
from .test_protocol_resume import _alive, _children, _cmdline

ISOTROPIC, K0, RADIAL = Branch("isotropic"), Branch("k0"), Branch("radial", 1, 0.4)
BRANCHES = [ISOTROPIC, K0, RADIAL]


class PicklePayload:
    """Unpickling this creates ``sentinel``: the proof that a pickle ran code."""

    def __init__(self, sentinel: Path) -> None:
        self.sentinel = sentinel

    def __reduce__(self):
        return (open, (str(self.sentinel), "w"))


# -- a run folder with genuine resume files (no simulation) ---------------------------------
def _claim(folder: Path, scene_toml: str) -> RunIdentity:
    """Claim ``folder`` for a protocol run and release its lock at once (as a finished run
    would), so that a later resume, in this process or another, may open it."""
    run = start_run(folder, "protocol", "smoke", scene_toml)
    identity = RunIdentity.of(run)
    close = getattr(run, "close", None)
    if close is not None:
        close()
    del run
    gc.collect()
    return identity


def _log(folder: Path) -> RunLog:
    measures = {"step": np.int64(7), "mean_stress": np.float64(2.5), "inertial_number": np.nan}
    state = RelaxedState("A", "isotropic_to_A", 3, (np.nan, np.nan), measures, True)
    log = RunLog(stages={"isotropic_to_A": StageRecord("isotropic_to_A", 1.25, 40)})
    log.states["A"], log.path_states = state, [state]
    log.configurations["A"] = (np.ones((2, 2)), np.zeros(2), np.array([3.0, 4.0]))
    log.checkpoints["A"] = str(folder / "state_A.npz")
    return log


def _stage_a(folder: Path) -> StageA:
    history = [{"step": np.int64(0), "stage": "gas", "kinetic_energy": -0.0}]
    state = {"angle": np.linspace(0.0, 1.0, 5), "step": np.array(7, dtype=np.int64)}
    return StageA(history, [dict(history[0])], _log(folder), state, 12.5)


def _outcome(branch: Branch, folder: Path):
    from dem_taichi.protocol.branches import BranchOutcome

    log = RunLog(stages={"A_to_B": StageRecord("A_to_B", 2.0, 99)})
    log.checkpoints["B"] = str(folder / "state_B.npz")
    return BranchOutcome(branch, [{"step": np.int64(9), "mean_stress": 20.0}], log)


@pytest.fixture(scope="module")
def scene_toml() -> str:
    return scene_to_toml(smoke_protocol_scene())


@pytest.fixture
def saved(tmp_path, scene_toml) -> RunIdentity:
    """A protocol run folder with ``resume/A.npz`` and ``resume/branch_0.npz``."""
    run = _claim(tmp_path / "run", scene_toml)
    save_stage_a(run, _stage_a(run.path))
    save_branch(run, 0, _outcome(ISOTROPIC, run.path))
    return run


@pytest.fixture
def other(tmp_path, scene_toml) -> RunIdentity:
    """Another run of the same scene, with its own resume files."""
    run = _claim(tmp_path / "other", scene_toml)
    save_stage_a(run, _stage_a(run.path))
    for index, branch in enumerate(BRANCHES):
        save_branch(run, index, _outcome(branch, run.path))
    return run


def _refused(call, *words: str) -> str:
    """The one-line message of the ResumeFileError that ``call()`` raises, with ``words``."""
    with pytest.raises(ResumeFileError) as caught:
        call()
    text = str(caught.value)
    assert "\n" not in text and all(w in text for w in words), text
    return text


# -- genuine files ---------------------------------------------------------------------------
def test_genuine_files_round_trip_bit_for_bit(saved):
    stage = load_stage_a(saved)
    expected = _stage_a(saved.path)
    assert stage.seconds == 12.5 and stage.history == expected.history
    assert np.signbit(stage.history[0]["kinetic_energy"])  # -0.0 kept
    assert type(stage.history[0]["step"]) is np.int64
    assert stage.state["angle"].tobytes() == expected.state["angle"].tobytes()
    measures = stage.log.states["A"].measures
    assert np.isnan(measures["inertial_number"]) and measures["mean_stress"] == 2.5
    assert stage.log.stages["isotropic_to_A"] == StageRecord("isotropic_to_A", 1.25, 40)
    targets = stage.log.states["A"].targets
    assert type(targets) is tuple and np.isnan(targets).all()
    assert [repr(s) for s in stage.log.path_states] == [repr(stage.log.states["A"])]
    assert stage.log.configurations["A"][2].tobytes() == np.array([3.0, 4.0]).tobytes()
    assert stage.log.checkpoints == {"A": str(saved.path / "state_A.npz")}
    done = load_branches(saved, BRANCHES)
    assert list(done) == [ISOTROPIC] and done[ISOTROPIC].history[0]["mean_stress"] == 20.0
    assert done[ISOTROPIC].branch == ISOTROPIC


def test_the_order_of_a_dicts_keys_survives_the_sorted_json(tmp_path):
    """The checkpoint sorts its JSON's keys; a dict in another order (a run log's labelled
    states: C before B′) comes back in its own order, a sorted one as a plain object."""
    from dem_taichi.io.checkpoint import save_checkpoint
    from dem_taichi.protocol.resume_codec import decode, encode

    value = {"sorted": {"a": 1, "b": [2, {"y": 0, "x": 1}]}, "states": {"C": 1.0, "B'": 2.0}}
    tree, arrays = encode(value)
    assert tree["sorted"]["a"] == 1 and "$dict" in tree["states"]
    path = save_checkpoint(tmp_path / "f.npz", arrays, {"payload": tree})
    back = decode(load_checkpoint(path)[1]["payload"], arrays)
    assert back == value and list(back["states"]) == ["C", "B'"]
    assert list(back["sorted"]["b"][1]) == ["y", "x"]


def test_the_files_are_data_only_with_the_run_and_relative_paths(saved):
    arrays, meta = load_checkpoint(stage_a_file(saved.path))
    assert meta["run_id"] == saved.run_id and meta["scene_sha256"] == saved.scene_sha256
    assert meta["format"] == "dem_taichi.protocol_resume" and meta["format_version"] == 1
    assert all(a.dtype.kind != "O" for a in arrays.values())
    text = json.dumps(meta)
    assert str(saved.path) not in text  # no absolute path of the folder inside
    log_fields = meta["payload"]["log"]["$obj"][1]
    assert log_fields["checkpoints"] == {"A": "state_A.npz"}
    with np.load(stage_a_file(saved.path), allow_pickle=False) as archive:
        assert sorted(archive.files)  # loads without pickles


def test_a_moved_run_folder_resolves_its_paths_in_the_new_place(saved, tmp_path):
    moved = tmp_path / "moved"
    shutil.move(saved.path, moved)
    run = RunIdentity(moved, saved.run_id, saved.scene_sha256)
    assert load_stage_a(run).log.checkpoints["A"] == str(moved / "state_A.npz")
    assert load_branches(run, BRANCHES)[ISOTROPIC].log.checkpoints["B"] == str(
        moved / "state_B.npz"
    )


# -- pickles are never opened ----------------------------------------------------------------
@pytest.mark.parametrize("name", ["A.pkl", "branch_0.pkl", "A.npz", "branch_1.npz"])
def test_a_pickle_payload_is_never_run(saved, tmp_path, scene_toml, name):
    """A pickle that would create a file when loaded, under the old names (``*.pkl``) and the
    new ones: the resume refuses it with one line, and the file is never created."""
    import pickle

    from dem_taichi.protocol.runner import run_protocol

    sentinel = tmp_path / "pwned"
    (saved.path / "resume" / name).write_bytes(pickle.dumps(PicklePayload(sentinel)))
    words = ("pickle format", "delete") if name.endswith(".pkl") else ("damaged", "delete it")
    _refused(lambda: run_protocol(smoke_protocol_scene(), saved.path, resume=True), *words)
    assert not sentinel.exists()
    if name.endswith(".npz"):
        load = load_stage_a if name == "A.npz" else (lambda r: load_branches(r, BRANCHES))
        _refused(lambda: load(saved), str(saved.path / "resume" / name))
    assert not sentinel.exists()


def test_an_npz_with_a_pickled_member_is_never_run(saved, tmp_path):
    """A checkpoint-looking archive whose array member is a pickled object array."""
    sentinel = tmp_path / "pwned"
    header = {
        "format": "dem_taichi.checkpoint", "format_version": 1,
        "arrays": {"a0": {"dtype": "|O", "shape": [1]}},
        "meta": {"format": "dem_taichi.protocol_resume", "format_version": 1},
    }  # fmt: skip
    payload = np.array([PicklePayload(sentinel)], dtype=object)
    with open(stage_a_file(saved.path), "wb") as fh:
        np.savez(fh, a0=payload, __meta__=np.array(json.dumps(header)))
    _refused(lambda: load_stage_a(saved), "A.npz", "damaged", "delete it")
    assert not sentinel.exists()


# -- files of another run, branch or format --------------------------------------------------
def test_state_a_copied_from_another_run_is_refused(saved, other):
    shutil.copy(stage_a_file(other.path), stage_a_file(saved.path))
    _refused(lambda: load_stage_a(saved), "A.npz", "copied from another run", other.run_id[:8])


def test_a_branch_copied_from_another_run_is_refused(saved, other):
    shutil.copy(branch_file(other.path, 1), branch_file(saved.path, 1))
    _refused(lambda: load_branches(saved, BRANCHES), "branch_1.npz", "copied from another run")


def test_a_file_of_another_scene_is_refused(saved, tmp_path):
    toml = scene_to_toml(smoke_protocol_scene(path_increments=3))
    foreign = _claim(tmp_path / "foreign", toml)
    assert foreign.scene_sha256 != saved.scene_sha256
    save_branch(foreign, 2, _outcome(RADIAL, foreign.path))
    shutil.copy(branch_file(foreign.path, 2), branch_file(saved.path, 2))
    _refused(lambda: load_branches(saved, BRANCHES), "branch_2.npz", foreign.scene_sha256[:12])


def test_a_branch_file_renamed_to_another_branch_is_refused(saved):
    shutil.copy(branch_file(saved.path, 0), branch_file(saved.path, 1))
    _refused(lambda: load_branches(saved, BRANCHES), "branch_1.npz", "holds index 0", "delete it")


def test_a_branch_file_in_place_of_state_a_is_refused(saved):
    shutil.copy(branch_file(saved.path, 0), stage_a_file(saved.path))
    _refused(lambda: load_stage_a(saved), "A.npz", "holds kind 'branch'")


def _ageing(folder: Path, phase: str = "ageing") -> AgeingPoint:
    stage = _stage_a(folder)
    progress = {"phase": phase, "done": 4000, "check": 40, "since_output": 0,
                "stage_seconds": 3.5, "details": {"criterion": "time", "note": "x"}}  # fmt: skip
    return AgeingPoint(stage.history, stage.relaxed, stage.log, stage.state, 9.0, progress)


def test_an_ageing_save_round_trips_and_another_runs_is_refused(saved, other):
    """``ageing.npz``: written and read back bit for bit (records, log, state, progress);
    copied from another run, in place of state A, or with an unknown phase: refused in one
    line naming the file."""
    point = _ageing(saved.path)
    save_ageing(saved, point)
    back = load_ageing(saved)
    assert back is not None and back.progress == point.progress and back.seconds == 9.0
    assert back.history == point.history and back.log.checkpoints == point.log.checkpoints
    assert all(np.array_equal(back.state[k], v) for k, v in point.state.items())
    shutil.copy(ageing_file(saved.path), stage_a_file(saved.path))
    _refused(lambda: load_stage_a(saved), "A.npz", "holds kind 'ageing'")
    save_ageing(other, _ageing(other.path))
    shutil.copy(ageing_file(other.path), ageing_file(saved.path))
    _refused(lambda: load_ageing(saved), "ageing.npz", "copied from another run")
    save_ageing(saved, _ageing(saved.path, phase="soaking"))
    _refused(lambda: load_ageing(saved), "ageing.npz", "no phase", "delete it")
    assert load_ageing(other) is not None


def _rewrite(path: Path, change) -> None:
    """Load a genuine resume file, ``change(meta)``, and save it again, whole and valid."""
    arrays, meta = load_checkpoint(path)
    change(meta)
    save_checkpoint(path, arrays, meta)


def test_a_newer_format_version_is_refused(saved):
    _rewrite(stage_a_file(saved.path), lambda meta: meta.update(format_version=2))
    _refused(lambda: load_stage_a(saved), "A.npz", "format version 2")


def test_an_unknown_record_type_in_the_payload_is_refused(saved):
    def plant(meta):
        meta["payload"]["log"] = {"$obj": ["Popen", {"args": ["touch", "x"]}]}

    _rewrite(stage_a_file(saved.path), plant)
    _refused(lambda: load_stage_a(saved), "A.npz", "'Popen' is not a record type")


def test_a_path_leaving_the_run_folder_is_refused(saved):
    def plant(meta):
        meta["payload"]["log"]["$obj"][1]["checkpoints"] = {"A": "../../elsewhere/state_A.npz"}

    _rewrite(stage_a_file(saved.path), plant)
    _refused(lambda: load_stage_a(saved), "A.npz", "not inside the run folder")


def test_wrong_field_types_are_refused(saved):
    _rewrite(stage_a_file(saved.path), lambda meta: meta["payload"].update(seconds="soon"))
    _refused(lambda: load_stage_a(saved), "A.npz", "damaged: bad seconds")


# -- damaged files ---------------------------------------------------------------------------
def _truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def _flip_byte(path: Path) -> None:
    """One bit of the stored JSON flipped (a bad sector): the member's CRC-32 no longer fits."""
    data = bytearray(path.read_bytes())
    at = bytes(data).index("payload".encode("utf-32-le"))  # numpy stores str as UTF-32
    data[at] ^= 0x01
    path.write_bytes(bytes(data))


def _npy(path: Path) -> None:
    with open(path, "wb") as fh:
        np.save(fh, np.arange(4))


DAMAGE = {
    "truncated": _truncate,
    "garbage": lambda p: p.write_bytes(os.urandom(512)),
    "empty": lambda p: p.write_bytes(b""),
    "flipped byte": _flip_byte,
    "an .npy, not an archive": _npy,
    "a plain npz": lambda p: np.savez(p, x=np.ones(3)),
}


@pytest.mark.parametrize("damage", list(DAMAGE))
def test_a_damaged_state_a_names_the_file(saved, damage):
    path = stage_a_file(saved.path)
    DAMAGE[damage](path)
    _refused(lambda: load_stage_a(saved), str(path), "delete it", "--overwrite")


@pytest.mark.parametrize("damage", ["truncated", "garbage"])
def test_a_damaged_branch_file_names_the_file(saved, damage):
    path = branch_file(saved.path, 0)
    DAMAGE[damage](path)
    _refused(lambda: load_branches(saved, BRANCHES), str(path), "the branch is run again")


def test_a_damaged_state_a_checkpoint_for_the_workers_is_refused(saved, tmp_path):
    """The workers' state A (``state_A.npz`` in the run folder) is checked whole and for the
    run's scene before any branch process starts."""
    from types import SimpleNamespace

    from dem_taichi.protocol.branches import _checkpoint_for_workers

    path = saved.path / "state_A.npz"
    path.write_bytes(b"not a checkpoint")
    runner = SimpleNamespace(checkpoints={"A": str(path)}, sim=None)
    _refused(lambda: _checkpoint_for_workers(runner, saved), str(path), "damaged state A")
    save_checkpoint(path, {"x": np.ones(2)}, {"scene_toml": scene_to_toml(smoke_protocol_scene(
        path_increments=5))})  # fmt: skip
    _refused(lambda: _checkpoint_for_workers(runner, saved), str(path), "another scene")


def test_command_line_resume_with_a_damaged_file_is_one_line(tmp_path):
    """``protocol --resume`` of a folder whose ``resume/A.npz`` is garbage: exit code 2, one
    line naming the file, never an internal error; no simulation is started."""
    from dem_taichi.scene.options import scene_from_options

    run = _claim(tmp_path / "run", scene_to_toml(scene_from_options("smoke", None, [])))
    stage_a_file(run.path).parent.mkdir()
    stage_a_file(run.path).write_bytes(b"PK\x03\x04 cut short")
    args = [sys.executable, "-m", "dem_taichi", "protocol", "smoke", "--out", str(run.path)]
    proc = subprocess.run(args + ["--resume"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "internal error" not in lines[0], proc.stderr
    assert str(stage_a_file(run.path)) in lines[0] and "delete it" in lines[0]


# -- worker processes die with their parent --------------------------------------------------
_ORPHAN = """
import os, sys, time, subprocess
code = (
    "import sys, time; sys.path.insert(0, {root!r});"
    "import dem_taichi.protocol.worker_lifetime as w;"
    "{patch};"
    "w.die_with_parent(int(sys.argv[1]), poll_seconds=0.1);"
    "print('ready', flush=True); time.sleep(120)"
)
child = subprocess.Popen([sys.executable, "-c", code, str(os.getpid())], stdout=subprocess.PIPE)
assert child.stdout.readline().strip() == b"ready"
print(child.pid, flush=True)
time.sleep(120)
"""

#: How the grandchild is left to die: the kernel's parent-death signal with no watchdog, or
#: the watchdog thread with no prctl (as where prctl does not exist).
_ONLY = {
    "prctl only": "w._watch_parent = lambda *args: None",
    "watchdog only": "w.set_parent_death_signal = lambda signum=None: False",
}


@pytest.mark.parametrize("only", list(_ONLY))
def test_a_worker_ends_when_its_parent_is_killed(only):
    """``die_with_parent`` in a grandchild; SIGKILL its parent: the grandchild ends within a
    few seconds, by the parent-death signal (Linux) alone or by the watchdog thread alone."""
    if only == "prctl only" and not sys.platform.startswith("linux"):
        pytest.skip("prctl is Linux only")
    root = str(Path(__file__).resolve().parents[2])
    code = _ORPHAN.format(root=root, patch=_ONLY[only])
    parent = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE)
    grandchild = int(parent.stdout.readline())
    assert _alive(grandchild)
    parent.kill()
    parent.wait()
    deadline = time.monotonic() + 5
    while _alive(grandchild) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(grandchild), _cmdline(grandchild)


def test_kill_9_of_the_protocol_leaves_no_branch_process(tmp_path):
    """``kill -9`` of ``protocol --workers 2`` once its two branch processes run: every
    descendant is gone within a few seconds and the output pipe is closed (about 12 s; without
    :func:`dem_taichi.protocol.worker_lifetime.die_with_parent` both workers and the resource
    tracker were left running)."""
    out = tmp_path / "run"
    args = [sys.executable, "-m", "dem_taichi", "protocol", "smoke", "--out", str(out), "--quiet"]
    args += ["--set", "probing.dynamic=false", "--set", "protocol.path_increments=1"]
    proc = subprocess.Popen(args + ["--workers", "2"], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    workers: list[int] = []
    while len(workers) < 2:
        assert proc.poll() is None, proc.stderr.read()
        assert time.monotonic() < deadline, "no branch processes within 5 min"
        time.sleep(0.2)
        workers = [c for c in _children(proc.pid) if "spawn_main" in _cmdline(c)]
    time.sleep(2.0)  # the workers are running their branches
    family = _children(proc.pid)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    deadline = time.monotonic() + 10
    while [c for c in family if _alive(c)] and time.monotonic() < deadline:
        time.sleep(0.1)
    left = [c for c in family if _alive(c)]
    assert not left, f"left alive after kill -9: {[_cmdline(c) for c in left]}"
    proc.stderr.read()  # returns: no process holds the pipe any more
