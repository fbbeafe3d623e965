"""The K0 path's stress ladder on loose samples (issue 19: a loose gel's A can carry σ_xx only).

On seed 12 of the agitated-aggregation cell (``benchmarks/study_clay_agitated.sh``, cell aggv)
the ladder started from σ_yy(A) < 0 and asked the servo for σ_yy = −0.0018, which it could not
reach in 2,000,000 steps. The ladder now starts from max(p, the A threshold) when σ_yy is below
that threshold, and is unchanged above it (the smoke references, which pass bitwise, check that).
"""

from __future__ import annotations

import math

import pytest

from dem_taichi.protocol.paths import k0_step_target


def test_the_ladder_multiplies_a_solid_sigma_yy():
    target, k0 = k0_step_target(40.0, 50.0, 45.0, 1.5, 0.5)
    assert target == pytest.approx(75.0, rel=1e-15)
    assert k0 == pytest.approx(0.8, rel=1e-15)


@pytest.mark.parametrize("stress_yy", [-0.0012, 0.0, 1e-6, 0.49])
def test_a_vanishing_or_tensile_sigma_yy_starts_the_ladder_at_p(stress_yy):
    stress_xx = 1.2
    p = 0.5 * (stress_xx + stress_yy)
    target, k0 = k0_step_target(stress_xx, stress_yy, p, 2.0, 0.5)
    assert target == pytest.approx(2.0 * max(p, 0.5), rel=1e-15)
    assert target > 0.0
    assert k0 == 1.0


def test_a_sample_below_the_threshold_everywhere_starts_at_the_threshold():
    target, k0 = k0_step_target(0.1, -0.2, -0.05, 3.0, 0.5)
    assert target == pytest.approx(1.5, rel=1e-15)
    assert math.isfinite(k0)
