"""Sanity ranges of docs/science/tiv-model.md §2.4 (Table 1, form A, constraint forces): not a
tuning target.

K0 ≈ 0.65–0.70 and β ≈ 0.13 at σ_v = 100 kPa, E_h/E_v above 2 by 100 kPa, elastic constant-p
unloading, and the stated contrast between the anisotropy forms (E_h/E_v ≈ 2–3 for A, ≈ 1.2 B).
"""

import numpy as np
import pytest

from tiv_model import drivers
from tiv_model.params import ModelOptions


def at_100_kpa(ds, name):
    k0 = ds.where(ds.stage == 0, drop=True)
    return float(np.interp(100.0, k0.axial_stress.values, k0[name].values))


@pytest.mark.validation
def test_k0_sanity_ranges_form_a():
    ds = drivers.k0_then_unload(200.0, increments=200, unload_increments=20)
    assert 0.65 <= at_100_kpa(ds, "radial_stress") / 100.0 <= 0.70
    assert at_100_kpa(ds, "fabric") == pytest.approx(0.13, abs=0.01)
    assert at_100_kpa(ds, "stiffness_ratio") > 2.0
    unloading = ds.where(ds.stage == 1, drop=True)
    assert float(unloading.plastic.sum()) == 0


@pytest.mark.validation
def test_form_b_gives_much_weaker_stiffness_anisotropy():
    ds = drivers.k0_then_unload(
        150.0, increments=100, unload_increments=5, options=ModelOptions(anisotropy="B")
    )
    assert 1.05 < at_100_kpa(ds, "stiffness_ratio") < 1.4
