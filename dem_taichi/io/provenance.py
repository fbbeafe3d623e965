"""Global attributes that say where a results file came from (CF-1.11 + project provenance).

No Taichi import here: the Taichi version is passed in as a string by the engine, so that this
module (and the bridge that reads results) works on machines without Taichi.
"""

from __future__ import annotations

import datetime as _dt
import platform
import subprocess
from pathlib import Path
from typing import Any

from .schema import DEM_UNIT_SYSTEM

CONVENTIONS = "CF-1.11"
INSTITUTION = "clay-multiscale project (DEM of rod-shaped clay particles)"
ALLOWED_ARCHS = ("cpu", "gpu", "cuda", "vulkan", "metal", "opengl")
ALLOWED_PRECISIONS = ("f32", "f64")

_PACKAGE_DIR = Path(__file__).resolve().parents[1]


def package_version() -> str:
    """Version string of ``dem_taichi`` (read without importing Taichi)."""
    from dem_taichi import __version__

    return str(__version__)


def git_revision(directory: Path | str = _PACKAGE_DIR) -> str:
    """Commit hash of the source tree (``+dirty`` with uncommitted changes), or ``"unknown"``.

    Never raises: results must be writable from an installed package with no git around.
    """
    try:
        head = subprocess.run(
            ["git", "-C", str(directory), "rev-parse", "--short=12", "HEAD"],
            capture_output=True,
            text=True,
            timeout=5,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(directory), "status", "--porcelain", "--untracked-files=no", "."],
            capture_output=True,
            text=True,
            timeout=5,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    if not head:
        return "unknown"
    return head + ("+dirty" if dirty else "")


def utc_timestamp() -> str:
    """Current UTC time as ISO 8601 with a ``Z`` suffix, to the second."""
    now = _dt.datetime.now(_dt.UTC).replace(microsecond=0)
    return now.isoformat().replace("+00:00", "Z")


def history_line(command: str) -> str:
    """One CF ``history`` entry: ``<ISO timestamp>: <command>``."""
    return f"{utc_timestamp()}: {command}"


def provenance_attrs(
    scene_toml: str,
    arch: str,
    precision: str,
    seed: int,
    command: str,
    *,
    taichi_version: str = "unknown",
    title: str = "DEM of 2D rod-shaped clay particles: run history",
) -> dict[str, Any]:
    """Global attributes for a results file.

    Parameters
    ----------
    scene_toml: the full text of the scene file the run used (stored verbatim).
    arch: Taichi backend, one of :data:`ALLOWED_ARCHS`.
    precision: ``"f32"`` or ``"f64"``.
    seed: the random seed of the run (non-negative integer).
    command: the command line that produced the file (goes into ``history``).
    taichi_version: e.g. ``"1.7.4"``; passed in so that this module never imports Taichi.
    """
    if not isinstance(scene_toml, str):
        raise TypeError(f"scene_toml must be the scene file's text (str), got {type(scene_toml)}")
    if arch not in ALLOWED_ARCHS:
        raise ValueError(f"arch {arch!r} not allowed; use one of {ALLOWED_ARCHS}")
    if precision not in ALLOWED_PRECISIONS:
        raise ValueError(f"precision {precision!r} not allowed; use one of {ALLOWED_PRECISIONS}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed must be a non-negative int, got {seed!r}")
    if not isinstance(command, str) or not command:
        raise ValueError(f"command must be a non-empty string, got {command!r}")
    version = package_version()
    revision = git_revision()
    return {
        "Conventions": CONVENTIONS,
        "title": title,
        "institution": INSTITUTION,
        "source": f"dem_taichi {version} (git {revision})",
        "history": history_line(command),
        "dem_taichi_version": version,
        "git_revision": revision,
        "taichi_version": str(taichi_version),
        "python_version": platform.python_version(),
        "arch": arch,
        "precision": precision,
        "seed": int(seed),
        "scene_toml": scene_toml,
        "dem_unit_system": DEM_UNIT_SYSTEM,
    }
