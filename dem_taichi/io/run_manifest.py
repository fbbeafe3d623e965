"""The record of a run directory (``run.json``) and its manifest: what the run wrote.

The rules they serve are in :mod:`dem_taichi.io.run_directory` (its module docstring): only
entries with a run's names (:data:`RUN_FILE_PATTERNS`) are ever listed, ``--overwrite`` deletes
what the manifest lists (never by name), a listed path outside the folder or a link on the way
is refused. No Taichi here.
"""

from __future__ import annotations

import contextlib
import errno
import fnmatch
import hashlib
import json
import os
import stat
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path, PurePosixPath

from .run_lock import (
    RUN_LOCK,
    RunDirectoryError,
)
from .run_lock import note as _note
from .run_lock import refuse_link as _refuse_link

__all__ = [
    "RUN_RECORD",
    "RUN_FORMAT",
    "RUN_FORMAT_VERSION",
    "RUN_FILE_PATTERNS",
    "RunRecord",
    "scene_sha256",
    "is_used",
]

RUN_RECORD = "run.json"
RUN_FORMAT = "dem_taichi.run"
RUN_FORMAT_VERSION = 1
#: The names a run writes in its directory. Only entries with these names are ever listed in a
#: run's manifest, and ``--overwrite`` deletes what the manifest lists (never by name).
RUN_FILE_PATTERNS = (
    RUN_RECORD,
    "scene.toml",
    "history.nc",
    "relaxed_states.nc",
    "probes.nc",
    "summary.json",
    "report.md",
    "figure_*.png",
    "configuration_*.nc",
    "state_*.npz",
    "path_*.npz",
    "checkpoints",
    "resume",
    "paraview",
)


def scene_sha256(scene_toml: str) -> str:
    """SHA-256 (hex) of a scene's full TOML text (``dem_taichi.scene.config.scene_to_toml``)."""
    return hashlib.sha256(scene_toml.encode("utf-8")).hexdigest()


@dataclass
class RunRecord:
    """The content of ``run.json`` (module docstring). ``files`` None: a record written before
    manifests (its files are unknown: ``overwrite`` is refused)."""

    run_id: str
    command: str
    scene_name: str
    scene_sha256: str
    created: str
    checkpoints: list[str] = field(default_factory=list)
    files: list[str] | None = None
    folders: list[str] = field(default_factory=list)
    preexisting: list[str] = field(default_factory=list)
    format: str = RUN_FORMAT
    format_version: int = RUN_FORMAT_VERSION

    def describe(self) -> str:
        return (
            f"run {self.run_id[:8]} of scene {self.scene_name!r} ({self.command}, "
            f"started {self.created})"
        )


def _read_record(directory: Path) -> RunRecord | None:
    path = directory / RUN_RECORD
    if not path.exists() and not path.is_symlink():
        return None
    try:
        if path.is_symlink():
            raise ValueError("it is a symbolic link")
        data = json.loads(path.read_text())
        if data.get("format") != RUN_FORMAT:
            raise ValueError(f"format is {data.get('format')!r}, not {RUN_FORMAT!r}")
        if int(data.get("format_version", 0)) > RUN_FORMAT_VERSION:
            raise ValueError(f"format version {data['format_version']} is newer than this code's")
        known = RunRecord.__dataclass_fields__
        return RunRecord(**{k: v for k, v in data.items() if k in known})
    except (ValueError, TypeError, KeyError, AttributeError) as error:
        raise RunDirectoryError(
            f"{path} is not a readable run record ({error}); move it away or choose a new --out"
        ) from error


def is_used(directory: str | os.PathLike[str]) -> bool:
    """Whether ``directory`` holds an entry with a name a run writes (:data:`RUN_FILE_PATTERNS`:
    ``run.json``, ``history.nc``, ``checkpoints/``, ``report.md``, ...): a fresh run there would
    replace it."""
    return bool(_run_named(Path(directory)))


def _run_named(folder: Path) -> list[str]:
    """The names of the entries of ``folder`` that a run could write (links included)."""
    if not folder.is_dir():
        return []
    return sorted(e.name for e in folder.iterdir() if _is_run_name(e.name))


# ---- paths inside a run directory -------------------------------------------------------------


def _is_run_name(name: str) -> bool:
    """Whether a top-level entry has one of the names a run writes."""
    return any(fnmatch.fnmatchcase(name, pattern) for pattern in RUN_FILE_PATTERNS)


def _relative(folder: Path, path: str | os.PathLike[str]) -> str:
    """``path`` (relative to ``folder``, or absolute inside it) as a clean ``/``-separated
    relative path; refused when it is not strictly inside ``folder``."""
    given = Path(path)
    if given.is_absolute():
        try:
            given = given.relative_to(folder.absolute())
        except ValueError:
            raise RunDirectoryError(f"{path} is not inside the run folder {folder}") from None
    rel = PurePosixPath(*given.parts)
    if not rel.parts or rel.is_absolute() or any(p in ("..", ".") for p in rel.parts):
        raise RunDirectoryError(f"{path} is not inside the run folder {folder}")
    return str(rel)


def _symlink_on_the_way(folder: Path, rel: str) -> Path | None:
    """The first symbolic link among ``folder/rel`` and its folders below ``folder``, or None."""
    here = folder
    for part in PurePosixPath(rel).parts:
        here = here / part
        if here.is_symlink():
            return here
    return None


def _run_entries(folder: Path) -> tuple[set[str], set[str], list[Path]]:
    """The files and folders with a run's names in ``folder`` (inside run-named folders, all
    of them), and the symbolic links among them (never followed)."""
    files: set[str] = set()
    folders: set[str] = set()
    links: list[Path] = []
    if not folder.is_dir():
        return files, folders, links
    for entry in sorted(folder.iterdir()):
        if not _is_run_name(entry.name):
            continue
        if entry.is_symlink():
            links.append(entry)
        elif entry.is_dir():
            folders.add(entry.name)
            for root, dirs, names in os.walk(entry, followlinks=False):
                base = Path(root)
                for name in [*dirs, *names]:
                    path = base / name
                    rel = str(PurePosixPath(*path.relative_to(folder).parts))
                    if path.is_symlink():
                        links.append(path)
                    elif path.is_dir():
                        folders.add(rel)
                    else:
                        files.add(rel)
        else:
            files.add(entry.name)
    return files, folders, links


def _check_no_links(folder: Path) -> None:
    """Refuse a claim when an entry a run writes is a symbolic link (module docstring)."""
    _, _, links = _run_entries(folder)
    lock = folder / RUN_LOCK
    if lock.is_symlink():
        links.insert(0, lock)
    if links:
        raise _refuse_link(links[0])


# ---- the manifest -------------------------------------------------------------------------


def _complete_manifest(folder: Path, record: RunRecord) -> None:
    """Add every entry with a run's name that was not there before the run (``preexisting``)."""
    files, folders, _ = _run_entries(folder)
    before = set(record.preexisting)
    listed = set(record.files or [])
    record.files = sorted(listed | (files - before))
    record.folders = sorted(set(record.folders) | (folders - before))


def _save_record(folder: Path, record: RunRecord) -> None:
    """Write ``run.json`` atomically (temporary file, fsync, rename: never through a link)."""
    text = json.dumps(asdict(record), indent=2) + "\n"
    handle, temp = tempfile.mkstemp(dir=folder, prefix=f".{RUN_RECORD}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "w") as stream:
            stream.write(text)
            stream.flush()
            os.fsync(stream.fileno())
        os.chmod(temp, 0o644)
        os.replace(temp, folder / RUN_RECORD)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temp)
        raise


def _checked_manifest(folder: Path, record: RunRecord) -> tuple[list[str], list[str]]:
    """The manifest's files and folders, each checked to lie inside ``folder`` (refused else:
    a record that names other paths is not deleted from)."""
    clean = []
    for entry in [*(record.files or []), *record.folders]:
        try:
            rel = _relative(folder, entry)
        except RunDirectoryError:
            rel = None
        if rel is None or rel != entry:
            raise RunDirectoryError(
                f"{folder / RUN_RECORD} lists {entry!r}, not a path inside {folder}; --overwrite "
                "deletes nothing on such a record: delete the old run's files by hand or choose "
                "a new --out"
            )
        clean.append(rel)
    return list(record.files or []), list(record.folders)


def _delete_manifest(folder: Path, record: RunRecord) -> None:
    """Delete what the run's manifest lists: its regular files, then its folders left empty
    (deepest first). A listed path behind a symbolic link, or that is now a link or a folder, is
    kept; so is a listed folder holding files the run did not write (one note)."""
    files, folders = _checked_manifest(folder, record)
    for rel in files:
        path = folder / rel
        if _symlink_on_the_way(folder, rel) is not None:
            continue
        with contextlib.suppress(FileNotFoundError):
            if stat.S_ISREG(path.lstat().st_mode):
                path.unlink()
    kept = []
    for rel in sorted(folders, key=lambda r: len(PurePosixPath(r).parts), reverse=True):
        path = folder / rel
        if _symlink_on_the_way(folder, rel) is not None or not path.is_dir():
            continue
        try:
            path.rmdir()
        except OSError as error:
            if error.errno not in (errno.ENOTEMPTY, errno.EEXIST):
                raise
            kept.append(rel)
    if kept:
        _note(f"kept {', '.join(kept)} in {folder}: they hold files the old run did not write")
