"""The largest contact overlap of a saved configuration (dem_taichi.analysis.overlaps), against
hand-placed rods: inside the cell, across its periodic boundary, with a rod's own discs
overlapping (excluded), and from configuration files (bonded: not computed)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dem_taichi.analysis.overlaps import configuration_max_overlap, max_overlap, run_max_overlap
from dem_taichi.io.writers import write_configuration

L = np.array([20.0, 10.0])


def test_two_parallel_rods_overlap_by_the_gap_they_lack():
    # two 3-disc rods along x, 0.98 d apart in y: every facing pair overlaps by 0.02 d
    pos, angle = np.array([[5.0, 5.0], [5.0, 5.98]]), np.zeros(2)
    assert max_overlap(pos, angle, L, 3, 1.0, 1.0) == pytest.approx(0.02, abs=1e-12)
    # the same in units of a 2-unit disc: δ/d is dimensionless
    assert max_overlap(2 * pos, angle, 2 * L, 3, 2.0, 2.0) == pytest.approx(0.02, abs=1e-12)


def test_the_overlap_across_the_periodic_boundary_is_the_minimum_image():
    # rod 1 at y = 0.1, rod 2 at y = L_y − 0.87: 0.97 d apart through the boundary
    pos, angle = np.array([[5.0, 0.1], [5.0, L[1] - 0.87]]), np.zeros(2)
    assert max_overlap(pos, angle, L, 3, 1.0, 1.0) == pytest.approx(0.03, abs=1e-12)
    # across x: an end disc of each rod, 0.96 d apart through x = 0 (rod axes along x)
    pos = np.array([[1.0 + 0.5, 5.0], [L[0] - 1.0 - 0.46, 5.0]])
    assert max_overlap(pos, angle, L, 3, 1.0, 1.0) == pytest.approx(0.04, abs=1e-12)


def test_a_rods_own_discs_and_distant_rods_do_not_count():
    # spacing 0.5 d: a rod's neighbouring discs overlap by half a diameter, which is its shape
    one = max_overlap(np.array([[5.0, 5.0]]), np.zeros(1), L, 5, 0.5, 1.0)
    assert one == 0.0
    apart = max_overlap(np.array([[5.0, 2.0], [5.0, 7.0]]), np.zeros(2), L, 5, 0.5, 1.0)
    assert apart == 0.0
    # crossing rods at right angles: the centre discs coincide, the overlap is a whole diameter
    cross = max_overlap(
        np.array([[5.0, 5.0], [5.0, 5.0]]), np.array([0.0, math.pi / 2]), L, 3, 1.0, 1.0
    )
    assert cross == pytest.approx(1.0)


def _write(path, rod_model, y2):
    pos, angle = np.array([[5.0, 5.0], [5.0, y2]]), np.zeros(2)
    attrs = {"n_spheres": 3, "spacing": 1.0, "diameter": 1.0, "rod_model": rod_model}
    return write_configuration(path, pos, angle, L, attrs=attrs)


def test_files_give_the_same_overlap_and_bonded_rods_none(tmp_path):
    a = _write(tmp_path / "configuration_A.nc", "rigid", 5.99)
    b = _write(tmp_path / "configuration_B.nc", "rigid", 5.95)
    assert configuration_max_overlap(b) == pytest.approx(0.05, abs=1e-12)
    assert configuration_max_overlap(a) == pytest.approx(0.01, abs=1e-12)
    assert run_max_overlap(tmp_path) == pytest.approx(0.05, abs=1e-12)  # the largest state
    bonded = tmp_path / "bonded"
    bonded.mkdir()
    assert math.isnan(
        configuration_max_overlap(_write(bonded / "configuration_A.nc", "bonded", 5.9))
    )
    assert math.isnan(run_max_overlap(bonded))
    assert math.isnan(run_max_overlap(tmp_path / "nothing"))
