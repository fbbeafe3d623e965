"""Resuming an interrupted protocol run: what it saves as it goes, and reading it back.

The protocol (:func:`dem_taichi.protocol.run_protocol`) is gas → A, then independent branches
from A (:mod:`dem_taichi.branches`: A→B; A→C with C→B; each radial path). It saves, in
``<run>/resume/``:

- ``A.pkl`` once state A is reached: the history and relaxed-state records written so far,
  the run's log at A (:class:`dem_taichi.protocol_records.RunLog`, with the probes at A), the
  engine state at A and the wall time so far;
- ``branch_<k>.pkl`` when the k-th branch has finished: its
  :class:`dem_taichi.branches.BranchOutcome` (history records and log), written by the process
  that ran it.

A resume (``python -m dem_taichi protocol SCENE --out DIR --resume``, or ``run_protocol(...,
resume=True)``) checks the run's record (the same scene, by hash: :func:`dem_taichi.io.
run_directory.reopen_run`), writes the history files again from the saved records, and runs
only the branches without a saved outcome, from the saved state A. The serial engine is
deterministic, so the resumed run's outputs equal those of a run never interrupted (tested
bitwise on the smoke protocol). The work lost by an interruption is at most the branches that
were running; a run stopped before A starts again from the gas. SIGINT/SIGTERM stop the run
with one line saying how to resume (exit code 130/143). The files are pickles of this
package's own records: read them only from run directories you made.
"""

from __future__ import annotations

import os
import pickle
import tempfile
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "RESUME_DIR",
    "StageA",
    "RecordingWriter",
    "save_stage_a",
    "load_stage_a",
    "save_branch",
    "load_branches",
    "branch_file",
    "saved_summary",
]

RESUME_DIR = "resume"


@dataclass
class StageA:
    """What a resume needs from the run up to state A."""

    history: list[dict]
    relaxed: list[dict]
    log: object  # RunLog at A
    state: dict  # Simulation.get_state() at A
    seconds: float


class RecordingWriter:
    """Writes through to a history writer and keeps a copy of every record (for ``A.pkl``)."""

    def __init__(self, writer) -> None:
        self.writer = writer
        self.records: list[dict] = []

    def append(self, frame: dict) -> int:
        self.records.append(dict(frame))
        return self.writer.append(frame)

    def __getattr__(self, name):
        return getattr(self.writer, name)


def _dump(path: Path, payload) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            pickle.dump(payload, fh, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def save_stage_a(out_dir: str | Path, stage: StageA) -> Path:
    return _dump(Path(out_dir) / RESUME_DIR / "A.pkl", stage)


def load_stage_a(out_dir: str | Path) -> StageA | None:
    path = Path(out_dir) / RESUME_DIR / "A.pkl"
    if not path.exists():
        return None
    with open(path, "rb") as fh:
        return pickle.load(fh)


def branch_file(out_dir: str | Path, index: int) -> Path:
    return Path(out_dir) / RESUME_DIR / f"branch_{index}.pkl"


def save_branch(out_dir: str | Path, index: int, outcome) -> Path:
    return _dump(branch_file(out_dir, index), outcome)


def load_branches(out_dir: str | Path, branches: list[str]) -> dict[str, object]:
    """The saved outcomes of ``branches`` (by name), those whose file exists and matches."""
    done = {}
    for index, name in enumerate(branches):
        path = branch_file(out_dir, index)
        if path.exists():
            with open(path, "rb") as fh:
                outcome = pickle.load(fh)
            if getattr(outcome, "branch", None) == name:
                done[name] = outcome
    return done


def saved_summary(out_dir: str | Path, branches: list[str]) -> str:
    """What a resume of the run in ``out_dir`` would start from, in words."""
    if not (Path(out_dir) / RESUME_DIR / "A.pkl").exists():
        return "state A was not reached (a resume starts again from the gas)"
    done = [b for i, b in enumerate(branches) if branch_file(out_dir, i).exists()]
    return f"state A and {len(done)} of {len(branches)} branches from A are saved"
