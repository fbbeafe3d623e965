"""Run directories: one run per directory, named by a run id and the hash of its scene.

A run (``python -m dem_taichi run`` or ``protocol``,
:func:`dem_taichi.protocol.runner.run_protocol`) claims its output directory: it takes the
directory's lock (:data:`RUN_LOCK`) and writes ``run.json`` (atomically):

- ``run_id``: a random 32-hex-digit id, also written into the history's global attributes;
- ``scene_sha256``: SHA-256 of the full scene TOML (``scene_to_toml``: every key, defaults
  included, so the hash does not depend on how the scene file was written);
- ``command``, ``scene_name``, ``created`` (UTC);
- ``checkpoints``: the names of the checkpoints this run has written and kept (``run`` only);
- ``files`` and ``folders``: the manifest, every file and folder the run has written (paths
  relative to the directory, ``/``-separated); ``preexisting``: the entries with a run's names
  (:data:`RUN_FILE_PATTERNS`) that were there before the run, which it never lists.

Rules (issues 11 and 22):

- a fresh run into a *used* directory (one holding an entry with a name a run writes:
  ``run.json``, ``history.nc``, ``checkpoints/``, ``report.md``, ...) is refused
  (:class:`RunDirectoryError`) unless ``overwrite``: then the files
  of the old run's manifest are deleted (its folders too when they are left empty) and nothing
  else. ``overwrite`` is refused for a directory without ``run.json`` (or with one from before
  manifests), for the current folder, the home folder, ``/`` and any folder above them, and an
  empty ``--out`` is refused always;
- the lock ``run.lock`` (JSON: ``pid``, ``host``, ``started``, ``command``, ``token``) is held
  while the run writes: a second run, a resume or an ``overwrite`` of a locked directory is
  refused naming the lock and its PID. A lock whose PID is dead on this host is stale: it is
  taken over with a one-line note (the dead run's manifest is completed first). A lock from
  another host is never judged: delete it by hand when that run is gone. The lock is released
  by :meth:`RunDirectory.close` (``with run:``), or when the :class:`RunDirectory` is garbage
  collected or the interpreter exits;
- a run never writes through a symbolic link: a link among the entries a run writes (or a
  link as a folder between the directory and such an entry) is refused when the directory is
  claimed and when an output is registered (:meth:`RunDirectory.output`). Refused, not
  replaced: the link is the user's, and replacing it would delete it;
- the manifest grows as outputs are registered (:meth:`RunDirectory.output`, before writing: a
  crash leaves a manifest listing a file not written yet, never a file not listed) and when the
  run closes: every entry with a run's name that was not in ``preexisting`` is added (this is
  how the files of writers that do not register, e.g. the protocol's, are listed);
- a resume (:func:`resume_run`, :func:`reopen_run`) is refused when the scene given differs
  from the run's (by hash) or from the scene in the run's latest checkpoint;
- checkpoint rotation (:meth:`RunDirectory.add_checkpoint`) deletes only checkpoints listed in
  the run's own record, never another file of the directory.

A directory written before run records existed (no ``run.json``) is adopted on resume when the
scene of its latest checkpoint equals the scene given. No Taichi here.
"""

from __future__ import annotations

import os
import uuid
import weakref
from pathlib import Path, PurePosixPath

from .checkpoint import latest_intact_checkpoint, list_checkpoints
from .run_lock import (
    RUN_LOCK,
    DirectoryLock,
    RunDirectoryError,
    RunLockedError,
    _now,
)
from .run_lock import note as _note
from .run_lock import refuse_link as _refuse_link
from .run_manifest import (
    RUN_FILE_PATTERNS,
    RUN_RECORD,
    RunRecord,
    _check_no_links,
    _complete_manifest,
    _delete_manifest,
    _read_record,
    _relative,
    _run_entries,
    _run_named,
    _save_record,
    _symlink_on_the_way,
    is_used,
    scene_sha256,
)

__all__ = [
    "RUN_RECORD",
    "RUN_LOCK",
    "RUN_FILE_PATTERNS",
    "RunDirectoryError",
    "RunLockedError",
    "RunLock",
    "RunRecord",
    "RunDirectory",
    "scene_sha256",
    "start_run",
    "resume_run",
    "reopen_run",
    "is_used",
    "release_all",
    "delete_listed",
]


def delete_listed(directory: str | os.PathLike[str], lock: DirectoryLock) -> bool:
    """Delete the run of ``directory`` as ``--overwrite`` does: the files and folders its
    ``run.json`` lists (a folder kept when it holds other files), nothing else. ``lock``: the
    directory's lock, held by the caller (:meth:`RunLock.acquire`). Returns False when there is
    no ``run.json`` (nothing is deleted); refused (:class:`RunDirectoryError`) for a record from
    before manifests or one naming paths outside the folder."""
    folder = Path(directory)
    if lock.path != folder / RUN_LOCK or not lock.is_held():
        raise RunDirectoryError(f"{folder}: delete_listed needs the folder's own lock, held")
    if _read_record(folder) is None:
        return False
    _delete_manifest(folder, _old_record_to_replace(folder))
    return True


class RunLock(DirectoryLock):
    """The lock of a run directory: taking over a stale one completes the dead run's manifest
    first; a run of this process left in a reference cycle is collected before a refusal."""

    @staticmethod
    def on_stale(folder: Path) -> None:
        record = _read_record(folder)
        if record is not None and record.files is not None:
            _complete_manifest(folder, record)
            _save_record(folder, record)

    @staticmethod
    def own_runs_open() -> bool:
        return bool(_HELD)


# ---- the claimed directory ----------------------------------------------------------------

_HELD: weakref.WeakSet = weakref.WeakSet()


def _finish(folder: Path, record: RunRecord, lock: RunLock) -> None:
    """Close a run: complete its manifest and release its lock (also the finalizer). Nothing
    in a forked child: the run and its lock are the parent's."""
    if os.getpid() != lock.data["pid"]:
        return
    try:
        if folder.is_dir() and (folder / RUN_RECORD).is_file() and record.files is not None:
            _complete_manifest(folder, record)
            _save_record(folder, record)
    finally:
        lock.release()


class RunDirectory:
    """A claimed run directory: its path, record and lock, with per-run checkpoint rotation.

    Use it as a context manager (``with start_run(...) as run:``) or call :meth:`close`; a
    directory never closed is closed when garbage collected or at interpreter exit.
    """

    def __init__(self, path: Path, record: RunRecord, lock: RunLock | None = None) -> None:
        self.path = path
        self.record = record
        self.lock = lock
        self._finalizer = (
            weakref.finalize(self, _finish, path, record, lock) if lock is not None else None
        )
        if lock is not None:
            _HELD.add(self)

    def __enter__(self) -> RunDirectory:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Complete the manifest and release the lock (idempotent)."""
        if self._finalizer is not None:
            self._finalizer()

    @property
    def closed(self) -> bool:
        return self._finalizer is None or not self._finalizer.alive

    @property
    def run_id(self) -> str:
        return self.record.run_id

    @property
    def checkpoint_dir(self) -> Path:
        return self.path / "checkpoints"

    def save(self) -> None:
        """Write ``run.json`` atomically (temporary file, fsync, rename)."""
        _save_record(self.path, self.record)

    def output(self, path: str | os.PathLike[str]) -> Path:
        """Register an output before writing it: ``path`` (relative to the run folder, or
        absolute inside it) is listed in the manifest with the folders made for it. Refused
        when it lies outside the folder or a symbolic link is on its way. Returns its path."""
        rel = _relative(self.path, path)
        link = _symlink_on_the_way(self.path, rel)
        if link is not None:
            raise _refuse_link(link)
        parts = PurePosixPath(rel).parts
        new_folders = {str(PurePosixPath(*parts[:i])) for i in range(1, len(parts))}
        new_folders -= set(self.record.preexisting)
        files = set(self.record.files or [])
        if rel not in files or not new_folders <= set(self.record.folders):
            self.record.files = sorted(files | {rel})
            self.record.folders = sorted(set(self.record.folders) | new_folders)
            self.save()
        return self.path / rel

    def latest_checkpoint(self) -> Path | None:
        """The run's own checkpoint of the greatest step that exists and loads whole, or None.

        A damaged newer one (flipped byte, cut short) is passed over with one note naming it
        and the older checkpoint used (:func:`~dem_taichi.io.checkpoint.latest_intact_checkpoint`).
        """
        own = set(self.record.checkpoints)
        found = [p for p in list_checkpoints(self.checkpoint_dir) if p.name in own]
        return latest_intact_checkpoint(found, _note)

    def add_checkpoint(self, path: str | os.PathLike[str], keep: int = 2) -> list[Path]:
        """Record a checkpoint just written and delete the run's own older ones beyond ``keep``.

        Only checkpoints listed in this run's record are ever deleted. Returns the deleted paths.
        """
        if isinstance(keep, bool) or not isinstance(keep, int) or keep < 1:
            raise ValueError(f"keep must be an int >= 1, got {keep!r}")
        name = Path(path).name
        names = [n for n in self.record.checkpoints if n != name] + [name]
        # checkpoint names sort in step order (12-digit steps)
        names.sort()
        removed = [self.checkpoint_dir / n for n in names[:-keep]]
        self.record.checkpoints = names[-keep:]
        if self.record.files is not None:
            gone = {f"checkpoints/{p.name}" for p in removed}
            listed = (set(self.record.files) | {f"checkpoints/{name}"}) - gone
            self.record.files = sorted(listed)
            if "checkpoints" not in self.record.preexisting:
                self.record.folders = sorted(set(self.record.folders) | {"checkpoints"})
        self.save()  # the record first: a crash now leaves extra files, never a dangling list
        for entry in removed:
            entry.unlink(missing_ok=True)
        for entry in self.checkpoint_dir.glob(".checkpoint_*.tmp"):
            entry.unlink(missing_ok=True)  # left by a crashed save of this run
        return removed


def release_all() -> None:
    """Close every run directory this process still holds (a command line's last word)."""
    for run in list(_HELD):
        run.close()


# ---- claiming ---------------------------------------------------------------------------


def _checked_out(directory: str | os.PathLike[str]) -> Path:
    """The ``--out`` folder as a path; refused when empty or a file."""
    if isinstance(directory, str) and not directory.strip():
        raise RunDirectoryError(
            "--out is empty: give the run's folder (an empty --out would mean the current folder)"
        )
    folder = Path(directory)
    if (folder.exists() or folder.is_symlink()) and not folder.is_dir():
        raise RunDirectoryError(f"--out {folder} is a file, not a directory; choose a directory")
    return folder


def _refuse_overwrite_of_a_top_folder(folder: Path) -> None:
    """``--overwrite`` never works in the current folder, the home folder, ``/`` or above."""
    target = folder.resolve()
    for name, top in (("the current folder", Path.cwd()), ("your home folder", Path.home())):
        top = top.resolve()
        if target == top or target in top.parents:
            what = name if target == top else f"a folder above {name}"
            raise RunDirectoryError(
                f"--out {folder} is {what} ({target}); --overwrite is refused there: give the "
                "run's own folder"
            )
    if target == Path(target.anchor):
        raise RunDirectoryError(f"--out {folder} is the root folder; --overwrite is refused there")


def _refuse_used(folder: Path, resume_hint: bool) -> RunDirectoryError:
    """The refusal of a used directory without ``overwrite``."""
    try:
        previous = _read_record(folder)
    except RunDirectoryError:
        return RunDirectoryError(
            f"--out {folder} already holds an unreadable {RUN_RECORD}; a run needs a directory "
            "of its own: choose a new --out; --overwrite deletes only what a readable "
            f"{RUN_RECORD} lists"
        )
    if previous is None:
        names = _run_named(folder)
        shown = ", ".join(names[:4]) + (", ..." if len(names) > 4 else "")
        resume = " (--resume continues a run from its checkpoints)" if resume_hint else ""
        return RunDirectoryError(
            f"--out {folder} already holds files with the names a run writes ({shown}) but no "
            f"{RUN_RECORD}, so they are not known to be a run's: move them away or choose a new "
            f"--out; --overwrite deletes only what a {RUN_RECORD} lists{resume}"
        )
    what = previous.describe()
    options = "add --overwrite to replace it"
    if resume_hint:
        options += ", or --resume to continue it"
    return RunDirectoryError(
        f"--out {folder} already holds {what}; a run needs a directory of its own: "
        f"choose a new --out, {options}"
    )


def _old_record_to_replace(folder: Path) -> RunRecord:
    """The record of the run ``overwrite`` replaces; refused when there is none to go by."""
    record = _read_record(folder)
    if record is None:
        raise RunDirectoryError(
            f"--overwrite: {folder} holds run files but no {RUN_RECORD}, so what they belong to "
            "is unknown and nothing is deleted; move them away or choose a new --out "
            "(--resume continues a run from its checkpoints)"
        )
    if record.files is None:
        raise RunDirectoryError(
            f"--overwrite: {folder / RUN_RECORD} is from before runs listed their files, so "
            "nothing is deleted; delete the old run's files by hand or choose a new --out"
        )
    return record


def start_run(
    directory: str | os.PathLike[str],
    command: str,
    scene_name: str,
    scene_toml: str,
    overwrite: bool = False,
    resume_hint: bool = False,
) -> RunDirectory:
    """Claim ``directory`` for a fresh run: take its lock and write its ``run.json``.

    A used directory (:func:`is_used`) is refused unless ``overwrite``, which first deletes the
    files listed in the old run's manifest (module docstring). ``resume_hint``: the refusal
    also names ``--resume`` (for the ``run`` command, which can continue a run).
    """
    folder = _checked_out(directory)
    if overwrite:
        _refuse_overwrite_of_a_top_folder(folder)
    folder.mkdir(parents=True, exist_ok=True)
    lock = RunLock.acquire(folder, command)
    try:
        _check_no_links(folder)
        if is_used(folder):
            if not overwrite:
                raise _refuse_used(folder, resume_hint)
            _delete_manifest(folder, _old_record_to_replace(folder))
        files, folders, _ = _run_entries(folder)
        record = RunRecord(
            run_id=uuid.uuid4().hex,
            command=command,
            scene_name=scene_name,
            scene_sha256=scene_sha256(scene_toml),
            created=_now(),
            files=[RUN_RECORD],
            preexisting=sorted(files | folders),
        )
        run = RunDirectory(folder, record, lock)
        run.save()
    except BaseException:
        lock.release()
        raise
    return run


def _listing(folder: Path, record: RunRecord) -> RunRecord:
    """A record from before manifests, listing from now on: what is there now stays unlisted."""
    if record.files is None:
        files, folders, _ = _run_entries(folder)
        record.files = [RUN_RECORD]
        record.preexisting = sorted((files | folders) - {RUN_RECORD})
    return record


def _claim_existing(folder: Path, command: str) -> RunLock:
    """Lock an existing run directory for a resume and refuse links among its outputs."""
    lock = RunLock.acquire(folder, command)
    try:
        _check_no_links(folder)
    except BaseException:
        lock.release()
        raise
    return lock


def resume_run(
    directory: str | os.PathLike[str],
    scene_name: str,
    scene_toml: str,
    checkpoint_scene_toml,
) -> tuple[RunDirectory, Path]:
    """The run of ``directory`` and its latest checkpoint, checked against the scene given.

    ``checkpoint_scene_toml(path)`` returns the full scene TOML stored in a checkpoint (the
    caller reads checkpoints; this module does not know the engine). Refused
    (:class:`RunDirectoryError`) when there is no run or no checkpoint, when the scene given
    differs from the run's, or when the checkpoint's scene differs from the run's. The run's
    lock is taken (refused when held).
    """
    folder = _checked_out(directory)
    given = scene_sha256(scene_toml)
    if not folder.is_dir():
        raise RunDirectoryError(
            f"--resume: {folder} holds no run to continue (no such folder); start a fresh run "
            "without --resume"
        )
    lock = _claim_existing(folder, "run")
    try:
        run, latest = _resumed(folder, scene_name, given, checkpoint_scene_toml, lock)
    except BaseException:
        lock.release()
        raise
    return run, latest


def _resumed(folder: Path, scene_name: str, given: str, checkpoint_scene_toml, lock: RunLock):
    """The body of :func:`resume_run` once the lock is held."""
    record = _read_record(folder)
    if record is None:
        found = list_checkpoints(folder / "checkpoints")
        if not found:
            raise RunDirectoryError(
                f"--resume: {folder} holds no run to continue (no {RUN_RECORD}, no checkpoint "
                "in checkpoints/); start a fresh run without --resume"
            )
        # a run directory from before run records: adopt it if its scene is the one given
        record = RunRecord(
            run_id=uuid.uuid4().hex,
            command="run",
            scene_name=scene_name,
            scene_sha256=scene_sha256(checkpoint_scene_toml(found[-1])),
            created="unknown (adopted on resume)",
            checkpoints=[p.name for p in found],
        )
    record = _listing(folder, record)
    if given != record.scene_sha256:
        raise RunDirectoryError(
            f"--resume: the scene given ({scene_name!r}, sha256 {given[:12]}) is not the scene of "
            f"{record.describe()} in {folder} (sha256 {record.scene_sha256[:12]}); give the "
            f"run's own scene ({folder / 'scene.toml'}) or start a fresh run in a new --out"
        )
    own = set(record.checkpoints)
    found = [p for p in list_checkpoints(folder / "checkpoints") if p.name in own]
    if not found:
        raise RunDirectoryError(
            f"--resume: {record.describe()} in {folder} has no checkpoint yet; start it again "
            "with --overwrite"
        )
    latest = latest_intact_checkpoint(found, _note)
    if latest is None:
        raise RunDirectoryError(
            f"--resume: no checkpoint of {record.describe()} in {folder} loads whole (each "
            "damaged one is named above); start it again with --overwrite"
        )
    stored = scene_sha256(checkpoint_scene_toml(latest))
    if stored != record.scene_sha256:
        raise RunDirectoryError(
            f"--resume: checkpoint {latest} holds another scene (sha256 {stored[:12]}) than "
            f"{record.describe()} (sha256 {record.scene_sha256[:12]}); the directory mixes runs: "
            "start a fresh run in a new --out"
        )
    run = RunDirectory(folder, record, lock)
    run.save()  # an adopted directory gets its record now
    return run, latest


def reopen_run(
    directory: str | os.PathLike[str], command: str, scene_name: str, scene_toml: str
) -> RunDirectory:
    """The run of ``directory`` for a resume of ``command`` (``protocol``), checked against the
    scene given: refused when there is no run record, when it is another command's run, or
    when the scene differs from the run's (by hash). The run's lock is taken (refused when
    held)."""
    folder = _checked_out(directory)
    record = _read_record(folder) if folder.is_dir() else None
    if record is None:
        raise RunDirectoryError(
            f"--resume: {folder} holds no run to continue (no {RUN_RECORD}); start a fresh run "
            "without --resume"
        )
    if record.command != command:
        raise RunDirectoryError(
            f"--resume: {folder} holds {record.describe()}, not a {command} run; resume it with "
            f"its own command or start a fresh {command} run in a new --out"
        )
    given = scene_sha256(scene_toml)
    if given != record.scene_sha256:
        raise RunDirectoryError(
            f"--resume: the scene given ({scene_name!r}, sha256 {given[:12]}) is not the scene of "
            f"{record.describe()} in {folder} (sha256 {record.scene_sha256[:12]}); give the "
            "run's own scene or start a fresh run in a new --out"
        )
    lock = _claim_existing(folder, command)
    try:
        record = _listing(folder, _read_record(folder) or record)
        run = RunDirectory(folder, record, lock)
        run.save()
    except BaseException:
        lock.release()
        raise
    return run
