"""Shared by the data-safety tests (run folders, the bridge's outputs): sentinel files that a
delete must leave alone, and the one-line error check."""

from __future__ import annotations

from pathlib import Path

SENTINEL = "SENTINEL: must survive"


def sentinel(path: Path) -> Path:
    """Write a sentinel file at ``path`` (its folders made)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(SENTINEL)
    return path


def survived(*paths: Path) -> bool:
    """Whether every sentinel is still there, unchanged."""
    return all(p.read_text() == SENTINEL for p in paths)


def one_line(err: str) -> str:
    """The one error line (fails when there are more lines or a traceback)."""
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]
