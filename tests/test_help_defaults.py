"""Every option of every command line has a help text, and it states its default."""

from __future__ import annotations

import argparse

import pytest


def _parsers():
    from bridge import pipeline, study_figure
    from dem_taichi.cli import commands as cli
    from dem_taichi.protocol import runner as protocol
    from dem_taichi.sweep import command as sweep
    from tiv_model import cli as tiv_cli

    return {
        "python -m dem_taichi": cli._parser(),
        "python -m dem_taichi protocol": protocol._parser("python -m dem_taichi protocol"),
        "python -m dem_taichi sweep": sweep._parser("python -m dem_taichi sweep"),
        "python -m tiv_model": tiv_cli._parser(),
        "python -m bridge calibrate": pipeline._parser(),
        "python -m bridge figure2": study_figure._parser(),
    }


def _options(parser, name):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub, child in action.choices.items():
                yield from _options(child, f"{name} {sub}")
        elif not isinstance(action, (argparse._HelpAction, argparse._VersionAction)):
            yield name, action


CASES = [(n, a) for n, p in _parsers().items() for n, a in _options(p, n)]


@pytest.mark.parametrize(("command", "action"), CASES, ids=[f"{n}:{a.dest}" for n, a in CASES])
def test_option_has_help_with_its_default(command, action):
    assert action.help and action.help != argparse.SUPPRESS, f"{command} {action.dest}: no help"
    default = action.default
    flag = isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction))
    if action.option_strings and not flag and default not in (None, [], "", argparse.SUPPRESS):
        assert "default" in action.help or str(default) in action.help, (
            f"{command} {action.option_strings[0]}: the help does not state the default "
            f"{default!r}: {action.help!r}"
        )
