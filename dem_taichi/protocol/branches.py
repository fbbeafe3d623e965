"""The branches of the protocol that start from state A, and running them in processes.

A branch is a path, or chain of paths, from A, a :class:`Branch`: ``Branch("isotropic")``
(A→B), ``Branch("k0")`` (A→C, then C→B when ``run_unloading``), ``Branch("radial", k, η)``;
its label (``"isotropic"``, ``"k0"``, ``"radial <k> <η>"``) is how progress lines and the
resume files name it. :func:`run_branch` runs one from A's checkpoint
in its own process and hands back a :class:`BranchOutcome` (its history records and its
:class:`RunLog`); :func:`run_branches_in_processes` runs them in spawned processes (Taichi's
runtime must not be forked) and merges the outcomes into the run's writers and log in the order
of the serial run, which they equal (the serial engine is deterministic).

Each finished branch's outcome is also saved in the run's ``resume/`` folder
(:mod:`dem_taichi.protocol.resume`, data-only files tied to the run's id and scene hash), by the
process that ran it (:func:`run_branch`, or :func:`run_branch_saved` in the serial run), so that
an interrupted run resumes with only the branches still missing; while it runs, a branch saves
points to go on from (:class:`dem_taichi.protocol.resume.BranchPoint`, after a relaxed path
state about every :data:`dem_taichi.protocol.paths.BRANCH_SAVE_SECONDS`), so that a stopped
branch goes on from its last point, to the outputs of a run never stopped.

A worker reads state A from the checkpoint named relative to the run folder it is given
(``state_A.npz``, checked to hold the run's scene), never by an absolute path saved earlier: a
moved run folder resumes, and another folder's file is never read. Workers die with the
parent (:func:`dem_taichi.protocol.worker_lifetime.die_with_parent`): a ``kill -9`` of the run
leaves no branch process behind.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from dem_taichi.engine.parameters import EngineParameters
from dem_taichi.protocol.paths import ProtocolRunner
from dem_taichi.protocol.records import (
    Branch,
    BranchOutcome,
    ProtocolError,
    RelaxedState,
    RunLog,
)
from dem_taichi.protocol.resume import (
    BranchPoint,
    RecordingWriter,
    ResumeFileError,
    RunIdentity,
    inside_run,
    load_branch_point,
    relative_to_run,
    remove_branch_point,
    save_branch,
    save_branch_point,
)
from dem_taichi.protocol.worker_lifetime import die_with_parent
from dem_taichi.scene.probing_sections import probing_settings
from dem_taichi.scene.protocol_sections import ProtocolConfig, protocol_settings

__all__ = [
    "Branch",
    "branch_names",
    "branch_labels",
    "run_branch_on",
    "run_branch_saved",
    "merge_branch",
    "BranchOutcome",
    "run_branch",
    "run_branches_in_processes",
]


def branch_names(config: ProtocolConfig) -> list[Branch]:
    """The branches that start from A, in the order of the serial run: ``Branch("isotropic")``
    (A→B), ``Branch("k0")`` (A→C, then C→B when ``run_unloading``), ``Branch("radial", k, η)``
    (the k-th radial path, η the k-th of ``radial_stress_ratios``)."""
    branches = []
    if config.run_isotropic:
        branches.append(Branch("isotropic"))
    if config.run_k0:
        branches.append(Branch("k0"))
    branches += [Branch("radial", k, eta) for k, eta in enumerate(config.radial_ratios, 1)]
    return branches


def branch_labels(branches: Iterable[Branch]) -> str:
    """The branches' labels, comma-separated (as progress lines name them)."""
    return ", ".join(branch.label for branch in branches)


def run_branch_on(runner: ProtocolRunner, branch: Branch) -> None:
    """Run one branch from A on ``runner`` (its simulation is set to A by the path itself) with
    the paths' runtime parameters (:func:`path_changes`: ``[protocol] path_time_step_factor`` ×
    the Δt the engine integrated A with, and no contact dashpot where ``path_contact_damping =
    false``), restored after the branch, also on error."""
    sim, state_a = runner.sim, runner.state_A
    prepared = sim.parameters
    changes = path_changes(runner.config, prepared)
    if changes:  # the paths restore A, its runtime parameters with it: A with the paths'
        sim.set_parameters(**changes)
        if state_a is not None:
            runner.state_A = state_with_changes(state_a, changes)
    try:
        if branch.kind == "isotropic":
            runner.isotropic_path()
        elif branch.kind == "k0":
            if not runner.resuming("C_to_B"):  # a point inside C→B: A→C is done
                runner.k0_path()
            if runner.config.run_unloading:
                runner.unloading_path()
        else:
            assert branch.eta is not None  # a radial branch has its η (Branch.__post_init__)
            runner.radial_path(branch.eta, branch.index)
    finally:
        if changes:
            runner.state_A = state_a
            sim.set_parameters(**{name: getattr(prepared, name) for name in changes})


def path_changes(config: ProtocolConfig, prepared: EngineParameters) -> dict[str, float]:
    """The runtime parameters the paths from A change, from those A was ``prepared`` with: Δt ×
    ``path_time_step_factor``; γ_n = γ_t = 0 where ``path_contact_damping = false`` (the
    explicit contact dashpot, with the local damping, lowers the stable step:
    ``benchmarks/results/period_two.md``). Empty for a scene whose paths change nothing."""
    changes: dict[str, float] = {}
    path_dt = config.path_time_step(prepared.time_step)
    if path_dt != prepared.time_step:
        changes["time_step"] = path_dt
    if config.path_contact_damping is False:
        changes.update(gamma_n=0.0, gamma_t=0.0)
    return changes


def state_with_changes(state: dict, changes: dict[str, float]) -> dict:
    """A copy of an engine state (:meth:`Simulation.get_state`) whose runtime parameters have
    ``changes`` (:meth:`EngineParameters.tuned`; the rest of the state shared, not copied)."""
    params = np.asarray(state["params"])
    tuned = EngineParameters.from_vector(params).tuned(**changes)
    return {**state, "params": tuned.vector(params.dtype)}


class _RecordList(list):
    """Stands in for a :class:`HistoryWriter` in a branch process: keeps the records."""

    # the record's index, as HistoryWriter.append returns it (list.append returns None)
    def append(self, frame: dict) -> int:  # type: ignore[override]
        super().append(dict(frame))
        return len(self) - 1


def run_branch(
    branch: Branch,
    run: RunIdentity,
    checkpoint_A: str,
    state_A: RelaxedState,
    arch: str,
    precision: str,
    save_states: bool,
    progress: bool,
    index: int,
) -> BranchOutcome:
    """Run one branch from the checkpoint of state A in this process (a worker of
    :func:`dem_taichi.protocol.runner.run_protocol`) and save its outcome in the run's ``resume/``
    as the ``index``-th branch (:func:`dem_taichi.protocol.resume.save_branch`).

    ``checkpoint_A`` is relative to the run folder ``run.path`` (resolved there, so a moved
    folder works); the scene, with its protocol and probing sections, comes from the checkpoint.
    ``save_states``: the branch writes its state files into the run folder. A branch with a
    saved point (``branch_<index>_point.npz``) goes on from it; points are saved as it runs."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.protocol.probing import ProbeRecorder

    source = inside_run(checkpoint_A, run.path, run.path / "run.json")
    sim = Simulation.from_checkpoint(source, arch=arch, precision=precision)
    config, probing = protocol_settings(sim.scene), probing_settings(sim.scene)
    point = load_branch_point(run, index, branch)
    history = _RecordList(point.history if point is not None else ())
    log = point.log if point is not None else RunLog()
    recorder = ProbeRecorder(probing, config, log)
    runner = ProtocolRunner(sim, config, probing, history, None, recorder, progress, log=log)
    runner.out_dir = run.path if save_states else None
    runner.bars = False  # beside other branch processes on one terminal: lines, not bars
    runner.state_A = sim.get_state()
    log.states["A"] = state_A
    _run_saving_points(runner, branch, run, index, point, history)
    del log.states["A"]
    outcome = BranchOutcome(branch=branch, history=list(history), log=log)
    save_branch(run, index, outcome)
    remove_branch_point(run, index)
    return outcome


def _run_saving_points(
    runner: ProtocolRunner,
    branch: Branch,
    run: RunIdentity,
    index: int,
    point: BranchPoint | None,
    records: list[dict],
) -> None:
    """Run ``branch`` on ``runner`` (:func:`run_branch_on`), going on from its saved ``point``
    (None: from A) and saving points as it runs, as the ``index``-th branch of ``run``: with
    ``records`` (the list the branch's history records are appended to) and the runner's log,
    the branch's own."""
    if point is not None:
        runner.resume_branch = dict(point.progress, state=point.state)
        runner._say(
            f"[resume] {branch.label}: from {point.progress['stage']} after its "
            f"{point.progress['increment']} path state(s)"
        )

    def save(progress: dict) -> None:
        state = runner.sim.get_state()
        point = BranchPoint(list(records), runner.log, state, progress)
        save_branch_point(run, index, branch, point)

    runner.save_branch_points(save)
    try:
        run_branch_on(runner, branch)
    finally:
        runner.save_branch_points(None)
        runner.resume_branch = None


def run_branch_saved(runner: ProtocolRunner, branch: Branch, index: int, run: RunIdentity) -> None:
    """Run one branch on the serial ``runner`` as :func:`run_branch_on` does (its records reach
    the run's writers as they come), with a log of its own merged into the run's at the end,
    and save its outcome as the ``index``-th branch in the ``resume/`` folder of ``run``. A
    branch with a saved point goes on from it (what it recorded before reaches the writers
    first); points are saved as it runs."""
    main_log, history = runner.log, runner.history
    recorder = runner.probe_hook
    point = load_branch_point(run, index, branch)
    log = point.log if point is not None else RunLog()
    log.states["A"] = main_log.states["A"]
    recording = RecordingWriter(history) if history is not None else None
    if point is not None:  # the branch's records so far, as a run never stopped wrote them
        if recording is not None:
            for record in point.history:
                recording.append(record)
        if runner.relaxed_writer is not None:
            for state in log.path_states:
                runner.relaxed_writer.append(state.measures)
    runner.log, runner.history = log, recording
    if recorder is not None:
        recorder.log = log
    records = recording.records if recording is not None else []
    try:
        _run_saving_points(runner, branch, run, index, point, records)
    finally:
        runner.log, runner.history = main_log, history
        if recorder is not None:
            recorder.log = main_log
    del log.states["A"]
    main_log.merge(log)
    save_branch(run, index, BranchOutcome(branch=branch, history=records, log=log))
    remove_branch_point(run, index)


def merge_branch(runner, history, relaxed, outcome: BranchOutcome) -> None:
    """Write a branch's records into the run's writers and merge its log into the run's."""
    for record in outcome.history:
        history.append(record)
    for state in outcome.log.path_states:
        relaxed.append(state.measures)
    runner.log.merge(outcome.log)


def _stop_workers(pool) -> None:
    """Terminate a process pool's workers (their finished branches are saved already) and
    drop its queued branches, so that an interrupted run stops at once instead of waiting
    for the branches still running."""
    processes = list((getattr(pool, "_processes", None) or {}).values())  # no public handle
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()


def _checkpoint_for_workers(runner, run: RunIdentity) -> str:
    """State A's checkpoint for the branch processes, relative to the run folder: the run's
    ``state_A.npz`` (written now from the engine, which is at A, if there is none), checked to
    be whole and to hold the run's scene."""
    from dem_taichi.io.checkpoint import CheckpointError, load_checkpoint
    from dem_taichi.io.run_directory import scene_sha256
    from dem_taichi.scene.config import scene_from_toml, scene_to_toml

    saved = runner.checkpoints.get("A")
    path = Path(saved) if saved is not None else run.path / "state_A.npz"
    if not path.exists():
        path = runner.sim.save_checkpoint(path)
    remedy = "delete it and resume again (it is written again from resume/A.npz)"
    try:
        _, meta = load_checkpoint(path)
        scene_hash = scene_sha256(scene_to_toml(scene_from_toml(meta["scene_toml"])))
    except (CheckpointError, KeyError, ValueError) as error:
        raise ResumeFileError(f"{path}: damaged state A ({error}); {remedy}") from None
    if scene_hash != run.scene_sha256:
        raise ResumeFileError(
            f"{path}: holds another scene (sha256 {scene_hash[:12]}) than the run "
            f"(sha256 {run.scene_sha256[:12]}): copied from another run; {remedy}"
        )
    return relative_to_run(path, run.path)


def run_branches_in_processes(
    runner,
    history,
    relaxed,
    branches: list[Branch],
    workers,
    arch,
    precision,
    progress,
    run,
    done: dict[Branch, BranchOutcome] | None = None,
) -> None:
    """Run the branches from A in ``workers`` spawned processes and merge them in order into
    ``history``, ``relaxed`` (the writers of history.nc and relaxed_states.nc) and
    ``runner.log`` (where the probe recorder of the run writes too).

    A branch that fails does not lose the others: the finished ones are merged (their records
    reach history.nc and relaxed_states.nc), then the first failure is raised. ``run``: the
    :class:`RunIdentity` of the run folder. ``branches``: the branches from A
    (:class:`Branch`) in the order of the serial run. ``done``: branch → saved
    :class:`BranchOutcome` of a resumed run; those are merged in their place, not run again.
    Every branch run here saves its outcome in ``<run>/resume/``. The workers die with this
    process (:func:`dem_taichi.protocol.worker_lifetime.die_with_parent`).
    """
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    checkpoint = _checkpoint_for_workers(runner, run)
    save_states = bool(runner.config.save_states)
    done = done or {}
    todo = [b for b in branches if b not in done]
    runner._say(f"[branches] {branch_labels(todo)} from A in {workers} processes")
    context = multiprocessing.get_context("spawn")  # Taichi's runtime must not be forked
    pool = ProcessPoolExecutor(
        max_workers=workers, mp_context=context, initializer=die_with_parent,
        initargs=(os.getpid(),),
    )  # fmt: skip
    with pool:
        futures = {
            b: pool.submit(
                run_branch, b, run, checkpoint, runner.states["A"], arch, precision, save_states,
                progress, index,
            )
            for index, b in enumerate(branches)
            if b not in done
        }  # fmt: skip
        errors = []
        try:
            for branch in branches:
                try:
                    outcome = done[branch] if branch in done else futures[branch].result()
                    merge_branch(runner, history, relaxed, outcome)
                except Exception as exc:  # noqa: BLE001 - keep the other branches, raise below
                    errors.append((branch, exc))
        except KeyboardInterrupt:  # SIGINT/SIGTERM of the run: stop the branches now
            _stop_workers(pool)
            raise
    if errors:
        failed, error = errors[0]
        raise ProtocolError(f"branch {failed.label!r} from A failed: {error}") from error
