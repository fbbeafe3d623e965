"""What a protocol run records: relaxed path states, stage records, the run's result.

:class:`RelaxedState` (one relaxed state of a path, with its measures and targets),
:class:`StageRecord` (wall time and quasi-static indicators of a stage), :class:`ProtocolResult`
(everything :func:`dem_taichi.protocol.run_protocol` did, with its JSON summary) and
:class:`ProtocolError`. Plain data, no engine.

Symbols: I inertial number, UFR unbalanced-force ratio (definitions: dem_taichi.io.schema).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dem_taichi.analysis import Transition
from dem_taichi.measures import Measures

__all__ = ["ProtocolError", "RelaxedState", "StageRecord", "ProtocolResult"]


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
