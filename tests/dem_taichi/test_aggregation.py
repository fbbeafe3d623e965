"""The aggregation (gas-ageing) stage before the compression to A and the A criterion relative to
the attraction (issue 19): ``[protocol] aggregation*`` and ``pressure_tolerance_reduced``.

Scenes: the smoke scene (40 rods) made strongly attractive (F_max = 100, k_a = 200: the range
g_max = 0.5 d of the smoke scene, ten times its force), so that the rods stick when they meet.
Stage tests run the stage alone on a :class:`Simulation` (about 10⁴ steps, a second); one
reduced protocol (A then one A→B increment, no probes) with aggregation is run uninterrupted,
interrupted during the ageing, and interrupted after A, and resumed.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from types import MappingProxyType

import numpy as np
import pytest

from dem_taichi.io.schema import stage_code
from dem_taichi.scene.config import SceneError, load_scene, scene_from_toml, scene_to_toml
from dem_taichi.scene.probing_sections import ProbingConfig
from dem_taichi.scene.protocol_sections import ProtocolConfig, protocol_settings

ATTRACTIVE = {"f_max_edge": 100.0, "f_max_inner": 100.0, "k_a_edge": 200.0, "k_a_inner": 200.0}


def attractive_scene(probing: ProbingConfig | None = None, **protocol):
    """The smoke scene with ten times its attraction and the given ``[protocol]`` keys."""
    base = load_scene("smoke").replace(long_range=ATTRACTIVE)
    config = dataclasses.replace(protocol_settings(base), **protocol)
    extensions = {"protocol": config, "probing": probing or ProbingConfig(enabled=False)}
    return dataclasses.replace(base, extensions=MappingProxyType(extensions), source_text="")


class Records:
    """A history writer that keeps the records."""

    def __init__(self) -> None:
        self.records: list[dict] = []

    def append(self, frame: dict) -> int:
        self.records.append(dict(frame))
        return len(self.records)


def run_stage(scene, progress: bool = False):
    """A fresh simulation of ``scene`` after its aggregation stage: (runner, details, records)."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.protocol.paths import ProtocolRunner

    sim = Simulation(scene)
    history = Records()
    runner = ProtocolRunner(
        sim, protocol_settings(scene), ProbingConfig(), history=history, progress=progress
    )
    details = runner.aggregate()
    return runner, details, history.records


# -- the stage on its own ---------------------------------------------------------------------
def test_stage_is_deterministic_bit_for_bit():
    """Two runs of the stage (compression, ageing with the speed rescaled at every check) from
    the same scene end in the same state bit for bit, with the same records."""
    from dem_taichi.engine.state import states_equal

    scene = attractive_scene(
        aggregation="time",
        aggregation_time=3.0,
        aggregation_area_fraction=0.2,
        aggregation_speed=0.2,
    )
    first, details_1, records_1 = run_stage(scene)
    second, details_2, records_2 = run_stage(scene)
    assert states_equal(first.sim.get_state(), second.sim.get_state())
    assert details_1 == details_2
    assert [r["step"] for r in records_1] == [r["step"] for r in records_2]
    # and the rescale did act: the gas was not left at its own speed
    velocity = first.sim.get_state()["velocity"]
    assert details_1["aging_steps"] > 0 and np.sqrt(np.mean(velocity**2)) > 0.0


def test_a_time_step_factor_ages_as_long_in_fewer_steps_and_restores_the_time_step():
    """``aggregation_time_step_factor = 2``: the ageing covers the same time in half the steps,
    at twice the scene's Δt; the thermostat acts at the same times (its check interval kept in
    time); the scene's Δt is back after the stage; the cost estimate counts the steps it takes."""
    from dem_taichi.protocol.cost import estimate_cost

    keys = dict(aggregation="time", aggregation_time=4.0, aggregation_speed=0.2)
    plain = attractive_scene(**keys)
    coarse = attractive_scene(**keys, aggregation_time_step_factor=2.0)
    calls: list[int] = []
    import dem_taichi.protocol.aggregation as stage_module

    original = stage_module.resample_speed

    def counting(sim, speed, seed):
        calls.append(sim.step)
        return original(sim, speed, seed)

    stage_module.resample_speed = counting
    try:
        runner_1, details_1, records_1 = run_stage(plain)
        n_plain = len(calls)
        runner_2, details_2, records_2 = run_stage(coarse)
        n_coarse = len(calls) - n_plain
    finally:
        stage_module.resample_speed = original
    dt = runner_1.sim.time_step
    assert runner_2.sim.time_step == dt  # restored
    assert details_1["aging_steps"] == math.ceil(4.0 / dt - 1e-9)
    assert details_2["aging_steps"] == math.ceil(4.0 / (2 * dt) - 1e-9)
    assert details_2["aging_time"] == pytest.approx(details_1["aging_time"], abs=2 * dt)
    assert details_2["time_step_factor"] == 2.0 and "time_step_factor" not in details_1
    assert abs(n_coarse - n_plain) <= 1  # the thermostat at the same times
    assert records_2[-1]["time"] == pytest.approx(records_1[-1]["time"], abs=2 * dt)
    fewer = estimate_cost(plain, "protocol").steps - estimate_cost(coarse, "protocol").steps
    assert fewer == pytest.approx(4.0 / (2 * dt), rel=1e-9)


def test_rescale_speed_sets_the_rms_velocity_component():
    """rescale_speed scales velocities and angular velocities by one factor so that
    sqrt(<v_x² + v_y²>/2) becomes the speed asked; it returns the rms before."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.protocol.quasistatic import rescale_speed

    sim = Simulation(attractive_scene())
    before = sim.get_state()
    rms = float(np.sqrt(np.mean(before["velocity"] ** 2)))
    assert rescale_speed(sim, 0.3) == pytest.approx(rms, rel=1e-12)
    after = sim.get_state()
    assert np.sqrt(np.mean(after["velocity"] ** 2)) == pytest.approx(0.3, rel=1e-12)
    factor = 0.3 / rms
    np.testing.assert_allclose(after["velocity"], before["velocity"] * factor, rtol=1e-12)
    np.testing.assert_allclose(
        after["angular_velocity"], before["angular_velocity"] * factor, rtol=1e-12
    )


@pytest.mark.parametrize(
    ("thermostat", "function"),
    [
        (None, "resample_speed"),
        ("resample", "resample_speed"),
        ("rescale", "rescale_speed"),
        ("langevin", "refresh_speed"),
        ("clusters", "cluster_speed"),
        ("rods", "rod_speed"),
    ],
)
def test_speed_is_imposed_at_the_start_and_after_every_check(monkeypatch, thermostat, function):
    """With aggregation_speed the thermostat (a fresh draw by default, or the rescale) runs at
    the start of the ageing and after every check but the last: the gas keeps the rms speed
    asked."""
    import dem_taichi.protocol.aggregation as stage_module  # where the stage calls its thermostat

    calls: list[float] = []
    original = getattr(stage_module, function)

    def counting(sim, speed, *args):
        calls.append(speed)
        return original(sim, speed, *args)

    monkeypatch.setattr(stage_module, function, counting)
    keys = {"aggregation_thermostat": thermostat} if thermostat else {}
    if thermostat == "langevin":
        keys["aggregation_thermostat_time"] = 0.5
    scene = attractive_scene(
        aggregation="time", aggregation_time=3.0, aggregation_speed=0.25, **keys
    )
    runner, details, records = run_stage(scene)
    checks = -(-details["aging_steps"] // protocol_settings(scene).relax_check_steps)
    assert calls == [0.25] * checks  # the start and after checks 1 … checks − 1
    assert details["thermostat"] == (thermostat or "resample")
    # every record comes one check after a thermostat call: its kinetic energy per rod is far
    # above that of the free gas (rms 0.05 per component, rod mass 5: 0.025)
    ke = [r["kinetic_energy"] / runner.sim.n_rods for r in records]
    assert min(ke) > 10 * 0.5 * 5.0 * 2 * 0.05**2


def test_resample_speed_draws_maxwell_velocities_seeded_by_seed_and_step():
    """resample_speed draws v ~ N(0, s²) per component with the mean removed and ω ~ N(0, s² M/I)
    from PCG64 seeded by (seed, 0x41474754, step): the same draw as written out here, whatever
    the velocities before (no memory: a spinning rod is not pumped), and zero total momentum."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.protocol.quasistatic import resample_speed

    sim = Simulation(attractive_scene())
    state = sim.get_state()
    rms = float(np.sqrt(np.mean(state["velocity"] ** 2)))
    state["angular_velocity"][0] = 50.0  # a rod spinning fast: forgotten by the draw
    sim.set_state(state)
    assert resample_speed(sim, 0.3, 7) == pytest.approx(rms, rel=1e-12)
    after = sim.get_state()
    rng = np.random.Generator(np.random.PCG64([7, 0x41474754, sim.step]))
    drawn = rng.normal(0.0, 0.3, size=after["velocity"].shape)
    drawn -= drawn.mean(axis=0, keepdims=True)
    spin = 0.3 * np.sqrt(sim.body.mass / sim.body.inertia)
    omega = rng.normal(0.0, spin, size=after["angular_velocity"].shape)
    np.testing.assert_array_equal(after["velocity"], drawn)
    np.testing.assert_array_equal(after["angular_velocity"], omega)
    np.testing.assert_allclose(after["velocity"].sum(axis=0), 0.0, atol=1e-12)
    # another seed draws another gas
    resample_speed(sim, 0.3, 8)
    assert not np.array_equal(sim.get_state()["velocity"], drawn)


def test_refresh_speed_is_the_ornstein_uhlenbeck_update_seeded_by_seed_and_step():
    """refresh_speed keeps a = ``keep`` of each velocity and adds sqrt(1 − a²) of a draw
    ξ ~ N(0, s²) (mean removed: the momentum kept) and ζ ~ N(0, s² M/I), PCG64 seeded by (seed,
    0x4C414E47, step): the same numbers as written out here; keep = 0 forgets the velocities
    like the fresh draw; repeated on a frozen gas it brings the rms speed to s whatever it was
    (the stationary variance a² s² + (1 − a²) s² = s²), and it refuses keep outside [0, 1)."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.protocol.quasistatic import refresh_speed, rms_velocity_component

    sim = Simulation(attractive_scene())
    state = sim.get_state()
    state["angular_velocity"][0] = 50.0
    sim.set_state(state)
    before = sim.get_state()
    keep = 0.6
    assert refresh_speed(sim, 0.3, 7, keep) == pytest.approx(
        rms_velocity_component(before["velocity"]), rel=1e-12
    )
    after = sim.get_state()
    rng = np.random.Generator(np.random.PCG64([7, 0x4C414E47, sim.step]))
    noise = rng.normal(0.0, 0.3, size=after["velocity"].shape)
    noise -= noise.mean(axis=0, keepdims=True)
    spin = 0.3 * np.sqrt(sim.body.mass / sim.body.inertia)
    fresh = np.sqrt(1 - keep**2)
    np.testing.assert_array_equal(after["velocity"], keep * before["velocity"] + fresh * noise)
    spun = rng.normal(0.0, spin, size=after["angular_velocity"].shape)
    np.testing.assert_array_equal(
        after["angular_velocity"], keep * before["angular_velocity"] + fresh * spun
    )
    np.testing.assert_allclose(
        after["velocity"].sum(axis=0), keep * before["velocity"].sum(axis=0), atol=1e-9
    )
    # stationary at s: from a gas 10x too hot, the spinning rod included, without dynamics
    state = sim.get_state()
    state["velocity"] *= 10.0 * 0.3 / rms_velocity_component(state["velocity"])
    sim.set_state(state)
    for _ in range(60):  # a^60 ~ 5e-14: the start is forgotten
        refresh_speed(sim, 0.3, 7, keep)
        sim.step += 1  # a new draw each time (the draw is seeded by the step)
    final = sim.get_state()
    assert rms_velocity_component(final["velocity"]) == pytest.approx(0.3, rel=0.1)
    assert abs(final["angular_velocity"][0]) < 10 * spin
    for bad in (-0.1, 1.0):
        with pytest.raises(ValueError, match="keep"):
            refresh_speed(sim, 0.3, 7, bad)


def test_free_ageing_raises_the_coordination_number_at_fixed_cell():
    """Free cooling of the attractive gas at its initial area fraction for 20 time units: the
    rods stick, Z grows from 0; the cell does not change; the records are labelled
    "aggregation" at the scene's output cadence; the stage is recorded with its steps."""
    scene = attractive_scene(aggregation="time", aggregation_time=20.0)
    runner, details, records = run_stage(scene)
    assert details["coordination_number_start"] == 0.0  # the gas starts force-free
    assert details["coordination_number"] > details["coordination_number_start"] + 0.5
    assert details["area_fraction"] == details["area_fraction_start"]
    dt = runner.sim.time_step
    assert details["aging_steps"] == int(np.ceil(20.0 / dt - 1e-9))
    assert details["aging_time"] == pytest.approx(20.0, abs=dt)
    every = scene.output.every
    steps = [r["step"] for r in records]
    assert steps[:-1] == list(range(every, every * len(steps), every))
    assert steps[-1] == details["aging_steps"]
    assert {int(r["stage"]) for r in records} == {stage_code("aggregation")}
    assert records[-1]["coordination_number"] == details["coordination_number"]
    record = runner.stages["aggregation"]
    assert record.steps == details["aging_steps"] and record.seconds > 0


def test_compression_reaches_the_asked_area_fraction():
    """The gas is brought from φ = 0.15 to 0.3 (½ ln 2 per axis at gas_strain_rate) before the
    ageing, then aged at that cell."""
    scene = attractive_scene(
        aggregation="time", aggregation_time=0.5, aggregation_area_fraction=0.3
    )
    runner, details, records = run_stage(scene)
    sim = runner.sim
    assert details["area_fraction_start"] == pytest.approx(0.15, rel=1e-12)
    assert details["area_fraction"] == pytest.approx(0.3, rel=1e-9)
    assert 1.0 / sim.measure()["specific_volume"] == pytest.approx(0.3, rel=1e-9)
    # the compression ran at the gas rate: ½ ln 2 / (rate Δt) steps, and then the ageing
    rate = protocol_settings(scene).gas_strain_rate
    compression = int(np.ceil(0.5 * np.log(2.0) / (rate * sim.time_step)))
    assert runner.stages["aggregation"].steps == compression + details["aging_steps"]
    assert records[0]["strain_rate_xx"] == pytest.approx(rate, rel=1e-3)


def test_coordination_criterion_stops_when_z_reaches_the_value():
    """With aggregation = "coordination" the ageing stops at the first check where Z ≥ the
    value: every earlier check (one record per check here: output every = check steps) is
    below it."""
    scene = attractive_scene(
        aggregation="coordination",
        aggregation_coordination=1.0,
        aggregation_max_time=50.0,
        aggregation_speed=0.3,
    )
    assert scene.output.every == protocol_settings(scene).relax_check_steps
    runner, details, records = run_stage(scene)
    assert details["criterion_met"] is True and "note" not in details
    z = [r["coordination_number"] for r in records]
    assert z[-1] >= 1.0 and all(value < 1.0 for value in z[:-1])
    assert details["coordination_number"] == z[-1]
    assert details["aging_time"] < 50.0


def test_coordination_cap_stops_with_a_note(capsys):
    """A Z the gas cannot reach in the time given: the ageing stops at aggregation_max_time
    with one line of note (not an error)."""
    scene = attractive_scene(
        aggregation="coordination", aggregation_coordination=6.0, aggregation_max_time=1.0
    )
    runner, details, _ = run_stage(scene, progress=True)
    assert details["criterion_met"] is False
    dt = runner.sim.time_step
    assert details["aging_steps"] == int(np.ceil(1.0 / dt - 1e-9))
    notes = [line for line in capsys.readouterr().err.splitlines() if "note:" in line]
    assert len(notes) == 1 and notes[0] == details["note"]
    assert "aggregation_coordination = 6" in notes[0] and "aggregation_max_time = 1" in notes[0]


def test_pressure_tolerance_reduced_gives_the_absolute_tolerance():
    """P* = p d / F_max: the tolerance is P* max(f_max_edge, f_max_inner) / d; unset, it is
    pressure_tolerance."""
    scene = load_scene("smoke").replace(
        long_range={"f_max_edge": 10.0, "f_max_inner": 30.0},
        particles={"diameter": 2.0, "spacing": 2.0},
    )
    config = ProtocolConfig(pressure_tolerance=0.7, pressure_tolerance_reduced=0.05)
    assert config.transition_pressure_tolerance(scene) == pytest.approx(0.05 * 30.0 / 2.0)
    assert ProtocolConfig(pressure_tolerance=0.7).transition_pressure_tolerance(scene) == 0.7


# -- the whole protocol with aggregation, uninterrupted and resumed ---------------------------
def protocol_scene():
    """Reduced protocol on the attractive smoke: aggregation to Z = 2 (at φ = 0.25, speed
    0.2), A with P* = 0.03 (p > 3), one A→B increment to p = 14, no probes."""
    return attractive_scene(
        aggregation="coordination",
        aggregation_coordination=2.0,
        aggregation_max_time=20.0,
        aggregation_area_fraction=0.25,
        aggregation_speed=0.2,
        pressure_tolerance_reduced=0.03,
        target_mean_stress=14.0,
        min_compression_increment=0.0025,
        transition_pressure_factor=1.0,
        path_increments=1,
        run_k0=False,
        run_unloading=False,
        radial_stress_ratios="",
    )


@pytest.fixture(scope="module")
def full_run(tmp_path_factory):
    from dem_taichi.protocol.runner import run_protocol

    return run_protocol(protocol_scene(), tmp_path_factory.mktemp("aggregation_run"))


def _release_runs() -> None:
    import gc

    gc.collect()


def _outputs(run) -> dict[str, np.ndarray]:
    """Every variable of history.nc and relaxed_states.nc and of the configuration at every
    labelled state, keyed ``<file>/<variable>`` (the runs have no probes)."""
    from dem_taichi.io import open_configuration, open_history

    out: dict[str, np.ndarray] = {}
    files = [(key, open_history) for key in ("history", "relaxed_states")]
    files += [(f"configuration_{label}", open_configuration) for label in run.states]
    for key, opener in files:
        ds = opener(run.files[key])
        for name in sorted(ds.variables):
            values = np.asarray(ds[name].values)
            out[f"{key}/{name}"] = values.astype(str) if values.dtype == object else values
    return out


def _assert_same_outputs(got, want) -> None:
    """Two runs on the same machine: every output equal bit for bit."""
    a, b = _outputs(got), _outputs(want)
    assert sorted(a) == sorted(b)
    different = [
        key
        for key in a
        if a[key].dtype != b[key].dtype
        or a[key].shape != b[key].shape
        or a[key].tobytes() != b[key].tobytes()
    ]
    assert not different, different


def test_protocol_records_the_aggregation_stage(full_run):
    """The stage comes between the gas and the compression to A in the history, is a stage of
    the summary with its steps and wall time, and its details are written with the
    transition; A is found with the tolerance P* F_max / d = 3."""
    import json

    from dem_taichi.io import open_history

    assert list(full_run.stages)[:2] == ["aggregation", "isotropic_to_A"]
    stage = full_run.stages["aggregation"]
    assert stage.steps > 0 and stage.seconds > 0
    details = full_run.transition_details
    assert details["pressure_tolerance"] == pytest.approx(0.03 * 100.0 / 1.0)
    assert details["pressure_tolerance_reduced"] == 0.03
    assert full_run.states["A"].measures["mean_stress"] > 3.0
    agg = details["aggregation"]
    assert agg["criterion_met"] and agg["coordination_number"] >= 2.0
    assert agg["coordination_number"] > agg["coordination_number_start"]
    assert agg["area_fraction"] == pytest.approx(0.25, rel=1e-9)
    codes = np.asarray(open_history(full_run.files["history"])["stage"].values)
    gas, aggregation, iso = (stage_code(s) for s in ("gas", "aggregation", "isotropic_to_A"))
    first_iso = int(np.argmax(codes == iso))
    assert codes[0] == gas and set(codes[1:first_iso]) == {aggregation}
    assert aggregation not in set(codes[first_iso:])
    summary = json.loads((full_run.out_dir / "summary.json").read_text())
    assert summary["stages"]["aggregation"]["steps"] == stage.steps
    assert summary["transition"]["aggregation"]["criterion_met"] is True


def test_run_interrupted_during_the_ageing_resumes_to_the_same_outputs(full_run, tmp_path):
    """Stopped (as Ctrl-C would) at the third check of the ageing, before its first save (every
    AGEING_SAVE_SECONDS of wall time): nothing is saved, the resume starts again from the gas and
    ends with the uninterrupted run's outputs."""
    # where the stage calls hold, rescale_speed
    import dem_taichi.protocol.aggregation as stage_module
    from dem_taichi.protocol.runner import run_protocol

    original = stage_module.hold
    calls = []

    def stop_at_third_check(*args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return original(*args, **kwargs)

    stage_module.hold = stop_at_third_check
    try:
        with pytest.raises(KeyboardInterrupt):
            run_protocol(protocol_scene(), tmp_path)
    finally:
        stage_module.hold = original
    _release_runs()
    assert not (tmp_path / "resume" / "A.npz").exists()
    resumed = run_protocol(protocol_scene(), tmp_path, resume=True)
    _release_runs()
    _assert_same_outputs(resumed, full_run)
    assert resumed.transition_details["aggregation"] == full_run.transition_details["aggregation"]


def _run_stopped(tmp_path, module, name: str) -> None:
    """Run the protocol scene in ``tmp_path`` with ``module.name`` replaced by a function that
    raises KeyboardInterrupt (as Ctrl-C would, where the run calls it), the original restored."""
    from dem_taichi.protocol.runner import run_protocol

    def stop(*args, **kwargs):
        raise KeyboardInterrupt

    original = getattr(module, name)
    setattr(module, name, stop)
    try:
        with pytest.raises(KeyboardInterrupt):
            run_protocol(protocol_scene(), tmp_path)
    finally:
        setattr(module, name, original)
    _release_runs()


def _assert_same_run(resumed, full_run) -> None:
    """A resumed run against the uninterrupted one: every output bit for bit, the aggregation
    stage's steps and details the same."""
    _assert_same_outputs(resumed, full_run)
    assert resumed.stages["aggregation"].steps == full_run.stages["aggregation"].steps
    assert resumed.transition_details["aggregation"] == full_run.transition_details["aggregation"]


def _count_holds(stage_module, stop_at: int | None = None):
    """Patch the stage's ``hold`` to count its calls (and raise KeyboardInterrupt at call
    ``stop_at``, as Ctrl-C would); returns the list of calls and the original."""
    original = stage_module.hold
    calls: list[int] = []

    def counted(*args, **kwargs):
        calls.append(1)
        if stop_at is not None and len(calls) == stop_at:
            raise KeyboardInterrupt
        return original(*args, **kwargs)

    stage_module.hold = counted
    return calls, original


def test_run_interrupted_inside_the_ageing_resumes_from_its_last_save(
    full_run, tmp_path, monkeypatch
):
    """With a save after every check's draw (AGEING_SAVE_SECONDS = 0), a run stopped at the
    third check of the ageing has ``resume/ageing.npz`` at check 2; the resume goes on from it
    (only the checks after it are run again) and ends with the uninterrupted run's outputs, bit
    for bit, and the same stage steps."""
    import json

    import dem_taichi.protocol.aggregation as stage_module
    from dem_taichi.protocol.resume import RunIdentity, load_ageing
    from dem_taichi.protocol.runner import run_protocol

    monkeypatch.setattr(stage_module, "AGEING_SAVE_SECONDS", 0.0)
    calls, original = _count_holds(stage_module, stop_at=3)
    try:
        with pytest.raises(KeyboardInterrupt):
            run_protocol(protocol_scene(), tmp_path)
    finally:
        stage_module.hold = original
    _release_runs()
    record = json.loads((tmp_path / "run.json").read_text())
    point = load_ageing(RunIdentity(tmp_path, record["run_id"], record["scene_sha256"]))
    assert point is not None and point.progress["phase"] == "ageing"
    assert point.progress["check"] == 2
    calls, original = _count_holds(stage_module)
    try:
        resumed = run_protocol(protocol_scene(), tmp_path, resume=True)
    finally:
        stage_module.hold = original
    _release_runs()
    _assert_same_run(resumed, full_run)
    # the resumed run held only the checks after the save (the first two were not run again)
    steps = full_run.transition_details["aggregation"]["aging_steps"]
    checks = -(-steps // protocol_settings(protocol_scene()).relax_check_steps)
    assert checks > 2 and len(calls) == checks - 2


def test_run_interrupted_after_the_ageing_resumes_without_it(full_run, tmp_path):
    """Stopped at the first compression increment after the aggregation stage: ``ageing.npz``
    holds the aged state (phase "aged"); the resume runs no ageing check at all and ends with
    the uninterrupted run's outputs."""
    import dem_taichi.protocol.aggregation as stage_module
    import dem_taichi.protocol.transition as transition
    from dem_taichi.protocol.runner import run_protocol

    _run_stopped(tmp_path, transition, "load_compression")
    assert (tmp_path / "resume" / "ageing.npz").exists()
    assert not (tmp_path / "resume" / "A.npz").exists()
    calls, original_hold = _count_holds(stage_module)
    try:
        resumed = run_protocol(protocol_scene(), tmp_path, resume=True)
    finally:
        stage_module.hold = original_hold
    _release_runs()
    assert calls == []
    _assert_same_run(resumed, full_run)


def test_run_interrupted_after_a_resumes_to_the_same_outputs(full_run, tmp_path):
    """Stopped at the start of the branch from A: state A (with the aggregation's records and
    log) is saved; the resume runs A→B only and ends with the uninterrupted run's outputs."""
    import dem_taichi.protocol.branches as branches
    from dem_taichi.protocol.runner import run_protocol

    _run_stopped(tmp_path, branches, "run_branch_on")
    assert (tmp_path / "resume" / "A.npz").exists()
    resumed = run_protocol(protocol_scene(), tmp_path, resume=True)
    _release_runs()
    _assert_same_run(resumed, full_run)


# -- the keys: defaults, round trip, refusals ---------------------------------------------------
def test_defaults_leave_the_scene_toml_unchanged_and_keys_round_trip():
    """Unset keys are not written (the TOML and hash of existing scenes do not change); set
    ones round-trip."""
    toml = scene_to_toml(load_scene("smoke"))
    assert "aggregation" not in toml and "pressure_tolerance_reduced" not in toml
    assert not ProtocolConfig().aggregates
    assert not ProtocolConfig(aggregation="none").aggregates
    scene = scene_from_toml(
        '[long_range]\nenabled = true\npattern = "acidic"\n'
        '[protocol]\naggregation = "coordination"\naggregation_coordination = 2.5\n'
        "aggregation_max_time = 100.0\naggregation_area_fraction = 0.2\n"
        "aggregation_speed = 0.1\npressure_tolerance_reduced = 0.02\n"
    )
    config = protocol_settings(scene)
    assert config.aggregates and config.aggregation_coordination == 2.5
    assert scene_from_toml(scene_to_toml(scene)).extensions["protocol"] == config


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ('aggregation = "sometimes"\n', ["[protocol] aggregation", "none | time | coordination"]),
        ('aggregation = "coordination"\naggregation_max_time = 10.0\n',
         ["[protocol] aggregation = 'coordination' needs aggregation_coordination"]),
        ('aggregation = "coordination"\naggregation_coordination = 2.0\n',
         ["needs aggregation_max_time"]),
        ('aggregation = "time"\n', ["[protocol] aggregation = 'time' needs aggregation_time"]),
        ('aggregation = "time"\naggregation_time = 1.0\naggregation_coordination = 2.0\n',
         ["[protocol] aggregation_coordination = 2.0 is used only with aggregation = "
          "'coordination'"]),
        ("aggregation_time = 5.0\n", ["aggregation_time", "aggregation = 'none'"]),
        ("aggregation_area_fraction = 0.3\n", ["aggregation_area_fraction", "used only"]),
        ('aggregation = "time"\naggregation_time = -1.0\n', ["aggregation_time", "out of range"]),
        ('aggregation = "time"\naggregation_time = 1.0\naggregation_area_fraction = 1.0\n',
         ["[protocol] aggregation_area_fraction = 1.0 is out of range", "1.0)"]),
        ('aggregation = "time"\naggregation_time = 1.0\naggregation_speed = 0.0\n',
         ["aggregation_speed", "out of range"]),
        ("pressure_tolerance_reduced = 0.0\n", ["pressure_tolerance_reduced", "out of range"]),
        ('aggregation = "time"\naggregation_time = 1.0\naggregation_thermostat = "resample"\n',
         ["aggregation_thermostat", "only with aggregation_speed"]),
        ('aggregation = "time"\naggregation_time = 1.0\naggregation_speed = 0.1\n'
         'aggregation_thermostat = "nose-hoover"\n',
         ["aggregation_thermostat", "resample", "rescale", "langevin", "clusters", "rods"]),
        ('aggregation = "time"\naggregation_time = 1.0\naggregation_speed = 0.1\n'
         'aggregation_thermostat = "langevin"\n',
         ["aggregation_thermostat_time", "'langevin'"]),
        ('aggregation = "time"\naggregation_time = 1.0\naggregation_speed = 0.1\n'
         "aggregation_thermostat_time = 2.0\n",
         ["aggregation_thermostat_time", "only then"]),
        ('aggregation = "time"\naggregation_time = 1.0\naggregation_speed = 0.1\n'
         'aggregation_thermostat = "langevin"\naggregation_thermostat_time = 0.0\n',
         ["aggregation_thermostat_time", "out of range"]),
        ("aggregation_time_step_factor = 2.0\n",
         ["aggregation_time_step_factor", "used only", "aggregation = 'none'"]),
        ('aggregation = "time"\naggregation_time = 1.0\naggregation_time_step_factor = 5.0\n',
         ["aggregation_time_step_factor", "out of range"]),
        ('aggregation = "time"\naggregation_time = 1.0\naggregation_time_step_factor = 0.0\n',
         ["aggregation_time_step_factor", "out of range"]),
        ('aggregation_rod_model = "rigid"\n',
         ["aggregation_rod_model", "used only", "aggregation = 'none'"]),
        ('aggregation = "time"\naggregation_time = 1.0\naggregation_rod_model = "flexible"\n',
         ["aggregation_rod_model", "rigid", "bonded"]),
        ('aggregation = "time"\naggregation_time = 1.0\naggregation_rod_model = "bonded"\n',
         ["aggregation_rod_model = 'bonded' needs bonded rods", "rod_model = 'rigid'"]),
        ('aggregation_springs = "kept"\n',
         ["aggregation_springs", "used only", "aggregation = 'none'"]),
        ('aggregation = "time"\naggregation_time = 1.0\naggregation_springs = "reset"\n',
         ["[protocol] aggregation_springs = 'reset' is used only when bonded rods age as "
          "rigid rods (aggregation_rod_model = 'rigid')", "remove aggregation_springs"]),
        ('aggregation = "time"\naggregation_time = 1.0\naggregation_rod_model = "rigid"\n'
         'aggregation_springs = "half"\n',
         ["aggregation_springs", "kept", "reset"]),
    ],
)  # fmt: skip
def test_bad_keys_are_refused_at_load_in_one_line_naming_the_key(text, words):
    with pytest.raises(SceneError) as info:
        scene_from_toml("[protocol]\n" + text)
    message = str(info.value)
    assert "\n" not in message
    for word in words:
        assert word in message


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ('[protocol]\naggregation = "time"\naggregation_time = 1.0\n'
         "aggregation_area_fraction = 0.1\n",
         ["[protocol] aggregation_area_fraction = 0.1 is below [particles] "
          "initial_area_fraction = 0.15", "[0.15, 1)"]),
        ("[long_range]\nenabled = false\n[protocol]\npressure_tolerance_reduced = 0.05\n",
         ["[protocol] pressure_tolerance_reduced = 0.05 needs long-range forces",
          "enabled = false"]),
        ('[long_range]\nenabled = true\npattern = "neutral"\n'
         "[protocol]\npressure_tolerance_reduced = 0.05\n",
         ["pressure_tolerance_reduced", "pattern = 'neutral'"]),
    ],
)  # fmt: skip
def test_keys_that_do_not_fit_the_scene_are_refused_at_load(text, words):
    """Checks that need [particles] or [long_range] (ProtocolConfig.check_scene): run with the
    whole-scene checks when the scene loads (and by Scene.replace, so after a --pattern
    override too)."""
    with pytest.raises(SceneError) as info:
        scene_from_toml("[particles]\ninitial_area_fraction = 0.15\n" + text)
    message = str(info.value)
    assert "\n" not in message
    for word in words:
        assert word in message


def test_command_line_refuses_a_reduced_tolerance_on_a_neutral_run_in_one_line(tmp_path):
    """--pattern neutral turns the attraction off: P* has no meaning, refused (exit 2) in one
    line before the run starts."""
    proc = subprocess.run(
        [sys.executable, "-m", "dem_taichi", "protocol", "smoke", "--out", str(tmp_path / "x"),
         "--pattern", "neutral", "--set", "protocol.pressure_tolerance_reduced=0.05"],
        capture_output=True,
        text=True,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "pressure_tolerance_reduced" in lines[0], proc.stderr
    assert not (tmp_path / "x" / "history.nc").exists()


@pytest.mark.parametrize("thermostat", ["rescale", "resample"])
def test_a_blow_up_under_the_rescaling_thermostat_names_it(monkeypatch, thermostat):
    """A blow-up while ageing with aggregation_thermostat = 'rescale' says that the thermostat
    pumps energy and to use 'resample' (the engine's message alone blames the time step); under
    'resample' the engine's message is left as it is."""
    import dem_taichi.protocol.aggregation as stage_module
    from dem_taichi.engine.failures import BlowUpError

    def blow_up(sim, stage, n):
        raise BlowUpError("runaway kinetic energy at step 1: reduce dt_safety")

    monkeypatch.setattr(stage_module, "hold", blow_up)
    scene = attractive_scene(
        aggregation="time",
        aggregation_time=3.0,
        aggregation_speed=0.25,
        aggregation_thermostat=thermostat,
    )
    with pytest.raises(BlowUpError) as info:
        run_stage(scene)
    message = str(info.value)
    assert message.startswith("runaway kinetic energy at step 1")
    assert ("aggregation_thermostat = 'resample'" in message) == (thermostat == "rescale")
    assert "\n" not in message


def test_cluster_labels_are_the_connected_components_of_the_rod_pairs():
    """Rods 0-1-2 (through 1), 3-4 and the free rods 5 and 6: three clusters of sizes 3, 2, 1,
    1; repeated pairs and either order change nothing."""
    from dem_taichi.protocol.cluster_thermostat import cluster_labels

    labels = cluster_labels(7, np.array([0, 2, 4, 1, 3]), np.array([1, 1, 3, 0, 4]))
    assert labels[0] == labels[1] == labels[2]
    assert labels[3] == labels[4] != labels[0]
    assert len({labels[5], labels[6], labels[0], labels[3]}) == 4
    assert sorted(np.bincount(labels)) == [1, 1, 2, 3]
    assert cluster_labels(3, np.array([], int), np.array([], int)).tolist() == [0, 1, 2]


def test_cluster_velocities_replace_the_centres_and_keep_the_insides():
    """v_i − V_c is unchanged for every rod; the new centre-of-mass velocities are the draw
    written out (N(0, s²/n_c) per component, in cluster order, the mass-weighted mean removed),
    so the total momentum is zero; a cluster's rods keep their relative motion exactly."""
    from dem_taichi.protocol.cluster_thermostat import cluster_velocities

    rng = np.random.default_rng(3)
    velocity = rng.normal(0.0, 1.0, size=(6, 2))
    labels = np.array([0, 0, 0, 1, 1, 2])
    new, fresh = cluster_velocities(velocity, labels, 0.4, np.random.default_rng(11))
    sizes = np.array([3.0, 2.0, 1.0])
    drawn = (
        np.random.default_rng(11).normal(0.0, 1.0, size=(3, 2)) * (0.4 / np.sqrt(sizes))[:, None]
    )
    drawn -= (sizes[:, None] * drawn).sum(axis=0) / sizes.sum()
    np.testing.assert_allclose(fresh, drawn, rtol=0, atol=1e-15)
    for c in range(3):
        rods = labels == c
        np.testing.assert_allclose(new[rods].mean(axis=0), drawn[c], atol=1e-14)
        np.testing.assert_allclose(
            new[rods] - new[rods].mean(axis=0),
            velocity[rods] - velocity[rods].mean(axis=0),
            atol=1e-14,
        )
    np.testing.assert_allclose(new.sum(axis=0), 0.0, atol=1e-14)


def test_cluster_speed_on_a_simulation_is_seeded_and_refuses_bonded_rods():
    """On the attractive smoke gas: the same seed and step give the same velocities, another seed
    others; the rms speed of a gas of free rods comes out near the one asked (every rod its own
    cluster); bonded rods are refused with a one-line reason."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.protocol.cluster_thermostat import cluster_labels, cluster_speed

    sim = Simulation(attractive_scene())
    sim.measure()  # the pair flags the thermostat reads
    start = sim.get_state()
    cluster_speed(sim, 0.3, 7)
    first = sim.get_state()
    sim.set_state(start)
    sim.measure()
    cluster_speed(sim, 0.3, 7)
    np.testing.assert_array_equal(sim.get_state()["velocity"], first["velocity"])
    np.testing.assert_array_equal(sim.get_state()["angular_velocity"], first["angular_velocity"])
    sim.set_state(start)
    sim.measure()
    cluster_speed(sim, 0.3, 8)
    assert not np.array_equal(sim.get_state()["velocity"], first["velocity"])
    labels = cluster_labels(sim.n_rods, *sim.interacting_rod_pairs())
    n_clusters = int(labels.max()) + 1
    # sum over clusters of n_c |U_c|² ≈ 2 s² per cluster (equipartition), minus the momentum
    centre = np.array([first["velocity"][labels == c].mean(axis=0) for c in range(n_clusters)])
    sizes = np.bincount(labels)
    energy = float((sizes[:, None] * centre**2).sum()) / n_clusters
    assert 0.3 * 2 * 0.09 < energy < 3.0 * 2 * 0.09
    bonded = Simulation(load_scene("smoke_bonded"))
    with pytest.raises(ValueError, match="needs rigid rods"):
        cluster_speed(bonded, 0.3, 7)


def test_the_cluster_thermostat_refuses_bonded_rods_before_the_stage_runs():
    """A bonded scene asking for aggregation_thermostat = 'clusters' is refused with one line
    naming the keys, before any step: by the scene checks (at load, and when the runner reads
    its [protocol] section)."""

    base = load_scene("smoke_bonded").replace(long_range=ATTRACTIVE)
    config = dataclasses.replace(
        protocol_settings(base),
        aggregation="time",
        aggregation_time=1.0,
        aggregation_speed=0.2,
        aggregation_thermostat="clusters",
    )
    extensions = {"protocol": config, "probing": ProbingConfig(enabled=False)}
    scene = dataclasses.replace(base, extensions=MappingProxyType(extensions), source_text="")
    with pytest.raises(SceneError, match="needs rigid rods .*use rod_model = 'rigid'"):
        run_stage(scene)
    with pytest.raises(SceneError, match="aggregation_thermostat = 'clusters' needs rigid rods"):
        scene_from_toml(
            '[particles]\nrod_model = "bonded"\n[protocol]\naggregation = "time"\n'
            'aggregation_time = 1.0\naggregation_speed = 0.2\naggregation_thermostat = "clusters"'
        )


def _full_restore(sim, velocity, angular_velocity) -> None:
    """What the thermostats did before they wrote the velocities alone: a full state round trip
    (get_state, the velocities replaced, set_state)."""
    state = sim.get_state()
    state["velocity"], state["angular_velocity"] = velocity, angular_velocity
    sim.set_state(state)


@pytest.mark.parametrize(
    ("scene_name", "thermostat"),
    [("smoke", "resample"), ("smoke", "refresh"), ("smoke", "rescale"), ("smoke", "clusters"),
     ("smoke_bonded", "rods"), ("smoke_bonded", "resample")],
)  # fmt: skip
def test_thermostats_writing_the_velocities_alone_age_as_a_full_restore_would(
    monkeypatch, scene_name, thermostat
):
    """Each thermostat writes the velocities alone (Simulation.set_velocities, a fraction of a
    full set_state's cost at the study's size): an ageing of checks and draws reaches the same
    state, every array bit for bit, as the same ageing whose draws go through a full restore."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.protocol import cluster_thermostat, quasistatic, rod_thermostat

    draw = {
        "resample": lambda sim: quasistatic.resample_speed(sim, 0.3, 7),
        "refresh": lambda sim: quasistatic.refresh_speed(sim, 0.3, 7, 0.5),
        "rescale": lambda sim: quasistatic.rescale_speed(sim, 0.3),
        "clusters": lambda sim: cluster_thermostat.cluster_speed(sim, 0.3, 7),
        "rods": lambda sim: rod_thermostat.rod_speed(sim, 0.3, 7),
    }[thermostat]
    base = load_scene(scene_name)
    scene = base.replace(long_range=ATTRACTIVE) if scene_name == "smoke" else base

    def age(sim) -> dict[str, np.ndarray]:
        for _ in range(6):
            sim.run(300)
            sim.measure()  # the pair flags the cluster thermostat reads
            draw(sim)
        sim.run(300)
        return sim.get_state()

    alone = age(Simulation(scene))
    with monkeypatch.context() as patch:
        patch.setattr(Simulation, "set_velocities", _full_restore)
        restored = age(Simulation(scene))
    assert alone.keys() == restored.keys()
    for key in alone:
        np.testing.assert_array_equal(alone[key], restored[key], err_msg=key)
    assert not np.array_equal(alone["velocity"], Simulation(scene).get_state()["velocity"])


def test_set_velocities_refuses_arrays_that_do_not_fit():
    from dem_taichi.engine.simulation import Simulation

    sim = Simulation(attractive_scene())
    velocity, omega = sim.velocities()
    with pytest.raises(ValueError, match="velocity of shape"):
        sim.set_velocities(velocity[:-1], omega)
    with pytest.raises(ValueError, match="angular_velocity of shape .* and type float32"):
        sim.set_velocities(velocity, omega.astype(np.float32))
    sim.set_velocities(2.0 * velocity, omega)
    np.testing.assert_array_equal(sim.velocities()[0], 2.0 * velocity)
