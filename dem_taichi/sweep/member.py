"""One member of a sweep, run on a Dask worker (or anywhere): :func:`run_member`.

Kept apart from :mod:`dem_taichi.sweep.command` (the client) so that Dask pickles the task by
reference, whatever module runs the client (``python -m dem_taichi.sweep`` makes that one
``__main__``, whose functions would be pickled by value with their globals).

A member's run directory holds the protocol run (:func:`dem_taichi.protocol.runner.run_protocol`),
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
import socket
import tempfile
import threading
import time
import traceback
from pathlib import Path
from typing import Any

from dem_taichi.sweep.spec import Member, SweepError, check_member_name

__all__ = [
    "MEMBER_RECORD",
    "TOPIC",
    "member_dir",
    "checked_member_dir",
    "can_resume",
    "run_member",
    "read_json",
    "write_json",
    "now",
]

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
    """The run directory of member ``name`` of the sweep in ``out`` (``name`` checked by
    :func:`dem_taichi.sweep.spec.check_member_name`: no path separator, not ``..``)."""
    return Path(out) / "members" / check_member_name(name, "member")


def checked_member_dir(out: str | Path, name: str) -> Path:
    """:func:`member_dir`, resolved (symbolic links followed) and checked to be the folder
    ``<name>`` directly in ``out/members``; :class:`SweepError` otherwise. Called before
    anything in a member's folder is written or deleted: a link (of the member's folder, or
    of ``members``) must not make a re-run delete another folder."""
    folder = member_dir(out, name)
    resolved = folder.resolve()
    expected = Path(out).resolve() / "members" / name
    if resolved != expected:
        raise SweepError(
            f"member {name}: its folder {folder} resolves to {resolved}, not inside the sweep "
            f"folder {expected.parent}: refusing to write or delete there (a symbolic link?)"
        )
    return resolved


def _check_run_dir(out: Path, name: str, sweep_dir: str) -> Path:
    """The member's run directory ``out``, resolved and checked before anything in it is
    deleted: ``<sweep_dir>/members/<name>`` when ``sweep_dir`` is given, else at least a
    folder named ``name`` in a folder named ``members``."""
    resolved = out.resolve()
    if sweep_dir:
        expected = checked_member_dir(sweep_dir, name)
        if resolved != expected:
            raise SweepError(
                f"member {name}: run directory {out} resolves to {resolved}, not {expected}: "
                "refusing to write or delete there"
            )
        return resolved
    check_member_name(name, "member")
    if resolved.name != name or resolved.parent.name != "members":
        raise SweepError(
            f"member {name}: run directory {out} resolves to {resolved}, not .../members/{name}: "
            "refusing to write or delete there"
        )
    return resolved


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


def can_resume(out: Path, scene_sha256: str) -> bool:
    """Whether the unfinished member run in ``out`` can resume: its protocol saved state A
    (:func:`dem_taichi.protocol.resume.stage_a_file`) or a point of its ageing stage
    (:func:`dem_taichi.protocol.resume.ageing_file`), and its run record holds this member's
    scene."""
    from dem_taichi.protocol.resume import ageing_file, stage_a_file

    record = read_json(out / "run.json")
    return (
        (stage_a_file(out).exists() or ageing_file(out).exists())
        and record is not None
        and record.get("scene_sha256") == scene_sha256
    )


def _clear_unfinished(out: Path, name: str, command: str, sha: str) -> dict | None:
    """Before a member runs again in its folder ``out``: take the folder's run lock and, when
    the run cannot resume, delete that run's files by its manifest (``run.json``: what
    ``--overwrite`` deletes), nothing else. A folder locked by a live process (the member
    still running elsewhere) is left alone: the member is skipped, and the returned record
    (status ``skipped``, not written to ``member.json``, which is that process's) says why in
    one line. None when the member may run."""
    import sys

    from dem_taichi.io.run_directory import RunLock, RunLockedError, delete_listed

    try:
        lock = RunLock.acquire(out, f"{command} (clearing member {name})")
    except RunLockedError as error:
        line = f"member {name}: skipped, its folder is in use ({error})"
        print(line, file=sys.stderr, flush=True)
        return {"name": name, "status": "skipped", "error": line, "scene_sha256": sha,
                "seconds": 0.0, "finished": now()}  # fmt: skip
    try:
        if not can_resume(out, sha):
            delete_listed(out, lock)
    finally:
        lock.release()  # the protocol takes it again for the run
    return None


def run_member(
    name: str,
    scene_toml: str,
    run_dir: str,
    arch: str = "cpu",
    precision: str = "f64",
    workers: int = 1,
    # the run record's name (kept from the flat layout: older runs resume)
    command: str = "dem_taichi.sweep",
    sweep_dir: str = "",
) -> dict:
    """Run one member's protocol into ``run_dir`` (on a Dask worker, or anywhere).

    An unfinished run of the member in ``run_dir`` (one whose ``member.json`` is not ``done``)
    resumes from its saved state A and finished branches when it has them and the same scene
    (:mod:`dem_taichi.protocol.resume`); else the files its ``run.json`` lists are deleted (with
    the folder's run lock held; nothing else in the folder) and the protocol starts afresh. A
    folder whose run lock a live process holds is not touched: the record returned has status
    ``skipped`` (one line in ``error``) and ``member.json`` is left as it is.
    Returns the member record written to ``run_dir/member.json``: status ``done`` or
    ``failed`` (with ``error``, one line, and ``traceback``), ``seconds``, ``worker``,
    ``started``, ``finished``, ``resumed``. Never raises for a failure of the run itself.
    ``run_dir`` must resolve to ``<sweep_dir>/members/<name>`` (or, without ``sweep_dir``, to a
    folder ``name`` in a folder ``members``): :class:`SweepError` before anything is deleted.
    """
    from dem_taichi.protocol.runner import run_protocol
    from dem_taichi.scene.config import scene_from_toml

    out = _check_run_dir(Path(run_dir), name, sweep_dir)
    publish = _publisher(name, str(out))
    with _MEMBER_LOCK:
        old = read_json(out / MEMBER_RECORD)
        sha = Member(name, {}, {}, scene_toml).scene_sha256
        resume = False
        if out.exists() and any(out.iterdir()):
            if old is None or old.get("status") == "done":
                raise SweepError(f"{out} holds a run this sweep did not leave unfinished")
            skipped = _clear_unfinished(out, name, command, sha)
            if skipped is not None:
                publish("skipped", skipped["error"])
                return skipped
            resume = can_resume(out, sha)
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
