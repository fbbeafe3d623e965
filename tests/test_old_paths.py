"""Old module paths outside ``dem_taichi`` (which has its own table, ``dem_taichi._moved``)
still work for one release, with a :class:`DeprecationWarning` naming the new path, and give
the same objects as the new one."""

from __future__ import annotations

import importlib
import sys

import pytest


def _fresh_import(name: str):
    """Import ``name`` again (its module code runs, so its warning is given again)."""
    sys.modules.pop(name, None)
    return importlib.import_module(name)


def test_tiv_model_command_line_is_clay_cli_with_a_warning():
    import clay_cli
    from clay_cli import conventions

    with pytest.deprecated_call(match="tiv_model.command_line moved to clay_cli"):
        old = _fresh_import("tiv_model.command_line")
    assert set(clay_cli.__all__) <= set(old.__all__)
    for name in old.__all__:
        assert getattr(old, name) is getattr(conventions, name), name
    assert old.run_command is clay_cli.run_command
    assert old.EXIT_USAGE == clay_cli.EXIT_USAGE == 2


def test_clay_cli_exports_what_its_module_holds():
    import clay_cli
    from clay_cli import conventions

    assert clay_cli.__all__ == conventions.__all__
    for name in clay_cli.__all__:
        assert getattr(clay_cli, name) is getattr(conventions, name), name


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ("bridge.calibration_options", "bridge.calibration.options"),
        ("bridge.calibration_result", "bridge.calibration.result"),
        ("bridge.identifiability", "bridge.calibration.identifiability"),
    ],
)
def test_old_bridge_calibration_modules_forward_with_a_warning(old, new):
    module = importlib.import_module(new)
    with pytest.deprecated_call(match=f"{old} moved to {new}"):
        shim = _fresh_import(old)
    assert shim.__all__ == module.__all__
    for name in module.__all__:
        assert getattr(shim, name) is getattr(module, name), name


def test_bridge_calibration_keeps_the_old_module_names():
    """``bridge.calibration`` was a module; its names are the subpackage's now, no warning."""
    import warnings

    import bridge.calibration
    from bridge.calibration import fit, options, result

    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        from bridge.calibration import CalibrationOptions, calibrate, covariance_from_jacobian
    assert calibrate is fit.calibrate
    assert CalibrationOptions is options.CalibrationOptions
    assert covariance_from_jacobian is result.covariance_from_jacobian
    for name in bridge.calibration.__all__:
        assert hasattr(bridge.calibration, name), name
