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
