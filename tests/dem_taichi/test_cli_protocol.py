"""`python -m dem_taichi protocol` delegates to the protocol CLI and reports bad scenes clearly."""

import subprocess
import sys


def run_cli(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "dem_taichi", *args], capture_output=True, text=True, cwd=cwd
    )


def test_protocol_subcommand_is_listed(tmp_path):
    result = run_cli("--help", cwd=tmp_path)
    assert result.returncode == 0 and "protocol" in result.stdout


def test_protocol_bad_scene_exits_2_naming_the_key(tmp_path):
    scene = tmp_path / "bad.toml"
    scene.write_text('[scene]\nname = "x"\nseeed = 1\n')
    result = run_cli("protocol", str(scene), "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert result.returncode == 2
    assert "seeed" in result.stderr and "allowed keys" in result.stderr


def test_protocol_bad_option_exits_2(tmp_path):
    result = run_cli("protocol", "smoke", "--out", "o", "--pattern", "salty", cwd=tmp_path)
    assert result.returncode == 2 and "acidic" in result.stderr
