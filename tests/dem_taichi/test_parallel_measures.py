"""The parallel paths' measure (:func:`dem_taichi.kernels.measures.measure_sums_blocked`): the
serial measure's sums to round-off and its counts and per-entry data exactly, on the same state;
deterministic (the same bits twice)."""

import numpy as np
import pytest

from dem_taichi.engine.simulation import CellControl, Simulation
from dem_taichi.kernels import layout
from dem_taichi.scene.config import load_scene

COUNTS = ("n_contacts", "n_long_range_pairs", "n_sliding")


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
    assert serial.a["block_sums"].shape[0] == 1  # the serial path allocates no block rows


def test_blocked_measure_is_deterministic():
    scene = load_scene("smoke")
    sim = Simulation(scene, execution="gather")
    sim.run(3000, control=CellControl.strain_rate(0.12), output_every=3000)
    first = sim.a["measures"].to_numpy().copy()
    sim.measure()
    assert first.tobytes() == sim.a["measures"].to_numpy().tobytes()
