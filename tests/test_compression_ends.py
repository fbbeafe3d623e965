"""benchmarks/compression_ends.py: v at the window's two ends and the chord between them, NaN
where an end is not on the path, and the per-cell table."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.scripts import load_script


def test_a_straight_line_gives_its_ends_and_slope():
    script = load_script("benchmarks/compression_ends.py")
    p = np.geomspace(0.5, 150.0, 9)
    v_1, v_100, chord = script.ends(p, 3.0 * p**-0.25)
    assert v_1 == pytest.approx(3.0, rel=1e-12)
    assert v_100 == pytest.approx(3.0 * 100.0**-0.25, rel=1e-12)
    assert chord == pytest.approx(0.25, rel=1e-12)


def test_an_end_off_the_path_is_nan():
    script = load_script("benchmarks/compression_ends.py")
    above = np.geomspace(2.0, 150.0, 6)  # A above 1 kPa
    v_1, v_100, chord = script.ends(above, 4.0 * above**-0.2)
    assert math.isnan(v_1) and math.isnan(chord)
    assert v_100 == pytest.approx(4.0 * 100.0**-0.2, rel=1e-12)
    short = np.geomspace(0.5, 60.0, 6)  # the path ends below 100 kPa
    assert math.isnan(script.ends(short, 4.0 * short**-0.2)[1])


def test_the_cell_table_gives_mean_and_interval_over_seeds():
    script = load_script("benchmarks/compression_ends.py")
    rows = [
        {"cell": "X", "seed": s, "scale": 1.0, "p_A_kpa": 0.5, "v_A": va, "v_1": v1,
         "v_100": v100, "chord": math.log(v1 / v100) / math.log(100.0)}
        for s, va, v1, v100 in ((1, 6.0, 5.8, 2.6), (2, 6.4, 6.0, 2.8), (3, 6.2, 5.6, 2.4))
    ]  # fmt: skip
    table = script.markdown(rows)
    assert "| X (1,2,3) | 0.5 ± 0 | 6.2 ± 0.5 | 5.8 ± 0.5 | 2.6 ± 0.5 |" in table
    assert "| X_s2 | 0.5 | 6.4 | 6 | 2.8 |" in table
