"""Stage progress of the protocol (dem_taichi.protocol.progress): the time left, lines and bars."""

from __future__ import annotations

import pytest

from dem_taichi.protocol import progress as progress_module
from dem_taichi.protocol.progress import StageProgress, format_seconds


@pytest.mark.parametrize(
    ("seconds", "text"),
    [(0.4, "0 s"), (42.2, "42 s"), (185, "3 min 05 s"), (3725, "1 h 02 min"), (-3, "0 s")],
)
def test_format_seconds(seconds, text):
    assert format_seconds(seconds) == text


def test_time_left_is_elapsed_times_remaining_over_done(monkeypatch):
    clock = iter([100.0, 130.0, 130.0])
    monkeypatch.setattr(progress_module.time, "perf_counter", lambda: next(clock))
    stage = StageProgress("A_to_B", 4, enabled=True, bar=False)  # started at t = 100
    assert stage.eta(1) == pytest.approx(90.0)  # 30 s for 1 of 4: 3 × 30 s left
    assert StageProgress.eta(stage, 0) is None


def test_lines_carry_elapsed_and_time_left(capsys):
    stage = StageProgress("A_to_C", 3, enabled=True, bar=False)
    stage.step(1, "[A_to_C] 1 p=2")
    stage.write("  probe A_to_C_1: ...")
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("[A_to_C] 1 p=2 (elapsed ") and err[0].endswith(" left)")
    assert err[1] == "  probe A_to_C_1: ..."
    unknown = StageProgress("isotropic_to_A", None, enabled=True, bar=True)  # no total: lines
    unknown.step(5, "[isotropic_to_A] inc 5")
    assert "left" not in capsys.readouterr().err


def test_bar_over_the_increments(capsys):
    stage = StageProgress("A_to_B", 3, enabled=True, bar=True)
    for k in (1, 2, 3):
        stage.step(k, f"[A_to_B] {k}/3 p=1")
    stage.close()
    err = capsys.readouterr().err
    assert "A_to_B" in err and "3/3" in err and "inc" in err


def test_disabled_prints_nothing(capsys):
    stage = StageProgress("A_to_B", 3, enabled=False, bar=True)
    stage.step(1, "x")
    stage.write("y")
    stage.close()
    assert capsys.readouterr().err == ""
