"""The lock of a run directory (``run.lock``), and the errors of run directories.

The lock file holds JSON (``pid``, ``host``, ``started``, ``command``, ``token``) and is created
in one step (a hard link of a complete temporary file; ``O_EXCL`` where hard links are not
supported). A live holder refuses a second taker (:class:`RunLockedError`, naming the lock and
its PID); a lock whose PID is dead on this host is stale and taken over with a one-line note; a
lock from another host is never judged. The rules of run directories that use it are in
:mod:`dem_taichi.io.run_directory`. No Taichi here.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import errno
import gc
import json
import os
import socket
import sys
import tempfile
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Self

__all__ = [
    "RUN_LOCK",
    "RunDirectoryError",
    "RunLockedError",
    "DirectoryLock",
    "refuse_link",
    "note",
]

RUN_LOCK = "run.lock"


class RunDirectoryError(ValueError):
    """A run directory that cannot be used as asked (used, other scene, nothing to resume)."""


class RunLockedError(RunDirectoryError):
    """The directory's lock is held by a running process (or one on another host)."""


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def note(line: str) -> None:
    """A one-line note on stderr (a stale lock taken over, a folder kept)."""
    print(f"note: {line}", file=sys.stderr, flush=True)


def refuse_link(link: Path) -> RunDirectoryError:
    return RunDirectoryError(
        f"{link} is a symbolic link (to {os.readlink(link)}); a run never writes through a "
        "link: remove the link or choose a new --out"
    )


# ---- the lock -----------------------------------------------------------------------------


def _pid_alive(pid: int) -> bool:
    """Whether process ``pid`` exists on this host (a zombie counts as alive)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OSError:
        return False
    return True


def _read_lock(path: Path) -> dict | None:
    """The content of a lock file; None when it vanished; {} when it is unreadable."""
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        return None
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _describe_lock(data: dict) -> str:
    return (
        f"PID {data.get('pid', '?')} on host {data.get('host', '?')}, started "
        f"{data.get('started', '?')} ({data.get('command', '?')})"
    )


def _write_new_lock(path: Path, data: dict) -> bool:
    """Create the lock file with its content in one step (hard link of a temporary file);
    False when a lock exists already."""
    handle, temp = tempfile.mkstemp(dir=path.parent, prefix=f".{RUN_LOCK}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "w") as stream:
            stream.write(json.dumps(data) + "\n")
        try:
            os.link(temp, path)
        except FileExistsError:
            return False
        except OSError as error:  # a file system without hard links
            if error.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP):
                raise
            return _write_new_lock_exclusive(path, data)
        return True
    finally:
        with contextlib.suppress(OSError):
            os.unlink(temp)


def _write_new_lock_exclusive(path: Path, data: dict) -> bool:
    """Create the lock file with O_EXCL, then write it (where hard links are not supported:
    a reader may then see it empty for a moment, and refuses it as unreadable)."""
    try:
        handle = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    except FileExistsError:
        return False
    with os.fdopen(handle, "w") as stream:
        stream.write(json.dumps(data) + "\n")
    return True


class DirectoryLock:
    """The lock of a directory held by this process (module docstring)."""

    def __init__(self, path: Path, data: dict) -> None:
        self.path = path
        self.data = data

    @staticmethod
    def on_stale(folder: Path) -> None:
        """Called with the folder when its stale lock is taken over (nothing here; the run
        directory's lock completes the dead run's manifest)."""

    @staticmethod
    def own_runs_open() -> bool:
        """Whether this process holds runs open (one dropped in a reference cycle still holds
        its lock: the taker collects garbage once before refusing). None here."""
        return False

    @classmethod
    def acquire(cls, folder: Path, command: str) -> Self:
        """Take ``folder/run.lock``: refused (:class:`RunLockedError`) when a live process holds
        it; a stale one (dead PID on this host) is taken over with a one-line note."""
        path = folder / RUN_LOCK
        if path.is_symlink():
            raise refuse_link(path)
        data = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "started": _now(),
            "command": command,
            "token": uuid.uuid4().hex,
        }
        for attempt in range(5):
            if _write_new_lock(path, data):
                return cls(path, data)
            held = _read_lock(path)
            if held is None:
                continue  # released meanwhile: try again
            if attempt == 0 and held.get("pid") == os.getpid() and cls.own_runs_open():
                gc.collect()  # a run of this process dropped in a reference cycle: closes it
                continue
            _take_over_if_stale(folder, path, held, cls.on_stale)
        raise RunLockedError(f"{path}: could not take the lock (others keep taking it); try again")

    def is_held(self) -> bool:
        """Whether the lock file is still exactly this lock."""
        return _read_lock(self.path) == self.data

    def release(self) -> None:
        """Delete the lock file if it is still this process's own."""
        held = _read_lock(self.path)
        if held and held.get("token") == self.data["token"]:
            with contextlib.suppress(FileNotFoundError):
                self.path.unlink()


def _take_over_if_stale(
    folder: Path, path: Path, held: dict, on_stale: Callable[[Path], None]
) -> None:
    """Remove a stale lock (``on_stale(folder)`` first: the run directory completes the dead
    run's manifest), or refuse a live one."""
    here = socket.gethostname()
    pid = held.get("pid")
    if not held or not isinstance(pid, int):
        raise RunLockedError(
            f"{path} is not a readable lock; if no run is writing into {folder}, delete the lock"
        )
    if held.get("host") != here:
        raise RunLockedError(
            f"{folder} is locked by {path}, held by {_describe_lock(held)}, not this host "
            f"({here}), so whether it still runs cannot be checked from here; if that run is "
            "gone, delete the lock"
        )
    if _pid_alive(pid):
        raise RunLockedError(
            f"{folder} is in use: {path} is held by running {_describe_lock(held)}; wait for it "
            f"to end, stop it (kill {pid}), or choose a new --out"
        )
    aside = path.with_name(f".{RUN_LOCK}.stale.{uuid.uuid4().hex[:8]}")
    try:
        os.rename(path, aside)
    except FileNotFoundError:
        return  # another process took it over first: try again
    if _read_lock(aside) != held:  # raced: a fresh lock was put there meanwhile; put it back
        with contextlib.suppress(OSError):
            os.link(aside, path)
        os.unlink(aside)
        return
    os.unlink(aside)
    with contextlib.suppress(RunDirectoryError):
        on_stale(folder)
    note(f"took over the stale lock {path} of {_describe_lock(held)}: that process is gone")
