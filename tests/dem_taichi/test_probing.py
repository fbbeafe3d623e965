"""Elastic probes: bitwise restoration of the path state, agreement of the two methods, the
degradation curve's plateau, and the probes dataset.

The state is a smoke sample compressed isotropically past jamming and relaxed at fixed cell
(a static packing at p ~ 10^2–10^3 DEM units), built once per module for each rod model
(rigid and bonded: the bonded linear response against the dynamic probe is the check of the
bonded model's linearisation, issue 10), without and with rolling resistance at the contacts
(``ROLLING``: the check of the rolling springs' linearisation, at the cap or not).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dem_taichi.scene.config import load_scene
from dem_taichi.scene.probing_sections import ProbingConfig
from dem_taichi.scene.protocol_sections import ProtocolConfig

PROTOCOL = ProtocolConfig()


def probing(**changes) -> ProbingConfig:
    settings = dict(amplitude_min=1e-8, amplitude_max=1e-8, relax_unbalanced_force=1e-8)
    settings.update(changes)
    return ProbingConfig(**settings)


#: Rolling resistance of the "+rolling" packings: k_r = k_t (0.2 k_n), μ_r = 0.3.
ROLLING = {"rolling_stiffness": 2.0e4, "rolling_friction": 0.3}


@pytest.fixture(
    scope="module", params=["smoke", "smoke_bonded", "smoke+rolling", "smoke_bonded+rolling"]
)
def packed(request):
    """A relaxed dense smoke packing and its state."""
    from dem_taichi.engine.simulation import CellControl, Simulation
    from dem_taichi.protocol.runner import relax

    name, _, rolling = request.param.partition("+")
    scene = load_scene(name)
    if rolling:
        scene = scene.replace(contact=ROLLING)
    sim = Simulation(scene)
    while sim.measure()["specific_volume"] > 1.75:
        sim.run(1000, CellControl.strain_rate(0.02, stage="isotropic_to_A"))
    measures, ok, _ = relax(sim, "relax", 1e-9, 1e-12, 500, 60_000)
    assert ok, measures["unbalanced_force_ratio"]
    assert measures["mean_stress"] > 10.0
    if rolling:  # the rolling springs are loaded, some at the cap
        snapshot = sim.snapshot()
        moment = np.abs(snapshot.rolling_stiffness * snapshot.pair_rolling_spring)
        assert np.count_nonzero(moment) > 10
    return sim, sim.get_state()


def test_probes_leave_the_path_state_bitwise_untouched(packed):
    from dem_taichi.engine.simulation import CellControl
    from dem_taichi.engine.state import states_equal
    from dem_taichi.protocol.probing import probe_state

    sim, base = packed
    sim.set_state(base)
    sim.run(300, CellControl.fixed("relax"))
    untouched = sim.get_state()

    sim.set_state(base)
    before = sim.get_state()
    result = probe_state(sim, probing(amplitude_max=1e-4), PROTOCOL, "A", "isotropic_to_A")
    assert result.state_restored_bitwise is True
    assert states_equal(before, sim.get_state())
    # the run goes on exactly as if no probe had been made
    sim.run(300, CellControl.fixed("relax"))
    assert states_equal(untouched, sim.get_state())


def test_linear_response_and_dynamic_probe_agree_at_small_amplitude(packed):
    from dem_taichi.protocol.probing import dynamic_modulus, linear_probe

    sim, base = packed
    sim.set_state(base)
    linear = linear_probe(sim, "stuck")
    for axis, expected in (("y", linear.e_oed_v), ("x", linear.e_oed_h)):
        modulus, details = dynamic_modulus(sim, axis, 1e-8, probing(), PROTOCOL, base)
        assert all(details["relaxed"])
        assert details["strain"][0] == pytest.approx(1e-8, rel=1e-6)
        assert details["strain"][1] == pytest.approx(-1e-8, rel=1e-6)
        assert modulus == pytest.approx(expected, rel=0.03), axis
    # the modulus is a property of the packing, not of the probe: E ~ k_n scale, both axes alike
    assert 0.3 < linear.e_oed_h / linear.e_oed_v < 3.0


def test_degradation_curve_is_flat_below_the_elastic_limit(packed):
    from dem_taichi.protocol.probing import degradation_curve, linear_probe

    sim, base = packed
    sim.set_state(base)
    config = probing(amplitude_min=1e-9, amplitude_max=1e-3, relax_unbalanced_force=1e-8)
    curve = degradation_curve(sim, "y", config, PROTOCOL)
    plateau = curve.plateau
    assert plateau.n_points >= 2
    below = curve.amplitudes <= plateau.elastic_limit
    assert np.all(np.abs(curve.moduli[below] / plateau.modulus - 1) <= config.plateau_tolerance)
    # beyond the plateau the secant modulus degrades (contacts slide, the network rearranges);
    # the rigid packing with rolling resistance stays on its plateau up to 1e-3 (−1.4 %)
    if plateau.elastic_limit < curve.amplitudes[-1] or not sim.physics.rolling:
        assert curve.moduli[-1] < (1 - config.plateau_tolerance) * plateau.modulus
    assert plateau.modulus == pytest.approx(linear_probe(sim, "stuck").e_oed_v, rel=0.03)
    from dem_taichi.engine.state import states_equal

    assert states_equal(base, sim.get_state())


def test_probes_dataset_follows_the_schema(packed, tmp_path):
    from dem_taichi.io import open_probes, write_dataset
    from dem_taichi.protocol.probing import probe_state, probes_dataset

    sim, base = packed
    sim.set_state(base)
    config = probing(amplitude_min=1e-8, amplitude_max=1e-7)
    results = [probe_state(sim, config, PROTOCOL, "B", "A_to_B")]
    ds = probes_dataset(results, config.amplitudes, config, {"title": "test"})
    path = write_dataset(tmp_path / "probes.nc", ds)
    back = open_probes(path)
    assert back.sizes["probe"] == 1 and back.sizes["amplitude"] == 2
    assert str(back["state_label"].values[0]) == "B"
    lin = results[0].linear
    assert float(back["e_oed_v_linear"][0]) == pytest.approx(lin.e_oed_v)
    assert np.allclose(back["stiffness_tensor_linear"].values[0], lin.stiffness)
    assert float(back["e_oed_h_dynamic"][0]) == pytest.approx(
        results[0].modulus("e_oed_h", "dynamic")
    )
    assert math.isfinite(float(back["e_oed_v_elastic_limit"][0]))
    assert "plateau_rule" in back.attrs


def test_dynamic_modulus_rejects_bad_input(packed):
    from dem_taichi.protocol.probing import dynamic_modulus

    sim, base = packed
    with pytest.raises(ValueError, match="axis"):
        dynamic_modulus(sim, "z", 1e-6, probing(), PROTOCOL, base)
    with pytest.raises(ValueError, match="amplitude"):
        dynamic_modulus(sim, "x", 0.0, probing(), PROTOCOL, base)


def test_a_linear_only_probe_relaxes_to_its_own_threshold(packed):
    """``linear_relax_unbalanced_force``: where only the linear response probes, the copy is
    relaxed to that looser threshold (fewer steps, nearly the same moduli); where the dynamic
    sweep runs, the strict ``relax_unbalanced_force`` stays."""
    from dem_taichi.engine.simulation import CellControl
    from dem_taichi.protocol.probing import probe_state

    sim, base = packed
    sim.set_state(base)
    sim.run(200, CellControl.strain_rate(0.02, stage="isotropic_to_A"))  # moving: not static
    moving = sim.get_state()

    def probe(config: ProbingConfig):
        sim.set_state(moving)
        sim.work = {}
        result = probe_state(sim, config, PROTOCOL, "A", "isotropic_to_A")
        steps = sum(int(entry[0]) for entry in sim.work.get("probe", {}).values())
        sim.work = None
        return result, steps

    strict, strict_steps = probe(probing(dynamic=False))
    loose, loose_steps = probe(probing(dynamic=False, linear_relax_unbalanced_force=1e-4))
    assert 0 < loose_steps < strict_steps
    for name in ("e_oed_v", "e_oed_h"):
        assert loose.modulus(name, "linear") == pytest.approx(
            strict.modulus(name, "linear"), rel=1e-2
        )
    config = probing(linear_relax_unbalanced_force=1e-4, dynamic_states="C")
    assert config.base_relax_unbalanced_force("C") == 1e-8  # the sweep runs at C
    assert config.base_relax_unbalanced_force("A") == 1e-4
    assert probing().base_relax_unbalanced_force("A") == 1e-8  # unset: as before
