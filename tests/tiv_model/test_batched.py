"""Batched evaluations: equal to the single-point and to the pre-issue-12 formulas."""

import numpy as np
import pytest

from tiv_model import drivers
from tiv_model.energy import (
    energy_exponent,
    isotropic_matrix,
    log_energy_constant,
    mapping_matrix,
    stiffness,
    volume_factor,
)
from tiv_model.integrate import Control, initial_state
from tiv_model.params import TABLE1, ModelOptions

from .conftest import random_elastic_state


def stiffness_before(eps, v, beta, params, options):
    """D = P D̃ P with D̃ formed explicitly (energy.stiffness before issue 12)."""
    a = energy_exponent(params)
    cmat = isotropic_matrix(params)
    pmat = mapping_matrix(beta, params, options)
    mapped = np.einsum("...ij,...j->...i", pmat, eps)
    c_eps = mapped @ cmat
    quad = np.sum(mapped * c_eps, axis=-1)
    scale = a * volume_factor(v, params) * np.exp(log_energy_constant(params)
                                                   + (a - 2.0) * np.log(quad))  # fmt: skip
    d_tilde = scale[..., None, None] * (
        4.0 * (a - 1.0) * c_eps[..., :, None] * c_eps[..., None, :]
        + 2.0 * quad[..., None, None] * cmat
    )
    return pmat @ d_tilde @ pmat


def random_batch(n, seed=3):
    rng = np.random.default_rng(seed)
    points = [random_elastic_state(rng) for _ in range(n)]
    return tuple(np.array(x) for x in zip(*points, strict=True))


@pytest.mark.parametrize("form", ["A", "B"])
def test_batched_stiffness_equals_the_formula_before_and_each_point(form):
    options = ModelOptions(anisotropy=form)
    eps, v, beta = random_batch(5000)  # more than one block of STIFFNESS_CHUNK
    d = stiffness(eps, v, beta, TABLE1, options)
    ref = stiffness_before(eps, v, beta, TABLE1, options)
    np.testing.assert_allclose(d, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    for i in (0, 2047, 2048, 4999):
        single = stiffness(eps[i], v[i], beta[i], TABLE1, options)
        assert single.shape == (6, 6)
        np.testing.assert_allclose(single, d[i], rtol=1e-13, atol=1e-13 * np.abs(d[i]).max())
    shared = stiffness(eps[:3], 1.7, beta[0], TABLE1, options)  # broadcast v and β
    np.testing.assert_allclose(
        shared, stiffness_before(eps[:3], np.full(3, 1.7), beta[[0, 0, 0]], TABLE1, options),
        rtol=1e-12,
    )  # fmt: skip


def test_batched_records_equal_the_single_state_record(options):
    ds = drivers.k0_then_unload(120.0, increments=8, unload_increments=3, options=options)
    states = drivers.run_path(
        initial_state(5.0, TABLE1, options),
        [Control.triaxial(axial_stress=s, radial_strain_increment=0.0)
         for s in np.geomspace(5.0, 60.0, 6)[1:]],
        TABLE1, options,
    )[0]  # fmt: skip
    table = drivers.records(states, TABLE1, options)
    for i, state in enumerate(states):
        row = drivers.record(state, TABLE1, options)
        probe = drivers.elastic_probe(state, TABLE1, options)
        assert row["e_oed_h"] == pytest.approx(probe.e_oed_h, rel=1e-13)
        for name, value in row.items():
            assert table[name][i] == pytest.approx(value, rel=1e-13, abs=1e-300), name
    assert set(ds.data_vars) >= set(drivers.VARIABLES)
