"""The normal force behind the contact caps (``[contact] cap_force``, issue 19).

- the law (:func:`dem_taichi.physics.forcelaw.cap_force`): "contact" is |f_c|; "net" takes the
  pair's attraction (long-range and van der Waals) off it, never below 0, and ignores repulsion;
- two rods held shut by their attraction alone: under "contact" the joint has the sliding
  strength μ f_c = μ F_att, under "net" none;
- one jammed acidic packing with friction and rolling resistance, evaluated under both laws: on
  the serial and parallel paths the engine's forces, torques and stress equal the numpy force law
  on its snapshot under each law, the snapshot carries the law, and the two laws differ on the
  contacts that the attraction holds;
- the switch compiles in only where it can act (an attraction and a cap), and a wrong value is
  refused at load naming the key.
"""

from __future__ import annotations

import numpy as np
import pytest

from dem_taichi.engine.simulation import Simulation
from dem_taichi.physics import forcelaw
from dem_taichi.scene.config import SceneError, scene_from_toml

from .test_two_body import (
    DENSE_NETWORK,
    assert_engine_matches_reference,
    facing_rods,
    jammed_network,
    make_static,
    rods_scene,
)


def test_the_cap_force_law():
    contact = np.array([5.0, 5.0, 5.0, 2.0, -3.0])
    long_range = np.array([0.0, -2.0, 3.0, -4.0, -1.0])
    vdw = np.array([0.0, -1.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(
        forcelaw.cap_force("contact", contact, long_range, vdw), [5.0, 5.0, 5.0, 2.0, 3.0]
    )
    np.testing.assert_array_equal(
        forcelaw.cap_force("net", contact, long_range, vdw), [5.0, 2.0, 5.0, 0.0, 2.0]
    )
    with pytest.raises(ValueError, match="allowed 'contact' or 'net'"):
        forcelaw.cap_force("load", contact)


def frictional_rods(cap_force: str):
    return rods_scene("acidic").replace(
        contact={"friction": True, "k_t": 2.0e4, "mu": 0.5, "cap_force": cap_force}
    )


@pytest.mark.parametrize("cap_force", ["contact", "net"])
def test_a_joint_held_by_its_attraction_alone_has_no_strength_under_net(cap_force):
    """Rod A's edge disc (+1) touches rod B's middle disc (−1) at the overlap where the contact
    spring balances the attraction (k_n δ = F_att = 15). A tangential spring far beyond any cap
    gives the capped force: μ F_att under "contact", 0 under "net"; the normal force is the
    same under both."""
    f_att = forcelaw.harmonic_mean(10.0, 30.0)
    overlap = f_att / 1.0e5
    gas, _ = facing_rods(-overlap, "inner")
    sim = Simulation(frictional_rods(cap_force), initial=gas)
    assert sim.physics.net_caps == (cap_force == "net")
    state = sim.get_state()
    state["tangential_spring"][:] = 1.0  # k_t ξ = 2e4 on the one contact: beyond either cap
    sim.set_state(state)
    sim.recompute_forces()
    force = sim.get_state()["force"][0]
    assert force[0] == pytest.approx(0.0, abs=1e-9)  # f_c − F_att = 0 along x
    want = 0.5 * f_att if cap_force == "contact" else 0.0
    assert abs(force[1]) == pytest.approx(want, rel=1e-9, abs=1e-9)
    snap = sim.snapshot()
    assert snap.cap_force == cap_force
    assert np.abs(forcelaw.pair_forces(snap).tangential_force).max() <= want + 1e-9


def dense(cap_force: str, execution: str = "serial"):
    return scene_from_toml(DENSE_NETWORK).replace(
        contact={"rolling_stiffness": 2.0e4, "rolling_friction": 0.5, "cap_force": cap_force},
        integration={"execution": execution},
    )


@pytest.mark.parametrize("execution", ["serial", "parallel"])
def test_engine_matches_the_numpy_reference_under_both_laws(execution):
    """One jammed packing (compressed under "contact"), its state loaded into a simulation of
    each law: forces, torques and stress equal the numpy law on the snapshot; under "net" the
    contacts the attraction loads carry less tangential force and rolling moment."""
    packed = jammed_network(dense("contact", execution))
    state = packed.get_state()
    results = {}
    for law in ("contact", "net"):
        sim = Simulation(dense(law, execution))
        sim.set_state(state)
        make_static(sim)
        snap = sim.snapshot()
        assert snap.cap_force == law
        assert_engine_matches_reference(sim, snap)
        results[law] = forcelaw.pair_forces(snap)
    contact, net = results["contact"], results["net"]
    attracted = contact.in_contact & (contact.long_range_force < 0.0)
    assert attracted.sum() > 10
    t_contact = np.linalg.norm(contact.tangential_force, axis=1)
    t_net = np.linalg.norm(net.tangential_force, axis=1)
    assert np.all(t_net <= t_contact + 1e-9)
    assert (t_net < t_contact - 1e-6)[attracted].sum() > 3  # the attraction's strength is gone
    assert np.all(np.abs(net.rolling_moment) <= np.abs(contact.rolling_moment) + 1e-9)
    repelled = ~attracted  # repulsion and non-contacts: the laws agree
    np.testing.assert_allclose(t_net[repelled], t_contact[repelled], rtol=0, atol=1e-9)


def test_the_switch_compiles_in_only_where_it_acts():
    net = {"cap_force": "net"}
    assert Simulation(dense("net")).physics.net_caps
    neutral = scene_from_toml(DENSE_NETWORK).replace(long_range={"pattern": "neutral"}, contact=net)
    assert not Simulation(neutral).physics.net_caps  # no attraction
    frictionless = rods_scene("acidic").replace(contact=net)
    gas, _ = facing_rods(0.05, "inner")
    assert not Simulation(frictionless, initial=gas).physics.net_caps  # no cap
    with pytest.raises(SceneError, match="cap_force"):
        scene_from_toml('[contact]\ncap_force = "attraction"')


def _same_state(a: dict, b: dict) -> None:
    for key in sorted(set(a) & set(b)):
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def test_net_after_a_is_the_study_law_until_switched_then_the_net_law(tmp_path):
    """``"net_after_A"``: compressed into a packing bit for bit as under ``"contact"`` (the
    kernels compile without the switch, no state key is read); once switched (the protocol does
    it at A), the kernels, the snapshot and the measures use the net caps, the engine equals the
    numpy law, and the switch travels with the state and a checkpoint."""
    study = jammed_network(dense("contact"))
    after = jammed_network(dense("net_after_A"))
    assert after.physics.net_caps and not after.kernel_physics.net_caps
    _same_state(study.get_state(), after.get_state())
    assert not after.get_state()["net_caps_on"] and "net_caps_on" not in study.get_state()
    assert after.snapshot().cap_force == "contact"
    after.drop_attraction_caps()
    assert after.kernel_physics.net_caps and after.get_state()["net_caps_on"]
    after.recompute_forces()
    snap = after.snapshot()
    assert snap.cap_force == "net"
    assert_engine_matches_reference(after, snap)
    net = Simulation(dense("net"))
    net.set_state(after.get_state())
    make_static(net)
    np.testing.assert_array_equal(net.get_state()["force"], after.get_state()["force"])
    again = Simulation.from_checkpoint(after.save_checkpoint(tmp_path / "a.npz"))
    assert again.kernel_physics.net_caps  # a state past A keeps the net caps
    fresh = Simulation(dense("net_after_A"))
    fresh.set_state(study.get_state())  # a state without the key: not switched
    assert not fresh.kernel_physics.net_caps
    with pytest.raises(ValueError, match="cap_force = 'net_after_A'"):
        study.drop_attraction_caps()


def test_the_protocol_switches_the_caps_as_the_paths_leave_a(tmp_path):
    """The smoke protocol's A→B with ``"net_after_A"``: state A (its file and record) is the
    study law's, without the switch: its mean stress is what the study's caps measure on A's
    configuration; the path from A switches, so state B carries the switch."""
    from dem_taichi.io.checkpoint import load_checkpoint
    from dem_taichi.protocol.runner import run_protocol

    from .test_protocol import smoke_protocol_scene

    scene = smoke_protocol_scene(run_k0=False, run_unloading=False, radial_stress_ratios="")
    after = run_protocol(scene.replace(contact={"cap_force": "net_after_A"}), tmp_path / "run")
    a_after, _ = load_checkpoint(after.files["state_A"])
    assert not a_after["net_caps_on"]
    study = Simulation(scene)
    study.set_state({k: v for k, v in a_after.items() if k != "net_caps_on"})
    assert after.log.states["A"].measures["mean_stress"] == pytest.approx(
        study.measure()["mean_stress"], rel=1e-12
    )
    at_b = Simulation.from_checkpoint(after.files["state_B"])
    assert at_b.get_state()["net_caps_on"] and at_b.kernel_physics.net_caps
