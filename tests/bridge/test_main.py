"""``python -m bridge``: the ``calibrate`` subcommand, ``--version`` and a refused command."""

from __future__ import annotations

from bridge import __version__
from bridge.__main__ import main


def test_version_and_help(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"bridge {__version__}"
    assert main(["--help"]) == 0
    assert "calibrate" in capsys.readouterr().out


def test_unknown_command_is_one_line(capsys):
    assert main(["fit"]) == 2
    err = capsys.readouterr().err
    assert "unknown command 'fit'; allowed: calibrate" in err and err.count("\n") == 1


def test_calibrate_is_the_pipeline(tmp_path, capsys):
    code = main(["calibrate", "--out", str(tmp_path), "--history", str(tmp_path / "none.nc")])
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("python -m bridge calibrate: error:") and "no such file" in err
