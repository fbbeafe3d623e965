"""The batched integrator gives the single-point answer at every point."""

import numpy as np
import pytest

from tiv_model import batch
from tiv_model.drivers import run_path
from tiv_model.errors import SpecificVolumeBelowOneError
from tiv_model.integrate import Control, advance, initial_state
from tiv_model.params import TABLE1, ModelOptions, SolverSettings

from .conftest import ALL_OPTIONS, option_id

GENERAL = SolverSettings(triaxial_fast_path=False)


def start_states(options, n=6):
    """Normally consolidated K0 states at several stresses, and isotropic ones."""
    controls = [Control.triaxial(axial_stress=s, radial_strain_increment=0.0)
                for s in np.geomspace(5.0, 80.0, 9)[1:]]  # fmt: skip
    k0 = run_path(initial_state(5.0, TABLE1, options), controls, TABLE1, options)[0]
    states = k0[2::2] + [initial_state(p, TABLE1, options) for p in (5.0, 30.0)]
    return states[:n]


@pytest.mark.parametrize("options", ALL_OPTIONS, ids=option_id)
def test_batch_equals_single_points(options):
    states = start_states(options)
    rng = np.random.default_rng(5)
    path = [1e-3 * np.array([2.0, -0.2, 0.1, 0.3, -0.1, 0.2])
            + 4e-4 * rng.standard_normal((len(states), 6)) for _ in range(5)]  # fmt: skip
    path.insert(2, np.array([-2e-3, 0.0, 0.0, 0.0, 0.0, 0.0]))  # an elastic unloading for all
    out = batch.strain_path(batch.BatchState.from_states(states), path, TABLE1, options)
    for i, state in enumerate(states):
        for k, deps in enumerate(path):
            d = deps if deps.ndim == 1 else deps[i]
            state = advance(state, Control.strain(d), TABLE1, options, GENERAL)
            got = out[k + 1].state(i)
            assert got.plastic == state.plastic
            scale = np.abs(state.stress).max()
            np.testing.assert_allclose(got.stress, state.stress, atol=1e-9 * scale)
            np.testing.assert_allclose(got.fabric, state.fabric, atol=1e-11)
            assert got.specific_volume == pytest.approx(state.specific_volume, rel=1e-12)
            assert got.dissipated_energy == pytest.approx(state.dissipated_energy, rel=1e-9,
                                                          abs=1e-12)  # fmt: skip


def test_batch_round_trip_and_errors_name_the_point():
    states = start_states(ModelOptions(), 3)
    b = batch.BatchState.from_states(states)
    assert len(b) == 3
    for a, s in zip(b.states(), states, strict=True):
        np.testing.assert_array_equal(a.stress, s.stress)
        assert a.plastic == s.plastic
    params = TABLE1.replace(N=1.02)  # the NCL reaches v = 1 at a low p_c
    start = batch.BatchState.from_states([initial_state(5.0, params) for _ in range(2)])
    with pytest.raises(SpecificVolumeBelowOneError, match="point"):
        for _ in range(40):
            start = batch.strain_increment(start, [0.02, 0.02, 0.02, 0, 0, 0], params)
