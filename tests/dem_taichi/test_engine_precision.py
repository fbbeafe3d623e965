"""f32 against f64, and CPU against GPU (GPU test marked ``gpu``, skipped without CUDA).

Each comparison runs in a subprocess so that switching the Taichi runtime (ti.reset) never
invalidates simulations held by other tests.

Stated tolerance (f32 vs f64, smoke scene, 1000 steps of gas compression from the same gas):
the cell (prescribed rate; L ← L exp(−ε̇Δt) rounded in f32 at every step) agrees to 1e-4 relative;
centroids (in cell units, times L) to 1e-3 d; the kinetic energy to 2 % (collisions amplify
round-off, the run is chaotic, so the tolerance is on a short run).
"""

import json
import subprocess
import sys

import pytest

from dem_taichi.engine.runtime import cuda_available

SCRIPT = """
import json, sys
import numpy as np
from dem_taichi.scene.config import load_scene
from dem_taichi.engine.simulation import CellControl, Simulation
arch, precision = sys.argv[1], sys.argv[2]
sim = Simulation(load_scene("smoke"), arch=arch, precision=precision)
m = sim.run(1000, control=CellControl.strain_rate(0.1))
print(json.dumps({"positions": sim.rod_positions().tolist(), "measures": m}))
"""


def run(arch, precision):
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT, arch, precision],
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def compare(a, b, position_tol, energy_rel, cell_rel):
    import numpy as np

    ma, mb = a["measures"], b["measures"]
    assert mb["cell_length_x"] == pytest.approx(ma["cell_length_x"], rel=cell_rel)
    assert mb["specific_volume"] == pytest.approx(ma["specific_volume"], rel=2 * cell_rel)
    # compare in cell units (the cells differ by the f32 rounding of L), scaled back to d
    lengths = np.array([ma["cell_length_x"], ma["cell_length_y"]])
    lengths_b = np.array([mb["cell_length_x"], mb["cell_length_y"]])
    diff = np.array(a["positions"]) / lengths - np.array(b["positions"]) / lengths_b
    diff = (diff - np.round(diff)) * lengths
    assert np.abs(diff).max() < position_tol
    assert mb["kinetic_energy"] == pytest.approx(ma["kinetic_energy"], rel=energy_rel)


def test_f32_agrees_with_f64_on_a_smoke_run():
    compare(run("cpu", "f64"), run("cpu", "f32"), position_tol=1e-3, energy_rel=0.02, cell_rel=1e-4)


@pytest.mark.gpu
def test_gpu_agrees_with_cpu_on_a_smoke_run():
    if not cuda_available():
        pytest.skip("no CUDA device")
    compare(
        run("cpu", "f64"), run("gpu", "f64"), position_tol=1e-6, energy_rel=1e-6, cell_rel=1e-12
    )
