"""The per-worker Taichi kernel cache of the test suite (``tests/conftest.py``)."""

from __future__ import annotations

import os
from pathlib import Path

from tests.conftest import _worker_cache


def test_each_xdist_worker_compiles_into_its_own_kernel_cache(monkeypatch, tmp_path):
    monkeypatch.delenv("TI_OFFLINE_CACHE_FILE_PATH", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setenv("PYTEST_XDIST_WORKER", "gw0")
    first = _worker_cache(Path("/checkouts/main"))
    monkeypatch.setenv("PYTEST_XDIST_WORKER", "gw1")
    second = _worker_cache(Path("/checkouts/main"))
    assert first is not None and first.parent.parent == tmp_path / "taichi" / "ticache-pytest"
    assert first.name == "gw0" and first.parent.name.startswith("main-")
    assert second is not None and second != first and second.parent == first.parent


def test_two_checkouts_never_share_a_workers_cache(monkeypatch, tmp_path):
    """Two clones' suites on one machine (both with a ``gw0``) compile into different folders,
    also when the clones have the same folder name."""
    monkeypatch.delenv("TI_OFFLINE_CACHE_FILE_PATH", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setenv("PYTEST_XDIST_WORKER", "gw0")
    one = _worker_cache(Path("/a/repo"))
    other = _worker_cache(Path("/b/repo"))
    assert one is not None and other is not None and one != other
    assert _worker_cache(Path("/a/repo")) == one


def test_the_users_cache_path_and_a_serial_run_are_left_alone(monkeypatch):
    monkeypatch.setenv("PYTEST_XDIST_WORKER", "gw0")
    monkeypatch.setenv("TI_OFFLINE_CACHE_FILE_PATH", "/somewhere/chosen")
    assert _worker_cache() is None
    monkeypatch.delenv("TI_OFFLINE_CACHE_FILE_PATH")
    monkeypatch.delenv("PYTEST_XDIST_WORKER")
    assert _worker_cache() is None


def test_this_worker_uses_its_cache(monkeypatch):
    """On CI (no cache path of the user's) every worker of this very run has its own, in this
    checkout's folder."""
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if worker and os.environ.get("CI"):
        in_use = os.environ["TI_OFFLINE_CACHE_FILE_PATH"]
        monkeypatch.delenv("TI_OFFLINE_CACHE_FILE_PATH")
        assert in_use == str(_worker_cache())
