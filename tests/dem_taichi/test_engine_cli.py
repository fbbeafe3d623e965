"""Command line: history written while running, checkpoints, exact --resume."""

import numpy as np
import pytest

from dem_taichi.cli.commands import builtin_schedule, main
from dem_taichi.io import latest_checkpoint, load_checkpoint, open_history
from dem_taichi.scene.config import load_scene


def test_run_writes_history_and_resumes_exactly(tmp_path):
    straight, split = tmp_path / "straight", tmp_path / "split"
    assert main(["run", "smoke", "--out", str(straight), "--steps", "1700", "--no-progress"]) == 0
    assert main(["run", "smoke", "--out", str(split), "--steps", "1200", "--no-progress"]) == 0
    assert main(["run", "smoke", "--out", str(split), "--steps", "1700", "--resume"]) == 0
    history = open_history(split / "history.nc")
    assert history["step"].values.tolist() == [0, 500, 1000, 1200, 1500, 1700]
    assert "scene_toml" in history.attrs or any("smoke" in str(v) for v in history.attrs.values())
    a, _ = load_checkpoint(latest_checkpoint(straight / "checkpoints"))
    b, _ = load_checkpoint(latest_checkpoint(split / "checkpoints"))
    for key in a:
        assert np.array_equal(a[key], b[key]), key
    reference = open_history(straight / "history.nc")
    assert float(history["mean_stress"][-1]) == float(reference["mean_stress"][-1])


def test_bad_scene_fails_with_the_key(tmp_path, capsys):
    scene = tmp_path / "bad.toml"
    scene.write_text("[contact]\nk_n = 0\n")
    assert main(["run", str(scene), "--out", str(tmp_path / "o")]) == 2
    assert "[contact] k_n = 0.0 is out of range" in capsys.readouterr().err


def test_builtin_schedule_reaches_the_target_specific_volume():
    scene = load_scene("smoke")
    (stage, steps, rate), relax = builtin_schedule(scene)
    v = np.exp(-2 * rate * steps * scene.time_step) / scene.particles.initial_area_fraction
    assert stage == "isotropic_to_A" and relax[0] == "relax"
    assert v == pytest.approx(scene.control.target_specific_volume, rel=1e-3)


@pytest.mark.slow
def test_default_scene_runs_to_its_target(tmp_path):
    assert main(["run", "default", "--out", str(tmp_path), "--no-progress"]) == 0
    history = open_history(tmp_path / "history.nc")
    scene = load_scene("default")
    assert float(history["specific_volume"][-1]) == pytest.approx(
        scene.control.target_specific_volume, rel=1e-3
    )
    assert float(history["coordination_number"][-1]) > 1.0


def test_sweep_is_a_subcommand(capsys):
    """``python -m dem_taichi sweep`` hands over to dem_taichi.sweep.command (its own help and
    prog)."""
    from dem_taichi.cli.commands import main

    assert main(["sweep", "--help"]) == 0
    assert "python -m dem_taichi sweep" in capsys.readouterr().out
