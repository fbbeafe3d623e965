"""The branches of the protocol that start from state A, and running them in processes.

A branch is a path, or chain of paths, from A: ``"isotropic"`` (A→B), ``"k0"`` (A→C, then C→B
when ``run_unloading``), ``"radial <k> <η>"``. :func:`run_branch` runs one from A's checkpoint
in its own process and hands back a :class:`BranchOutcome` (its history records and its
:class:`RunLog`); :func:`run_branches_in_processes` runs them in spawned processes (Taichi's
runtime must not be forked) and merges the outcomes into the run's writers and log in the order
of the serial run, which they equal (the serial engine is deterministic).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from dem_taichi.paths import ProtocolRunner
from dem_taichi.protocol_config import ProtocolConfig, probing_settings, protocol_settings
from dem_taichi.protocol_records import ProtocolError, RelaxedState, RunLog

__all__ = [
    "branch_names",
    "run_branch_on",
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
) -> BranchOutcome:
    """Run one branch from the checkpoint of state A in this process (a worker of
    :func:`dem_taichi.protocol.run_protocol`); the scene, with its protocol and probing
    sections, comes from the checkpoint."""
    from dem_taichi.engine import Simulation
    from dem_taichi.probing import ProbeRecorder

    sim = Simulation.from_checkpoint(checkpoint_A, arch=arch, precision=precision)
    config, probing = protocol_settings(sim.scene), probing_settings(sim.scene)
    history = _RecordList()
    log = RunLog()
    recorder = ProbeRecorder(probing, config, log)
    runner = ProtocolRunner(sim, config, probing, history, None, recorder, progress, log=log)
    runner.out_dir = Path(out_dir) if out_dir is not None else None
    runner.state_A = sim.get_state()
    log.states["A"] = state_A
    run_branch_on(runner, branch)
    del log.states["A"]
    return BranchOutcome(branch=branch, history=list(history), log=log)


def _merge_branch(runner, history, relaxed, outcome: BranchOutcome) -> None:
    for record in outcome.history:
        history.append(record)
    for state in outcome.log.path_states:
        relaxed.append(state.measures)
    runner.log.merge(outcome.log)


def run_branches_in_processes(
    runner, history, relaxed, branches, workers, arch, precision, progress
) -> None:
    """Run the branches from A in ``workers`` spawned processes and merge them in order into
    ``history``, ``relaxed`` (the writers of history.nc and relaxed_states.nc) and
    ``runner.log`` (where the probe recorder of the run writes too).

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
                _merge_branch(runner, history, relaxed, future.result())
            except Exception as exc:  # noqa: BLE001 - keep the other branches, raise below
                errors.append((branch, exc))
    if errors:
        branch, exc = errors[0]
        raise ProtocolError(f"branch {branch!r} from A failed: {exc}") from exc
