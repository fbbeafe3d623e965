"""Attraction only between the rods bonded at state A (``[long_range] attraction_pairs =
"bonded_at_A"``, issue 19).

- the partner table (:mod:`dem_taichi.physics.attraction`): built from rod pairs, read back,
  its capacity, and which pairs it lets attract (a rod whose partners are not set: all);
- two rods: before the partners are set, and between partners, the law is the study's; between
  rods that are not partners an attractive pair feels nothing (force and energy), a repulsive
  one its full repulsion;
- a jammed packing, rigid and bonded, on the serial, parallel and gather paths: setting the
  partners leaves every force bit for bit; compressed further, new attractive pairs form that
  are cut, and the engine's forces, stress and long-range energy equal the numpy reference on
  the snapshot, which carries the table;
- the state: the table is saved and restored with it, and a state past A is refused by a scene
  without the option; ``"any"`` (the default) allocates one unused row;
- the protocol sets the partners at state A, and from A on no pair of non-partners attracts.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from dem_taichi.engine.simulation import CellControl, Simulation
from dem_taichi.kernels import layout
from dem_taichi.physics import forcelaw
from dem_taichi.physics.attraction import (
    are_partners,
    partner_pairs,
    partner_table,
    unset_table,
)
from dem_taichi.scene.config import SceneError, scene_from_toml

from .test_two_body import (
    DENSE_NETWORK,
    assert_engine_matches_reference,
    facing_rods,
    jammed_network,
    make_static,
    rods_scene,
)

BONDED_AT_A = {"attraction_pairs": "bonded_at_A"}


def test_the_partner_table_holds_each_pair_in_both_rows():
    table = partner_table(np.array([[3, 1], [0, 3], [1, 3], [2, 0]]), 5, 4)  # (1, 3) twice
    assert table.dtype == np.int32 and table.shape == (5, 4)
    np.testing.assert_array_equal(table[:, 0], [2, 1, 1, 2, 0])
    np.testing.assert_array_equal(table[3], [2, 0, 1, -1])  # sorted partners, -1 unused
    np.testing.assert_array_equal(partner_pairs(table), [[0, 2], [0, 3], [1, 3]])
    assert partner_pairs(unset_table(5, 4)).shape == (0, 2)
    ok = are_partners(table, np.array([0, 0, 4, 3, 1]), np.array([3, 1, 0, 1, 1]))
    np.testing.assert_array_equal(ok, [True, False, False, True, False])
    unset = unset_table(3, 4)
    assert are_partners(unset, np.array([0, 2]), np.array([1, 0])).all()  # not set: all attract
    with pytest.raises(ValueError, match="rod 0 attracts 4 rods at state A, more than the 3"):
        partner_table(np.array([[0, 1], [0, 2], [0, 3], [0, 4]]), 5, 4)
    with pytest.raises(ValueError, match="its own partner"):
        partner_table(np.array([[2, 2]]), 5, 4)


def two_rods(option: str = "bonded_at_A"):
    """The two 3-disc rods of test_two_body.py (acidic: edge discs +1, the middle one −1; F_max
    10/30, k_a 50/150; no friction) with ``attraction_pairs``."""
    return rods_scene("acidic").replace(long_range={"attraction_pairs": option})


def with_partners(sim: Simulation, table: np.ndarray) -> None:
    """Set ``sim``'s partner table through its state, as a restored state would."""
    state = sim.get_state()
    state["attraction_partners"] = table
    sim.set_state(state)
    sim.recompute_forces()


@pytest.mark.parametrize("gap", [-0.01, 0.05, 0.15])
def test_two_rods_attract_only_as_partners_and_always_repel(gap):
    """A's edge disc (+1) faces B's middle disc (−1, attractive) or B's edge disc (+1,
    repulsive). The study's law before the partners are set and between partners; between
    rods that are not partners, the attractive pair's force and energy are 0 (the contact
    remains), the repulsive pair's unchanged."""
    for face in ("inner", "edge"):
        gas, (si, sj) = facing_rods(gap, face)
        f_max, k_a = np.array([10.0, 30.0, 10.0]), np.array([50.0, 150.0, 50.0])
        charge = np.array([1, -1, 1])
        f_pair = forcelaw.harmonic_mean(f_max[si], f_max[sj])
        k_pair = forcelaw.harmonic_mean(k_a[si], k_a[sj])
        sign = charge[si] * charge[sj]
        law = float(forcelaw.long_range_force(gap, f_pair, k_pair, sign))
        energy = float(forcelaw.long_range_potential(gap, f_pair, k_pair, sign))
        contact = 1.0e5 * max(-gap, 0.0)
        sim = Simulation(two_rods(), initial=gas)
        cases = [
            (unset_table(2, layout.PARTNER_COLUMNS), law, energy),  # before A
            (partner_table(np.array([[0, 1]]), 2, layout.PARTNER_COLUMNS), law, energy),
            (partner_table(np.zeros((0, 2)), 2, layout.PARTNER_COLUMNS),) + (
                (0.0, 0.0) if sign < 0 else (law, energy)
            ),
        ]  # fmt: skip
        for table, want, want_energy in cases:
            with_partners(sim, table)
            force_a = sim.get_state()["force"][0]
            assert force_a[0] == pytest.approx(-(want + contact), rel=1e-12, abs=1e-12)
            got = sim.measure()["long_range_energy"]
            assert got == pytest.approx(want_energy, rel=1e-12, abs=1e-12)
        if sign < 0:
            assert law < 0.0  # the cut pair did attract under the study's law


def test_the_default_keeps_the_study_law_and_one_unused_row():
    sim = Simulation(two_rods("any"), initial=facing_rods(0.05, "inner")[0])
    assert not sim.physics.partners
    assert sim.a["attraction_partners"].shape == (1, layout.PARTNER_COLUMNS)
    assert sim.snapshot().attraction_partners is None
    with pytest.raises(ValueError, match="attraction_pairs = 'bonded_at_A'"):
        sim.freeze_attraction()
    with pytest.raises(SceneError, match="attraction_pairs"):
        scene_from_toml('[long_range]\nenabled = true\nattraction_pairs = "at_A"')


def dense(rod_model: str, execution: str):
    return scene_from_toml(DENSE_NETWORK).replace(
        particles={"rod_model": rod_model},
        long_range=BONDED_AT_A,
        integration={"execution": execution},
    )


@pytest.mark.parametrize(
    "rod_model, execution",
    [("rigid", "serial"), ("bonded", "serial"), ("rigid", "parallel"), ("bonded", "gather")],
)
def test_engine_matches_the_numpy_reference_after_the_partners_are_set(rod_model, execution):
    sim = jammed_network(dense(rod_model, execution))
    before = sim.get_state()
    assert (before["attraction_partners"][:, 0] == -1).all()
    assert not sim.kernel_physics.partners  # until A: the kernels of the scene without it
    pairs = sim.freeze_attraction()
    assert sim.kernel_physics.partners
    snap = sim.snapshot()
    np.testing.assert_array_equal(pairs, forcelaw.attracting_rod_pairs(snap))
    assert len(pairs) > 10
    np.testing.assert_array_equal(partner_pairs(snap.attraction_partners), pairs)
    sim.recompute_forces()
    after = sim.get_state()
    scale = np.abs(before["force"]).max()
    for key in ("force", "torque"):  # every pair that attracted still attracts (to round-off)
        np.testing.assert_allclose(after[key], before[key], rtol=0, atol=1e-12 * scale)
    np.testing.assert_array_equal(sim.freeze_attraction(), pairs)  # set once
    # compressed further, with every other rod pair of A kept as partners: the attractive
    # pairs of the other rods, and of rods that meet on the way, are cut
    sim.run(1500, control=CellControl.strain_rate(0.1), output_every=10**9)
    with_partners(sim, partner_table(pairs[::2], 30, layout.PARTNER_COLUMNS))
    make_static(sim)
    snap = sim.snapshot()
    free = dataclasses.replace(snap, attraction_partners=None)
    cut = {tuple(p) for p in forcelaw.attracting_rod_pairs(free)} - {tuple(p) for p in pairs[::2]}
    assert len(cut) > 5
    energy = forcelaw.potential_energy(snap).long_range
    assert sim.measure()["long_range_energy"] == pytest.approx(energy, rel=1e-9)
    assert abs(forcelaw.potential_energy(free).long_range - energy) > 1e-3 * abs(energy)
    if rod_model == "rigid":
        assert_engine_matches_reference(sim, snap)


def test_until_the_partners_are_set_the_run_is_the_scene_without_them_bit_for_bit():
    """The option compiles into the kernels only once the partners are set, so the gas, its
    ageing and the compression to A are those of the scene without it, bit for bit. (The
    study_demo gas of 100 rods, 20,000 steps: with the partner test compiled in from the start,
    its trajectory departs from the scene's without it, measured.)"""
    from dem_taichi.scene.config import load_scene

    runs = {}
    for option in ("any", "bonded_at_A"):
        scene = load_scene("study_demo").replace(
            long_range={"attraction_pairs": option}, particles={"n_rods": 100}
        )
        sim = Simulation(scene)
        assert not sim.kernel_physics.partners
        sim.run(20_000, output_every=10**9)
        runs[option] = sim.get_state()
    for key, value in runs["any"].items():
        if key != "attraction_partners":
            np.testing.assert_array_equal(runs["bonded_at_A"][key], value, err_msg=key)


def test_the_partners_travel_with_the_state_and_a_checkpoint(tmp_path):
    sim = jammed_network(dense("rigid", "serial"))
    pairs = sim.freeze_attraction()
    path = sim.save_checkpoint(tmp_path / "a.npz")
    again = Simulation.from_checkpoint(path)
    np.testing.assert_array_equal(
        again.get_state()["attraction_partners"], sim.get_state()["attraction_partners"]
    )
    assert again.kernel_physics.partners  # a state past A runs with the partner test
    np.testing.assert_array_equal(again.freeze_attraction(), pairs)
    plain = Simulation(scene_from_toml(DENSE_NETWORK))
    with pytest.raises(ValueError, match="carries the attraction partners set at state A"):
        plain.set_state(sim.get_state())
    old = sim.get_state()
    del old["attraction_partners"]  # a state written before the option: partners not set
    fresh = Simulation(dense("rigid", "serial"))
    fresh.set_state(sim.get_state())
    assert fresh.kernel_physics.partners
    fresh.set_state(old)
    assert (fresh.get_state()["attraction_partners"][:, 0] == -1).all()
    assert not fresh.kernel_physics.partners


def test_the_protocol_sets_the_partners_at_a_and_keeps_them(tmp_path):
    """The smoke protocol's A→B with the option: state A carries the rod pairs that attract at
    A, state B (another process's branch would load it from state A) the same table, and the
    engine's long-range energy at B is the reference's with the table. (This small dense
    sample forms no new attractive rod pair between A and B; the cut itself is tested above.)"""
    from dem_taichi.io.checkpoint import load_checkpoint
    from dem_taichi.protocol.runner import run_protocol

    from .test_protocol import smoke_protocol_scene

    scene = smoke_protocol_scene(run_k0=False, run_unloading=False, radial_stress_ratios="")
    scene = scene.replace(long_range=BONDED_AT_A)
    result = run_protocol(scene, tmp_path / "run")
    arrays, _ = load_checkpoint(result.files["state_A"])
    at_a = Simulation(scene.replace(long_range={"attraction_pairs": "any"}))
    state = dict(arrays)
    state["attraction_partners"] = unset_table(1, layout.PARTNER_COLUMNS)
    at_a.set_state(state)
    pairs = forcelaw.attracting_rod_pairs(at_a.snapshot())
    assert len(pairs) > 0
    np.testing.assert_array_equal(partner_pairs(arrays["attraction_partners"]), pairs)
    at_b = Simulation.from_checkpoint(result.files["state_B"])
    np.testing.assert_array_equal(
        at_b.get_state()["attraction_partners"], arrays["attraction_partners"]
    )
    make_static(at_b)
    snap = at_b.snapshot()
    assert snap.attraction_partners is not None
    energy = forcelaw.potential_energy(snap).long_range
    assert at_b.measure()["long_range_energy"] == pytest.approx(energy, rel=1e-9)
