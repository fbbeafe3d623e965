"""The parallel paths' measure (:func:`dem_taichi.kernels.measures.measure_sums_blocked`): the
serial measure's sums to round-off and its counts and per-entry data exactly, on the same state;
deterministic (the same bits twice); its block rows added in levels; the mechanical coordination
counted on the device (:mod:`dem_taichi.kernels.coordination`) exactly the host's; on a GPU, the
serial CPU measures of the same state."""

import json
import subprocess
import sys

import numpy as np
import pytest

from dem_taichi.engine.runtime import cuda_available
from dem_taichi.engine.simulation import CellControl, Simulation
from dem_taichi.kernels import layout
from dem_taichi.scene.config import load_scene

COUNTS = (
    "mechanical_coordination_number", "coordination_number", "n_contacts", "n_long_range_pairs"
)  # fmt: skip


def measured(scene, state, execution):
    sim = Simulation(scene, execution=execution)
    sim.set_state(state)
    m = sim.measure()
    return sim, m


@pytest.mark.parametrize("name", ["smoke", "smoke_bonded"])
def test_blocked_measure_equals_the_serial_one(name):
    scene = load_scene(name)
    sim = Simulation(scene)
    sim.run(4000, control=CellControl.strain_rate(0.12), output_every=4000)
    state = sim.get_state()
    serial, ms = measured(scene, state, "serial")
    for execution in ("parallel", "gather"):
        par, mp = measured(scene, state, execution)
        assert par.a["block_sums"].shape[0] == layout.measure_block_rows(
            par.n_bodies, par.n_discs, par.bonded
        )
        assert ms["n_contacts"] > 0
        for key, value in ms.items():
            if isinstance(value, int | float) and not isinstance(value, bool):
                assert mp[key] == pytest.approx(value, rel=1e-12, abs=1e-12), key
        np.testing.assert_array_equal(
            par.a["rod_contacts"].to_numpy(), serial.a["rod_contacts"].to_numpy()
        )
        # Z_m counted on the device: the host's integers, so the same float
        assert mp["mechanical_coordination_number"] == ms["mechanical_coordination_number"] > 0
    assert serial.a["block_sums"].shape[0] == 1  # the serial path allocates no block rows


def one_round(rod_i, rod_j, n_rods):
    """Z_m with the rattlers of one round removed only (the cascade left out)."""
    count = np.bincount(rod_i, minlength=n_rods) + np.bincount(rod_j, minlength=n_rods)
    alive = count >= 2
    keep = alive[rod_i] & alive[rod_j]
    return 2.0 * keep.sum() / alive.sum() if alive.any() else 0.0


@pytest.mark.parametrize("execution", ["parallel", "gather"])
def test_device_coordination_removes_rattlers_as_the_host_does(execution):
    """On a packing, and on the same packing with a tenth of its contacts cleared (rattlers in
    layers: removing one makes others), the device's rounds give the host's Z_m
    (dem_taichi.engine.network.mechanical_coordination) exactly."""
    from dem_taichi.engine.network import mechanical_coordination

    sim = Simulation(load_scene("smoke"), execution=execution)
    sim.run(4000, control=CellControl.strain_rate(0.12), output_every=4000)
    i, k, packed, bits = sim.views._contact_pairs()
    ns, n = sim.geometry.n_spheres, sim.n_rods
    assert sim.views._mechanical_coordination() == mechanical_coordination(i, packed, bits, ns, n)
    flags = sim.a["pair_flags"].to_numpy()
    contact = (bits & layout.PAIR_CONTACT) != 0
    cascades = 0
    for seed in range(10):
        cleared = contact & (np.random.default_rng(seed).random(len(i)) < 0.1)
        kept = ~cleared
        expected = mechanical_coordination(i[kept], packed[kept], bits[kept], ns, n)
        touching = contact & kept
        rod_i, rod_j = i[touching] // ns, packed[touching] // layout.IMAGE_CODES // ns
        cascades += expected > 0 and one_round(rod_i, rod_j, n) != expected
        cut = flags.copy()
        cut[i[cleared], k[cleared]] = 0
        sim.a["pair_flags"].from_numpy(cut)
        assert sim.views._device_coordination() == expected
    assert cascades >= 2  # packings where more than one round of removal mattered


def test_blocked_measure_is_deterministic():
    scene = load_scene("smoke")
    sim = Simulation(scene, execution="gather")
    sim.run(3000, control=CellControl.strain_rate(0.12), output_every=3000)
    first = sim.a["measures"].to_numpy().copy()
    sim.measure()
    assert first.tobytes() == sim.a["measures"].to_numpy().tobytes()


GPU_SCRIPT = """
import json, sys
from dem_taichi.engine.simulation import CellControl, Simulation
from dem_taichi.scene.config import load_scene
sim = Simulation(load_scene(sys.argv[1]), arch="gpu", execution=sys.argv[3])
sim.run(4000, control=CellControl.strain_rate(0.12), output_every=4000)
sim.save_checkpoint(sys.argv[2])
print(json.dumps(sim.measure(), default=float))
"""


@pytest.mark.gpu
@pytest.mark.parametrize("scene", ["smoke", "smoke_bonded"])
@pytest.mark.parametrize("execution", ["parallel", "gather"])
def test_the_gpu_measures_are_the_serial_cpu_ones(scene, execution, tmp_path):
    """On a GPU (blocked sums, Z_m counted on the device, in a subprocess: its own runtime) the
    measures of a state are those of the serial CPU path on the same state: Z_m and the counts
    exactly, the sums to round-off."""
    from dem_taichi.io.checkpoint import load_checkpoint

    if not cuda_available():
        pytest.skip("no CUDA device")
    path = tmp_path / "state.npz"
    out = subprocess.run(
        [sys.executable, "-c", GPU_SCRIPT, scene, str(path), execution],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    on_gpu = json.loads(out.stdout.strip().splitlines()[-1])
    arrays, _ = load_checkpoint(path)
    serial, on_cpu = measured(load_scene(scene), arrays, "serial")
    assert on_cpu["n_contacts"] > 0
    for key in COUNTS:
        assert on_gpu[key] == on_cpu[key], key
    assert on_gpu["mean_stress"] == pytest.approx(on_cpu["mean_stress"], rel=1e-9)


@pytest.mark.parametrize("rows", [1, 63, 64, 4097, 300_000])
def test_the_block_rows_are_added_in_levels_to_the_whole_sum(rows):
    """``add_rows_in_levels`` (three levels of 64, then the rest on one thread): every row
    counted once, whatever the number of rows (past 64³ = 262,144 too); integers exactly."""
    import taichi as ti

    from dem_taichi.engine.runtime import ensure_runtime
    from dem_taichi.kernels.measures import add_rows_in_levels

    ensure_runtime("cpu", "f64")

    @ti.kernel
    def add(block_sums: ti.types.ndarray(ndim=2), measures: ti.types.ndarray(ndim=1)):
        add_rows_in_levels(block_sums, measures)

    values = np.random.default_rng(rows).integers(-1000, 1000, size=(rows, 3)).astype(float)
    block_sums = ti.ndarray(ti.f64, shape=values.shape)
    block_sums.from_numpy(values)
    measures = ti.ndarray(ti.f64, shape=(3,))
    add(block_sums, measures)
    np.testing.assert_array_equal(measures.to_numpy(), values.sum(axis=0))
