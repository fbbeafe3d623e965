"""Resuming an interrupted protocol run: what it saves as it goes, and reading it back.

The protocol (:func:`dem_taichi.protocol.runner.run_protocol`) is gas → A, then independent branches
from A (:mod:`dem_taichi.protocol.branches`: A→B; A→C with C→B; each radial path). It saves, in
``<run>/resume/``:

- ``A.npz`` once state A is reached: the history and relaxed-state records written so far,
  the run's log at A (:class:`dem_taichi.protocol.records.RunLog`, with the probes at A), the
  engine state at A and the wall time so far;
- ``ageing.npz`` while the aggregation (gas-ageing) stage runs, when the scene has one: the same
  as ``A.npz`` (records, log, engine state, wall time) and where the stage stood (``phase``
  "ageing": the checks done, rewritten about every ``AGEING_SAVE_SECONDS`` of wall time; "aged":
  the stage finished, before the compression to A), so that a long ageing resumes where it was
  (:mod:`dem_taichi.protocol.aggregation`); an ageing on a rigid twin
  (``aggregation_rod_model = "rigid"``) is saved only once aged;
- ``branch_<k>.npz`` when the k-th branch has finished: its
  :class:`dem_taichi.protocol.records.BranchOutcome` (history records and log), written by the
  process that ran it;
- ``branch_<k>_point.npz`` while the k-th branch runs: its records and log so far, the engine
  state and where the branch stood (:class:`BranchPoint`), rewritten after a relaxed path state
  about every :data:`dem_taichi.protocol.paths.BRANCH_SAVE_SECONDS` of wall time, deleted when
  the branch's outcome is saved. A branch at the study's size takes an hour; this is what a
  stopped one goes on from.

A resume (``python -m dem_taichi protocol SCENE --out DIR --resume``, or ``run_protocol(...,
resume=True)``) checks the run's record (the same scene, by hash: :func:`dem_taichi.io.
run_directory.reopen_run`), writes the history files again from the saved records, and runs
only the branches without a saved outcome, from the saved state A, or from a branch's last
point. The serial engine is deterministic, so the resumed run's outputs equal those of a run
never interrupted (tested bitwise on the smoke protocol). The work lost by an interruption is at
most what the running branches did since their last point; a run stopped before A starts again
from the gas, or from its last ageing save
(``ageing.npz``: the thermostat's draws are seeded by the step, so the resumed ageing draws what
the uninterrupted one drew, and the outputs are again bit for bit those of a run never
interrupted). SIGINT/SIGTERM stop the run with one line saying how to resume (exit code
130/143).

What a resume trusts and checks. The files are data only: a checkpoint-format ``.npz``
(:mod:`dem_taichi.io.checkpoint`: arrays and one JSON member, read with
``allow_pickle=False``, CRC-checked) whose JSON holds the format name and version, the kind of
file (A or branch k, with the branch's label), the run id and scene hash of the run that wrote
it, and the records in the encoding of :mod:`dem_taichi.protocol.resume_codec` (numbers, strings,
arrays and this package's record dataclasses, nothing else). Loading one runs no code of the
file. A file whose run id or scene hash differs from the run's ``run.json`` (copied from
another run), of another kind or branch, of a newer format, damaged, truncated or not a resume
file at all is refused with one line (:class:`ResumeFileError`, exit code 2) naming it and what
to do: delete it (the resume then recomputes that part) or start again with ``--overwrite``.
Pickle files left by older versions (``A.pkl``, ``branch_<k>.pkl``) are never opened: a resume
that finds one is refused the same way. Paths inside the run folder (the state files of the
log) are stored relative to it and resolved in the folder being resumed, so a moved run folder
resumes. What is not checked: that the saved numbers are the ones the engine computed (a file
edited consistently, with the right run id and hash, is believed), as for every other output of
the run folder.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING, Any

import numpy as np

from dem_taichi.io.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from dem_taichi.protocol.resume_codec import EncodingError, decode, encode

if TYPE_CHECKING:
    from dem_taichi.protocol.records import Branch, BranchOutcome

__all__ = [
    "RESUME_DIR",
    "RESUME_FORMAT",
    "RESUME_FORMAT_VERSION",
    "ResumeFileError",
    "RunIdentity",
    "StageA",
    "AgeingPoint",
    "RecordingWriter",
    "stage_a_file",
    "ageing_file",
    "save_ageing",
    "load_ageing",
    "branch_file",
    "BranchPoint",
    "branch_point_file",
    "save_branch_point",
    "load_branch_point",
    "remove_branch_point",
    "refuse_pickles",
    "save_stage_a",
    "load_stage_a",
    "save_branch",
    "load_branches",
    "inside_run",
    "relative_to_run",
    "saved_summary",
]

RESUME_DIR = "resume"
#: the files' format name (the module's name before the role subpackages: kept, so that resume
#: files written before still load)
RESUME_FORMAT = "dem_taichi.protocol_resume"
#: Bump when the layout of the payload changes; files of a greater version are refused.
RESUME_FORMAT_VERSION = 1


class ResumeFileError(ValueError):
    """A resume file that cannot be used (damaged, another run's, another format): one line
    naming the file and what to do. A ``ValueError``: the command line reports it as bad
    input (exit code 2, :mod:`clay_cli`)."""


@dataclass(frozen=True)
class RunIdentity:
    """The run a resume file belongs to: its folder, id and scene hash (from ``run.json``,
    :class:`dem_taichi.io.run_directory.RunDirectory`). Passed to branch processes."""

    path: Path
    run_id: str
    scene_sha256: str

    @classmethod
    def of(cls, run_dir) -> RunIdentity:
        """The identity of a :class:`~dem_taichi.io.run_directory.RunDirectory`."""
        return cls(Path(run_dir.path), run_dir.run_id, run_dir.record.scene_sha256)


@dataclass(frozen=True)
class StageA:
    """What a resume needs from the run up to state A."""

    history: list[dict]
    relaxed: list[dict]
    log: Any  # RunLog at A
    state: dict[str, np.ndarray]  # Simulation.get_state() at A
    seconds: float


@dataclass(frozen=True)
class AgeingPoint:
    """What a resume needs from the run inside the aggregation stage (``ageing.npz``): the
    fields of :class:`StageA` up to now, and ``progress``, where the stage stood (a dict of
    numbers, strings and the stage's details: ``phase`` "ageing" or "aged", ``done`` the ageing
    steps and ``check`` the checks done, ``details`` the stage's details so far,
    ``since_output`` the history cadence's count, ``stage_seconds`` the stage's wall time)."""

    history: list[dict]
    relaxed: list[dict]
    log: Any  # RunLog
    state: dict[str, np.ndarray]  # Simulation.get_state() of the protocol's simulation
    seconds: float
    progress: dict


@dataclass(frozen=True)
class BranchPoint:
    """What a resume needs from a branch part-way (``branch_<k>_point.npz``): its history
    records and :class:`~dem_taichi.protocol.records.RunLog` so far (the log holds state A as
    the branch's logs do while they run), the engine state after its last relaxed path state,
    and ``progress``, where it stood (:meth:`dem_taichi.protocol.paths.ProtocolRunner.
    branch_progress`: ``stage`` the path's stage, ``increment`` the path states done in it,
    ``measures`` the last one's, ``since_output`` the history cadence's count,
    ``servo_times`` the servo's time constants)."""

    history: list[dict]
    log: Any  # RunLog
    state: dict[str, np.ndarray]  # Simulation.get_state() after the last path state
    progress: dict


class RecordingWriter:
    """Writes through to a history writer and keeps a copy of every record (for ``A.npz``)."""

    def __init__(self, writer) -> None:
        self.writer = writer
        self.records: list[dict] = []

    def append(self, frame: dict) -> int:
        self.records.append(dict(frame))
        return self.writer.append(frame)

    def __getattr__(self, name):
        return getattr(self.writer, name)


# -- file names -----------------------------------------------------------------------------
def stage_a_file(out_dir: str | Path) -> Path:
    """``<run>/resume/A.npz``."""
    return Path(out_dir) / RESUME_DIR / "A.npz"


def ageing_file(out_dir: str | Path) -> Path:
    """``<run>/resume/ageing.npz``."""
    return Path(out_dir) / RESUME_DIR / "ageing.npz"


def branch_file(out_dir: str | Path, index: int) -> Path:
    """``<run>/resume/branch_<index>.npz``."""
    return Path(out_dir) / RESUME_DIR / f"branch_{index}.npz"


def branch_point_file(out_dir: str | Path, index: int) -> Path:
    """``<run>/resume/branch_<index>_point.npz``."""
    return Path(out_dir) / RESUME_DIR / f"branch_{index}_point.npz"


def refuse_pickles(out_dir: str | Path) -> None:
    """Refuse a resume folder holding pickles (``*.pkl``: the format of older versions, or a
    file planted to run code): they are never opened; the user deletes them."""
    found = sorted((Path(out_dir) / RESUME_DIR).glob("*.pkl"))
    if found:
        raise ResumeFileError(
            f"{found[0]}: resume files in pickle format are not read (loading a pickle can run "
            f"any code; dem_taichi now writes data-only .npz files); delete "
            f"{Path(out_dir) / RESUME_DIR}/*.pkl and resume again (what they held is "
            "recomputed), or start again with --overwrite"
        )


# -- paths inside the run folder ------------------------------------------------------------
def relative_to_run(path: str | Path, run_dir: str | Path) -> str:
    """``path`` (a file the run wrote in its folder) relative to the folder, POSIX style."""
    relative = os.path.relpath(os.path.abspath(path), os.path.abspath(run_dir))
    if relative.startswith(os.pardir) or os.path.isabs(relative):
        raise ValueError(f"{path} is not inside the run folder {run_dir}")
    return PurePosixPath(Path(relative)).as_posix()


def inside_run(relative: str, run_dir: str | Path, source: Path) -> Path:
    """The file ``relative`` (as :func:`relative_to_run` wrote it) in the run folder
    ``run_dir``; a path that is absolute or leaves the folder is refused (``source`` names the
    file that held it)."""
    parts = PurePosixPath(relative).parts if isinstance(relative, str) else ("..",)
    if not parts or PurePosixPath(relative).is_absolute() or ".." in parts:
        raise ResumeFileError(
            f"{source}: names the file {relative!r}, which is not inside the run folder; the "
            "file is not one this package wrote: delete it and resume again"
        )
    return Path(run_dir).joinpath(*parts)


def _log_relative(log, run_dir: Path):
    checkpoints = {k: relative_to_run(v, run_dir) for k, v in log.checkpoints.items()}
    return dataclasses.replace(log, checkpoints=checkpoints)


def _log_absolute(log, run_dir: Path, source: Path):
    checkpoints = {k: str(inside_run(v, run_dir, source)) for k, v in log.checkpoints.items()}
    return dataclasses.replace(log, checkpoints=checkpoints)


# -- writing and reading one file -----------------------------------------------------------
def _header(run: RunIdentity, kind: str, **extra: Any) -> dict[str, Any]:
    return {
        "format": RESUME_FORMAT,
        "format_version": RESUME_FORMAT_VERSION,
        "kind": kind,
        "run_id": run.run_id,
        "scene_sha256": run.scene_sha256,
        **extra,
    }


def _save(path: Path, header: dict[str, Any], payload: Any) -> Path:
    """Write ``payload`` with ``header`` atomically (temporary file, fsync, os.replace); a dict
    payload (the fields of a saved stage) in sorted order, so that it stays a plain object."""
    if isinstance(payload, dict):
        payload = dict(sorted(payload.items()))
    tree, arrays = encode(payload)
    return save_checkpoint(path, arrays, dict(header, payload=tree))


def _refusal(path: Path, problem: str, remedy: str) -> ResumeFileError:
    return ResumeFileError(f"{path}: {problem}; {remedy}")


def _load(path: Path, run: RunIdentity, kind: str, remedy: str, **expected: Any) -> Any:
    """The payload of the resume file ``path``, checked: a data-only file of this format, of
    ``kind`` with the ``expected`` header values, written by ``run``."""
    try:
        arrays, meta = load_checkpoint(path)
    except (CheckpointError, OSError) as error:
        raise _refusal(path, f"damaged or not a resume file ({error})", remedy) from None
    if meta.get("format") != RESUME_FORMAT:
        raise _refusal(path, f"not a {RESUME_FORMAT} file", remedy)
    version = meta.get("format_version")
    if not isinstance(version, int) or version > RESUME_FORMAT_VERSION:
        raise _refusal(
            path, f"format version {version!r}, this code reads up to {RESUME_FORMAT_VERSION}",
            remedy,
        )  # fmt: skip
    if meta.get("run_id") != run.run_id or meta.get("scene_sha256") != run.scene_sha256:
        raise _refusal(
            path,
            f"written by run {str(meta.get('run_id'))[:8]} of scene sha256 "
            f"{str(meta.get('scene_sha256'))[:12]}, not by this folder's run {run.run_id[:8]} "
            f"(sha256 {run.scene_sha256[:12]}, {run.path / 'run.json'}): copied from another "
            "run",
            remedy,
        )
    for key, value in dict(kind=kind, **expected).items():
        if meta.get(key) != value:
            raise _refusal(path, f"holds {key} {meta.get(key)!r}, not {value!r}", remedy)
    try:
        return decode(meta.get("payload"), arrays)
    except (EncodingError, TypeError) as error:
        raise _refusal(path, f"damaged: {error}", remedy) from None


def _check_fields(values: Any, kinds: dict[str, type], path: Path, what: str, remedy: str):
    """``values`` (a loaded payload) as a dict with exactly the fields ``kinds`` of those
    types, its ``state`` a dict of arrays; else refused as damaged (``what`` names the file's
    kind)."""
    if not (isinstance(values, dict) and set(values) == set(kinds)):
        raise _refusal(path, f"damaged: not the fields of {what}", remedy)
    wrong = [k for k, kind in kinds.items() if not isinstance(values[k], kind)]
    if wrong or not all(isinstance(a, np.ndarray) for a in values["state"].values()):
        raise _refusal(path, f"damaged: bad {', '.join(wrong) or 'state'}", remedy)
    return values


# -- state A --------------------------------------------------------------------------------
_STAGE_A_FIELDS = tuple(f.name for f in dataclasses.fields(StageA))


def _stage_a_payload(stage: StageA) -> dict[str, Any]:
    """StageA as a dict of its fields (the encoding builds only the record types)."""
    return {f: getattr(stage, f) for f in _STAGE_A_FIELDS}


_REMEDY_A = (
    "delete it and resume again (the run then starts again from the gas), or start again with "
    "--overwrite"
)


def save_stage_a(run: RunIdentity, stage: StageA) -> Path:
    """Write ``resume/A.npz`` of ``run``."""
    saved = dataclasses.replace(stage, log=_log_relative(stage.log, run.path))
    return _save(stage_a_file(run.path), _header(run, "A"), _stage_a_payload(saved))


def load_stage_a(run: RunIdentity) -> StageA | None:
    """The saved state A of ``run``, None when it was not reached (no ``A.npz``); refuses
    (:class:`ResumeFileError`) a file that is damaged or not this run's."""
    path = stage_a_file(run.path)
    if not path.exists():
        return None
    values = _load(path, run, "A", _REMEDY_A)
    from dem_taichi.protocol.records import RunLog

    kinds = {"history": list, "relaxed": list, "log": RunLog, "state": dict, "seconds": float}
    values = _check_fields(values, kinds, path, "state A", _REMEDY_A)
    values["log"] = _log_absolute(values["log"], run.path, path)
    return StageA(**values)


# -- inside the aggregation stage -----------------------------------------------------------
_AGEING_FIELDS = tuple(f.name for f in dataclasses.fields(AgeingPoint))
_REMEDY_AGEING = (
    "delete it and resume again (the run then starts again from the gas), or start again with "
    "--overwrite"
)


def save_ageing(run: RunIdentity, point: AgeingPoint) -> Path:
    """Write (replace) ``resume/ageing.npz`` of ``run``."""
    saved = dataclasses.replace(point, log=_log_relative(point.log, run.path))
    return _save(ageing_file(run.path), _header(run, "ageing"), {
        f: getattr(saved, f) for f in _AGEING_FIELDS
    })  # fmt: skip


def load_ageing(run: RunIdentity) -> AgeingPoint | None:
    """The last saved point inside the aggregation stage of ``run``, None when there is none;
    refuses (:class:`ResumeFileError`) a file that is damaged or not this run's."""
    path = ageing_file(run.path)
    if not path.exists():
        return None
    values = _load(path, run, "ageing", _REMEDY_AGEING)
    from dem_taichi.protocol.records import RunLog

    kinds = {"history": list, "relaxed": list, "log": RunLog, "state": dict, "seconds": float,
             "progress": dict}  # fmt: skip
    values = _check_fields(values, kinds, path, "an ageing save", _REMEDY_AGEING)
    progress = values["progress"]
    if progress.get("phase") not in ("ageing", "aged") or not isinstance(
        progress.get("details"), dict
    ):
        raise _refusal(path, "damaged: no phase or details of the ageing", _REMEDY_AGEING)
    values["log"] = _log_absolute(values["log"], run.path, path)
    return AgeingPoint(**values)


# -- branches -------------------------------------------------------------------------------
_REMEDY_BRANCH = "delete it and resume again (the branch is run again)"


def save_branch(run: RunIdentity, index: int, outcome: BranchOutcome) -> Path:
    """Write ``resume/branch_<index>.npz`` of ``run``; the branch is written as its label."""
    saved = dataclasses.replace(outcome, log=_log_relative(outcome.log, run.path))
    header = _header(run, "branch", index=int(index), branch=outcome.branch.label)
    return _save(branch_file(run.path, index), header, saved)


def load_branches(run: RunIdentity, branches: Sequence[Branch]) -> dict[Branch, BranchOutcome]:
    """The saved outcomes of ``branches`` of ``run``, for those whose file exists (the k-th
    branch's is ``branch_<k>.npz``); refuses (:class:`ResumeFileError`) a file that is
    damaged, not this run's, or of another branch (its label is not the branch's). A point of
    a branch whose outcome is saved (left when a run stopped between writing the outcome and
    deleting the point) is spent, and deleted."""
    from dem_taichi.protocol.records import BranchOutcome, RunLog

    done = {}
    for index, branch in enumerate(branches):
        path = branch_file(run.path, index)
        if not path.exists():
            continue
        outcome = _load(path, run, "branch", _REMEDY_BRANCH, index=index, branch=branch.label)
        if not (
            isinstance(outcome, BranchOutcome)
            and outcome.branch == branch
            and isinstance(outcome.history, list)
            and isinstance(outcome.log, RunLog)
        ):
            raise _refusal(
                path, f"damaged: not the outcome of branch {branch.label!r}", _REMEDY_BRANCH
            )
        done[branch] = dataclasses.replace(outcome, log=_log_absolute(outcome.log, run.path, path))
        remove_branch_point(run, index)
    return done


# -- inside a branch -------------------------------------------------------------------------
_REMEDY_POINT = "delete it and resume again (the branch then starts again from A)"
#: the stages a branch's point may stand in, by the branch's kind
_POINT_STAGES = {"isotropic": ("A_to_B",), "k0": ("A_to_C", "C_to_B"), "radial": ("radial",)}


def save_branch_point(run: RunIdentity, index: int, branch: Branch, point: BranchPoint) -> Path:
    """Write (replace) ``resume/branch_<index>_point.npz`` of ``run`` for ``branch``."""
    saved = dataclasses.replace(point, log=_log_relative(point.log, run.path))
    header = _header(run, "branch_point", index=int(index), branch=branch.label)
    return _save(branch_point_file(run.path, index), header, {
        f.name: getattr(saved, f.name) for f in dataclasses.fields(BranchPoint)
    })  # fmt: skip


def load_branch_point(run: RunIdentity, index: int, branch: Branch) -> BranchPoint | None:
    """The last point saved inside the ``index``-th branch of ``run`` (``branch``), None when
    there is none; refuses (:class:`ResumeFileError`) a file that is damaged, not this run's
    or of another branch."""
    path = branch_point_file(run.path, index)
    if not path.exists():
        return None
    values = _load(path, run, "branch_point", _REMEDY_POINT, index=index, branch=branch.label)
    from dem_taichi.protocol.records import RunLog

    kinds = {"history": list, "log": RunLog, "state": dict, "progress": dict}
    values = _check_fields(values, kinds, path, "a branch point", _REMEDY_POINT)
    progress = values["progress"]
    if progress.get("stage") not in _POINT_STAGES[branch.kind]:
        raise _refusal(
            path, f"stands inside {progress.get('stage')}, which the branch {branch.label!r} "
            "does not run", _REMEDY_POINT,
        )  # fmt: skip
    if (
        not isinstance(progress.get("increment"), int)
        or not isinstance(progress.get("measures"), dict)
        or not isinstance(progress.get("since_output"), int)
        or not isinstance(progress.get("servo_times"), dict)
    ):
        raise _refusal(path, "damaged: not where a branch stood", _REMEDY_POINT)
    values["log"] = _log_absolute(values["log"], run.path, path)
    return BranchPoint(**values)


def remove_branch_point(run: RunIdentity, index: int) -> None:
    """Delete the ``index``-th branch's point (its outcome is saved: the point is spent)."""
    branch_point_file(run.path, index).unlink(missing_ok=True)


def saved_summary(out_dir: str | Path, branches: Sequence[Branch]) -> str:
    """What a resume of the run in ``out_dir`` would start from, in words."""
    if not stage_a_file(out_dir).exists():
        if ageing_file(out_dir).exists():
            return "state A was not reached (a resume continues the aggregation stage's last save)"
        return "state A was not reached (a resume starts again from the gas)"
    done = [b for i, b in enumerate(branches) if branch_file(out_dir, i).exists()]
    text = f"state A and {len(done)} of {len(branches)} branches from A are saved"
    part = [
        b.label for i, b in enumerate(branches)
        if not branch_file(out_dir, i).exists() and branch_point_file(out_dir, i).exists()
    ]  # fmt: skip
    return text + (f", and part of {', '.join(part)}" if part else "")
