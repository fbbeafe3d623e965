"""The largest contact overlap of a saved configuration (dem_taichi.analysis.overlaps), against
hand-placed rods: inside the cell, across its periodic boundary, with a rod's own discs
overlapping (excluded), from configuration files (bonded: not computed from them) and from state
checkpoints (rigid and bonded rods)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from dem_taichi.analysis.overlaps import (
    configuration_max_overlap,
    disc_max_overlap,
    disc_overlaps,
    max_overlap,
    run_max_overlap,
    state_max_overlap,
)
from dem_taichi.io.checkpoint import load_checkpoint, save_checkpoint
from dem_taichi.io.writers import write_configuration
from dem_taichi.scene.config import load_scene, scene_to_toml

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


def test_every_touching_pair_is_in_the_distribution():
    """disc_overlaps: one δ/d per touching pair of discs of different rods, across the periodic
    boundary too; its maximum is disc_max_overlap; none touching gives an empty array and 0."""
    # two 1-disc "rods" 0.98 d apart, two 0.95 d apart through x = 0, one far from all
    centres = np.array([[5.0, 5.0], [5.0, 5.98], [0.2, 2.0], [L[0] - 0.75, 2.0], [12.0, 8.0]])
    got = np.sort(disc_overlaps(centres, 1, L, 1.0))
    assert got == pytest.approx([0.02, 0.05], abs=1e-12)
    assert disc_max_overlap(centres, 1, L, 1.0) == pytest.approx(0.05, abs=1e-12)
    # the first four as two 2-disc rods (discs 0-1 and 2-3): each touching pair is one rod's
    assert disc_overlaps(centres[:4], 2, L, 1.0).size == 0
    assert disc_max_overlap(centres[:4], 2, L, 1.0) == 0.0


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


def _state(path, scene_name, n_spheres, bodies, angles):
    """A state checkpoint holding only what the overlap reads: the bodies' reduced positions,
    their angles and the cell, with the scene (``n_spheres`` discs per rod) in its metadata."""
    scene = load_scene(scene_name)
    particles = dataclasses.replace(scene.particles, n_spheres=n_spheres)
    meta = {"scene_toml": scene_to_toml(dataclasses.replace(scene, particles=particles))}
    cell = np.zeros(8)
    cell[:2] = L
    arrays = {"reduced_position": np.asarray(bodies) / L, "angle": np.asarray(angles), "cell": cell}
    return save_checkpoint(path, arrays, meta)


def test_bonded_states_give_the_overlap_of_their_discs(tmp_path):
    # two bonded 3-disc rods along x, 0.97 d apart in y; the first rod's discs 1 d apart (its
    # bonds), the second one's end disc wrapped through x = 0 (a rod may straddle the boundary)
    rod1 = [[4.0, 5.0], [5.0, 5.0], [6.0, 5.0]]
    rod2 = [[L[0], 5.97], [1.0, 5.97], [2.0, 5.97]]  # x = 20 ≡ 0, 1, 2
    bodies = np.array(rod1 + rod2)
    # (no pair of different rods touches yet: the rods are 2 d apart along x)
    assert (
        state_max_overlap(_state(tmp_path / "state_A.npz", "smoke_bonded", 3, bodies, np.zeros(6)))
        == 0.0
    )
    bodies[3:, 0] += 4.0  # rod 2 now under rod 1: x = 4, 5, 6 (the first disc from 20 → 24 ≡ 4)
    b = _state(tmp_path / "state_B.npz", "smoke_bonded", 3, bodies, np.zeros(6))
    assert state_max_overlap(b) == pytest.approx(0.03, abs=1e-12)
    # the discs of one rod overlapping each other (a bent rod) do not count
    bent = np.array([[4.0, 5.0], [4.5, 5.0], [5.0, 5.0], [9.0, 5.0], [10.0, 5.0], [11.0, 5.0]])
    assert (
        state_max_overlap(_state(tmp_path / "x.npz", "smoke_bonded", 3, bent, np.zeros(6))) == 0.0
    )
    # a run of bonded rods: its configurations give NaN, so the states decide
    _write(tmp_path / "configuration_A.nc", "bonded", 5.9)
    assert run_max_overlap(tmp_path) == pytest.approx(0.03, abs=1e-12)


def test_rigid_states_give_the_overlap_of_their_configurations(tmp_path):
    # rigid rods: the bodies are the rods, their discs placed along the angle
    bodies, angles = np.array([[5.0, 5.0], [5.0, 5.96]]), np.zeros(2)
    state = _state(tmp_path / "state_A.npz", "smoke", 3, bodies, angles)
    assert state_max_overlap(state) == pytest.approx(0.04, abs=1e-12)
    assert state_max_overlap(state) == pytest.approx(max_overlap(bodies, angles, L, 3, 1.0, 1.0))


def test_a_simulations_state_gives_the_overlap_of_its_discs(tmp_path):
    """The engine's own state file, bonded rods: its bodies are the simulation's discs, rod-major,
    so an overlap placed between two rods' discs is found there."""
    from dem_taichi.engine.simulation import Simulation

    sim = Simulation(load_scene("smoke_bonded"))
    n_spheres = sim.scene.particles.n_spheres
    lengths = np.asarray(sim.cell_lengths, dtype=float)
    path = sim.save_checkpoint(tmp_path / "state_A.npz")
    arrays, meta = load_checkpoint(path)
    bodies = arrays["reduced_position"] * arrays["cell"][:2]
    gap = bodies - sim.disc_positions()
    assert np.abs(gap - lengths * np.round(gap / lengths)).max() < 1e-9  # the same discs
    # move rod 1 onto rod 0, shifted 0.993 d across rod 0's axis: the overlap is 0.007 d
    axis = bodies[n_spheres - 1] - bodies[0]
    normal = np.array([-axis[1], axis[0]]) / np.linalg.norm(axis)
    bodies[n_spheres : 2 * n_spheres] = bodies[:n_spheres] + 0.993 * normal
    arrays["reduced_position"] = bodies / arrays["cell"][:2]
    moved = save_checkpoint(tmp_path / "state_B.npz", arrays, meta)
    assert state_max_overlap(moved) == pytest.approx(0.007, abs=1e-9)
