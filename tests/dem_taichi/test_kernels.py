"""Neighbour lists against brute force: complete at build time, and every pair within the
interaction cut-off is listed at every checked time of a deforming, strained run (the skin
criterion accounts for displacements, rotations and the cell deformation)."""

import numpy as np
import pytest

from dem_taichi.engine.simulation import CellControl, Simulation
from dem_taichi.kernels import layout
from dem_taichi.scene.config import load_scene


def disc_positions(reduced, angle, lengths, offsets):
    centre = reduced * lengths
    axis = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    return (centre[:, None, :] + offsets[None, :, None] * axis[:, None, :]).reshape(-1, 2)


def brute_force_pairs(x, lengths, n_spheres, radius):
    diff = x[:, None, :] - x[None, :, :]
    diff -= np.round(diff / lengths) * lengths
    dist = np.linalg.norm(diff, axis=-1)
    rod = np.arange(len(x)) // n_spheres
    i, j = np.nonzero((dist < radius) & (rod[:, None] != rod[None, :]))
    keep = i < j
    return set(zip(i[keep].tolist(), j[keep].tolist(), strict=True))


def listed_pairs(state):
    pairs = set()
    for i, count in enumerate(state["neighbour_count"]):
        for entry in state["neighbours"][i, :count]:
            pairs.add((i, int(entry) // layout.IMAGE_CODES))
    return pairs


@pytest.fixture(scope="module")
def scene():
    return load_scene("smoke")


def test_list_is_exactly_the_pairs_within_the_list_radius_at_build(scene):
    sim = Simulation(scene)
    sim.run(3000, control=CellControl.strain_rate(0.12))
    state = sim.get_state()
    build_lengths = state["cell"][[layout.C_LBX, layout.C_LBY]]
    x = disc_positions(
        state["ref_position"], state["ref_angle"], build_lengths, sim.geometry.offsets
    )
    expected = brute_force_pairs(x, build_lengths, sim.geometry.n_spheres, sim.list_radius)
    assert len(expected) > 100
    assert listed_pairs(state) == expected


def test_every_interacting_pair_is_listed_during_a_strained_run(scene):
    sim = Simulation(scene.replace(integration={"steps_per_call": 37}))
    checked = 0
    for rate in (0.15, -0.05, 0.1):
        for _ in range(12):
            sim.run(150, control=CellControl.strain_rate(rate, 0.5 * rate))
            state = sim.get_state()
            lengths = sim.cell_lengths
            x = disc_positions(
                state["reduced_position"], state["angle"], lengths, sim.geometry.offsets
            )
            within = brute_force_pairs(x, lengths, sim.geometry.n_spheres, sim.cutoff)
            missing = within - listed_pairs(state)
            assert not missing, f"pairs within the cut-off missing from the list: {missing}"
            checked += len(within)
    assert checked > 500
    assert sim.get_state()["flags"][layout.F_REBUILDS] > 5


def test_a_one_disc_body_has_its_disc_at_its_centre():
    """The kernels place a one-disc body's disc without its axis (``kernels.common.rod_axis``
    returns (1, 0) for ``ns`` = 1), which is exact only because that disc's offset is 0: for
    a rigid rod of one disc and for every bonded rod's disc."""
    from dem_taichi.physics.forcelaw import disc_offsets

    for spacing in (0.5, 1.0, 1.7):
        assert np.array_equal(disc_offsets(1, spacing), np.zeros(1))
    sim = Simulation(load_scene("smoke_bonded"))
    assert sim.body.n_spheres == 1 and np.array_equal(sim.body.offsets, np.zeros(1))
