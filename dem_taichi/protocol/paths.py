"""The loading paths of the study on the DEM engine (docs/science/dem-model.md §1.6):
:class:`ProtocolRunner`.

Stages (stage labels of :data:`dem_taichi.io.schema.STAGE_CODES`):

0. ``aggregation`` (optional, ``[protocol] aggregation`` = "time" | "coordination") — the gas is
   brought to ``aggregation_area_fraction`` by an isotropic strain-controlled compression at
   ``gas_strain_rate``, then aged at fixed cell (its rms speed optionally rescaled to
   ``aggregation_speed`` at every check) for ``aggregation_time``, or until the coordination
   number Z reaches ``aggregation_coordination`` (at most ``aggregation_max_time``).
1. ``isotropic_to_A`` — from the gas, isotropic strain-controlled compression in relaxed
   increments, bisected, until the fluid–solid transition (state **A**): p stays above
   ``pressure_tolerance`` with Z_m ≥ ``coordination_min``
   (:mod:`dem_taichi.protocol.transition`, which states the rule).
2. ``A_to_B`` — isotropic stress path, σ_xx = σ_yy = p_k, p_k log-spaced from p_A to
   ``target_mean_stress`` (state **B**).
3. ``A_to_C`` — K0 (oedometric) path from A: L_x never changes (ε_xx = ε_xx(A) exactly),
   σ_yy servoed up log-spaced targets, the last target being p = ``target_mean_stress``
   (state **C**).
4. ``C_to_B`` — from C, both axes servoed: p = p_C constant, q decreasing linearly to 0
   (state **B'**).
5. ``radial`` — from A (the stored state), p increasing log-spaced to ``target_mean_stress`` at
   constant η = q/p: σ_yy = p (1 + η/2), σ_xx = p (1 − η/2) (states **R<k>_end**).

The stress targets are held by :class:`dem_taichi.protocol.servo.StressServo`; probes run through
``probe_hook``; the whole run with its outputs is :func:`dem_taichi.protocol.runner.run_protocol`.

Symbols: σ stress (force/length, compression positive), p = (σ_xx+σ_yy)/2, q = σ_yy − σ_xx,
η = q/p, ε logarithmic strain (compression positive), v specific volume, Z_m mechanical
coordination number, UFR unbalanced-force ratio, I inertial number.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from dem_taichi.analysis.arrays import Transition
from dem_taichi.engine.measures import Measures
from dem_taichi.engine.work_profile import doing
from dem_taichi.io.vtk_snapshots import simulation_snapshot
from dem_taichi.protocol.aggregation import aggregate
from dem_taichi.protocol.progress import StageProgress, use_bars
from dem_taichi.protocol.quasistatic import relax
from dem_taichi.protocol.records import ProtocolError, RelaxedState, RunLog, StageRecord
from dem_taichi.protocol.servo import ServoMemory, StressServo
from dem_taichi.protocol.transition import compress_to_transition
from dem_taichi.scene.probing_sections import ProbingConfig
from dem_taichi.scene.protocol_sections import ProtocolConfig

if TYPE_CHECKING:
    from dem_taichi.engine.simulation import Simulation

__all__ = ["ProbeHook", "ProtocolRunner", "BRANCH_SAVE_SECONDS"]

#: wall seconds between a branch's resume points (:meth:`ProtocolRunner.branch_progress`): a
#: point costs one engine state on disk (10 MB at the study's size), a path state there takes
#: minutes; the smoke scene's states, a fraction of a second, save once per branch at most
BRANCH_SAVE_SECONDS = 300.0


def k0_step_target(
    stress_xx: float, stress_yy: float, mean_stress: float, ratio: float, floor: float
) -> tuple[float, float]:
    """The next σ_yy target of the K0 ladder and the current K0 = σ_xx/σ_yy (force/length, 1).

    The ladder multiplies the current σ_yy by ``ratio`` (> 1). On a loose, aggregated sample the
    stress at A can be far from isotropic, with σ_yy near zero or negative while p > 0 (the
    network carries σ_xx only): a ladder from such a σ_yy targets a stress the sample cannot
    hold (a tensile or vanishing σ_yy, refused by the servo's relative tolerance after 2,000,000
    steps), and K0 from it is meaningless. Below ``floor`` (the A threshold, the stress at
    which the sample counts as solid) the ladder starts from max(p, ``floor``) instead and K0
    is taken as 1. Above it (every state of the built-in scenes) the ladder is unchanged.
    """
    if stress_yy >= floor:
        return stress_yy * ratio, stress_xx / stress_yy
    return max(mean_stress, floor) * ratio, 1.0


def beyond_targets(target: float, end: float, p_a: float, n: int) -> np.ndarray:
    """The mean stresses of a path's increments past its target, up to ``end``: log-spaced, as
    few as keep each increment's ratio no larger than the path's own, (target/p_a)^(1/n);
    the last one is ``end`` itself."""
    ratio = math.log(target / p_a) / n
    m = max(1, math.ceil(math.log(end / target) / ratio - 1e-9))
    return target * (end / target) ** (np.arange(1, m + 1) / m)


class ProbeHook(Protocol):
    """What the runner calls at every relaxed path state to be probed, with the run log it
    records into (``log``: a branch swaps it,
    :func:`dem_taichi.protocol.branches.run_branch_saved`);
    :class:`dem_taichi.protocol.probing.ProbeRecorder` is one."""

    log: RunLog

    def __call__(self, runner: ProtocolRunner, state: RelaxedState, /) -> None: ...


class ProtocolRunner:
    """Runs the stages of the protocol on a :class:`dem_taichi.engine.simulation.Simulation`.

    Usually driven by :func:`dem_taichi.protocol.runner.run_protocol`; the stage methods can be
    called one by one (tests).
    ``probe_hook(runner, state)`` is called at every relaxed path state that should be probed.
    What the stages record goes to ``log`` (a new :class:`RunLog` unless given; the protocol
    gives the probe recorder's); its entries also read as attributes of the runner
    (``runner.stages``, ``runner.states``, ``runner.path_states``...).
    """

    def __init__(
        self,
        sim: Simulation,
        config: ProtocolConfig,
        probing: ProbingConfig,
        history=None,
        relaxed_writer=None,
        probe_hook: ProbeHook | None = None,
        progress: bool = False,
        log: RunLog | None = None,
    ) -> None:
        self.sim = sim
        self.config = config
        self.probing = probing
        self.history = history
        self.relaxed_writer = relaxed_writer
        self.probe_hook = probe_hook
        self.progress = progress
        self.log = log if log is not None else RunLog()  # the simulation's work goes there
        self.compression_sequence: list[dict] = []
        self.state_A: dict | None = None
        self.state_C: dict | None = None
        self.aggregation_details: dict | None = None
        # resumable ageing (dem_taichi.protocol.aggregation): save_point(progress) writes the
        # run's resume point inside the stage; resume_ageing, the progress of a save to go on from
        self.save_point: Callable[[dict], None] | None = None
        self.resume_ageing: dict | None = None
        # resumable branches (dem_taichi.protocol.branches): branch_save(progress) writes the
        # branch's resume point after a path state; resume_branch, a saved point to go on from
        # (its progress, with the engine state as "state")
        self.branch_save: Callable[[dict], None] | None = None
        self.resume_branch: dict | None = None
        self._last_branch_save = 0.0
        self._since_output = 0
        self.out_dir: Path | None = None
        self.bars = progress and use_bars()  # tqdm bars per stage on a terminal (else lines)
        self._stage: StageProgress | None = None
        self.stress_servo = StressServo(sim, config, self._relax, self._output, self._say)

    @property
    def log(self) -> RunLog:
        """The run log the runner writes; setting it also points the simulation's work ledger
        (:mod:`dem_taichi.engine.work_profile`) at the new log's."""
        return self._log

    @log.setter
    def log(self, log: RunLog) -> None:
        self._log = log
        self.sim.work = log.work

    # -- the log's entries, read here -------------------------------------------------------
    @property
    def stages(self) -> dict[str, StageRecord]:
        return self.log.stages

    @property
    def states(self) -> dict[str, RelaxedState]:
        return self.log.states

    @property
    def path_states(self) -> list[RelaxedState]:
        return self.log.path_states

    @property
    def configurations(self) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        return self.log.configurations

    @property
    def checkpoints(self) -> dict[str, str]:
        return self.log.checkpoints

    @property
    def transition(self) -> Transition | None:
        return self.log.transition

    @property
    def transition_details(self) -> dict:
        return self.log.transition_details

    @property
    def servo_times(self) -> dict[str, float]:
        """The servo's time constant per stage, raised when it hunts (:class:`ServoMemory`)."""
        return self.stress_servo.memory.times

    # -- helpers ----------------------------------------------------------------------------
    def _say(self, text: str) -> None:
        if not self.progress:
            return
        if self._stage is not None:
            self._stage.write(text)  # above the stage's bar
        else:
            print(text, file=sys.stderr, flush=True)

    def _begin_stage(self, tag: str, total: int | None) -> StageProgress:
        """The progress of a stage of ``total`` increments (:mod:`dem_taichi.protocol.progress`)."""
        self._end_stage()
        self._stage = StageProgress(tag, total, self.progress, self.bars)
        return self._stage

    def _end_stage(self) -> None:
        if self._stage is not None:
            self._stage.close()
            self._stage = None

    def _record(self, stage: str) -> StageRecord:
        return self.log.stage(stage)

    def _relax(self, stage: str, give_up=None) -> tuple[Measures, bool]:
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
        self,
        label: str,
        stage: str,
        increment: int,
        targets,
        measures: Measures,
        relaxed: bool,
        iterations: int = 0,
    ) -> RelaxedState:
        target_xx, target_yy = targets  # (σ_xx, σ_yy), NaN where not servoed
        state = RelaxedState(
            label, stage, increment, (float(target_xx), float(target_yy)), measures.copy(),
            relaxed, iterations,
        )  # fmt: skip
        log = self.log
        log.path_states.append(state)
        self._record(stage).n_relaxed_states += 1
        if label:
            log.states[label] = state
            sim = self.sim
            log.configurations[label] = (sim.rod_positions(), sim.rod_angles(), sim.cell_lengths)
            log.snapshots[label] = simulation_snapshot(sim)
            if self.config.save_states and self.out_dir is not None:
                path = self.out_dir / f"state_{label.replace(chr(39), '_prime')}.npz"
                log.checkpoints[label] = str(sim.save_checkpoint(path))
        elif (
            self.config.save_path_states and self.out_dir is not None and stage != "isotropic_to_A"
        ):
            key = f"{stage}_{increment:03d}"
            if stage == "radial":  # several radial paths: name them by their η
                sx, sy = targets
                key = f"radial_eta{2.0 * (sy - sx) / (sx + sy):+.3f}_{increment:03d}"
            path = self.out_dir / f"path_{key}.npz"
            log.checkpoints[f"path_{key}"] = str(self.sim.save_checkpoint(path))
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
            with doing("probe"):
                self.probe_hook(self, state)

    # -- resume points inside a branch ----------------------------------------------------------
    def save_branch_points(self, save: Callable[[dict], None] | None) -> None:
        """From now on call ``save(progress)`` after a relaxed path state about every
        :data:`BRANCH_SAVE_SECONDS` (None: no more points); ``progress`` as
        :meth:`branch_progress` returns it."""
        self.branch_save = save
        self._last_branch_save = time.perf_counter()

    def branch_progress(self, stage: str, increment: int, measures: Measures) -> dict:
        """Where a branch stands after the path state ``increment`` of ``stage`` (0: none of
        the stage's yet; C→B before its first) with ``measures``: all a path needs to go on."""
        return {
            "stage": stage, "increment": int(increment), "measures": dict(measures),
            "since_output": int(self._since_output),
            "servo_times": dict(self.stress_servo.memory.times),
        }  # fmt: skip

    def _branch_point(self, stage: str, increment: int, measures: Measures) -> None:
        """Save the branch's resume point (:meth:`save_branch_points`) if it is time."""
        if self.branch_save is None:
            return
        if time.perf_counter() - self._last_branch_save < BRANCH_SAVE_SECONDS:
            return
        self.branch_save(self.branch_progress(stage, increment, measures))
        self._last_branch_save = time.perf_counter()

    def resuming(self, stage: str) -> bool:
        """Whether the branch goes on from a saved point inside ``stage``."""
        return self.resume_branch is not None and self.resume_branch["stage"] == stage

    def _take_resume_point(self) -> tuple[int, Measures]:
        """Put the engine, the history cadence and the servo where the saved point left them;
        returns (the path states done in its stage, the last one's measures)."""
        point, self.resume_branch = self.resume_branch, None
        assert point is not None  # resuming(stage) was asked first
        self.sim.set_state(point["state"])
        self._since_output = int(point["since_output"])
        self.stress_servo.memory = ServoMemory(dict(point["servo_times"]))
        measures: Measures = point["measures"]
        return int(point["increment"]), measures

    # -- stage 0 ----------------------------------------------------------------------------
    def aggregate(self) -> dict:
        """The aggregation (gas-ageing) stage before the compression to A
        (:func:`dem_taichi.protocol.aggregation.aggregate`); returns (and keeps as
        ``aggregation_details``) what it did."""
        return aggregate(self)

    # -- stage 1 ----------------------------------------------------------------------------
    def compress_to_transition(self) -> RelaxedState:
        """Isotropic strain-controlled compression in relaxed increments until state A (after
        the aggregation stage when ``[protocol] aggregation`` asks for one)
        (:func:`dem_taichi.protocol.transition.compress_to_transition`)."""
        return compress_to_transition(self)

    # -- servo ------------------------------------------------------------------------------
    def servo(
        self,
        stage: str,
        axes: tuple[int, ...],
        weights: np.ndarray,
        targets: np.ndarray,
        measures: Measures,
        last: bool = True,
    ) -> tuple[Measures, int]:
        """Reach W σ = targets at a relaxed state (:class:`dem_taichi.protocol.servo.StressServo`),
        within ``stress_tolerance`` at the ``last`` state of a path and within the inner
        tolerance (``path_stress_tolerance``) inside it; returns the relaxed measures and the
        number of relaxations."""
        c = self.config
        tolerance = c.stress_tolerance if last else c.inner_stress_tolerance()
        return self.stress_servo(
            stage, axes, weights, targets, measures, self._record(stage), tolerance
        )

    def _output(self, measures: Measures, steps: int) -> None:
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

    def _restore_A(self) -> Measures:
        if self.state_A is None:
            raise ProtocolError("state A is not known yet: run compress_to_transition first")
        self.sim.set_state(self.state_A)
        if self.sim.scene.contact.cap_force == "net_after_A" and self.sim.physics.net_caps:
            # a diagnostic of issue 19: from A on every joint loses the attraction's share of its
            # strength; A itself (its record, probes and file) is the study's caps'
            self.sim.drop_attraction_caps()
        # each path from A keeps its own output cadence and starts the servo afresh (the time
        # constants it doubled while hunting): the same whether the paths run one after the other,
        # in parallel processes or resumed
        self._since_output = 0
        self.stress_servo.memory = ServoMemory()
        return self.states["A"].measures

    def isotropic_path(self) -> RelaxedState:
        """A→B: σ_xx = σ_yy = p_k up to ``target_mean_stress`` (state B), then on to
        ``isotropic_end_stress`` when it is set (unlabelled states of stage A_to_B); returns
        state B."""
        end = self.config.isotropic_end_stress
        return self._proportional_path("A_to_B", 0.0, "B", "A_to_B", beyond=end)

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
        floor = self.config.transition_pressure_tolerance(self.sim.scene)
        progress = self._begin_stage(stage, n)
        state = None
        k = 0
        if self.resuming(stage):
            k, measures = self._take_resume_point()
        while True:
            k += 1
            s_yy, k0 = k0_step_target(
                measures["stress_xx"], measures["stress_yy"], measures["mean_stress"], ratio, floor
            )
            last = 0.5 * s_yy * (1.0 + k0) >= p_end * (1 - 1e-9) or k >= 4 * n
            if last:  # the final target is on p itself
                weights, targets = np.array([[0.5, 0.5]]), np.array([p_end])
                target_pair = (math.nan, math.nan)
            else:
                weights, targets = np.array([[0.0, 1.0]]), np.array([s_yy])
                target_pair = (math.nan, s_yy)
            measures, it = self.servo(stage, (1,), weights, targets, measures, last)
            if last:
                target_pair = (math.nan, measures["stress_yy"])
            self._record(stage).servo_iterations += it
            state = self._path_state("C" if last else "", stage, k, target_pair, measures, True, it)
            progress.step(
                k,
                f"[{stage}] {k} p={measures['mean_stress']:.4g} "
                f"q={measures['deviatoric_stress']:.4g} v={measures['specific_volume']:.4f} "
                f"fabric={measures['fabric_deviator']:.4f}",
            )
            self._record(stage).seconds += time.perf_counter() - t0
            self._maybe_probe(state, last=False)
            if not last:
                self._branch_point(stage, k, measures)
            elif self.config.run_unloading:  # C: the unloading goes on from here
                self._branch_point("C_to_B", 0, measures)
            t0 = time.perf_counter()
            if last:
                break
        self._record(stage).seconds += time.perf_counter() - t0
        self._end_stage()
        self.state_C = self.sim.get_state()
        assert state is not None
        return state

    def unloading_path(self) -> RelaxedState:
        """C→B: both axes servoed, p = p_C, q decreasing linearly to 0 (state B')."""
        stage = "C_to_B"
        t0 = time.perf_counter()
        start = 0
        if self.resuming(stage):  # "C" is in the saved log
            start, measures = self._take_resume_point()
        elif "C" not in self.states or self.state_C is None:
            raise ProtocolError("state C is not known yet: run k0_path first")
        else:
            self.sim.set_state(self.state_C)
            measures = self.states["C"].measures
        at_c = self.states["C"].measures
        p_c, q_c = at_c["mean_stress"], at_c["deviatoric_stress"]
        n = self.config.unloading_increments
        progress = self._begin_stage(stage, n)
        state = None
        for k in range(start + 1, n + 1):
            q = q_c * (1.0 - k / n)
            targets = np.array([p_c - 0.5 * q, p_c + 0.5 * q])
            measures, it = self.servo(stage, (0, 1), np.eye(2), targets, measures, k == n)
            self._record(stage).servo_iterations += it
            label = "B'" if k == n else ""
            state = self._path_state(label, stage, k, tuple(targets), measures, True, it)
            progress.step(
                k,
                f"[{stage}] {k}/{n} p={measures['mean_stress']:.4g} "
                f"q={measures['deviatoric_stress']:.4g} v={measures['specific_volume']:.4f}",
            )
            self._record(stage).seconds += time.perf_counter() - t0
            self._maybe_probe(state, last=False)
            if k < n:
                self._branch_point(stage, k, measures)
            t0 = time.perf_counter()
        self._record(stage).seconds += time.perf_counter() - t0
        self._end_stage()
        assert state is not None
        return state

    def radial_path(self, eta: float, index: int) -> RelaxedState:
        """From A, p log-spaced to ``target_mean_stress`` at constant η (state R<index>_end)."""
        return self._proportional_path("radial", eta, f"R{index}_end", f"radial η={eta:g}")

    def _proportional_path(
        self, stage: str, eta: float, end_label: str, tag: str, beyond: float | None = None
    ) -> RelaxedState:
        """From A, both axes servoed to σ = p_k (1 ∓ η/2), p_k log-spaced to the target mean
        stress (η = q/p with q = σ_yy − σ_xx; η = 0 is the isotropic path), labelled
        ``end_label`` there; with ``beyond`` (a p above the target), on to it in log-spaced
        increments no larger than the path's own (:func:`beyond_targets`), unlabelled. Returns
        the labelled state."""
        t0 = time.perf_counter()
        measures = self._restore_A()
        p_a = measures["mean_stress"]
        self._check_start(p_a)
        n = self.config.path_increments
        target = self.config.target_mean_stress
        p_targets = self._log_targets(p_a, target, n)
        if beyond is not None:
            p_targets = np.concatenate([p_targets, beyond_targets(target, beyond, p_a, n)])
        total = len(p_targets)
        progress = self._begin_stage(tag, total)
        labelled, start = None, 0
        if self.resuming(stage):
            start, measures = self._take_resume_point()
            labelled = self.states.get(end_label)  # passed already when past the target
        for k, p in enumerate(p_targets, 1):
            if k <= start:
                continue
            targets = (p * (1.0 - 0.5 * eta), p * (1.0 + 0.5 * eta))
            # the labelled state and every state past it are held to the final tolerance
            final = k >= n
            measures, it = self.servo(stage, (0, 1), np.eye(2), np.array(targets), measures, final)
            self._record(stage).servo_iterations += it
            label = end_label if k == n else ""
            state = self._path_state(label, stage, k, targets, measures, True, it)
            if k == n:
                labelled = state
            progress.step(k, f"[{tag}] {k}/{total} p={p:.4g} v={measures['specific_volume']:.4f}")
            self._record(stage).seconds += time.perf_counter() - t0
            self._maybe_probe(state, last=False)
            if k < total:
                self._branch_point(stage, k, measures)
            t0 = time.perf_counter()
        self._record(stage).seconds += time.perf_counter() - t0
        self._end_stage()
        assert labelled is not None
        return labelled
