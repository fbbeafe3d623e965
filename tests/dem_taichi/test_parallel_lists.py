"""The parallel neighbour-list build (:mod:`dem_taichi.kernels.parallel_lists`, the default on a
GPU) builds the serial build's list entry for entry: on the deterministic gather path, the two
builds give the same state bit for bit, through list rebuilds, capacity growth (overflow and a
repeated build), bonded rods (intact bonds left out of the list) and rolling springs (ψ carried).
"""

import subprocess
import sys

import numpy as np
import pytest

from dem_taichi.engine.runtime import cuda_available
from dem_taichi.engine.simulation import CellControl, Simulation
from dem_taichi.engine.state import states_equal
from dem_taichi.kernels import layout
from dem_taichi.scene.config import load_scene


def run_both(scene, steps, rate, capacity=None):
    """The gather path from the same gas with each list build: (states, rebuild counts)."""
    states, rebuilds = [], []
    for build in ("serial", "parallel"):
        sim = Simulation(scene, execution="gather", list_build=build, neighbour_capacity=capacity)
        sim.run(steps, control=CellControl.strain_rate(rate), output_every=steps)
        states.append(sim.get_state())
        rebuilds.append(int(states[-1]["flags"][layout.F_REBUILDS]))
    return states, rebuilds


def test_parallel_build_gives_the_serial_state_bit_for_bit():
    states, rebuilds = run_both(load_scene("smoke"), 2000, 0.12)
    assert rebuilds[0] == rebuilds[1] > 3  # the compression rebuilt the list several times
    assert int(states[0]["neighbour_count"].sum()) > 0
    assert states_equal(*states)


def test_parallel_build_repeats_an_overflowing_build_as_the_serial_one():
    # capacity 2 overflows at the first builds: the host grows it and the build is repeated
    states, _ = run_both(load_scene("smoke"), 1500, 0.12, capacity=2)
    assert states[0]["neighbours"].shape[1] > 2
    assert states_equal(*states)


def test_parallel_build_on_bonded_rods_with_rolling_springs():
    scene = load_scene("smoke_bonded").replace(
        contact={"rolling_stiffness": 1.0e3, "rolling_friction": 0.3}
    )
    states, rebuilds = run_both(scene, 4000, 0.12)
    assert rebuilds[1] > 1
    assert states_equal(*states)
    assert np.abs(states[1]["rolling_spring"]).max() > 0  # ψ carried through the builds


def test_list_build_is_checked():
    with pytest.raises(ValueError, match="list_build = 'fast': allowed values are serial"):
        Simulation(load_scene("smoke"), execution="parallel", list_build="fast")


def test_cpu_defaults_to_the_serial_build():
    assert Simulation(load_scene("smoke"), execution="parallel").list_build == "serial"


def test_half_list_parallel_path_with_the_parallel_build_agrees_with_serial():
    """The atomic-scatter path (not bitwise: forces summed in the threads' order) with the
    parallel build and prime, against the serial fused path, over a compression with builds."""
    scene = load_scene("smoke")
    results = {}
    for execution, build in (("serial", None), ("parallel", "parallel")):
        sim = Simulation(scene, execution=execution, list_build=build)
        sim.run(2000, control=CellControl.strain_rate(0.12), output_every=2000)
        results[execution] = (sim.get_state(), sim.measure())
    (a, ma), (b, mb) = results["serial"], results["parallel"]
    assert mb["n_contacts"] == ma["n_contacts"] > 0
    assert int(b["flags"][layout.F_REBUILDS]) == int(a["flags"][layout.F_REBUILDS])
    assert mb["mean_stress"] == pytest.approx(ma["mean_stress"], rel=1e-6, abs=1e-9)
    np.testing.assert_allclose(a["reduced_position"], b["reduced_position"], atol=1e-9)


GPU_SCRIPT = """
import hashlib, sys
import numpy as np
from dem_taichi.engine.simulation import CellControl, Simulation
from dem_taichi.kernels import layout
from dem_taichi.scene.config import load_scene
scene = load_scene(sys.argv[1])
for build in ("serial", "parallel"):
    sim = Simulation(scene, arch="gpu", execution="gather", list_build=build)
    sim.run(3000, control=CellControl.strain_rate(0.12), output_every=3000)
    state = sim.get_state()
    digest = hashlib.sha256(b"".join(np.ascontiguousarray(state[k]).tobytes() for k in sorted(state)
                                     if k != "__meta__")).hexdigest()
    pairs = int(state["neighbour_count"].sum())
    print(build, int(state["flags"][layout.F_REBUILDS]), pairs, digest)
"""


@pytest.mark.gpu
@pytest.mark.parametrize("scene", ["smoke", "smoke_bonded"])
def test_parallel_build_on_a_gpu_gives_the_serial_state_bit_for_bit(scene):
    """On a GPU (thousands of threads racing for the cells' atomic cursors): the same state as
    the one-thread build, bit for bit, on the gather path (in a subprocess: its own runtime)."""
    if not cuda_available():
        pytest.skip("no CUDA device")
    out = subprocess.run(
        [sys.executable, "-c", GPU_SCRIPT, scene], capture_output=True, text=True, check=True
    )
    rows = [line.split() for line in out.stdout.strip().splitlines()[-2:]]
    assert [r[0] for r in rows] == ["serial", "parallel"]
    assert int(rows[0][1]) > 3 and int(rows[0][2]) > 0  # builds happened, pairs listed
    assert rows[0][1:] == rows[1][1:]
