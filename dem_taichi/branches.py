"""The branches of the protocol that start from state A, and running them in processes.

A branch is a path, or chain of paths, from A: ``"isotropic"`` (A→B), ``"k0"`` (A→C, then C→B
when ``run_unloading``), ``"radial <k> <η>"``. :func:`run_branch` runs one from A's checkpoint
in its own process and hands back a :class:`BranchOutcome` (its history records and its
:class:`RunLog`); :func:`run_branches_in_processes` runs them in spawned processes (Taichi's
runtime must not be forked) and merges the outcomes into the run's writers and log in the order
of the serial run, which they equal (the serial engine is deterministic).

Each finished branch's outcome is also saved in the run's ``resume/`` folder
(:mod:`dem_taichi.protocol_resume`), by the process that ran it (:func:`run_branch`, or
:func:`run_branch_saved` in the serial run), so that an interrupted run resumes with only the
branches still missing.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from dem_taichi.paths import ProtocolRunner
from dem_taichi.protocol_config import ProtocolConfig, probing_settings, protocol_settings
from dem_taichi.protocol_records import ProtocolError, RelaxedState, RunLog
from dem_taichi.protocol_resume import RecordingWriter, save_branch

__all__ = [
    "branch_names",
    "run_branch_on",
    "run_branch_saved",
    "merge_branch",
    "BranchOutcome",
    "run_branch",
    "run_branches_in_processes",
]


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


def run_branch_on(runner: ProtocolRunner, branch: str) -> None:
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
    """What one branch run in its own process hands back to
    :func:`dem_taichi.protocol.run_protocol`: its history records and its log (without A,
    which the run's log holds)."""

    branch: str
    history: list[dict]
    log: RunLog


def run_branch(
    branch: str,
    checkpoint_A: str,
    state_A: RelaxedState,
    arch: str,
    precision: str,
    out_dir: str | None,
    progress: bool,
    index: int | None = None,
    resume_dir: str | None = None,
) -> BranchOutcome:
    """Run one branch from the checkpoint of state A in this process (a worker of
    :func:`dem_taichi.protocol.run_protocol`); the scene, with its protocol and probing
    sections, comes from the checkpoint. With ``resume_dir`` the outcome is saved there as the
    ``index``-th branch (:func:`dem_taichi.protocol_resume.save_branch`)."""
    from dem_taichi.engine import Simulation
    from dem_taichi.probing import ProbeRecorder

    sim = Simulation.from_checkpoint(checkpoint_A, arch=arch, precision=precision)
    config, probing = protocol_settings(sim.scene), probing_settings(sim.scene)
    history = _RecordList()
    log = RunLog()
    recorder = ProbeRecorder(probing, config, log)
    runner = ProtocolRunner(sim, config, probing, history, None, recorder, progress, log=log)
    runner.out_dir = Path(out_dir) if out_dir is not None else None
    runner.bars = False  # beside other branch processes on one terminal: lines, not bars
    runner.state_A = sim.get_state()
    log.states["A"] = state_A
    run_branch_on(runner, branch)
    del log.states["A"]
    outcome = BranchOutcome(branch=branch, history=list(history), log=log)
    if resume_dir is not None and index is not None:
        save_branch(resume_dir, index, outcome)
    return outcome


def run_branch_saved(runner: ProtocolRunner, branch: str, index: int, resume_dir) -> None:
    """Run one branch on the serial ``runner`` as :func:`run_branch_on` does (its records reach
    the run's writers as they come), with a log of its own merged into the run's at the end,
    and save its outcome as the ``index``-th branch in ``resume_dir``."""
    main_log, history = runner.log, runner.history
    recorder = runner.probe_hook
    log = RunLog()
    log.states["A"] = main_log.states["A"]
    recording = RecordingWriter(history) if history is not None else None
    runner.log, runner.history = log, recording
    if recorder is not None:
        recorder.log = log
    try:
        run_branch_on(runner, branch)
    finally:
        runner.log, runner.history = main_log, history
        if recorder is not None:
            recorder.log = main_log
    del log.states["A"]
    main_log.merge(log)
    records = recording.records if recording is not None else []
    save_branch(resume_dir, index, BranchOutcome(branch=branch, history=records, log=log))


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


def run_branches_in_processes(
    runner, history, relaxed, branches, workers, arch, precision, progress, done=None
) -> None:
    """Run the branches from A in ``workers`` spawned processes and merge them in order into
    ``history``, ``relaxed`` (the writers of history.nc and relaxed_states.nc) and
    ``runner.log`` (where the probe recorder of the run writes too).

    A branch that fails does not lose the others: the finished ones are merged (their records
    reach history.nc and relaxed_states.nc), then the first failure is raised. ``done``: branch
    name → saved :class:`BranchOutcome` of a resumed run; those are merged in their place, not
    run again. Every branch run here saves its outcome in ``<run>/resume/``.
    """
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    checkpoint = runner.checkpoints.get("A")
    if checkpoint is None:
        checkpoint = str(runner.sim.save_checkpoint(Path(runner.out_dir) / "state_A.npz"))
    out_dir = str(runner.out_dir) if runner.config.save_states else None
    resume_dir = str(runner.out_dir)
    done = done or {}
    todo = [b for b in branches if b not in done]
    runner._say(f"[branches] {', '.join(todo)} from A in {workers} processes")
    context = multiprocessing.get_context("spawn")  # Taichi's runtime must not be forked
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        futures = {
            b: pool.submit(
                run_branch, b, checkpoint, runner.states["A"], arch, precision, out_dir,
                progress, index, resume_dir,
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
        branch, exc = errors[0]
        raise ProtocolError(f"branch {branch!r} from A failed: {exc}") from exc
