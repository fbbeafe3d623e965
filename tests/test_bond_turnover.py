"""benchmarks/bond_turnover.py: bonds are pairs of opposite charge within the range across the
periodic cell, counted per rod; disc centres from a saved state, rigid or bonded; the turnover
from A to B counts kept, broken and new bonds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.scripts import load_script

ACIDIC = np.array([1, -1, -1, 1])  # 4-disc rods: edges +1, inner discs -1


LENGTHS = np.array([20.0, 20.0])
UPRIGHT = np.array([0.0, math.pi / 2])  # rod 0 along x, rod 1 along y


def rigid_state(positions, angles) -> dict:
    """A saved state's arrays for rigid rods at ``positions`` in the 20 × 20 cell."""
    cell = np.zeros(8)
    cell[:2] = LENGTHS
    return {"reduced_position": np.asarray(positions) / LENGTHS, "angle": angles, "cell": cell}


def rigid_bonds(script, positions, angles, g_max=0.5):
    discs, lengths = script.disc_centres(rigid_state(positions, angles), 4, 1.0, bonded=False)
    return script.bonds(discs, lengths, ACIDIC, 1.0, g_max)


def test_a_t_junction_bonds_and_a_collinear_pair_does_not():
    script = load_script("benchmarks/bond_turnover.py")
    # rod 0 along x centred at (5, 5): discs at x = 3.5 ... 6.5; rod 1 vertical, its lower edge
    # disc (+1) at gap 0.3 above rod 0's inner disc (-1) at x = 5.5
    positions = np.array([[5.0, 5.0], [5.5, 5.0 + 1.3 + 1.5]])
    found = rigid_bonds(script, positions, UPRIGHT)
    np.testing.assert_array_equal(found, [[2, 4]])  # disc 2 of rod 0, disc 0 of rod 1
    assert rigid_bonds(script, positions, UPRIGHT, g_max=0.2).size == 0
    # collinear, edge to edge (+1 +1) at gap 0.1: repulsive, not a bond
    line = np.array([[5.0, 5.0], [5.0 + 4.1, 5.0]])
    assert rigid_bonds(script, line, np.zeros(2)).size == 0


def test_a_bond_across_the_periodic_boundary_is_found():
    script = load_script("benchmarks/bond_turnover.py")
    # rod 0 along x at y = 0.4; rod 1 vertical below it across the boundary: its upper edge disc
    # (+1) at y = -0.8 (gap 0.2 under rod 0's inner disc at x = 10.5), its centre 1.5 lower and
    # given two cell lengths up
    positions = np.array([[10.0, 0.4], [10.5, -0.8 - 1.5 + 40.0]])
    np.testing.assert_array_equal(rigid_bonds(script, positions, UPRIGHT), [[2, 7]])


def test_bonded_rods_are_read_disc_by_disc():
    """A bonded state's bodies are its discs: the same T-junction, rod 1 bent at its top, gives
    the same bond from the discs where they are."""
    script = load_script("benchmarks/bond_turnover.py")
    rigid, _ = script.disc_centres(
        rigid_state([[5.0, 5.0], [5.5, 7.8]], UPRIGHT), 4, 1.0, bonded=False
    )
    bent = rigid.copy()
    bent[7] += [0.4, -0.1]  # rod 1's upper edge disc moved: a bent rod
    cell = np.zeros(8)
    cell[:2] = LENGTHS
    state = {"reduced_position": bent / LENGTHS, "angle": np.zeros(8), "cell": cell}
    discs, lengths = script.disc_centres(state, 4, 1.0, bonded=True)
    np.testing.assert_allclose(discs, bent, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(script.bonds(discs, lengths, ACIDIC, 1.0, 0.5), [[2, 4]])


def test_turnover_counts_kept_broken_and_new_bonds():
    script = load_script("benchmarks/bond_turnover.py")
    n_s = 4
    at_a = np.array([[0, 4], [1, 8], [5, 9]])  # rods (0,1), (0,2), (1,2)
    at_b = np.array([[0, 5], [5, 9], [8, 12]])  # (0,1) kept by another disc pair, (1,2), new (2,3)
    row = script.turnover(at_a, at_b, 4, n_s)
    assert row["bonds_A"] == pytest.approx(1.5) and row["rod_pairs_A"] == pytest.approx(1.5)
    assert row["kept"] == pytest.approx(2 / 3)  # (0,2) broke
    assert row["kept_bonds"] == pytest.approx(1 / 3)  # only (5, 9) is the same disc pair
    assert row["old_at_B"] == pytest.approx(2 / 3)  # (2,3) is new
    empty = script.turnover(np.zeros((0, 2), int), at_b, 4, n_s)
    assert math.isnan(empty["kept"]) and empty["old_at_B"] == 0.0
