"""benchmarks/runs_paired.py: paired differences by seed, one cell of a file that holds several,
and the tables of local_compressibility.py and compression_ends.py as well as
study_clay_pilots.py's."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from tests.scripts import load_script


def _write(path: Path, header: list[str], rows: list[list]) -> Path:
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows(rows)
    return path


def test_one_cell_of_a_file_with_several_is_paired_by_seed(tmp_path):
    script = load_script("benchmarks/runs_paired.py")
    header = ["cell", "seed", "converged", "lambda_window"]
    before = _write(tmp_path / "b.csv", header, [["X", 11, True, 0.1], ["X", 2, True, 0.2]])
    after = _write(
        tmp_path / "a.csv",
        header,
        [["Y", 11, True, 0.3], ["Z", 11, True, 0.5], ["Z", 2, True, 0.6], ["Y", 2, True, 0.4]],
    )
    z = script.read_runs(after, "Z")
    assert z[11]["lambda_window"] == 0.5 and z[2]["lambda_window"] == 0.6
    y = script.read_runs(after, "Y")
    text = "\n".join(script.table(script.read_runs(before, "X"), y))
    # differences +0.2 and +0.2 (seeds 2, 11): mean +0.2; the rows of Z are left out
    assert "| λ* 1–200 kPa | 0.2, 0.1 | 0.4, 0.3 | +0.2 ± " in text


def _cells_a_to_b(script, path: Path) -> tuple[list[str], str]:
    """The columns runs_paired.py reads from ``path`` and the paired table of its cell B
    against its cell A."""
    columns = script.columns_of(path)
    table = script.table(script.read_runs(path, "A"), script.read_runs(path, "B"), columns)
    return [key for key, _label, _digits in columns], "\n".join(table)


def test_a_local_compressibility_table_is_read_with_its_own_columns(tmp_path):
    script = load_script("benchmarks/runs_paired.py")
    header = ["cell", "seed", "scale", "p_A_kpa", "v_A", "seg_1_3", "kappa_1_3"]
    path = _write(
        tmp_path / "local.csv",
        header,
        [["A", 11, 1.0, 0.5, 6.0, 0.10, 0.01], ["B", 11, 1.0, 0.6, 6.2, 0.16, 0.02]],
    )
    keys, text = _cells_a_to_b(script, path)
    assert "seg_1_3" in keys and "kappa_1_3" in keys and "lambda_window" not in keys
    assert "| λ 1–3 | 0.1 | 0.16 | +0.06 |" in text


def test_a_compression_ends_table_is_read_with_its_own_columns(tmp_path):
    script = load_script("benchmarks/runs_paired.py")
    header = ["cell", "seed", "scale", "p_A_kpa", "v_A", "v_1", "v_100", "chord"]
    path = _write(
        tmp_path / "ends.csv",
        header,
        [["A", 11, 1.0, 0.5, 6.0, 5.8, 2.9, 0.15], ["B", 11, 1.0, 0.6, 6.2, 5.6, 2.4, 0.18]],
    )
    keys, text = _cells_a_to_b(script, path)
    assert keys == ["p_A_kpa", "v_A", "v_1", "v_100", "chord"]
    assert "| v at 100 kPa | 2.9 | 2.4 | -0.5 |" in text


def test_files_of_different_kinds_are_refused(tmp_path):
    script = load_script("benchmarks/runs_paired.py")
    pilots = _write(tmp_path / "p.csv", ["cell", "seed", "lambda_window"], [["X", 11, 0.1]])
    local = _write(tmp_path / "l.csv", ["cell", "seed", "seg_1_3"], [["X", 11, 0.1]])
    with pytest.raises(SystemExit):
        script.main([str(pilots), str(local)])
