"""The package's public API: ``from dem_taichi import Simulation, load_scene, run_protocol``."""

from __future__ import annotations

import subprocess
import sys

import pytest


def test_import_is_light_and_names_resolve_on_use():
    code = (
        "import sys, dem_taichi\n"
        "assert 'taichi' not in sys.modules, 'import dem_taichi must not import taichi'\n"
        "from dem_taichi import Scene, SceneError, load_scene, CellControl\n"
        "assert 'taichi' not in sys.modules\n"
        "print(sorted(dem_taichi.__all__))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "Simulation" in out.stdout and "run_protocol" in out.stdout


def test_simulation_takes_a_scene_name_or_path(tmp_path):
    import dem_taichi
    from dem_taichi import Simulation, load_scene

    by_name = Simulation("smoke")
    assert by_name.n_rods == 40 and by_name.scene == load_scene("smoke")
    path = tmp_path / "tiny.toml"
    path.write_text("[particles]\nn_rods = 30\nn_spheres = 3\n")
    assert Simulation(path).n_rods == 30
    assert Simulation(str(path)).geometry.n_spheres == 3
    with pytest.raises(dem_taichi.SceneError, match="no built-in scene 'nope'; available"):
        Simulation("nope")
    with pytest.raises(AttributeError, match="no attribute 'Simulator'"):
        dem_taichi.Simulator  # noqa: B018
