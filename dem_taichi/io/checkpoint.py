"""Checkpoints for an exact resume: numpy arrays + JSON metadata in one ``.npz``, saved atomically.

A checkpoint is written to a temporary file in the target's directory, flushed to disk
(``fsync``) and moved over the target with :func:`os.replace`, so a crash at any moment leaves
either the previous checkpoint or the new one, never a mix. The file is an uncompressed ``.npz``
(zip; every member has a CRC-32 that is checked on load) holding the arrays under their names and
one extra member, ``__meta__``: a JSON text with the format name and version, the name, dtype and
shape of every array (checked on load) and the caller's metadata. No pickles: object arrays are
refused, and files are loaded with ``allow_pickle=False``.

A damaged file (truncated, a flipped byte, not a checkpoint) is :class:`CheckpointError`, one
line naming it; :func:`latest_intact_checkpoint` picks the newest checkpoint of a list that
loads whole, saying in one line which damaged one it passed over for the older one.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import tempfile
import zipfile
import zlib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

FORMAT_NAME = "dem_taichi.checkpoint"
#: Bump when the layout changes; files with a greater version are refused by this code.
FORMAT_VERSION = 1
META_KEY = "__meta__"
CHECKPOINT_PREFIX = "checkpoint_"
CHECKPOINT_SUFFIX = ".npz"
#: Keywords of np.savez itself, which it would take for its own, not as arrays.
_SAVEZ_KEYWORDS = ("file", "allow_pickle")
_STEP_PATTERN = re.compile(rf"^{CHECKPOINT_PREFIX}(\d+){re.escape(CHECKPOINT_SUFFIX)}$")


class CheckpointError(RuntimeError):
    """A checkpoint file that is corrupt, not a checkpoint, or of an incompatible version."""


def checkpoint_path(directory: str | os.PathLike[str], step: int) -> Path:
    """``DIR/checkpoint_<step, 12 digits>.npz``: names sort in step order."""
    if isinstance(step, bool) or not isinstance(step, int | np.integer) or step < 0:
        raise ValueError(f"step must be a non-negative integer, got {step!r}")
    return Path(directory) / f"{CHECKPOINT_PREFIX}{int(step):012d}{CHECKPOINT_SUFFIX}"


def _check_arrays(arrays: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    checked: dict[str, np.ndarray] = {}
    for name, value in arrays.items():
        reserved = (META_KEY, *_SAVEZ_KEYWORDS)
        if not isinstance(name, str) or not name.isidentifier() or name in reserved:
            raise ValueError(
                f"array name {name!r} not allowed: use an identifier other than "
                + ", ".join(repr(r) for r in reserved)
            )
        array = np.asarray(value)
        if array.dtype.kind not in "biufcUS":
            raise TypeError(
                f"array {name!r} has dtype {array.dtype}; only numeric, bool and fixed-width "
                "string arrays can be checkpointed (no pickles)"
            )
        checked[name] = array
    return checked


def _fsync_directory(directory: Path) -> None:
    # Makes the rename durable; not possible on every platform/filesystem, hence best effort.
    with contextlib.suppress(OSError):
        descriptor = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(descriptor)
        finally:
            os.close(descriptor)


def save_checkpoint(
    path: str | os.PathLike[str],
    arrays: Mapping[str, np.ndarray],
    meta: Mapping[str, Any],
) -> Path:
    """Save ``arrays`` and JSON-serialisable ``meta`` to ``path`` atomically; returns the path.

    Arrays come back from :func:`load_checkpoint` bit for bit, with their dtypes and shapes.
    """
    target = Path(path)
    if target.suffix != CHECKPOINT_SUFFIX:
        raise ValueError(f"checkpoint path {target} must end in {CHECKPOINT_SUFFIX}")
    checked = _check_arrays(arrays)
    header = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "arrays": {
            name: {"dtype": array.dtype.str, "shape": list(array.shape)}
            for name, array in checked.items()
        },
        "meta": dict(meta),
    }
    try:
        meta_text = json.dumps(header, allow_nan=True, sort_keys=True)
    except (TypeError, ValueError) as error:
        raise TypeError(
            f"checkpoint meta must be JSON-serialisable (str, int, float, bool, None, lists, "
            f"dicts): {error}"
        ) from error
    target.parent.mkdir(parents=True, exist_ok=True)
    handle, temp_name = tempfile.mkstemp(
        dir=target.parent, prefix=f".{target.name}.", suffix=".tmp"
    )
    temp = Path(temp_name)
    # Any: numpy's stub would take the arrays for savez's own keyword allow_pickle (never one
    # of them: _check_arrays refuses its keywords)
    members: dict[str, Any] = {**checked, META_KEY: np.array(meta_text)}
    try:
        with os.fdopen(handle, "wb") as stream:
            np.savez(stream, **members)
            stream.flush()
            os.fsync(stream.fileno())
        mask = os.umask(0)  # mkstemp makes owner-only files; a checkpoint is an ordinary file
        os.umask(mask)
        os.chmod(temp, 0o666 & ~mask)
        os.replace(temp, target)
    except BaseException:
        temp.unlink(missing_ok=True)
        raise
    _fsync_directory(target.parent)
    return target


def load_checkpoint(path: str | os.PathLike[str]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """``(arrays, meta)`` of a checkpoint saved by :func:`save_checkpoint`.

    Raises FileNotFoundError for a missing file and :class:`CheckpointError` for a file that is
    corrupt (bad zip, CRC mismatch, missing members, dtype/shape differing from the header), not
    a checkpoint, or of a newer format version.
    """
    source = Path(path)
    if not source.is_file():
        raise FileNotFoundError(f"checkpoint {source} does not exist")
    try:
        with _open_archive(source) as archive:
            header = _read_header(source, archive)
            arrays = _read_arrays(source, archive, header["arrays"])
            meta = dict(header["meta"])
    except CheckpointError:
        raise
    except _READ_ERRORS as error:
        raise CheckpointError(f"{source} is corrupt or not a checkpoint: {error}") from error
    return arrays, meta


#: What reading a damaged or foreign file can raise (caught and reported as CheckpointError).
_READ_ERRORS = (
    zipfile.BadZipFile, zlib.error, ValueError, KeyError, TypeError, AttributeError, OSError,
    EOFError,
)  # fmt: skip


def _open_archive(source: Path):
    """The ``.npz`` archive of ``source``, read with ``allow_pickle=False`` (a ``.npy`` or
    anything else is refused)."""
    archive = np.load(source, allow_pickle=False)
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise CheckpointError(f"{source} is not a dem_taichi checkpoint (not an .npz archive)")
    return archive


def _read_header(source: Path, archive) -> dict[str, Any]:
    """The checked JSON header of an open checkpoint archive."""
    if META_KEY not in archive.files:
        raise CheckpointError(f"{source} is not a dem_taichi checkpoint (no {META_KEY})")
    header = json.loads(str(archive[META_KEY][()]))
    if not isinstance(header, dict) or header.get("format") != FORMAT_NAME:
        raise CheckpointError(f"{source} is not a {FORMAT_NAME} file")
    version = header.get("format_version")
    if not isinstance(version, int) or version > FORMAT_VERSION:
        raise CheckpointError(
            f"{source} has checkpoint format version {version!r}; this code reads "
            f"versions up to {FORMAT_VERSION} (update dem_taichi or rerun)"
        )
    if not (isinstance(header.get("arrays"), dict) and isinstance(header.get("meta"), dict)):
        raise CheckpointError(f"{source} is corrupt: its header lists no arrays or no meta")
    return header


def _read_arrays(source: Path, archive, listed: dict) -> dict[str, np.ndarray]:
    """Every array of an open checkpoint archive, checked against the header's list (the zip
    checks each member's CRC-32 as it is read)."""
    stored = set(archive.files) - {META_KEY}
    if set(listed) != stored:
        raise CheckpointError(
            f"{source} is corrupt: arrays {sorted(stored)} do not match the header's "
            f"{sorted(listed)}"
        )
    arrays: dict[str, np.ndarray] = {}
    for name, spec in listed.items():
        array = archive[name]
        if array.dtype.str != spec["dtype"] or list(array.shape) != spec["shape"]:
            raise CheckpointError(
                f"{source} is corrupt: array {name!r} is {array.dtype.str}{array.shape}, "
                f"the header says {spec['dtype']}{tuple(spec['shape'])}"
            )
        arrays[name] = array
    return arrays


def latest_intact_checkpoint(
    candidates: Sequence[str | os.PathLike[str]],
    say: Callable[[str], None] | None = None,
) -> Path | None:
    """The newest of ``candidates`` (oldest first, as :func:`list_checkpoints` gives them)
    that loads whole (every array's CRC and header checked), or None when none does.

    Why: a checkpoint damaged on disk (a bad sector, a copy cut short) must not stop a resume
    while an older intact one is there. Each damaged checkpoint passed over is reported with
    one line to ``say`` naming it and the older one used instead.
    """
    paths = [Path(p) for p in candidates]
    for position in range(len(paths) - 1, -1, -1):
        try:
            load_checkpoint(paths[position])
            return paths[position]
        except (CheckpointError, FileNotFoundError) as error:
            older = paths[position - 1] if position > 0 else None
            instead = f"falling back to {older}" if older else "no older checkpoint to use"
            if say is not None:
                say(f"checkpoint {paths[position]} is unusable ({_one_line(error)}); {instead}")
    return None


def _one_line(error: BaseException) -> str:
    return " ".join(str(error).split())


def checkpoint_meta(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The caller's metadata of a checkpoint (``meta`` of :func:`save_checkpoint`), read without
    loading its arrays. Raises like :func:`load_checkpoint`."""
    source = Path(path)
    if not source.is_file():
        raise FileNotFoundError(f"checkpoint {source} does not exist")
    try:
        with _open_archive(source) as archive:
            return dict(_read_header(source, archive)["meta"])
    except CheckpointError:
        raise
    except _READ_ERRORS as error:
        raise CheckpointError(f"{source} is corrupt or not a checkpoint: {error}") from error


def list_checkpoints(directory: str | os.PathLike[str]) -> list[Path]:
    """Checkpoints named by :func:`checkpoint_path` in ``directory``, oldest step first."""
    folder = Path(directory)
    if not folder.is_dir():
        return []
    found = [
        (int(match.group(1)), entry)
        for entry in folder.iterdir()
        if (match := _STEP_PATTERN.match(entry.name)) and entry.is_file()
    ]
    return [entry for _, entry in sorted(found)]


def latest_checkpoint(directory: str | os.PathLike[str]) -> Path | None:
    """The checkpoint of the greatest step in ``directory``, or None."""
    found = list_checkpoints(directory)
    return found[-1] if found else None


def rotate_checkpoints(directory: str | os.PathLike[str], keep: int = 2) -> list[Path]:
    """Delete all but the ``keep`` latest checkpoints (and temporary files left by crashed saves).

    Returns the deleted paths. Call it after a successful :func:`save_checkpoint`, from the one
    process that writes checkpoints in ``directory``. It deletes whatever checkpoints the
    directory holds; a run rotates with
    :meth:`dem_taichi.io.run_directory.RunDirectory.add_checkpoint`, which deletes only its own.
    """
    if isinstance(keep, bool) or not isinstance(keep, int) or keep < 1:
        raise ValueError(f"keep must be an int >= 1, got {keep!r}")
    folder = Path(directory)
    found = list_checkpoints(folder)
    removed = found[:-keep] if len(found) > keep else []
    if folder.is_dir():
        removed += sorted(
            entry
            for entry in folder.iterdir()
            if entry.name.startswith(f".{CHECKPOINT_PREFIX}") and entry.name.endswith(".tmp")
        )
    for entry in removed:
        entry.unlink(missing_ok=True)
    return removed
