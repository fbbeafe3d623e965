"""The per-worker Taichi kernel cache of the test suite (``tests/conftest.py``)."""

from __future__ import annotations

import os

from tests.conftest import _worker_cache


def test_each_xdist_worker_compiles_into_its_own_kernel_cache(monkeypatch, tmp_path):
    monkeypatch.delenv("TI_OFFLINE_CACHE_FILE_PATH", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setenv("PYTEST_XDIST_WORKER", "gw0")
    first = _worker_cache()
    monkeypatch.setenv("PYTEST_XDIST_WORKER", "gw1")
    second = _worker_cache()
    assert first == tmp_path / "taichi" / "ticache-pytest" / "gw0"
    assert second is not None and second != first


def test_the_users_cache_path_and_a_serial_run_are_left_alone(monkeypatch):
    monkeypatch.setenv("PYTEST_XDIST_WORKER", "gw0")
    monkeypatch.setenv("TI_OFFLINE_CACHE_FILE_PATH", "/somewhere/chosen")
    assert _worker_cache() is None
    monkeypatch.delenv("TI_OFFLINE_CACHE_FILE_PATH")
    monkeypatch.delenv("PYTEST_XDIST_WORKER")
    assert _worker_cache() is None


def test_this_worker_uses_its_cache():
    """On CI (no cache path of the user's) every worker of this very run has its own."""
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if worker and os.environ.get("CI"):
        assert os.environ["TI_OFFLINE_CACHE_FILE_PATH"].endswith(worker)
