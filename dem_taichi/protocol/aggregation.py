"""The aggregation (gas-ageing) stage of the protocol, before the compression to A (issue 19).

A stage of :class:`dem_taichi.protocol.paths.ProtocolRunner` (``runner.aggregate()`` calls
:func:`aggregate`), kept apart because it is optional and long. Keys: ``[protocol]
aggregation*`` (:class:`dem_taichi.scene.protocol_sections.ProtocolConfig`).
"""

from __future__ import annotations

import math
import time

from dem_taichi.engine.failures import BlowUpError
from dem_taichi.protocol.cluster_thermostat import cluster_speed
from dem_taichi.protocol.quasistatic import (
    apply_strain,
    hold,
    refresh_speed,
    resample_speed,
    rescale_speed,
)
from dem_taichi.protocol.records import ProtocolError
from dem_taichi.protocol.rigid_ageing import hand_over, rigid_twin
from dem_taichi.protocol.rod_thermostat import rod_speed

__all__ = ["AGEING_SAVE_SECONDS", "aggregate"]

#: wall seconds between two saves of the ageing's progress (``resume/ageing.npz``, when the
#: runner has a ``save_point``: a protocol run with a run folder)
AGEING_SAVE_SECONDS = 600.0


def aggregate(runner) -> dict:
    """The aggregation (gas-ageing) stage before the compression to A; returns (and keeps
    as ``aggregation_details``, written with the transition in the results) what it did.

    1. Isotropic strain-controlled compression of the gas from its area fraction φ_0 to
       ``aggregation_area_fraction`` (per-axis log strain ½ ln(φ/φ_0), at
       ``gas_strain_rate``; none when unset or equal).
    2. Ageing at fixed cell (at ``aggregation_time_step_factor`` × the scene's Δt), checked
       every ``relax_check_steps`` steps of the scene's Δt (the same time at any factor): for
       ``aggregation_time`` ("time"), or until the coordination number Z
       (``coordination_number``, contacts per rod) reaches ``aggregation_coordination``
       ("coordination"), at most ``aggregation_max_time`` — then a one-line note, not an
       error. With ``aggregation_speed`` the bodies' velocities are brought to it at the
       start and after every check, by ``aggregation_thermostat``: drawn afresh
       (:func:`~dem_taichi.protocol.quasistatic.resample_speed`, the default), rescaled by one
       factor (:func:`~dem_taichi.protocol.quasistatic.rescale_speed`) or refreshed in part, keeping
       exp(−Δt/τ) of each velocity over the check interval Δt (:func:`~dem_taichi.
       quasistatic.refresh_speed`, τ = ``aggregation_thermostat_time``), by cluster, the
       clusters' centre-of-mass velocities drawn afresh (:func:`~dem_taichi.protocol.
       cluster_thermostat.cluster_speed`) or, by rod, every rod's rigid-body motion drawn
       afresh, a bonded rod's discs moving with it (:func:`~dem_taichi.protocol.
       rod_thermostat.rod_speed`).

    With ``aggregation_rod_model = "rigid"`` on bonded rods, steps 1 and 2 run on a rigid twin
    of the rods at its own Δt, the check interval kept in time, and the rods are handed back as
    straight chains at the end (:mod:`dem_taichi.protocol.rigid_ageing`).

    History records at the scene's ``[output] every`` (and the end of the stage), stage
    label "aggregation". Deterministic: the same scene gives the same state bit for bit.

    Resumable: with ``runner.save_point`` set (a protocol run with a run folder), the progress
    of the ageing is saved about every :data:`AGEING_SAVE_SECONDS` of wall time (after a
    check's thermostat draw; not on a rigid twin) and once the stage is done
    (:mod:`dem_taichi.protocol.resume`, ``ageing.npz``); a run resumed from a save inside the
    ageing (``runner.resume_ageing``, its ``progress``) goes on from that check, and ends
    with the state and records of the run never interrupted (the thermostats' draws are seeded
    by the step).
    """
    c = runner.config
    sim = runner.sim
    stage = "aggregation"
    if not c.aggregates:
        raise ProtocolError("[protocol] aggregation = 'none': there is no aggregation stage")
    resumed, runner.resume_ageing = runner.resume_ageing, None
    if resumed is not None:
        return _resume_ageing(runner, resumed)
    t0 = time.perf_counter()
    record = runner._record(stage)
    every = sim.scene.output.every
    progress = runner._begin_stage(stage, None)
    twin = rigid_twin(sim) if c.ages_rigid(sim.scene) else None
    scene_dt = sim.time_step
    if twin is not None:  # steps 1 and 2 on the rigid twin (module docstring)
        sim = twin
    start = sim.measure()
    phi_start = 1.0 / start["specific_volume"]
    details: dict = {
        "criterion": c.aggregation,
        "thermostat": (
            (c.aggregation_thermostat or "resample") if c.aggregation_speed is not None else "none"
        ),
        "area_fraction_start": phi_start,
        "coordination_number_start": start["coordination_number"],
        "step_start": start["step"],
    }
    if twin is not None:
        details.update(rod_model="rigid", time_step_ratio=twin.time_step / scene_dt)
    # 1. compression of the gas to the ageing area fraction
    phi_target = c.aggregation_area_fraction
    if phi_target is not None and phi_target > phi_start:
        h = 0.5 * math.log(phi_target / phi_start)
        before = sim.step
        measures = apply_strain(
            sim, (h, h), stage, c.gas_strain_rate, c.load_steps_min, runner.history, every
        )
        record.steps += sim.step - before
        measures = measures.copy()
        measures["inertial_number"] = float("nan")  # a gas: I is undefined
        record.note(measures, False, c.unbalanced_force_max)
        progress.step(
            0,
            f"[{stage}] compressed to phi={1.0 / measures['specific_volume']:.4f} "
            f"in {sim.step - before} steps p={measures['mean_stress']:.4g} "
            f"Z={measures['coordination_number']:.3f}",
        )
    else:
        measures = start
    details["area_fraction"] = 1.0 / measures["specific_volume"]
    details["coordination_number_compressed"] = measures["coordination_number"]
    # 2. ageing at fixed cell, at factor × the scene's Δt (restored after it, also on error)
    return _age_at_factor(runner, sim, twin, record, progress, measures, details, t0, None)


def _resume_ageing(runner, resumed: dict) -> dict:
    """:func:`aggregate` from a save inside its ageing (``progress`` of ``ageing.npz``): the
    runner's simulation, log and records are already those of the save."""
    sim = runner.sim
    t0 = time.perf_counter() - float(resumed["stage_seconds"])
    record = runner._record("aggregation")
    progress = runner._begin_stage("aggregation", None)
    runner._since_output = int(resumed["since_output"])
    details = dict(resumed["details"])
    start = (int(resumed["done"]), int(resumed["check"]))
    measures = sim.measure()
    return _age_at_factor(runner, sim, None, record, progress, measures, details, t0, start)


def _age_at_factor(runner, sim, twin, record, progress, measures, details, t0, start) -> dict:
    """Step 2 of :func:`aggregate` at ``aggregation_time_step_factor`` × the scene's Δt (restored
    after it, also on error), then the hand-over from a rigid twin; ``start`` (done, check)
    where a resumed ageing goes on, None from its beginning."""
    c = runner.config
    factor = c.aggregation_time_step_factor or 1.0
    base_dt = sim.time_step
    if factor != 1.0:
        sim.set_parameters(time_step=base_dt * factor)
        details["time_step_factor"] = factor
    save = runner.save_point if twin is None else None
    try:
        _age(runner, c, sim, "aggregation", record, progress, measures, details, t0, start, save)
    finally:
        if factor != 1.0:
            sim.set_parameters(time_step=base_dt)
    if twin is not None:
        details.update(hand_over(twin, runner.sim, c.aggregation_springs or "kept"))
    if runner.save_point is not None:  # the stage done: a resume skips it
        runner.save_point(
            {"phase": "aged", "done": int(details["aging_steps"]), "check": -1,
             "details": details, "since_output": runner._since_output,
             "stage_seconds": record.seconds}
        )  # fmt: skip
    return details


def _age(runner, c, sim, stage, record, progress, measures, details, t0, start, save) -> dict:
    """Step 2 of :func:`aggregate`: the ageing at fixed cell, at the time step set; from its
    beginning (``start`` None) or from (done, check) of a save; ``save(progress)`` called about
    every :data:`AGEING_SAVE_SECONDS` after a check's thermostat draw (None: no saves)."""
    dt = sim.time_step
    # the thermostat's check interval kept in time (the scene's relax_check_steps at its Δt; a
    # rigid twin's Δt is time_step_ratio times the bonded scene's)
    factor = (c.aggregation_time_step_factor or 1.0) * details.get("time_step_ratio", 1.0)
    check_steps = max(int(round(c.relax_check_steps / factor)), 1)
    limit = c.aggregation_time if c.aggregation == "time" else c.aggregation_max_time
    assert limit is not None  # ProtocolConfig.check
    total = max(int(math.ceil(limit / dt - 1e-9)), 1)
    target_z = c.aggregation_coordination if c.aggregation == "coordination" else None
    speed = c.aggregation_speed
    seed = sim.scene.scene.seed
    keep = 0.0
    if c.aggregation_thermostat_time is not None:
        keep = math.exp(-check_steps * dt / c.aggregation_thermostat_time)
        details["thermostat_time"] = c.aggregation_thermostat_time
        details["thermostat_keep"] = keep

    def thermostat() -> None:
        if speed is None:
            return
        if details["thermostat"] == "rescale":
            rescale_speed(sim, speed)
        elif details["thermostat"] == "langevin":
            refresh_speed(sim, speed, seed, keep)
        elif details["thermostat"] == "clusters":
            cluster_speed(sim, speed, seed)
        elif details["thermostat"] == "rods":
            rod_speed(sim, speed, seed)
        else:
            resample_speed(sim, speed, seed)

    if start is None:
        thermostat()
        runner._since_output = 0
        done, check = 0, 0
    else:  # resumed after a check's draw: the state is the one saved then
        done, check = start
    last_save = time.perf_counter()
    z = measures["coordination_number"]
    reached = target_z is not None and z >= target_z  # by the compression already
    while not reached and done < total:
        n = min(check_steps, total - done)
        measures = _hold_explained(sim, stage, n, details["thermostat"])
        done += n
        check += 1
        record.steps += n
        runner._output(measures, n)
        z = measures["coordination_number"]
        reached = target_z is not None and z >= target_z
        if runner._since_output == 0 or reached or done >= total:  # a line per record
            progress.step(
                check,
                f"[{stage}] t={done * dt:.4g}/{limit:g} Z={z:.3f} "
                f"Zm={measures['mechanical_coordination_number']:.3f} "
                f"KE/N={measures['kinetic_energy'] / sim.n_rods:.3g} "
                f"p={measures['mean_stress']:.4g}",
            )
        if not reached and done < total:
            thermostat()
            if save is not None and time.perf_counter() - last_save >= AGEING_SAVE_SECONDS:
                save(
                    {"phase": "ageing", "done": done, "check": check, "details": details,
                     "since_output": runner._since_output,
                     "stage_seconds": time.perf_counter() - t0}
                )  # fmt: skip
                last_save = time.perf_counter()
    met = reached or target_z is None
    if runner.history is not None and runner._since_output > 0:
        runner.history.append(measures)  # the end of the stage
    runner._since_output = 0
    details.update(
        criterion_met=bool(met),
        aging_time=done * dt,
        aging_steps=done,
        coordination_number=z,
        mechanical_coordination_number=measures["mechanical_coordination_number"],
        mean_stress=measures["mean_stress"],
        step=measures["step"],
    )
    if not met:
        note = (
            f"[{stage}] note: Z = {z:.3f} has not reached aggregation_coordination = "
            f"{target_z:g} within aggregation_max_time = {limit:g}: the ageing stops at the "
            "cap and the compression to A follows"
        )
        details["note"] = note
        runner._say(note)
    record.seconds += time.perf_counter() - t0
    runner._end_stage()
    runner._say(
        f"[aggregated] phi={details['area_fraction']:.4f} Z "
        f"{details['coordination_number_start']:.3f} -> {z:.3f} after t={done * dt:.4g}"
    )
    runner.aggregation_details = details
    return details


#: what a blow-up during the ageing adds to its message with the rescaling thermostat
RESCALE_HINT = (
    "; this happened while ageing the gas with [protocol] aggregation_thermostat = 'rescale', "
    "which pumps energy into bodies that lose none between checks (measured: a free-spinning "
    "rod from omega 2 to 50 in 20 checks): use aggregation_thermostat = 'resample' (the "
    "default) before a smaller time step"
)


def _hold_explained(sim, stage: str, n: int, thermostat: str):
    """:func:`hold`, with a blow-up under the rescaling thermostat explained (the engine's
    message blames the time step, which does not cure it: measured at dt_safety 0.1)."""
    try:
        return hold(sim, stage, n)
    except BlowUpError as error:
        if thermostat != "rescale":
            raise
        raise BlowUpError(f"{error}{RESCALE_HINT}") from error
