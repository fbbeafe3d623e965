"""benchmarks/servo_approach_trace.py --phases: a trace split at its relaxed checks (a gap in the
steps), and per servo call its steps, those at the cap, and when the residual first fell below
5 %, 1 % and 0.2 %."""

from __future__ import annotations

from tests.scripts import load_script


def _row(step, kind, s, residual, sxx, syy):
    res = " ".join(f"{r:g}" for r in residual)
    return f"{step}\t{kind}\t{s}\t1 1\t{res}\t0 0\t1e-4\t{sxx}\t{syy}\t0.001\n"


def test_phases_split_at_the_relaxed_checks(tmp_path, capsys):
    trace = load_script("benchmarks/servo_approach_trace.py")
    path = tmp_path / "trace.tsv"
    rows = ["step\tkind\ts\tfactors\tresidual\twanted\tcap\tsxx\tsyy\tufr\n"]
    # call 1: targets (1, 1); relative residual 0.5, 0.04, 0.008, 0.001 at steps 0..300
    for k, (rel, kind, s) in enumerate(
        [
            (0.5, "cap", 0.3),
            (0.04, "approach", 1.0),
            (0.008, "approach", 0.2),
            (0.001, "approach", 0.2),
        ]
    ):
        rows.append(_row(100 * k, kind, s, (rel, rel), 1 - rel, 1 - rel))
    # a relaxed check (steps 400-999 not in the trace), then call 2: one control (σ_yy), on target
    rows.append(_row(1000, "approach", 1.0, (0.0015,), 0.4, 1.0 - 0.0015))
    path.write_text("".join(rows))
    trace.phases(path)
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("call\tsteps")
    assert lines[1].split("\t") == ["1", "400", "100", "100", "200", "300", "100"]
    assert lines[2].split("\t") == ["2", "100", "0", "0", "0", "0", "100"]
