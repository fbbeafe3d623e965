"""Session-wide test set-up: one Taichi offline kernel cache per pytest-xdist worker.

Taichi keeps compiled kernels in an offline cache (``~/.cache/taichi/ticache`` by default,
``offline_cache=True`` in :mod:`dem_taichi.engine.runtime`). `make test` runs one pytest process
per core, and each compiles the same kernels at the same time into that one folder. A fresh
clone's suite once failed 4 tests of ``test_fire.py`` with Taichi's "RuntimeError: argument
not found" and passed when rerun (2026-12-02), a failure that fits one process loading a kernel
another was still writing. Each worker therefore gets its own cache folder (and so do the
command-line processes a test starts: they inherit the environment). The folder is also one per
checkout: a fresh clone's suite failed once more the same way (2026-12-04, one test of
``test_run_directory.py``) while another checkout's suite ran on the same machine, and the two
runs' ``gw0`` workers shared ``ticache-pytest/gw0``. A cache path the user set
(``TI_OFFLINE_CACHE_FILE_PATH``) is kept. This module runs before any test module imports
Taichi, which reads the variable at ``ti.init``.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

_CHECKOUT = Path(__file__).resolve().parents[1]


def _worker_cache(checkout: Path = _CHECKOUT) -> Path | None:
    """The offline-cache folder of this xdist worker in this checkout, or None (no worker, or the
    user's own): ``<cache>/taichi/ticache-pytest/<checkout name>-<hash of its path>/<worker>``."""
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if not worker or os.environ.get("TI_OFFLINE_CACHE_FILE_PATH"):
        return None
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    tag = hashlib.sha256(str(checkout).encode()).hexdigest()[:12]
    return base / "taichi" / "ticache-pytest" / f"{checkout.name}-{tag}" / worker


_cache = _worker_cache()
if _cache is not None:
    os.environ["TI_OFFLINE_CACHE_FILE_PATH"] = str(_cache)
