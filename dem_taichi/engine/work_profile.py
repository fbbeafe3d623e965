"""Where a run's steps and wall time go, by stage and kind of work (the protocol profile,
``benchmarks/results/protocol_profile.md``).

A work ledger is a plain dict, stage label → work label → ``[steps, kernel seconds, measure
seconds, calls]``, so that it travels in the run log (:class:`dem_taichi.protocol.records.
RunLog` ``work``), its resume files and ``summary.json`` as data. A simulation given one
(``sim.work = ledger``) adds every :meth:`dem_taichi.engine.simulation.Simulation.run` call to it:
the steps, the seconds spent in the step kernels, the seconds spent measuring (the reductions and
their copy to the host), under the stage of the call's control and the current work label.

The work label is the nesting of :func:`doing` blocks at the call, joined by ``/``: the
quasi-static blocks say what they do (``strain``, ``relax``, ``hold``), their callers what for
(``servo``, ``probe``, ``search``/``confirm`` of state A), e.g. ``servo/relax`` is a relaxation
the servo asked for to check a state. Calls outside any block count as ``other``. The probes run
under the control stage ``probe`` (the stage wall times exclude them; the probing time per
stage is in the run log's ``probing_seconds_by_stage``).

The wall time of a stage that is neither kernel nor measure (Python between kernel launches,
state copies, the servo's linear algebra, writing files) is the stage's wall time minus the
sums here (:func:`overhead_seconds`).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar

__all__ = [
    "WorkLedger",
    "doing",
    "current_work",
    "add_work",
    "merge_work",
    "stage_totals",
    "overhead_seconds",
]

#: stage → work → [steps, kernel seconds, measure seconds, calls]
WorkLedger = dict[str, dict[str, list[float]]]

_WORK: ContextVar[tuple[str, ...]] = ContextVar("dem_taichi_work", default=())


@contextmanager
def doing(label: str) -> Iterator[None]:
    """Count the simulation steps run inside the block under the work label ``label``, nested
    in the enclosing blocks' labels."""
    if not label or "/" in label:
        raise ValueError(f"work label {label!r}: a non-empty name without '/'")
    token = _WORK.set(_WORK.get() + (label,))
    try:
        yield
    finally:
        _WORK.reset(token)


def current_work() -> str:
    """The work label the steps run now count under (``other`` outside any block)."""
    return "/".join(_WORK.get()) or "other"


def add_work(
    ledger: WorkLedger,
    stage: str,
    work: str,
    steps: int,
    kernel_seconds: float,
    measure_seconds: float,
    calls: int = 1,
) -> None:
    """Add ``calls`` run calls (one by default) to ``ledger``."""
    entry = ledger.setdefault(stage, {}).setdefault(work, [0, 0.0, 0.0, 0])
    entry[0] += int(steps)
    entry[1] += float(kernel_seconds)
    entry[2] += float(measure_seconds)
    entry[3] += int(calls)


def merge_work(into: WorkLedger, other: WorkLedger) -> None:
    """Add the ledger ``other`` (a branch run in its own process) to ``into``."""
    for stage, works in other.items():
        for work, (steps, kernel, measure, calls) in works.items():
            add_work(into, stage, work, int(steps), kernel, measure, int(calls))


def stage_totals(ledger: WorkLedger, stage: str) -> tuple[int, float, float, int]:
    """(steps, kernel seconds, measure seconds, calls) of a stage over all its work labels."""
    works = ledger.get(stage, {})
    return (
        int(sum(e[0] for e in works.values())),
        float(sum(e[1] for e in works.values())),
        float(sum(e[2] for e in works.values())),
        int(sum(e[3] for e in works.values())),
    )


def overhead_seconds(ledger: WorkLedger, stage: str, stage_seconds: float) -> float:
    """Wall time of a stage outside the step kernels and the measures (Python between the
    kernel launches, state copies, the servo's algebra, file writes)."""
    _, kernel, measure, _ = stage_totals(ledger, stage)
    return float(stage_seconds) - kernel - measure


def work_rows(ledger: WorkLedger, stage_seconds: dict[str, float]) -> list[dict]:
    """One row per (stage, work) in ledger order, then each stage's ``overhead`` row (when its
    wall time is known): steps, their share of the stage's steps, kernel and measure seconds,
    steps per kernel second, calls."""
    rows = []
    for stage, works in ledger.items():
        steps_total = max(stage_totals(ledger, stage)[0], 1)
        for work, (steps, kernel, measure, calls) in works.items():
            rows.append(
                {
                    "stage": stage,
                    "work": work,
                    "steps": int(steps),
                    "share_of_steps": steps / steps_total,
                    "kernel_seconds": kernel,
                    "measure_seconds": measure,
                    "steps_per_kernel_second": steps / kernel if kernel > 0 else float("nan"),
                    "calls": int(calls),
                }
            )
        if stage in stage_seconds:
            rows.append(
                {
                    "stage": stage,
                    "work": "overhead",
                    "steps": 0,
                    "share_of_steps": 0.0,
                    "kernel_seconds": 0.0,
                    "measure_seconds": 0.0,
                    "overhead_seconds": overhead_seconds(ledger, stage, stage_seconds[stage]),
                    "steps_per_kernel_second": float("nan"),
                    "calls": 0,
                }
            )
    return rows
