"""The bridge's output folder: what a calibration wrote (its manifest), and its safety rules.

A calibration lists every file it writes in ``calibration_files.json`` (paths relative to the
output folder). The rules (issue 22):

- the command line refuses an ``--out`` that holds an earlier calibration (the manifest, or a
  file with a name the bridge writes: :data:`BRIDGE_PATTERNS`) unless ``--overwrite``; with it,
  the files the earlier manifest lists are deleted first (nothing else), so no stale output
  (``prediction_radial_1.nc`` of a calibration with more radial paths) is left beside the new.
  ``--overwrite`` is refused where such files lie without a manifest (foreign, or written
  before manifests): they would be replaced by name;
- an empty ``--out`` is refused (it would mean the current folder);
- ``--out`` must not be a DEM run folder (its ``run.json``): the bridge's ``report.md`` would
  replace the run's;
- the bridge never writes through a symbolic link: an entry with a bridge output's name that is
  a link is refused (one line), never followed nor replaced (the link is the user's);
- :func:`bridge.pipeline.calibrate_from_results` called from Python replaces the earlier
  calibration of its folder too: after writing, it deletes the files the earlier manifest lists
  that it did not write again (never its own input files).
"""

from __future__ import annotations

import contextlib
import fnmatch
import json
import os
import stat
import tempfile
from collections.abc import Set
from pathlib import Path, PurePosixPath

__all__ = [
    "MANIFEST",
    "BRIDGE_PATTERNS",
    "OutputFolderError",
    "Outputs",
    "check_out",
    "holds_outputs",
    "read_manifest",
    "refuse_links",
    "files_now",
    "write_netcdf",
]

MANIFEST = "calibration_files.json"
MANIFEST_FORMAT = "bridge.outputs"
#: Names the bridge writes at the top of its output folder.
BRIDGE_PATTERNS = (
    MANIFEST,
    "calibration.json",
    "calibration.txt",
    "report.md",
    "prediction_*.nc",
    "bridge_*.png",
    "synthetic_*.nc",
    "replicas.json",
    "replicas.md",
    "mean",
    "replica_*",
)


class OutputFolderError(ValueError):
    """An output folder the bridge cannot write into as asked (bad input: exit code 2)."""


def _is_bridge_name(name: str) -> bool:
    return any(fnmatch.fnmatchcase(name, pattern) for pattern in BRIDGE_PATTERNS)


def refuse_links(out: Path) -> None:
    """Refuse (one line) when an entry with a bridge output's name in ``out`` is a link."""
    if not out.is_dir():
        return
    for entry in sorted(out.iterdir()):
        if _is_bridge_name(entry.name) and entry.is_symlink():
            raise OutputFolderError(
                f"{entry} is a symbolic link (to {os.readlink(entry)}); the bridge never writes "
                "through a link: remove the link or choose a new --out"
            )


def read_manifest(out: Path) -> list[str] | None:
    """The files listed by the earlier calibration in ``out`` (None: no manifest)."""
    path = out / MANIFEST
    if not path.exists() and not path.is_symlink():
        return None
    try:
        if path.is_symlink():
            raise ValueError("it is a symbolic link")
        data = json.loads(path.read_text())
        if data.get("format") != MANIFEST_FORMAT or not isinstance(data.get("files"), list):
            raise ValueError(f"format {data.get('format')!r}, not {MANIFEST_FORMAT!r}")
        return [_inside(out, str(name)) for name in data["files"]]
    except (ValueError, TypeError, AttributeError) as error:
        raise OutputFolderError(
            f"{path} is not a readable list of the bridge's files ({error}); nothing is deleted: "
            "move the folder's files away or choose a new --out"
        ) from error


def _inside(out: Path, name: str) -> str:
    """``name`` as a clean relative path inside ``out`` (refused else)."""
    rel = PurePosixPath(name)
    if not rel.parts or rel.is_absolute() or any(p in ("..", ".") for p in rel.parts):
        raise ValueError(f"{name!r} is not a path inside {out}")
    if str(rel) != name:
        raise ValueError(f"{name!r} is not a clean relative path")
    return name


def _link_on_the_way(out: Path, rel: str) -> bool:
    here = out
    for part in PurePosixPath(rel).parts:
        here = here / part
        if here.is_symlink():
            return True
    return False


def files_now(out: Path) -> dict[str, tuple[int, int, int]]:
    """Every regular file below ``out`` (links not followed): relative path → (inode, size,
    mtime_ns), to tell what a command wrote (:meth:`Outputs.add_written_since`)."""
    found: dict[str, tuple[int, int, int]] = {}
    if not out.is_dir():
        return found
    for root, _dirs, names in os.walk(out, followlinks=False):
        for name in names:
            path = Path(root) / name
            info = path.lstat()
            if stat.S_ISREG(info.st_mode):
                rel = str(PurePosixPath(*path.relative_to(out).parts))
                found[rel] = (info.st_ino, info.st_size, info.st_mtime_ns)
    return found


class Outputs:
    """The files one calibration writes into ``out`` (its manifest, :data:`MANIFEST`)."""

    def __init__(self, out: Path) -> None:
        self.out = out
        self.written: set[str] = set()

    def path(self, name: str) -> Path:
        """Register output ``name`` (relative to the folder) before writing it; refused when a
        link is on its way. Returns its path."""
        rel = _inside(self.out, name)
        if _link_on_the_way(self.out, rel):
            raise OutputFolderError(
                f"{self.out / rel}: a symbolic link is on the way; the bridge never writes "
                "through a link: remove it or choose a new --out"
            )
        self.written.add(rel)
        return self.out / rel

    def add_written_since(self, before: dict[str, tuple[int, int, int]]) -> None:
        """Register every file below the folder that is new or changed since ``before``."""
        for rel, key in files_now(self.out).items():
            if rel != MANIFEST and before.get(rel) != key:
                self.written.add(rel)

    def remove_earlier(self, keep: Set[str] = frozenset()) -> list[str]:
        """Delete the files the earlier manifest lists (regular files, no link on the way),
        except ``keep`` and those written by this calibration; then their folders left empty.
        Returns what was deleted."""
        listed = read_manifest(self.out) or []
        removed = []
        for rel in listed:
            if rel in keep or rel in self.written or _link_on_the_way(self.out, rel):
                continue
            path = self.out / rel
            with contextlib.suppress(FileNotFoundError):
                if stat.S_ISREG(path.lstat().st_mode):
                    path.unlink()
                    removed.append(rel)
        folders = {str(PurePosixPath(r).parent) for r in removed} - {"."}
        for rel in sorted(folders, key=lambda r: len(PurePosixPath(r).parts), reverse=True):
            with contextlib.suppress(OSError):
                (self.out / rel).rmdir()  # only when left empty
        return removed

    def save(self, keep: Set[str] = frozenset()) -> Path:
        """Write the manifest: the files written by this calibration, and ``keep`` (earlier
        files still in use, e.g. inputs read from the folder)."""
        path = self.out / MANIFEST
        if path.is_symlink():
            raise OutputFolderError(
                f"{path} is a symbolic link; the bridge never writes through a link: remove it"
            )
        files = sorted(self.written | {r for r in keep if (self.out / r).exists()})
        text = json.dumps({"format": MANIFEST_FORMAT, "files": files}, indent=2) + "\n"
        handle, name = tempfile.mkstemp(dir=self.out, prefix=f".{MANIFEST}.", suffix=".tmp")
        temporary = Path(name)
        try:
            with os.fdopen(handle, "w") as stream:
                stream.write(text)
            os.chmod(temporary, 0o644)
            os.replace(temporary, path)
        finally:
            temporary.unlink(missing_ok=True)
        return path


def holds_outputs(out: Path) -> list[str]:
    """The entries of ``out`` with a name the bridge writes (an earlier calibration)."""
    if not out.is_dir():
        return []
    return sorted(e.name for e in out.iterdir() if _is_bridge_name(e.name))


def check_out(out_text: str, overwrite: bool) -> Path:
    """The command line's checks of ``--out`` (module docstring); returns it as a path."""
    if not out_text.strip():
        raise OutputFolderError(
            "--out is empty: give the folder for the results (an empty --out would mean the "
            "current folder)"
        )
    out = Path(out_text)
    if (out.exists() or out.is_symlink()) and not out.is_dir():
        raise OutputFolderError(f"--out {out} is a file: give a folder for the results")
    if (out / "run.json").exists():
        raise OutputFolderError(
            f"--out {out} is a DEM run folder (it holds run.json): the calibration's report.md "
            f"would replace the run's; give a folder of its own, e.g. {out / 'calibration'}"
        )
    refuse_links(out)
    earlier = holds_outputs(out)
    shown = ", ".join(earlier[:4]) + (", ..." if len(earlier) > 4 else "")
    if earlier and overwrite and MANIFEST not in earlier:
        raise OutputFolderError(
            f"--out {out} holds {shown} but no {MANIFEST}, so whose they are is unknown and "
            "--overwrite would replace them by name: move them away or choose a new --out"
        )
    if earlier and not overwrite:
        raise OutputFolderError(
            f"--out {out} already holds an earlier calibration ({shown}); add --overwrite to "
            "replace it (the files its calibration_files.json lists are deleted first), or "
            "choose a new --out"
        )
    return out


def write_netcdf(ds, path: Path) -> Path:
    """``ds.to_netcdf(path)`` atomically (:func:`clay_cli.replace_file`: no half
    file, netCDF4's "HDF error" on a full disk raised as ``OSError`` ENOSPC)."""
    from clay_cli import replace_file

    return replace_file(path, ds.to_netcdf)
