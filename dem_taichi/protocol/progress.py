"""Progress of the protocol's stages: one bar (or line) per stage with the time left.

A path from A has a known number of relaxed increments (``path_increments``; C→B
``unloading_increments``), so the time left after k of n is estimated as
elapsed × (n − k) / k (each increment costs about the same: the servo runs near the
inertial-number cap, and a probe's share is counted in). On a terminal (stderr is a TTY) each
stage is a ``tqdm`` bar over its increments, and the runner's other lines are written above
it; elsewhere (a log file, a sweep member's ``progress.log``, a branch process beside
others) each increment is one line ending with ``(elapsed …, ~… left)``. The compression to
the fluid–solid transition (state A) has no known number of increments: its lines give the
elapsed time only.
"""

from __future__ import annotations

import sys
import time

__all__ = ["StageProgress", "format_seconds", "use_bars"]


def format_seconds(seconds: float) -> str:
    """``42 s``, ``3 min 05 s``, ``1 h 02 min``."""
    seconds = max(float(seconds), 0.0)
    if seconds < 60:
        return f"{seconds:.0f} s"
    minutes, sec = divmod(int(round(seconds)), 60)
    if minutes < 60:
        return f"{minutes} min {sec:02d} s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours} h {minutes:02d} min"


def use_bars(stream=None) -> bool:
    """Bars only on a terminal."""
    stream = sys.stderr if stream is None else stream
    return bool(getattr(stream, "isatty", lambda: False)())


class StageProgress:
    """The progress of one stage of ``total`` increments (None: unknown).

    ``step(k, text)`` reports increment k with ``text`` (the state reached); ``write(text)``
    prints another line without breaking the bar; ``close()`` ends the stage. ``enabled``
    False prints nothing.
    """

    def __init__(self, stage: str, total: int | None, enabled: bool, bar: bool) -> None:
        self.stage = stage
        self.total = total
        self.enabled = enabled
        self.start = time.perf_counter()
        self._bar = None
        if enabled and bar and total:
            from tqdm import tqdm

            self._bar = tqdm(
                total=total, desc=stage, unit="inc", file=sys.stderr, leave=True, smoothing=0.0
            )

    def eta(self, k: int) -> float | None:
        """Seconds left after ``k`` increments (None when the total is unknown or k = 0)."""
        if not self.total or k <= 0:
            return None
        return (time.perf_counter() - self.start) * max(self.total - k, 0) / k

    def suffix(self, k: int) -> str:
        elapsed = format_seconds(time.perf_counter() - self.start)
        left = self.eta(k)
        return (
            f"(elapsed {elapsed})"
            if left is None
            else f"(elapsed {elapsed}, ~{format_seconds(left)} left)"
        )

    def step(self, k: int, text: str) -> None:
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.set_postfix_str(text.split("] ", 1)[-1], refresh=False)  # no "[stage] "
            self._bar.update(k - self._bar.n)
        else:
            print(f"{text} {self.suffix(k)}", file=sys.stderr, flush=True)

    def write(self, text: str) -> None:
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.write(text, file=sys.stderr)
        else:
            print(text, file=sys.stderr, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None
