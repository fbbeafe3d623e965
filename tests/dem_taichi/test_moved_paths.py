"""The old module paths of the flat layout (``dem_taichi.forcelaw``, ``dem_taichi.engine``, ...)
still work for one release, through the one table of :mod:`dem_taichi._moved`, with a
:class:`DeprecationWarning` that names the new path."""

from __future__ import annotations

import importlib
import subprocess
import sys
import warnings

import pytest

from dem_taichi._moved import MOVED


def _fresh_import(name: str):
    sys.modules.pop(name, None)
    return importlib.import_module(name)


def test_an_old_module_path_is_the_new_module_with_a_warning():
    import dem_taichi.physics.forcelaw as new

    with pytest.deprecated_call(match="dem_taichi.forcelaw moved to dem_taichi.physics.forcelaw"):
        old = _fresh_import("dem_taichi.forcelaw")
    assert old is new  # one module: a patch through either path is seen by both


def test_from_an_old_module_path_import_a_name():
    from dem_taichi.sweep.results import open_sweep

    sys.modules.pop("dem_taichi.sweep_results", None)
    with pytest.deprecated_call(match="dem_taichi.sweep_results moved to dem_taichi.sweep.results"):
        from dem_taichi.sweep_results import open_sweep as old  # noqa: PLC0415
    assert old is open_sweep


def test_an_old_module_now_a_subpackage_forwards_its_names():
    import dem_taichi.engine
    from dem_taichi.engine.simulation import Simulation

    vars(dem_taichi.engine).pop("Simulation", None)
    with pytest.deprecated_call(match="dem_taichi.engine.Simulation moved to "):
        from dem_taichi.engine import Simulation as old
    assert old is Simulation
    with pytest.raises(AttributeError, match="no attribute 'Simulator'"):
        dem_taichi.engine.Simulator  # noqa: B018


def test_every_old_path_resolves():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        for old, new in MOVED.items():
            module = importlib.import_module(old)
            if new.startswith(old + "."):  # now a subpackage: forwards the old module's names
                assert module.__name__ == old and callable(module.__getattr__)
            else:
                assert module is importlib.import_module(new), old


def test_an_old_path_runs_with_python_m():
    out = subprocess.run(
        [sys.executable, "-m", "dem_taichi.anisotropy", "--help"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "usage: python -m dem_taichi anisotropy" in out.stdout
    assert "dem_taichi.anisotropy moved to dem_taichi.response.anisotropy" in out.stderr
