"""Virtual experiments of the study on the DEM engine (model.md §1.6): the loading paths.

Stages (stage labels of :data:`dem_taichi.io.schema.STAGE_CODES`):

1. ``isotropic_to_A`` — from the gas, isotropic strain-controlled compression in increments of
   per-axis logarithmic strain h, each followed by a relaxation at fixed cell. A relaxed state is
   a candidate for the fluid–solid transition when p > ``pressure_tolerance`` and
   Z_m ≥ ``coordination_min``. On a candidate found with h > ``min_compression_increment`` the
   sample is restored to the previous relaxed state and h is halved (bisection of the
   transition); at the smallest h a candidate becomes **A** when p stays above the tolerance over
   the next ``confirm_increments`` relaxed increments (then the sample is restored to the
   candidate). The rule is :func:`dem_taichi.analysis.detect_transition`, which is re-applied
   to the whole relaxed sequence and recorded (with p, Z_m and the Z_m jump) in the results.
2. ``A_to_B`` — isotropic stress path, σ_xx = σ_yy = p_k, p_k log-spaced from p_A to
   ``target_mean_stress`` (state **B**).
3. ``A_to_C`` — K0 (oedometric) path from A: L_x never changes (ε_xx = ε_xx(A) exactly),
   σ_yy servoed up log-spaced targets, the last target being p = ``target_mean_stress``
   (state **C**).
4. ``C_to_B`` — from C, both axes servoed: p = p_C constant, q decreasing linearly to 0
   (state **B'**).
5. ``radial`` — from A (the stored state), p increasing log-spaced to ``target_mean_stress`` at
   constant η = q/p: σ_yy = p (1 + η/2), σ_xx = p (1 − η/2) (states **R<k>_end**).

Servo at relaxed states (how the stress targets are held). Between relaxed states the cell is
strain-controlled: a strain correction Δε on the servoed axes is applied at a rate capped by the
inertial number, ε̇ ≤ I_max sqrt(p/ρ)/d (p the current relaxed mean stress, ρ = rod mass / rod
area), and the sample is relaxed at fixed cell until UFR < ``relax_unbalanced_force`` and the
kinetic energy per rod < ``relax_kinetic_energy_per_rod``. The correction solves
J Δε = t − W σ (quasi-Newton): W maps (σ_xx, σ_yy) to the controlled quantities (σ_xx, σ_yy, or
p), J = W C is started from the linear-response stiffness C of the relaxed network and
updated by Broyden's rule with the measured secant responses. A target is reached when
|t − Wσ|/|t| ≤ ``stress_tolerance`` (1e-3) at a relaxed state; only such states are recorded as
path states. Quasi-static checks: every history record carries the inertial number and the UFR;
:class:`ProtocolResult` keeps their maxima per stage.

Outputs in ``out_dir``: ``history.nc`` (every loading output step and every relaxed state),
``relaxed_states.nc`` (one record per relaxed path state, same schema), ``probes.nc``,
``configuration_<label>.nc`` at A, B, C, B', R<k>_end, ``figure_paths.png`` (study Figure 1),
``figure_states.png`` (study Figure 2), ``report.md`` and ``summary.json``.

Symbols: σ stress (force/length, compression positive), p = (σ_xx+σ_yy)/2, q = σ_yy − σ_xx,
η = q/p, ε logarithmic strain (compression positive), v specific volume, Z_m mechanical
coordination number, UFR unbalanced-force ratio, I inertial number.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dem_taichi.analysis import Transition, detect_transition
from dem_taichi.config import Scene, load_scene, scene_to_toml
from dem_taichi.protocol_config import (
    ProbingConfig,
    ProtocolConfig,
    probing_settings,
    protocol_settings,
)
from dem_taichi.quasistatic import _control, apply_strain, relax, strain_rate_cap

__all__ = [
    "ProtocolError",
    "RelaxedState",
    "StageRecord",
    "ProtocolResult",
    "ProtocolRunner",
    "relax",
    "apply_strain",
    "strain_rate_cap",
    "SecantStiffness",
    "run_protocol",
    "run_branch",
    "branch_names",
    "BranchOutcome",
    "main",
]


class ProtocolError(RuntimeError):
    """A stage could not reach its goal; the message says which and what to change."""


@dataclass(frozen=True)
class RelaxedState:
    """A relaxed state of a path: its label (``""`` when unlabelled), stage, increment index,
    stress targets (NaN when not servoed), the measures and whether the relaxation converged."""

    label: str
    stage: str
    increment: int
    targets: tuple[float, float]
    measures: dict
    relaxed: bool
    servo_iterations: int = 0


@dataclass
class StageRecord:
    """Wall time and quasi-static indicators of one stage."""

    stage: str
    seconds: float = 0.0
    steps: int = 0
    max_inertial_number: float = 0.0
    max_unbalanced_force_loading: float = 0.0
    max_unbalanced_force_relaxed: float = 0.0
    n_relaxed_states: int = 0
    servo_iterations: int = 0
    n_loading_checks: int = 0
    n_loading_checks_above_limit: int = 0

    def note(self, measures: dict, relaxed: bool, ufr_limit: float = math.inf) -> None:
        """Keep the maxima of I (states with p > 0 only: I is undefined in a gas) and UFR."""
        i = measures.get("inertial_number", float("nan"))
        u = measures.get("unbalanced_force_ratio", float("nan"))
        if math.isfinite(i):
            self.max_inertial_number = max(self.max_inertial_number, i)
        if not relaxed:
            self.n_loading_checks += 1
            if math.isfinite(u) and u > ufr_limit:
                self.n_loading_checks_above_limit += 1
        if math.isfinite(u):
            if relaxed:
                self.max_unbalanced_force_relaxed = max(self.max_unbalanced_force_relaxed, u)
            else:
                self.max_unbalanced_force_loading = max(self.max_unbalanced_force_loading, u)


@dataclass
class ProtocolResult:
    """What :func:`run_protocol` did: files, states, the transition, timings."""

    out_dir: Path
    scene_name: str
    pattern: str
    n_rods: int
    arch: str
    precision: str
    transition: Transition | None = None
    transition_details: dict = field(default_factory=dict)
    states: dict[str, RelaxedState] = field(default_factory=dict)
    path_states: list[RelaxedState] = field(default_factory=list)
    stages: dict[str, StageRecord] = field(default_factory=dict)
    probes: list = field(default_factory=list)
    probing_seconds: float = 0.0
    probing_dynamic_seconds: float = 0.0
    probing_linear_seconds: float = 0.0
    total_seconds: float = 0.0
    files: dict[str, str] = field(default_factory=dict)
    stress_scale_kpa: float = 1.0
    workers: int = 1

    def summary(self) -> dict:
        """JSON-serialisable summary (also written to ``summary.json``)."""

        def state(s: RelaxedState) -> dict:
            keep = (
                "step", "mean_stress", "deviatoric_stress", "stress_xx", "stress_yy",
                "strain_xx", "strain_yy", "specific_volume", "fabric_deviator",
                "mechanical_coordination_number", "coordination_number",
                "unbalanced_force_ratio",
            )  # fmt: skip
            out = {k: _jsonable(s.measures.get(k)) for k in keep}
            out.update(stage=s.stage, increment=s.increment, relaxed=s.relaxed)
            out["targets"] = [_jsonable(t) for t in s.targets]
            return out

        return {
            "scene": self.scene_name,
            "pattern": self.pattern,
            "n_rods": self.n_rods,
            "arch": self.arch,
            "precision": self.precision,
            "stress_scale_kpa": self.stress_scale_kpa,
            "transition": self.transition_details,
            "states": {k: state(v) for k, v in self.states.items()},
            "stages": {k: vars(v) for k, v in self.stages.items()},
            "probing_seconds": self.probing_seconds,
            "probing_dynamic_seconds": self.probing_dynamic_seconds,
            "probing_linear_seconds": self.probing_linear_seconds,
            "total_seconds": self.total_seconds,
            "workers": self.workers,
            "files": self.files,
        }


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


# ---------------------------------------------------------------------------------------------
# The protocol
# ---------------------------------------------------------------------------------------------


def _controlled(weights: np.ndarray, measures: dict) -> np.ndarray:
    return weights @ np.array([measures["stress_xx"], measures["stress_yy"]])


def _strains(measures: dict, axes: list[int]) -> np.ndarray:
    strain = np.array([measures["strain_xx"], measures["strain_yy"]], dtype=float)
    return strain[axes]


class SecantStiffness:
    """Secant/elastic stiffness ratio s of the servoed response since loading began in the
    current direction (``[protocol] servo_stiffness = "secant"``).

    The servo's rate law is ε̇ = (s J)⁻¹ (t − Wσ)/T with J = W C_a the elastic (linear-response)
    stiffness. On a plastic path the material's tangent stiffness is far below J (K0 on the
    paper scene near A: ~1/20), so with s = 1 the stress approaches its target with the time
    constant T J/J_tangent instead of T, and the loading runs an order of magnitude below the
    inertial-number cap. s is the projection of the measured change of the controlled stresses
    on the elastic prediction, s = (Δy·J Δε)/|J Δε|², both Δ since the start, used once
    |J Δε| exceeds ``min_change`` × |t| (below that, waves and noise dominate), clipped to
    [``s_min``, 1]. A residual that changes sign (overshoot: the response reverses, and a
    reversal is elastic) restarts the estimate at s = 1.
    """

    def __init__(self, jacobian: np.ndarray, s_min: float, min_change: float) -> None:
        self.jacobian = np.atleast_2d(np.asarray(jacobian, dtype=float))
        self.s_min = float(s_min)
        self.min_change = float(min_change)
        self.ratio = 1.0
        self._y0: np.ndarray | None = None
        self._e0: np.ndarray | None = None
        self._sign: np.ndarray | None = None

    def restart(self, controlled: np.ndarray, strains: np.ndarray) -> None:
        """Start a new estimate from the current controlled stresses and strains (s = 1)."""
        self.ratio = 1.0
        self._y0, self._e0, self._sign = controlled.copy(), strains.copy(), None

    def update(
        self, controlled: np.ndarray, strains: np.ndarray, residual: np.ndarray, scale: np.ndarray
    ) -> float:
        """Take the state after a servo update; return the new s."""
        sign = np.sign(residual)
        if self._sign is None:
            self._sign = sign
        elif np.any((sign != self._sign) & (sign != 0) & (self._sign != 0)):
            self.restart(controlled, strains)
            self._sign = sign
            return self.ratio
        predicted = self.jacobian @ (strains - self._e0)
        if np.linalg.norm(predicted) > self.min_change * np.linalg.norm(scale):
            measured = controlled - self._y0
            s = float(measured @ predicted / (predicted @ predicted))
            self.ratio = min(max(s, self.s_min), 1.0)
        return self.ratio


class ProtocolRunner:
    """Runs the stages of the protocol on a :class:`dem_taichi.engine.Simulation`.

    Usually driven by :func:`run_protocol`; the stage methods can be called one by one (tests).
    ``probe_hook(runner, state)`` is called at every relaxed path state that should be probed.
    """

    def __init__(
        self,
        sim,
        config: ProtocolConfig,
        probing: ProbingConfig,
        history=None,
        relaxed_writer=None,
        probe_hook: Callable[[ProtocolRunner, RelaxedState], None] | None = None,
        progress: bool = False,
    ) -> None:
        self.sim = sim
        self.config = config
        self.probing = probing
        self.history = history
        self.relaxed_writer = relaxed_writer
        self.probe_hook = probe_hook
        self.progress = progress
        self.stages: dict[str, StageRecord] = {}
        self.states: dict[str, RelaxedState] = {}
        self.path_states: list[RelaxedState] = []
        self.compression_sequence: list[dict] = []
        self.transition: Transition | None = None
        self.transition_details: dict = {}
        self.state_A: dict | None = None
        self.state_C: dict | None = None
        self.configurations: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._since_output = 0
        self.out_dir: Path | None = None
        self.checkpoints: dict[str, str] = {}
        # servo time constant per stage, raised by the servo when it hunts (see servo)
        self.servo_times: dict[str, float] = {}

    # -- helpers ----------------------------------------------------------------------------
    def _say(self, text: str) -> None:
        if self.progress:
            print(text, file=sys.stderr, flush=True)

    def _record(self, stage: str) -> StageRecord:
        return self.stages.setdefault(stage, StageRecord(stage))

    def _relax(self, stage: str, give_up=None) -> tuple[dict, bool]:
        c = self.config
        measures, ok, steps = relax(
            self.sim,
            stage,
            c.relax_unbalanced_force,
            c.relax_kinetic_energy_per_rod,
            c.relax_check_steps,
            c.relax_max_steps,
            give_up,
        )
        self._record(stage).steps += steps
        self._record(stage).note(measures, True)
        if self.history is not None:
            self.history.append(measures)
        return measures, ok

    def _path_state(
        self, label: str, stage: str, increment: int, targets, measures, relaxed, iterations=0
    ) -> RelaxedState:
        state = RelaxedState(
            label, stage, increment, tuple(float(t) for t in targets), dict(measures), relaxed,
            iterations,
        )  # fmt: skip
        self.path_states.append(state)
        self._record(stage).n_relaxed_states += 1
        if label:
            self.states[label] = state
            sim = self.sim
            self.configurations[label] = (sim.rod_positions(), sim.rod_angles(), sim.cell_lengths)
            if self.config.save_states and self.out_dir is not None:
                path = self.out_dir / f"state_{label.replace(chr(39), '_prime')}.npz"
                self.checkpoints[label] = str(sim.save_checkpoint(path))
        elif (
            self.config.save_path_states and self.out_dir is not None and stage != "isotropic_to_A"
        ):
            key = f"{stage}_{increment:03d}"
            if stage == "radial":  # several radial paths: name them by their η
                sx, sy = targets
                key = f"radial_eta{2.0 * (sy - sx) / (sx + sy):+.3f}_{increment:03d}"
            path = self.out_dir / f"path_{key}.npz"
            self.checkpoints[f"path_{key}"] = str(self.sim.save_checkpoint(path))
        if self.relaxed_writer is not None:
            self.relaxed_writer.append(measures)
        return state

    def _maybe_probe(self, state: RelaxedState, last: bool) -> None:
        if self.probe_hook is None or not self.probing.enabled:
            return
        n = self.probing.every_n_increments
        wanted = state.label in self.probing.state_labels or (
            n > 0 and state.increment > 0 and state.increment % n == 0 and not last
        )
        if wanted:
            self.probe_hook(self, state)

    # -- stage 1 ----------------------------------------------------------------------------
    def compress_to_transition(self) -> RelaxedState:
        """Isotropic strain-controlled compression in relaxed increments until state A."""
        c = self.config
        sim = self.sim
        stage = "isotropic_to_A"
        t0 = time.perf_counter()
        record = self._record(stage)
        h = c.compression_increment
        tol = c.pressure_tolerance

        def gas(measures: dict, steps: int) -> bool:
            # a state whose (dynamic) pressure is far below the tolerance after a few checks is
            # clearly not loaded: do not spend the whole relaxation budget on a gas
            return steps >= 4 * c.relax_check_steps and measures["mean_stress"] < 0.1 * tol

        measures, ok = self._relax(stage, gas)
        previous = (sim.get_state(), measures)
        candidate: tuple[dict, dict] | None = None
        confirmed = 0
        sequence = self.compression_sequence
        for increment in range(c.max_compression_increments):
            p_now = previous[1]["mean_stress"] if candidate is None else measures["mean_stress"]
            rate_p = p_now if p_now > tol else 0.0
            self._load_compression(stage, h, rate_p)
            measures, ok = self._relax(stage, gas)
            entry = {
                "increment": increment,
                "h": h,
                "mean_stress": measures["mean_stress"],
                "mechanical_coordination_number": measures["mechanical_coordination_number"],
                "specific_volume": measures["specific_volume"],
                "relaxed": ok,
                "step": measures["step"],
            }
            sequence.append(entry)
            loaded = ok and measures["mean_stress"] > tol
            is_candidate = loaded and measures["mechanical_coordination_number"] >= (
                c.coordination_min
            )
            self._say(
                f"[{stage}] inc {increment} h={h:.4g} v={measures['specific_volume']:.4f} "
                f"p={measures['mean_stress']:.4g} "
                f"Zm={measures['mechanical_coordination_number']:.3f} relaxed={ok}"
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
                "max_compression_increments or lower pressure_tolerance / coordination_min"
            )
        assert candidate is not None
        sim.set_state(candidate[0])
        a_measures = candidate[1]
        # the recorded rule, applied to the relaxed sequence up to the confirmation
        relaxed_seq = [e for e in sequence if e["relaxed"] and not e.get("restored")]
        pressure = np.array([e["mean_stress"] for e in relaxed_seq])
        coordination = np.array([e["mechanical_coordination_number"] for e in relaxed_seq])
        transition = detect_transition(pressure, coordination, tol, c.coordination_min)
        self.transition = transition
        cand_index = next(i for i, e in enumerate(relaxed_seq) if e.get("candidate"))
        last_cand = max(i for i, e in enumerate(relaxed_seq) if e.get("candidate"))
        self.transition_details = {
            "rule": transition.rule
            + f"; confirmed over {c.confirm_increments} further relaxed increments; "
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
        sim.set_strain_reference()
        a_measures = sim.measure()
        if self.history is not None:
            self.history.append(a_measures)
        state = self._path_state("A", stage, len(sequence), (math.nan, math.nan), a_measures, True)
        self.state_A = sim.get_state()
        record.seconds += time.perf_counter() - t0
        self._say(
            f"[A] p={a_measures['mean_stress']:.4g} v={a_measures['specific_volume']:.4f} "
            f"Zm={a_measures['mechanical_coordination_number']:.3f}"
        )
        self._maybe_probe(state, last=False)
        return state

    def _load_compression(self, stage: str, h: float, p_now: float) -> None:
        c = self.config
        sim = self.sim
        rate = c.gas_strain_rate
        if p_now > 0:
            rate = min(
                rate,
                strain_rate_cap(sim, p_now, c.pressure_tolerance, c.inertial_number_safety),
            )
        every = sim.scene.output.every
        before = sim.step
        measures = apply_strain(sim, (h, h), stage, rate, c.load_steps_min, self.history, every)
        self._record(stage).steps += sim.step - before
        if measures["mean_stress"] <= c.pressure_tolerance:
            # gas: I = ε̇ d sqrt(ρ/p) is undefined/meaningless; the gas rate cap applies instead
            measures = dict(measures, inertial_number=float("nan"))
        self._record(stage).note(measures, False, c.unbalanced_force_max)

    # -- servo ------------------------------------------------------------------------------
    def _initial_jacobian(self) -> np.ndarray:
        """dσ/dε (2×2, axial part) of the relaxed network from the linear-response probe."""
        from dem_taichi.linear_response import linear_response

        try:
            response = linear_response(self.sim.snapshot(), sliding_contacts="free")
            c = np.asarray(response.stiffness[:2, :2], dtype=float)
            if np.all(np.isfinite(c)) and np.linalg.det(c) > 0:
                return c
        except Exception:  # noqa: BLE001 - a guess only; fall back below
            pass
        p = max(self.sim.measure()["mean_stress"], self.config.pressure_tolerance)
        return np.array([[20.0 * p, 5.0 * p], [5.0 * p, 20.0 * p]])

    def servo(
        self,
        stage: str,
        axes: tuple[int, ...],
        weights: np.ndarray,
        targets: np.ndarray,
        measures: dict,
    ) -> tuple[dict, int]:
        """Reach W σ = targets at a relaxed state by servo-controlled strain rates on ``axes``.

        ``weights`` (n_ctrl × 2) maps (σ_xx, σ_yy) to the controlled quantities; ``axes`` lists
        the axes (0 = x, 1 = y) driven by the servo (as many as controls), the others are held
        fixed. Rate law, updated every ``servo_check_steps``: ε̇ = (W C_a)⁻¹ (t − W σ) / T with
        C_a the columns ``axes`` of the linear-response stiffness C of the relaxed network at the
        start, T = ``servo_time``, each rate capped by the inertial-number limit (and halved
        while UFR > ``unbalanced_force_max``). When every error is below half the tolerance and
        UFR below 100 × the relaxation threshold, the cell is fixed and the sample relaxed; the
        target is reached when the relaxed state is within ``stress_tolerance``, else the servo
        goes on. Hunting: when the servo has not settled ``servo_stall_times`` × T after first
        coming within ``servo_near_target`` of the targets and UFR is still ≥ 100 × the
        relaxation threshold, T is doubled for the rest of the stage (``servo_times``), at most
        to ``servo_time_max_factor`` × ``servo_time``: in soft repulsive
        packings (basic pattern, 300 rods) the loop at T = 2 is faster than the slow soft network
        (cell transit time L/c ≈ 1.5–2.5) and the stress hunts ±10 % around the target with
        UFR ≈ 0.05–0.1 forever; a slow but static approach (creep) does not change T.
        With ``servo_stiffness = "secant"`` the rate law uses s C_a, s the secant/elastic ratio
        measured since loading began in the current direction (:class:`SecantStiffness`).
        (A quasi-Newton correction between relaxed states was tried and dropped: on
        the smoke scene near A each correction triggers rearrangements and the relaxed stress
        jumps by ±2 %, so it alternated around the target without converging.) Returns the
        relaxed measures and the number of relaxations.
        """
        c = self.config
        sim = self.sim
        weights = np.atleast_2d(np.asarray(weights, dtype=float))
        targets = np.atleast_1d(np.asarray(targets, dtype=float))
        control_axes = list(axes)

        def inverse(stiffness: np.ndarray) -> np.ndarray:
            jac = weights @ stiffness[:, control_axes]
            try:
                return np.linalg.inv(jac)
            except np.linalg.LinAlgError:
                return np.diag(1.0 / np.abs(np.diag(jac)))

        elastic = self._initial_jacobian()
        inverse_jacobian = inverse(elastic)
        servo_time = self.servo_times.get(stage, c.servo_time)
        gain = inverse_jacobian / servo_time
        secant = SecantStiffness(
            weights @ elastic[:, control_axes], c.servo_softening_min, c.servo_near_target
        )
        secant.restart(_controlled(weights, measures), _strains(measures, control_axes))
        steps = 0
        checks = 0
        record = self._record(stage)
        factor = 1.0
        scale = np.abs(targets)
        residual = targets - weights @ np.array([measures["stress_xx"], measures["stress_yy"]])
        near_steps = 0  # steps since the residual first came near the target (or last doubling)
        while steps < c.servo_max_steps:
            sigma = np.array([measures["stress_xx"], measures["stress_yy"]])
            residual = targets - weights @ sigma
            ufr = measures["unbalanced_force_ratio"]
            if np.all(np.abs(residual) <= 0.5 * c.stress_tolerance * scale) and (
                math.isfinite(ufr) and ufr < 100.0 * c.relax_unbalanced_force
            ):
                # close and nearly static: fix the cell, relax, and check the relaxed state
                before = sim.step
                measures, ok = self._relax(stage)
                steps += sim.step - before
                checks += 1
                sigma = np.array([measures["stress_xx"], measures["stress_yy"]])
                residual = targets - weights @ sigma
                self._say(
                    f"    [{stage}] relaxed check {checks}: residual/target "
                    f"{np.round(residual / scale, 5).tolist()} relaxed={ok} steps={steps}"
                )
                if ok and np.all(np.abs(residual) <= c.stress_tolerance * scale):
                    return measures, checks
                continue
            if near_steps > 0 or np.all(np.abs(residual) <= c.servo_near_target * scale):
                near_steps += c.servo_check_steps
                stalled = near_steps * sim.scene.time_step > c.servo_stall_times * servo_time
                hunting = not (math.isfinite(ufr) and ufr < 100.0 * c.relax_unbalanced_force)
                if stalled and not hunting:
                    near_steps = 0  # slow but static (creep): the gain is not the problem
                elif stalled and servo_time < c.servo_time_max_factor * c.servo_time:
                    # hunting around the target without settling: the loop is faster than the
                    # network (soft repulsive packings): halve the gain for the rest of the stage
                    servo_time *= 2.0
                    self.servo_times[stage] = servo_time
                    gain = inverse_jacobian / (servo_time * secant.ratio)
                    near_steps = 0
                    self._say(
                        f"    [{stage}] servo not settling near the target "
                        f"(residual/target {np.round(residual / scale, 4).tolist()}, UFR "
                        f"{ufr:.3g}): servo time doubled to {servo_time:g}"
                    )
            factor = self._rate_factor(factor, ufr)
            rate_cap = factor * strain_rate_cap(
                sim, measures["mean_stress"], c.pressure_tolerance, c.inertial_number_safety
            )
            rates = np.zeros(2)
            rates[control_axes] = np.clip(gain @ residual, -rate_cap, rate_cap)
            measures = sim.run(
                c.servo_check_steps, _control(stage, float(rates[0]), float(rates[1]))
            )
            if c.servo_stiffness == "secant":
                controlled = _controlled(weights, measures)
                secant.update(
                    controlled, _strains(measures, control_axes), targets - controlled, scale
                )
                gain = inverse_jacobian / (servo_time * secant.ratio)
            steps += c.servo_check_steps
            record.steps += c.servo_check_steps
            record.note(measures, False, c.unbalanced_force_max)
            self._output(measures, c.servo_check_steps)
        raise ProtocolError(
            f"[{stage}] stress targets {targets.tolist()} not reached within "
            f"{c.servo_max_steps} steps (residual {residual.tolist()}, tolerance "
            f"{c.stress_tolerance:g} relative); raise [protocol] servo_max_steps, or lower "
            "servo_time for a faster servo"
        )

    def _rate_factor(self, factor: float, ufr: float) -> float:
        """Halve the loading rate while UFR > ``unbalanced_force_max``; recover ×1.25 below."""
        if math.isfinite(ufr) and ufr > self.config.unbalanced_force_max:
            # floor 0.1: in a packing held by soft repulsion (basic pattern, default scene) UFR
            # stays above 0.1 while loading at any rate, and a lower floor stalled the servo
            return max(0.5 * factor, 0.1)
        return min(1.25 * factor, 1.0)

    def _output(self, measures: dict, steps: int) -> None:
        """Append loading records to the history every ``[output] every`` steps."""
        self._since_output += steps
        if self.history is not None and self._since_output >= self.sim.scene.output.every:
            self.history.append(measures)
            self._since_output = 0

    # -- paths ------------------------------------------------------------------------------
    def _log_targets(self, start: float, end: float, n: int) -> np.ndarray:
        return start * (end / start) ** (np.arange(1, n + 1) / n)

    def _check_start(self, p_a: float) -> None:
        if self.config.target_mean_stress <= p_a:
            raise ProtocolError(
                f"[protocol] target_mean_stress = {self.config.target_mean_stress:g} is not above "
                f"p at A = {p_a:.4g}: raise target_mean_stress"
            )

    def _restore_A(self) -> dict:
        if self.state_A is None:
            raise ProtocolError("state A is not known yet: run compress_to_transition first")
        self.sim.set_state(self.state_A)
        # each path from A keeps its own output cadence (the same whether the paths run one
        # after the other or in parallel processes)
        self._since_output = 0
        return self.states["A"].measures

    def isotropic_path(self) -> RelaxedState:
        """A→B: σ_xx = σ_yy = p_k up to ``target_mean_stress`` (state B)."""
        return self._proportional_path("A_to_B", 0.0, "B", "A_to_B")

    def k0_path(self) -> RelaxedState:
        """A→C: ε_xx fixed, σ_yy servoed; the last target is p = ``target_mean_stress`` (C)."""
        stage = "A_to_C"
        t0 = time.perf_counter()
        measures = self._restore_A()
        p_a = measures["mean_stress"]
        p_end = self.config.target_mean_stress
        self._check_start(p_a)
        n = self.config.path_increments
        ratio = (p_end / p_a) ** (1.0 / n)
        state = None
        k = 0
        while True:
            k += 1
            s_yy = measures["stress_yy"] * ratio
            k0 = measures["stress_xx"] / measures["stress_yy"]
            last = 0.5 * s_yy * (1.0 + k0) >= p_end * (1 - 1e-9) or k >= 4 * n
            if last:  # the final target is on p itself
                weights, targets = np.array([[0.5, 0.5]]), np.array([p_end])
                target_pair = (math.nan, math.nan)
            else:
                weights, targets = np.array([[0.0, 1.0]]), np.array([s_yy])
                target_pair = (math.nan, s_yy)
            measures, it = self.servo(stage, (1,), weights, targets, measures)
            if last:
                target_pair = (math.nan, measures["stress_yy"])
            self._record(stage).servo_iterations += it
            state = self._path_state("C" if last else "", stage, k, target_pair, measures, True, it)
            self._say(
                f"[{stage}] {k} p={measures['mean_stress']:.4g} "
                f"q={measures['deviatoric_stress']:.4g} v={measures['specific_volume']:.4f} "
                f"fabric={measures['fabric_deviator']:.4f}"
            )
            self._record(stage).seconds += time.perf_counter() - t0
            self._maybe_probe(state, last=False)
            t0 = time.perf_counter()
            if last:
                break
        self._record(stage).seconds += time.perf_counter() - t0
        self.state_C = self.sim.get_state()
        assert state is not None
        return state

    def unloading_path(self) -> RelaxedState:
        """C→B: both axes servoed, p = p_C, q decreasing linearly to 0 (state B')."""
        stage = "C_to_B"
        t0 = time.perf_counter()
        if "C" not in self.states or self.state_C is None:
            raise ProtocolError("state C is not known yet: run k0_path first")
        self.sim.set_state(self.state_C)
        measures = self.states["C"].measures
        p_c, q_c = measures["mean_stress"], measures["deviatoric_stress"]
        n = self.config.unloading_increments
        state = None
        for k in range(1, n + 1):
            q = q_c * (1.0 - k / n)
            targets = np.array([p_c - 0.5 * q, p_c + 0.5 * q])
            measures, it = self.servo(stage, (0, 1), np.eye(2), targets, measures)
            self._record(stage).servo_iterations += it
            label = "B'" if k == n else ""
            state = self._path_state(label, stage, k, tuple(targets), measures, True, it)
            self._say(
                f"[{stage}] {k}/{n} p={measures['mean_stress']:.4g} "
                f"q={measures['deviatoric_stress']:.4g} v={measures['specific_volume']:.4f}"
            )
            self._record(stage).seconds += time.perf_counter() - t0
            self._maybe_probe(state, last=False)
            t0 = time.perf_counter()
        self._record(stage).seconds += time.perf_counter() - t0
        assert state is not None
        return state

    def radial_path(self, eta: float, index: int) -> RelaxedState:
        """From A, p log-spaced to ``target_mean_stress`` at constant η (state R<index>_end)."""
        return self._proportional_path("radial", eta, f"R{index}_end", f"radial η={eta:g}")

    def _proportional_path(self, stage: str, eta: float, end_label: str, tag: str) -> RelaxedState:
        """From A, both axes servoed to σ = p_k (1 ∓ η/2), p_k log-spaced to the target mean
        stress (η = q/p with q = σ_yy − σ_xx; η = 0 is the isotropic path)."""
        t0 = time.perf_counter()
        measures = self._restore_A()
        p_a = measures["mean_stress"]
        self._check_start(p_a)
        n = self.config.path_increments
        state = None
        for k, p in enumerate(self._log_targets(p_a, self.config.target_mean_stress, n), 1):
            targets = (p * (1.0 - 0.5 * eta), p * (1.0 + 0.5 * eta))
            measures, it = self.servo(stage, (0, 1), np.eye(2), np.array(targets), measures)
            self._record(stage).servo_iterations += it
            label = end_label if k == n else ""
            state = self._path_state(label, stage, k, targets, measures, True, it)
            self._say(f"[{tag}] {k}/{n} p={p:.4g} v={measures['specific_volume']:.4f}")
            self._record(stage).seconds += time.perf_counter() - t0
            self._maybe_probe(state, last=False)
            t0 = time.perf_counter()
        self._record(stage).seconds += time.perf_counter() - t0
        assert state is not None
        return state


# ---------------------------------------------------------------------------------------------
# Whole run with outputs
# ---------------------------------------------------------------------------------------------


def branch_names(config: ProtocolConfig) -> list[str]:
    """The branches that start from A, in the order of the serial run: ``"isotropic"`` (A→B),
    ``"k0"`` (A→C, then C→B when ``run_unloading``), ``"radial <k> <η>"`` (k-th radial path)."""
    names = []
    if config.run_isotropic:
        names.append("isotropic")
    if config.run_k0:
        names.append("k0")
    names += [f"radial {k} {eta!r}" for k, eta in enumerate(config.radial_ratios, 1)]
    return names


def _run_branch_on(runner: ProtocolRunner, branch: str) -> None:
    """Run one branch from A on ``runner`` (its simulation is set to A by the path itself)."""
    if branch == "isotropic":
        runner.isotropic_path()
    elif branch == "k0":
        runner.k0_path()
        if runner.config.run_unloading:
            runner.unloading_path()
    elif branch.startswith("radial "):
        _, index, eta = branch.split()
        runner.radial_path(float(eta), int(index))
    else:
        raise ValueError(f"branch = {branch!r}: allowed isotropic | k0 | radial <k> <eta>")


class _RecordList(list):
    """Stands in for a :class:`HistoryWriter` in a branch process: keeps the records."""

    def append(self, frame: dict) -> int:  # type: ignore[override]
        super().append(dict(frame))
        return len(self)


@dataclass
class BranchOutcome:
    """What one branch run in its own process hands back to :func:`run_protocol`."""

    branch: str
    history: list[dict]
    path_states: list[RelaxedState]
    states: dict[str, RelaxedState]
    stages: dict[str, StageRecord]
    configurations: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]
    checkpoints: dict[str, str]
    probes: list
    probing_seconds: float
    probing_dynamic_seconds: float
    probing_linear_seconds: float


def run_branch(
    branch: str,
    checkpoint_A: str,
    state_A: RelaxedState,
    arch: str,
    precision: str,
    out_dir: str | None,
    progress: bool,
) -> BranchOutcome:
    """Run one branch from the checkpoint of state A in this process (a worker of
    :func:`run_protocol`); the scene, with its protocol and probing sections, comes from the
    checkpoint."""
    from dem_taichi.engine import Simulation
    from dem_taichi.probing import ProbeRecorder

    sim = Simulation.from_checkpoint(checkpoint_A, arch=arch, precision=precision)
    config, probing = protocol_settings(sim.scene), probing_settings(sim.scene)
    history = _RecordList()
    recorder = ProbeRecorder(probing, config)
    runner = ProtocolRunner(sim, config, probing, history, None, recorder, progress)
    runner.out_dir = Path(out_dir) if out_dir is not None else None
    runner.state_A = sim.get_state()
    runner.states["A"] = state_A
    _run_branch_on(runner, branch)
    return BranchOutcome(
        branch=branch,
        history=list(history),
        path_states=runner.path_states,
        states={k: v for k, v in runner.states.items() if k != "A"},
        stages=runner.stages,
        configurations=runner.configurations,
        checkpoints=runner.checkpoints,
        probes=recorder.results,
        probing_seconds=recorder.seconds,
        probing_dynamic_seconds=recorder.dynamic_seconds,
        probing_linear_seconds=recorder.linear_seconds,
    )


def _merge_branch(runner, recorder, history, relaxed, outcome: BranchOutcome) -> None:
    for record in outcome.history:
        history.append(record)
    for state in outcome.path_states:
        relaxed.append(state.measures)
    runner.path_states.extend(outcome.path_states)
    runner.states.update(outcome.states)
    runner.stages.update(outcome.stages)
    runner.configurations.update(outcome.configurations)
    runner.checkpoints.update(outcome.checkpoints)
    recorder.results.extend(outcome.probes)
    recorder.seconds += outcome.probing_seconds
    recorder.dynamic_seconds += outcome.probing_dynamic_seconds
    recorder.linear_seconds += outcome.probing_linear_seconds


def _run_branches_in_processes(
    runner, recorder, history, relaxed, branches, workers, arch, precision, progress
) -> None:
    """Run the branches from A in ``workers`` spawned processes and merge them in order.

    A branch that fails does not lose the others: the finished ones are merged (their records
    reach history.nc and relaxed_states.nc), then the first failure is raised.
    """
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    checkpoint = runner.checkpoints.get("A")
    if checkpoint is None:
        checkpoint = str(runner.sim.save_checkpoint(Path(runner.out_dir) / "state_A.npz"))
    out_dir = str(runner.out_dir) if runner.config.save_states else None
    runner._say(f"[branches] {', '.join(branches)} from A in {workers} processes")
    context = multiprocessing.get_context("spawn")  # Taichi's runtime must not be forked
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        futures = [
            pool.submit(
                run_branch, b, checkpoint, runner.states["A"], arch, precision, out_dir, progress
            )
            for b in branches
        ]
        errors = []
        for branch, future in zip(branches, futures, strict=True):
            try:
                _merge_branch(runner, recorder, history, relaxed, future.result())
            except Exception as exc:  # noqa: BLE001 - keep the other branches, raise below
                errors.append((branch, exc))
    if errors:
        branch, exc = errors[0]
        raise ProtocolError(f"branch {branch!r} from A failed: {exc}") from exc


def _with_pattern(scene: Scene, pattern: str | None) -> Scene:
    if pattern is None or pattern == scene.long_range.pattern:
        return scene
    if pattern not in ("acidic", "basic", "neutral"):
        raise ValueError(f"pattern = {pattern!r}: allowed values are acidic | basic | neutral")
    return scene.replace(long_range={"pattern": pattern})


def _file_label(label: str) -> str:
    return label.replace("'", "_prime")


def run_protocol(
    scene: Scene | str | Path,
    out_dir: str | Path,
    arch: str = "cpu",
    precision: str = "f64",
    progress: bool = False,
    pattern: str | None = None,
    command: str = "dem_taichi.protocol.run_protocol",
    workers: int = 1,
) -> ProtocolResult:
    """Run the whole protocol of a scene and write its results to ``out_dir``.

    ``scene`` is a :class:`Scene`, a TOML path or a built-in scene name; ``pattern`` overrides the
    scene's charge pattern (acidic | basic | neutral). Returns a :class:`ProtocolResult`.

    ``workers`` > 1 runs the branches that start from A (A→B; A→C with C→B; each radial path)
    in that many processes at once (see :func:`run_branch`); their results are merged in the
    order of the serial run, and equal it (the serial engine is deterministic and every branch
    starts from the same state A). Stage wall times then overlap, so they add up to more than
    the total.
    """
    import taichi as ti

    from dem_taichi.engine import Simulation
    from dem_taichi.io import HistoryWriter, provenance_attrs, write_configuration, write_dataset
    from dem_taichi.probing import ProbeRecorder, probes_dataset

    start = time.perf_counter()
    if not (isinstance(workers, int) and workers >= 1):
        raise ValueError(f"workers = {workers!r}: allowed values are integers >= 1")
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    scene = _with_pattern(scene, pattern)
    config = protocol_settings(scene)
    probing = probing_settings(scene)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    effective_pattern = scene.long_range.pattern if scene.long_range.enabled else "neutral"
    result = ProtocolResult(
        out_dir=out,
        scene_name=scene.scene.name,
        pattern=effective_pattern,
        n_rods=scene.particles.n_rods,
        arch=arch,
        precision=precision,
        stress_scale_kpa=config.stress_scale_kpa,
    )
    attrs = provenance_attrs(
        scene.source_text or scene_to_toml(scene),
        arch,
        precision,
        scene.scene.seed,
        command,
        taichi_version=".".join(str(x) for x in ti.__version__),
        title="DEM virtual experiments of 2D rod-shaped clay particles: protocol history",
    )
    attrs["scene_toml_effective"] = scene_to_toml(scene)
    attrs["charge_pattern"] = effective_pattern
    attrs["stress_scale_kpa"] = config.stress_scale_kpa
    attrs["stress_scale"] = f"one DEM stress unit (force/length) = {config.stress_scale_kpa:g} kPa"
    attrs["strain_reference"] = (
        "cell at the start of the run until state A, then the cell at state A"
    )
    sim = Simulation(scene, arch=arch, precision=precision)
    recorder = ProbeRecorder(probing, config)
    history = HistoryWriter(out / "history.nc", attrs=attrs, sync_every=20)
    relaxed_attrs = dict(attrs, title=attrs["title"].replace("history", "relaxed path states"))
    relaxed = HistoryWriter(out / "relaxed_states.nc", attrs=relaxed_attrs, sync_every=1)
    runner = ProtocolRunner(
        sim, config, probing, history, relaxed, probe_hook=recorder, progress=progress
    )
    runner.out_dir = out
    branches = branch_names(config)
    try:
        history.append(sim.measure() | {"stage": "gas"})
        runner.compress_to_transition()
        if workers == 1 or len(branches) < 2:
            for branch in branches:
                _run_branch_on(runner, branch)
        else:
            _run_branches_in_processes(
                runner, recorder, history, relaxed, branches, workers, arch, precision, progress
            )
    finally:
        history.close()
        relaxed.close()
    result.transition = runner.transition
    result.transition_details = runner.transition_details
    result.states = runner.states
    result.path_states = runner.path_states
    result.stages = runner.stages
    result.probes = recorder.results
    result.probing_seconds = recorder.seconds
    result.probing_dynamic_seconds = recorder.dynamic_seconds
    result.probing_linear_seconds = recorder.linear_seconds
    # stage wall times exclude the probes (timed apart by the recorder)
    for label, path in runner.checkpoints.items():
        result.files[f"state_{label}"] = path
    result.files["history"] = str(out / "history.nc")
    result.files["relaxed_states"] = str(out / "relaxed_states.nc")
    # configurations at the labelled states, taken when they were reached
    for label, state in runner.states.items():
        positions, angles, lengths = runner.configurations[label]
        m = state.measures
        geo = sim.geometry
        path = out / f"configuration_{_file_label(label)}.nc"
        write_configuration(
            path,
            positions,
            angles,
            lengths,
            attrs={
                "title": f"DEM configuration at state {label}",
                "state_label": label,
                "path": state.stage,
                "step": int(m["step"]),
                "mean_stress": float(m["mean_stress"]),
                "deviatoric_stress": float(m["deviatoric_stress"]),
                "specific_volume": float(m["specific_volume"]),
                "fabric_deviator": float(m["fabric_deviator"]),
                "n_spheres": int(geo.n_spheres),
                "spacing": float(geo.spacing),
                "diameter": float(geo.diameter),
                "charge_pattern": effective_pattern,
                "stress_scale_kpa": float(config.stress_scale_kpa),
            },
        )
        result.files[f"configuration_{label}"] = str(path)
    if recorder.results:
        probe_attrs = dict(attrs, title="DEM elastic probes at states of the loading paths")
        ds = probes_dataset(recorder.results, recorder.amplitudes, probing, probe_attrs)
        write_dataset(out / "probes.nc", ds)
        result.files["probes"] = str(out / "probes.nc")
    result.workers = min(workers, len(branches)) if len(branches) > 1 else 1
    result.total_seconds = time.perf_counter() - start
    _write_figures_and_report(result, sim)
    (out / "summary.json").write_text(json.dumps(result.summary(), indent=2, default=_jsonable))
    result.files["summary"] = str(out / "summary.json")
    return result


def _write_figures_and_report(result: ProtocolResult, sim) -> None:
    from dem_taichi.report import write_figures, write_report

    try:
        result.files.update(write_figures(result, sim.geometry))
    except Exception as exc:  # noqa: BLE001 - figures must not lose a finished run
        result.files["figures_error"] = f"{type(exc).__name__}: {exc}"
    result.files["report"] = str(write_report(result))


def main(argv: list[str] | None = None) -> int:
    """``python -m dem_taichi.protocol SCENE --out DIR [--arch] [--precision] [--pattern]``."""
    parser = argparse.ArgumentParser(
        prog="python -m dem_taichi.protocol",
        description="Run the study's virtual experiments (gas -> A -> A-B, A-C, C-B, radial) "
        "with elastic probes; write history, probes, configurations, figures and a report.",
    )
    parser.add_argument(
        "scene", help="scene TOML file or built-in name (smoke, demo, default, paper)"
    )
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument("--arch", default="cpu", choices=("cpu", "gpu"))
    parser.add_argument("--precision", default="f64", choices=("f64", "f32"))
    parser.add_argument(
        "--pattern", default=None, choices=("acidic", "basic", "neutral"),
        help="charge pattern (overrides the scene's [long_range] pattern)",
    )  # fmt: skip
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    parser.add_argument(
        "--workers", type=int, default=1,
        help="processes for the paths from A (A-B, A-C-B', radial) run at once (default 1)",
    )  # fmt: skip
    args = parser.parse_args(argv)
    if args.workers < 1:
        parser.error(f"--workers {args.workers}: allowed values are integers >= 1")
    command = "python -m dem_taichi.protocol " + " ".join(
        argv if argv is not None else sys.argv[1:]
    )
    result = run_protocol(
        args.scene,
        args.out,
        arch=args.arch,
        precision=args.precision,
        progress=not args.quiet,
        pattern=args.pattern,
        command=command,
        workers=args.workers,
    )
    print(f"protocol done in {result.total_seconds:.1f} s; results in {result.out_dir}")
    for label, state in result.states.items():
        m = state.measures
        print(
            f"  {label:7s} p={m['mean_stress']:.5g} q={m['deviatoric_stress']:.5g} "
            f"v={m['specific_volume']:.5f} fabric={m['fabric_deviator']:+.4f}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
