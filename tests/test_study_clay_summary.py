"""benchmarks/study_clay_summary.py: every experiment it lists has its table, script and page in
the repository, and the committed matrix page is what the script writes from the committed
tables (a table regenerated without the page fails here)."""

from __future__ import annotations

from pathlib import Path

from tests.scripts import ROOT, load_script


def test_every_listed_experiment_has_its_table_script_and_page():
    script = load_script("benchmarks/study_clay_summary.py")
    for table, run, page in script.EXPERIMENTS:
        assert (ROOT / "benchmarks" / "results" / table).exists(), table
        for one in run.split(", "):  # one script, or the sweeps that ran the table's members
            assert (ROOT / "benchmarks" / one).exists(), one
        assert (ROOT / "benchmarks" / "results" / page).exists(), page
    assert set(script.PILOT_OPTIONS) <= {table for table, _run, _page in script.EXPERIMENTS}


def test_the_committed_matrix_page_is_the_scripts_output(tmp_path: Path):
    script = load_script("benchmarks/study_clay_summary.py")
    assert script.main(["--out", str(tmp_path / "study_clay")]) == 0
    written = (tmp_path / "study_clay.md").read_text()
    committed = (ROOT / "benchmarks" / "results" / "study_clay.md").read_text()
    assert written == committed
    assert (tmp_path / "study_clay.csv").read_text() == (
        ROOT / "benchmarks" / "results" / "study_clay.csv"
    ).read_text()
