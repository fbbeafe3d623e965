"""Run directories: one run per directory, named by a run id and the hash of its scene.

A run (``python -m dem_taichi run`` or ``protocol``, :func:`dem_taichi.protocol.run_protocol`)
claims its output directory by writing ``run.json`` first (atomically):

- ``run_id``: a random 32-hex-digit id, also written into the history's global attributes;
- ``scene_sha256``: SHA-256 of the full scene TOML (``scene_to_toml``: every key, defaults
  included, so the hash does not depend on how the scene file was written);
- ``command``, ``scene_name``, ``created`` (UTC);
- ``checkpoints``: the names of the checkpoints this run has written and kept (``run`` only).

Rules (issue 11):

- a fresh run into a *used* directory (one holding ``run.json``, ``history.nc`` or
  ``checkpoints/``) is refused (:class:`RunDirectoryError`) unless ``overwrite``: then the files
  a run writes (:data:`RUN_FILE_PATTERNS`) are deleted first, other files are kept;
- a resume (:func:`resume_run`) is refused when the scene given differs from the run's (by
  hash) or from the scene in the run's latest checkpoint;
- checkpoint rotation (:meth:`RunDirectory.add_checkpoint`) deletes only checkpoints listed in
  the run's own record, never another file of the directory.

A directory written before run records existed (no ``run.json``) is adopted on resume when the
scene of its latest checkpoint equals the scene given. No Taichi here.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import hashlib
import json
import os
import shutil
import tempfile
import uuid
from dataclasses import asdict, dataclass, field
from pathlib import Path

from .checkpoint import list_checkpoints

__all__ = [
    "RUN_RECORD",
    "RUN_FILE_PATTERNS",
    "RunDirectoryError",
    "RunRecord",
    "RunDirectory",
    "scene_sha256",
    "start_run",
    "resume_run",
    "reopen_run",
    "is_used",
]

RUN_RECORD = "run.json"
RUN_FORMAT = "dem_taichi.run"
RUN_FORMAT_VERSION = 1
#: What a run writes in its directory (``--overwrite`` deletes these and nothing else).
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
_USED_MARKERS = (RUN_RECORD, "history.nc", "checkpoints")


class RunDirectoryError(ValueError):
    """A run directory that cannot be used as asked (used, other scene, nothing to resume)."""


def scene_sha256(scene_toml: str) -> str:
    """SHA-256 (hex) of a scene's full TOML text (``dem_taichi.config.scene_to_toml``)."""
    return hashlib.sha256(scene_toml.encode("utf-8")).hexdigest()


@dataclass
class RunRecord:
    """The content of ``run.json`` (module docstring)."""

    run_id: str
    command: str
    scene_name: str
    scene_sha256: str
    created: str
    checkpoints: list[str] = field(default_factory=list)
    format: str = RUN_FORMAT
    format_version: int = RUN_FORMAT_VERSION

    def describe(self) -> str:
        return (
            f"run {self.run_id[:8]} of scene {self.scene_name!r} ({self.command}, "
            f"started {self.created})"
        )


def _read_record(directory: Path) -> RunRecord | None:
    path = directory / RUN_RECORD
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_text())
        if data.get("format") != RUN_FORMAT:
            raise ValueError(f"format is {data.get('format')!r}, not {RUN_FORMAT!r}")
        if int(data.get("format_version", 0)) > RUN_FORMAT_VERSION:
            raise ValueError(f"format version {data['format_version']} is newer than this code's")
        known = RunRecord.__dataclass_fields__
        return RunRecord(**{k: v for k, v in data.items() if k in known})
    except (ValueError, TypeError, KeyError) as error:
        raise RunDirectoryError(
            f"{path} is not a readable run record ({error}); move it away or use --overwrite"
        ) from error


def is_used(directory: str | os.PathLike[str]) -> bool:
    """Whether ``directory`` holds a run (``run.json``, ``history.nc`` or ``checkpoints/``)."""
    folder = Path(directory)
    return folder.is_dir() and any((folder / name).exists() for name in _USED_MARKERS)


def _remove_run_files(folder: Path) -> None:
    for pattern in RUN_FILE_PATTERNS:
        for entry in folder.glob(pattern):
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink(missing_ok=True)


class RunDirectory:
    """A claimed run directory: its path and record, with per-run checkpoint rotation."""

    def __init__(self, path: Path, record: RunRecord) -> None:
        self.path = path
        self.record = record

    @property
    def run_id(self) -> str:
        return self.record.run_id

    @property
    def checkpoint_dir(self) -> Path:
        return self.path / "checkpoints"

    def save(self) -> None:
        """Write ``run.json`` atomically (temporary file, fsync, rename)."""
        text = json.dumps(asdict(self.record), indent=2) + "\n"
        handle, temp = tempfile.mkstemp(dir=self.path, prefix=f".{RUN_RECORD}.", suffix=".tmp")
        try:
            with os.fdopen(handle, "w") as stream:
                stream.write(text)
                stream.flush()
                os.fsync(stream.fileno())
            os.chmod(temp, 0o644)
            os.replace(temp, self.path / RUN_RECORD)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(temp)
            raise

    def latest_checkpoint(self) -> Path | None:
        """The run's own checkpoint of the greatest step that exists, or None."""
        own = set(self.record.checkpoints)
        found = [p for p in list_checkpoints(self.checkpoint_dir) if p.name in own]
        return found[-1] if found else None

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
        self.save()  # the record first: a crash now leaves extra files, never a dangling list
        for entry in removed:
            entry.unlink(missing_ok=True)
        for entry in self.checkpoint_dir.glob(".checkpoint_*.tmp"):
            entry.unlink(missing_ok=True)  # left by a crashed save of this run
        return removed


def start_run(
    directory: str | os.PathLike[str],
    command: str,
    scene_name: str,
    scene_toml: str,
    overwrite: bool = False,
    resume_hint: bool = False,
) -> RunDirectory:
    """Claim ``directory`` for a fresh run and write its ``run.json``.

    A used directory (:func:`is_used`) is refused unless ``overwrite``, which first deletes the
    files a run writes (:data:`RUN_FILE_PATTERNS`). ``resume_hint``: the refusal also names
    ``--resume`` (for the ``run`` command, which can continue a run).
    """
    folder = Path(directory)
    if folder.exists() and not folder.is_dir():
        raise RunDirectoryError(f"--out {folder} is a file, not a directory; choose a directory")
    if is_used(folder):
        if not overwrite:
            try:
                previous = _read_record(folder)
                what = previous.describe() if previous else "the files of an earlier run"
            except RunDirectoryError:
                what = "an unreadable run record"
            options = "add --overwrite to replace it"
            if resume_hint:
                options += ", or --resume to continue it"
            raise RunDirectoryError(
                f"--out {folder} already holds {what}; a run needs a directory of its own: "
                f"choose a new --out, {options}"
            )
        _remove_run_files(folder)
    folder.mkdir(parents=True, exist_ok=True)
    record = RunRecord(
        run_id=uuid.uuid4().hex,
        command=command,
        scene_name=scene_name,
        scene_sha256=scene_sha256(scene_toml),
        created=_dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
    )
    run = RunDirectory(folder, record)
    run.save()
    return run


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
    differs from the run's, or when the checkpoint's scene differs from the run's.
    """
    folder = Path(directory)
    given = scene_sha256(scene_toml)
    record = _read_record(folder) if folder.is_dir() else None
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
    run = RunDirectory(folder, record)
    if given != record.scene_sha256:
        raise RunDirectoryError(
            f"--resume: the scene given ({scene_name!r}, sha256 {given[:12]}) is not the scene of "
            f"{record.describe()} in {folder} (sha256 {record.scene_sha256[:12]}); give the "
            f"run's own scene ({folder / 'scene.toml'}) or start a fresh run in a new --out"
        )
    latest = run.latest_checkpoint()
    if latest is None:
        raise RunDirectoryError(
            f"--resume: {record.describe()} in {folder} has no checkpoint yet; start it again "
            "with --overwrite"
        )
    stored = scene_sha256(checkpoint_scene_toml(latest))
    if stored != record.scene_sha256:
        raise RunDirectoryError(
            f"--resume: checkpoint {latest} holds another scene (sha256 {stored[:12]}) than "
            f"{record.describe()} (sha256 {record.scene_sha256[:12]}); the directory mixes runs: "
            "start a fresh run in a new --out"
        )
    run.save()  # an adopted directory gets its record now
    return run, latest


def reopen_run(
    directory: str | os.PathLike[str], command: str, scene_name: str, scene_toml: str
) -> RunDirectory:
    """The run of ``directory`` for a resume of ``command`` (``protocol``), checked against the
    scene given: refused when there is no run record, when it is another command's run, or
    when the scene differs from the run's (by hash)."""
    folder = Path(directory)
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
    return RunDirectory(folder, record)
