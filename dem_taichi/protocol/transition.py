"""Stage 1 of the protocol, ``isotropic_to_A``: the compression of the gas to the fluid–solid
transition, state A (docs/science/dem-model.md §1.6).

A stage of :class:`dem_taichi.protocol.paths.ProtocolRunner` (``runner.compress_to_transition()``
calls :func:`compress_to_transition`), kept apart because it is the longest stage, and the only
one that searches instead of following targets. Isotropic strain-controlled compression in
increments of per-axis logarithmic strain h, each followed by a relaxation at fixed cell. A
relaxed state is a candidate for the transition when p > ``pressure_tolerance`` and
Z_m ≥ ``coordination_min``. On a candidate found with h > ``min_compression_increment`` the
sample is restored to the previous relaxed state and h is halved (bisection of the transition); at
the smallest h a candidate becomes **A** when p stays above the tolerance over the next
``confirm_increments`` relaxed increments, each of h or of ``confirm_increment`` when set (then
the sample is restored to the candidate: the confirmation decides, it does not move A). The rule
is :func:`dem_taichi.analysis.arrays.detect_transition`, re-applied to the whole relaxed sequence
and recorded with p, Z_m and the Z_m jump (:func:`transition_record`).

Symbols: p = (σ_xx+σ_yy)/2 (force/length, compression positive), h per-axis logarithmic strain,
Z_m mechanical coordination number, I inertial number.
"""

from __future__ import annotations

import math
import time

import numpy as np

from dem_taichi.analysis.arrays import Transition, detect_transition
from dem_taichi.engine.measures import Measures
from dem_taichi.engine.work_profile import doing
from dem_taichi.protocol.quasistatic import apply_strain, strain_rate_cap
from dem_taichi.protocol.records import ProtocolError, RelaxedState
from dem_taichi.scene.protocol_sections import ProtocolConfig

__all__ = ["compress_to_transition", "increment_h", "load_compression", "transition_record"]


def compress_to_transition(runner) -> RelaxedState:
    """Isotropic strain-controlled compression in relaxed increments until state A (after
    the aggregation stage when ``[protocol] aggregation`` asks for one); returns A's relaxed
    state, leaves the sample at A (kept as ``runner.state_A``) and records the transition in
    ``runner.log``.

    ``runner``: the :class:`~dem_taichi.protocol.paths.ProtocolRunner`, untyped as in
    :func:`dem_taichi.protocol.aggregation.aggregate` (its module imports this one, and no
    import may go back, not even for typing)."""
    c = runner.config
    sim = runner.sim
    if c.aggregates and runner.aggregation_details is None:
        runner.aggregate()
    stage = "isotropic_to_A"
    t0 = time.perf_counter()
    record = runner._record(stage)
    h = c.compression_increment
    tol = c.transition_pressure_tolerance(sim.scene)

    def gas(measures: Measures, steps: int) -> bool:
        # a state whose (dynamic) pressure is far below the tolerance after a few checks is
        # clearly not loaded: do not spend the whole relaxation budget on a gas
        return steps >= 4 * c.relax_check_steps and measures["mean_stress"] < 0.1 * tol

    measures, ok = runner._relax(stage, gas)
    previous = (sim.get_state(), measures)
    candidate: tuple[dict, Measures] | None = None
    confirmed = 0
    sequence = runner.compression_sequence
    progress = runner._begin_stage(stage, None)  # the number of increments is not known
    for increment in range(c.max_compression_increments):
        p_now = previous[1]["mean_stress"] if candidate is None else measures["mean_stress"]
        rate_p = p_now if p_now > tol else 0.0
        h_now = increment_h(c, h, confirming=candidate is not None)
        with doing("search" if candidate is None else "confirm"):
            load_compression(runner, stage, h_now, rate_p, tol)
            measures, ok = runner._relax(stage, gas)
        entry = {
            "increment": increment,
            "h": h_now,
            "mean_stress": measures["mean_stress"],
            "mechanical_coordination_number": measures["mechanical_coordination_number"],
            "specific_volume": measures["specific_volume"],
            "relaxed": ok,
            "step": measures["step"],
        }
        sequence.append(entry)
        loaded = ok and measures["mean_stress"] > tol
        is_candidate = loaded and measures["mechanical_coordination_number"] >= c.coordination_min
        progress.step(
            increment,
            f"[{stage}] inc {increment} h={h:.4g} v={measures['specific_volume']:.4f} "
            f"p={measures['mean_stress']:.4g} "
            f"Zm={measures['mechanical_coordination_number']:.3f} relaxed={ok}",
        )
        if candidate is None:
            resolved = measures["mean_stress"] <= c.transition_pressure_factor * tol
            if is_candidate and not resolved and h > c.min_compression_increment * (1 + 1e-12):
                sim.set_state(previous[0])
                h = max(0.5 * h, c.min_compression_increment)
                entry["restored"] = True
                continue
            if is_candidate:
                candidate = (sim.get_state(), measures)
                confirmed = 0
                entry["candidate"] = True
                if c.confirm_increments == 0:
                    break
            else:
                previous = (sim.get_state(), measures)
            continue
        if loaded:
            confirmed += 1
            if confirmed >= c.confirm_increments:
                break
        else:  # the load relaxed away: not a solid yet
            entry["candidate_rejected"] = True
            candidate = None
            previous = (sim.get_state(), measures)
    else:
        raise ProtocolError(
            f"no fluid–solid transition after {c.max_compression_increments} compression "
            f"increments (last relaxed p = {measures['mean_stress']:.4g}, Z_m = "
            f"{measures['mechanical_coordination_number']:.3g}); raise [protocol] "
            "max_compression_increments or lower "
            + (
                "pressure_tolerance_reduced"
                if c.pressure_tolerance_reduced is not None
                else "pressure_tolerance"
            )
            + " / coordination_min"
        )
    assert candidate is not None
    sim.set_state(candidate[0])
    a_measures = candidate[1]
    # the recorded rule, applied to the relaxed sequence up to the confirmation
    transition, details = transition_record(sequence, a_measures, c, tol)
    if runner.aggregation_details is not None:
        details["aggregation"] = runner.aggregation_details
    runner.log.transition = transition
    runner.log.transition_details = details
    sim.set_strain_reference()
    if sim.physics.partners:
        # [long_range] attraction_pairs = "bonded_at_A": the gel's bonds as they are at A (the
        # forces at A unchanged); state A, and every branch from it, carries them
        try:
            bonded = sim.freeze_attraction()
        except ValueError as error:  # a rod with more partners than the table holds
            raise ProtocolError(
                f"{error}: use attraction_pairs = 'any', or a shorter range g_max"
            ) from error
        runner._say(f"[A] attraction kept between the {len(bonded)} rod pairs bonded at A")
    a_measures = sim.measure()
    if runner.history is not None:
        runner.history.append(a_measures)
    state = runner._path_state("A", stage, len(sequence), (math.nan, math.nan), a_measures, True)
    runner.state_A = sim.get_state()
    record.seconds += time.perf_counter() - t0
    runner._end_stage()
    runner._say(
        f"[A] p={a_measures['mean_stress']:.4g} v={a_measures['specific_volume']:.4f} "
        f"Zm={a_measures['mechanical_coordination_number']:.3f}"
    )
    runner._maybe_probe(state, last=False)
    return state


def increment_h(c: ProtocolConfig, h: float, confirming: bool) -> float:
    """The per-axis strain of the next compression increment: ``h`` while searching; while
    confirming a candidate A, ``[protocol] confirm_increment`` when set (at most ``h``), else
    ``h``."""
    if confirming and c.confirm_increment is not None:
        return min(h, c.confirm_increment)
    return h


def load_compression(runner, stage: str, h: float, p_now: float, tol: float) -> None:
    """One compression increment h; ``tol`` the A criterion's pressure tolerance (below
    it the gas rate applies and I is not recorded)."""
    c = runner.config
    sim = runner.sim
    rate = c.gas_strain_rate
    if p_now > 0:
        rate = min(
            rate,
            strain_rate_cap(sim, p_now, c.pressure_tolerance, c.inertial_number_safety),
        )
    every = sim.scene.output.every
    before = sim.step
    measures = apply_strain(sim, (h, h), stage, rate, c.load_steps_min, runner.history, every)
    runner._record(stage).steps += sim.step - before
    if measures["mean_stress"] <= tol:
        # gas: I = ε̇ d sqrt(ρ/p) is undefined/meaningless; the gas rate cap applies instead
        measures = measures.copy()
        measures["inertial_number"] = float("nan")
    runner._record(stage).note(measures, False, c.unbalanced_force_max)


def transition_record(
    sequence: list[dict], a_measures: Measures, c: ProtocolConfig, tol: float
) -> tuple[Transition, dict]:
    """The transition rule (:func:`dem_taichi.analysis.arrays.detect_transition`) applied to the
    relaxed increments of ``sequence`` (the compression's entries, as
    :func:`compress_to_transition` records them; restored ones left out), and the details the
    results record with it: the rule in words, where the detector and the protocol put A, p,
    Z_m and its jump at A (``a_measures``), and the sequence itself. ``tol``: the A
    criterion's pressure tolerance (force/length)."""
    relaxed_seq = [e for e in sequence if e["relaxed"] and not e.get("restored")]
    pressure = np.array([e["mean_stress"] for e in relaxed_seq])
    coordination = np.array([e["mechanical_coordination_number"] for e in relaxed_seq])
    transition = detect_transition(pressure, coordination, tol, c.coordination_min)
    cand_index = next(i for i, e in enumerate(relaxed_seq) if e.get("candidate"))
    last_cand = max(i for i, e in enumerate(relaxed_seq) if e.get("candidate"))
    details: dict = {
        "rule": transition.rule
        + f"; confirmed over {c.confirm_increments} further relaxed increments"
        + ("" if c.confirm_increment is None else f" of at most {c.confirm_increment:g}")
        + "; "
        "increments bisected (sample restored to the previous relaxed state, increment "
        f"halved) from {c.compression_increment:g} until p <= "
        f"{c.transition_pressure_factor:g} x tolerance or the increment reaches "
        f"{c.min_compression_increment:g}",
        "pressure_tolerance": tol,
        "coordination_min": c.coordination_min,
        "detector_index": transition.index,
        "protocol_index": last_cand,
        "detector_agrees": bool(transition.index == last_cand),
        "first_candidate_index": cand_index,
        "mean_stress": a_measures["mean_stress"],
        "mechanical_coordination_number": a_measures["mechanical_coordination_number"],
        "coordination_jump": float(
            a_measures["mechanical_coordination_number"]
            - (relaxed_seq[last_cand - 1]["mechanical_coordination_number"] if last_cand else 0)
        ),
        "mean_stress_before": float(relaxed_seq[last_cand - 1]["mean_stress"])
        if last_cand
        else float("nan"),
        "specific_volume": a_measures["specific_volume"],
        "step": a_measures["step"],
        "n_increments": len(sequence),
        "sequence": sequence,
    }
    if c.pressure_tolerance_reduced is not None:
        details["pressure_tolerance_reduced"] = c.pressure_tolerance_reduced
    return transition, details
