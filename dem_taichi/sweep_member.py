"""One member of a sweep, run on a Dask worker (or anywhere): :func:`run_member`.

Kept apart from :mod:`dem_taichi.sweep` (the client) so that Dask pickles the task by
reference, whatever module runs the client (``python -m dem_taichi.sweep`` makes that one
``__main__``, whose functions would be pickled by value with their globals).

A member's run directory holds the protocol run (:func:`dem_taichi.protocol.run_protocol`),
``member.json`` (the member record: ``status`` running | done | failed | stale, ``error`` on one
line and ``traceback``, ``seconds``, ``worker``, ``started``, ``finished``, the scene's
SHA-256) and ``progress.log`` (the protocol's progress lines, also sent to the client as Dask
events on the topic :data:`TOPIC`). Taichi is imported and initialised by the protocol, in the
worker process, at the first member it runs; one member runs at a time in a process.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import io
import json
import os
import shutil
import socket
import tempfile
import threading
import time
import traceback
from pathlib import Path
from typing import Any

from dem_taichi.sweep_spec import Member, SweepError

__all__ = ["MEMBER_RECORD", "TOPIC", "member_dir", "run_member", "read_json", "write_json", "now"]

MEMBER_RECORD = "member.json"
TOPIC = "dem_taichi.sweep"
_MEMBER_LOCK = threading.Lock()  # Taichi's runtime is per process: one member at a time


def now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def write_json(path: Path, data: Any) -> None:
    """Write ``data`` as JSON atomically (a killed writer leaves the old file or the new one)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "w") as fh:
        json.dump(data, fh, indent=2, default=str)
    os.replace(tmp, path)


def read_json(path: Path) -> dict | None:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def member_dir(out: str | Path, name: str) -> Path:
    """The run directory of member ``name`` of the sweep in ``out``."""
    return Path(out) / "members" / name


class _ProgressStream(io.TextIOBase):
    """The protocol's progress lines: to ``progress.log``, and each line to the client."""

    def __init__(self, fh, publish) -> None:
        self._fh, self._publish, self._partial = fh, publish, ""

    def write(self, text: str) -> int:
        self._fh.write(text)
        self._fh.flush()
        lines = (self._partial + text).split("\n")
        self._partial = lines.pop()
        for line in lines:
            if line.strip():
                self._publish(line)
        return len(text)

    def flush(self) -> None:
        self._fh.flush()


def _publisher(name: str, folder: str = ""):
    """A function sending ``{"member", "folder", "kind", "text"}`` events to the client (no-op
    outside a Dask worker); ``folder`` (the member's run directory) tells apart members of the
    same name in sweeps sharing one scheduler."""
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):
        return lambda kind, text="": None

    def publish(kind: str, text: str = "") -> None:
        with contextlib.suppress(Exception):  # progress must never fail a member
            worker.log_event(TOPIC, {"member": name, "folder": folder, "kind": kind, "text": text})

    return publish


def _resumable(out: Path, scene_sha256: str) -> bool:
    """Whether the unfinished member run in ``out`` can resume: its protocol saved state A
    (:mod:`dem_taichi.protocol_resume`) and its run record holds this member's scene."""
    from dem_taichi.protocol_resume import RESUME_DIR

    record = read_json(out / "run.json")
    return (
        (out / RESUME_DIR / "A.pkl").exists()
        and record is not None
        and record.get("scene_sha256") == scene_sha256
    )


def run_member(
    name: str,
    scene_toml: str,
    run_dir: str,
    arch: str = "cpu",
    precision: str = "f64",
    workers: int = 1,
    command: str = "dem_taichi.sweep",
) -> dict:
    """Run one member's protocol into ``run_dir`` (on a Dask worker, or anywhere).

    An unfinished run of the member in ``run_dir`` (one whose ``member.json`` is not ``done``)
    resumes from its saved state A and finished branches when it has them and the same scene
    (:mod:`dem_taichi.protocol_resume`); else it is deleted and the protocol starts afresh.
    Returns the member record written to ``run_dir/member.json``: status ``done`` or
    ``failed`` (with ``error``, one line, and ``traceback``), ``seconds``, ``worker``,
    ``started``, ``finished``, ``resumed``. Never raises for a failure of the run itself.
    """
    from dem_taichi.config import scene_from_toml
    from dem_taichi.protocol import run_protocol

    publish = _publisher(name, str(Path(run_dir).resolve()))
    out = Path(run_dir)
    with _MEMBER_LOCK:
        old = read_json(out / MEMBER_RECORD)
        sha = Member(name, {}, {}, scene_toml).scene_sha256
        resume = False
        if out.exists() and any(out.iterdir()):
            if old is None or old.get("status") == "done":
                raise SweepError(f"{out} holds a run this sweep did not leave unfinished")
            resume = _resumable(out, sha)
            if not resume:
                shutil.rmtree(out)
        out.mkdir(parents=True, exist_ok=True)
        record: dict[str, Any] = {
            "name": name,
            "status": "running",
            "scene_sha256": sha,
            "started": now(),
            "resumed": resume,
            "worker": f"{socket.gethostname()}:{os.getpid()}",
            "arch": arch,
            "precision": precision,
        }
        write_json(out / MEMBER_RECORD, record)
        publish("started", record["worker"] + (" (resumed from state A)" if resume else ""))
        start = time.perf_counter()
        try:
            with (
                open(out / "progress.log", "a" if resume else "w") as log,
                contextlib.redirect_stderr(_ProgressStream(log, lambda t: publish("line", t))),
            ):
                result = run_protocol(
                    scene_from_toml(scene_toml),
                    out,
                    arch=arch,
                    precision=precision,
                    progress=True,
                    command=command,
                    workers=workers,
                    resume=resume,
                )
            record["status"] = "done"
            record["states"] = sorted(result.states)
        except Exception as exc:  # noqa: BLE001 - a failed member is a result, not a crash
            record["status"] = "failed"
            record["error"] = f"{type(exc).__name__}: {exc}".splitlines()[0]
            record["traceback"] = traceback.format_exc()
        record["seconds"] = time.perf_counter() - start
        record["finished"] = now()
        write_json(out / MEMBER_RECORD, record)
        publish(record["status"], record.get("error", ""))
        return record
