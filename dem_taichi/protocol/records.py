"""What a protocol run records: relaxed path states, stage records, the run's log and result.

:class:`RelaxedState` (one relaxed state of a path, with its measures and targets),
:class:`StageRecord` (wall time and quasi-static indicators of a stage), :class:`RunLog` (the
one log of a run: stage records, relaxed states, configurations, checkpoints, probes and their
times, the transition), :class:`ProtocolResult` (everything
:func:`dem_taichi.protocol.runner.run_protocol` did, its log with the files written, and its JSON
summary), :class:`Branch` (a path, or chain of paths, from state A) with
:class:`BranchOutcome` (what running one hands back) and :class:`ProtocolError`. Plain data, no
engine.

Who writes the log: :class:`dem_taichi.protocol.paths.ProtocolRunner` (stages, states,
configurations, checkpoints, transition) and :class:`dem_taichi.protocol.probing.ProbeRecorder`
(probes and their times) write into the same :class:`RunLog`; a branch run in its own process hands
its log back (:class:`dem_taichi.protocol.branches.BranchOutcome`) and :meth:`RunLog.merge` adds it
to the run's; the :class:`ProtocolResult` reads it.

Symbols: I inertial number, UFR unbalanced-force ratio (definitions: dem_taichi.io.schema).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np

from dem_taichi.analysis.arrays import Transition
from dem_taichi.engine.measures import Measures
from dem_taichi.engine.work_profile import WorkLedger, merge_work, work_rows

__all__ = [
    "ProtocolError",
    "RelaxedState",
    "StageRecord",
    "RunLog",
    "Branch",
    "BranchKind",
    "BranchOutcome",
    "ProtocolResult",
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
    measures: Measures
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

    def add(self, other: StageRecord) -> None:
        """Add another record of the same stage (a later path of it): sums and maxima."""
        for name in ("seconds", "steps", "n_relaxed_states", "servo_iterations",
                     "n_loading_checks", "n_loading_checks_above_limit"):  # fmt: skip
            setattr(self, name, getattr(self, name) + getattr(other, name))
        for name in ("max_inertial_number", "max_unbalanced_force_loading",
                     "max_unbalanced_force_relaxed"):  # fmt: skip
            setattr(self, name, max(getattr(self, name), getattr(other, name)))

    def note(self, measures: Measures, relaxed: bool, ufr_limit: float = math.inf) -> None:
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
class RunLog:
    """The one log of a protocol run, filled as the run goes.

    ``stages`` stage label → :class:`StageRecord`; ``states`` labelled relaxed states (A, B, C,
    B', R<k>_end) in the order reached; ``path_states`` every relaxed path state in order;
    ``configurations`` label → (rod positions, rod angles, cell lengths) when the state was
    reached; ``snapshots`` label → the discs then (``vtk_snapshots.simulation_snapshot``, for
    the ParaView files); ``checkpoints`` name → path of the saved state files; ``probes`` the
    :class:`dem_taichi.protocol.probing.ProbeResult` of every probed state in order, with the
    probing wall times (total, dynamic sweeps, linear responses, per stage); ``transition`` and
    ``transition_details`` the fluid–solid transition (state A) and how it was found; ``work``
    where the steps and wall time went, by stage and kind of work (a ledger of
    :mod:`dem_taichi.engine.work_profile`, filled by the simulation the runner drives).
    """

    stages: dict[str, StageRecord] = field(default_factory=dict)
    states: dict[str, RelaxedState] = field(default_factory=dict)
    path_states: list[RelaxedState] = field(default_factory=list)
    configurations: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = field(
        default_factory=dict
    )
    snapshots: dict[str, dict] = field(default_factory=dict)
    checkpoints: dict[str, str] = field(default_factory=dict)
    probes: list = field(default_factory=list)
    probing_seconds: float = 0.0
    probing_dynamic_seconds: float = 0.0
    probing_linear_seconds: float = 0.0
    probing_seconds_by_stage: dict[str, float] = field(default_factory=dict)
    transition: Transition | None = None
    transition_details: dict = field(default_factory=dict)
    work: WorkLedger = field(default_factory=dict)

    def stage(self, name: str) -> StageRecord:
        """The record of stage ``name``, created empty on first use."""
        return self.stages.setdefault(name, StageRecord(name))

    def merge(self, branch: RunLog) -> None:
        """Add the log of a branch from A run in its own process after what is here (branches
        are merged in the order of the serial run). The branch's stage records replace any of
        the same name; its states must not repeat A, which this log already holds."""
        self.path_states.extend(branch.path_states)
        self.states.update(branch.states)
        for name, record in branch.stages.items():
            if name in self.stages:  # the radial paths share one stage: add them up
                self.stages[name].add(record)
            else:
                self.stages[name] = record
        self.configurations.update(branch.configurations)
        self.snapshots.update(branch.snapshots)
        self.checkpoints.update(branch.checkpoints)
        self.probes.extend(branch.probes)
        self.probing_seconds += branch.probing_seconds
        self.probing_dynamic_seconds += branch.probing_dynamic_seconds
        self.probing_linear_seconds += branch.probing_linear_seconds
        for stage, seconds in branch.probing_seconds_by_stage.items():
            by_stage = self.probing_seconds_by_stage
            by_stage[stage] = by_stage.get(stage, 0.0) + seconds
        merge_work(self.work, branch.work)


BranchKind = Literal["isotropic", "k0", "radial"]
_BRANCH_KINDS: tuple[str, ...] = get_args(BranchKind)


@dataclass(frozen=True)
class Branch:
    """One branch of the protocol from state A (:mod:`dem_taichi.protocol.branches` runs it):
    ``Branch("isotropic")`` A→B; ``Branch("k0")`` A→C, then C→B when ``run_unloading``;
    ``Branch("radial", k, η)`` the k-th radial path (k ≥ 1, from 1 in the order of
    ``radial_stress_ratios``) at the stress ratio η = q/p (finite; stored as a float).
    Here, below the branches, beside :class:`BranchOutcome`, which holds one.

    Its :attr:`label` (also its ``str``) is the text the outputs have always carried
    (``"isotropic"``, ``"k0"``, ``"radial 1 0.5"``: η by ``repr``, so exact), in progress
    lines and the resume files; :meth:`parse` reads a label back from a file.

    >>> Branch("radial", 2, 0.5).label
    'radial 2 0.5'
    >>> Branch.parse("radial 2 0.5") == Branch("radial", 2, 0.5)
    True
    """

    kind: BranchKind
    index: int = 0
    eta: float | None = None

    def __post_init__(self) -> None:
        allowed = "allowed: Branch('isotropic'), Branch('k0'), Branch('radial', k >= 1, eta)"
        if self.kind not in _BRANCH_KINDS:
            raise ValueError(f"branch kind {self.kind!r} is not a branch from A; {allowed}")
        if type(self.index) is not int:  # not a bool, a float or a numpy integer either
            raise ValueError(f"branch index {self.index!r} must be an int")
        if self.kind != "radial":
            if self.index != 0 or self.eta is not None:
                raise ValueError(
                    f"Branch({self.kind!r}) takes no index or eta (given index {self.index!r}, "
                    f"eta {self.eta!r}); {allowed}"
                )
            return
        if self.index < 1:
            raise ValueError(
                f"a radial branch's index {self.index!r} must be >= 1 (the k-th radial path)"
            )
        eta = self.eta
        if isinstance(eta, bool) or not isinstance(eta, int | float) or not math.isfinite(eta):
            raise ValueError(f"a radial branch's eta {eta!r} must be a finite number")
        object.__setattr__(self, "eta", float(eta))  # a plain float: its repr is the label's

    @property
    def label(self) -> str:
        """The branch as text: ``"isotropic"``, ``"k0"`` or ``"radial <k> <repr(η)>"``."""
        if self.kind == "radial":
            return f"radial {self.index} {self.eta!r}"
        return self.kind

    def __str__(self) -> str:
        return self.label

    @classmethod
    def parse(cls, text: str) -> Branch:
        """The branch whose :attr:`label` is ``text`` (as a resume file of an earlier run holds
        it); a text that is not exactly such a label raises ``ValueError`` saying why."""
        expected = "expected 'isotropic', 'k0' or 'radial <k> <eta>' as this package writes it"
        if not isinstance(text, str):  # read from a file: any JSON value
            raise ValueError(f"branch {text!r} is not text; {expected}")
        try:
            match text.split(" "):
                case ["isotropic"]:
                    branch = cls("isotropic")
                case ["k0"]:
                    branch = cls("k0")
                case ["radial", index, eta]:
                    branch = cls("radial", int(index), float(eta))
                case _:
                    raise ValueError("not of this form")  # caught just below
        except ValueError as error:
            raise ValueError(f"branch {text!r}: {error}; {expected}") from None
        if branch.label != text:  # "radial 1 0.50", "radial +1 .5": not written by this package
            raise ValueError(f"branch {text!r} is not written as {branch.label!r}; {expected}")
        return branch


@dataclass
class BranchOutcome:
    """What one branch run in its own process hands back to
    :func:`dem_taichi.protocol.runner.run_protocol` (:mod:`dem_taichi.protocol.branches`): its
    history records and its log (without A, which the run's log holds). Here, below the branches, so
    the resume files (:mod:`dem_taichi.protocol.resume_codec`) can name it without importing the
    runners."""

    branch: Branch
    history: list[dict]
    log: RunLog

    def __post_init__(self) -> None:
        if not isinstance(self.branch, Branch):  # a label where the type belongs
            raise TypeError(f"BranchOutcome.branch must be a Branch, not {self.branch!r}")


@dataclass
class ProtocolResult:
    """What :func:`run_protocol` did: the run's :class:`RunLog`, the files written, timings.

    The log's entries read as attributes of the result (``result.states``,
    ``result.path_states``, ``result.stages``, ``result.probes``, ``result.probing_seconds``...).
    """

    out_dir: Path
    scene_name: str
    pattern: str
    n_rods: int
    arch: str
    precision: str
    log: RunLog = field(default_factory=RunLog)
    total_seconds: float = 0.0
    files: dict[str, str] = field(default_factory=dict)
    stress_scale_kpa: float = 1.0
    workers: int = 1

    @property
    def transition(self) -> Transition | None:
        return self.log.transition

    @property
    def transition_details(self) -> dict:
        return self.log.transition_details

    @property
    def states(self) -> dict[str, RelaxedState]:
        return self.log.states

    @property
    def path_states(self) -> list[RelaxedState]:
        return self.log.path_states

    @property
    def stages(self) -> dict[str, StageRecord]:
        return self.log.stages

    @property
    def probes(self) -> list:
        return self.log.probes

    @property
    def probing_seconds(self) -> float:
        return self.log.probing_seconds

    @property
    def probing_dynamic_seconds(self) -> float:
        return self.log.probing_dynamic_seconds

    @property
    def probing_linear_seconds(self) -> float:
        return self.log.probing_linear_seconds

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
            "work": work_rows(self.log.work, {k: v.seconds for k, v in self.stages.items()}),
            "files": self.files,
        }


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
