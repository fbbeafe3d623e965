"""``benchmarks/study_clay_pilots.py``: a run's K0 path added later from its A (the JSON of
``benchmarks/paired_paths.py --from-run`` beside the run folder) fills the C and B′ columns."""

from __future__ import annotations

import csv
import json
import math

import pytest

from tests.scripts import load_script


@pytest.fixture(scope="module")
def pilots():
    return load_script("benchmarks/study_clay_pilots.py")


def test_the_added_k0_path_fills_c_and_b_prime(pilots, tmp_path):
    run = tmp_path / "KB300_s11"
    run.mkdir()
    findings = {
        "k0_C": 0.62, "fabric_C": -0.25, "e_ratio@C": 1.40, "e_ratio@B'": 1.35,
        "max_overlap@C": 0.012, "max_overlap@B'": None,
    }  # fmt: skip
    variant = {"findings": findings, "branches_wall_seconds": 600.0}
    (tmp_path / "KB300_s11_k0.json").write_text(json.dumps({"variants": {"k0": variant}}))
    row = {"ratio_B": 1.05, "ratio_C": math.nan, "max_overlap": 0.008, "minutes": 30.0}
    pilots._add_paths_from_a(run, row)
    assert row["k0_C"] == 0.62 and row["fabric_C"] == -0.25
    assert row["ratio_C_minus_B"] == pytest.approx(0.35)
    assert row["ratio_Bp_minus_B"] == pytest.approx(0.30)
    assert row["max_overlap"] == 0.012  # the largest of the run's and the added states'
    assert row["minutes"] == pytest.approx(40.0)
    untouched = {"ratio_B": 1.0, "minutes": 1.0}
    pilots._add_paths_from_a(tmp_path / "other_s2", untouched)  # no JSON: nothing changes
    assert untouched == {"ratio_B": 1.0, "minutes": 1.0}
    assert math.isnan(pilots._max_overlap_all_states(run))  # no path states saved


def test_earlier_rows_join_the_new_runs_cells(pilots, tmp_path):
    """``--with-runs``: the rows of an earlier ``_runs.csv`` (folders not kept) are read back as
    numbers and summarised with the new folders' rows; a seed in both is refused."""
    earlier = tmp_path / "earlier_runs.csv"
    earlier.write_text(
        "cell,seed,converged,lambda_window,ratio_C_minus_B,minutes\n"
        "R,11,True,0.17,0.4,39.8\n"
        "R,2,True,0.19,0.2,\n"
        "R,12,False,,,\n"
    )
    rows = pilots.read_runs_csv(earlier)
    assert [r["seed"] for r in rows] == [11, 2, 12]
    assert rows[0]["converged"] is True and rows[2]["converged"] is False
    assert rows[0]["lambda_window"] == 0.17 and math.isnan(rows[1]["minutes"])
    assert math.isnan(rows[0]["v_A"])  # a column the earlier file lacks
    runs = tmp_path / "runs"
    (runs / "R_s3").mkdir(parents=True)  # a new seed that stopped: no summary.json
    out = tmp_path / "out"
    assert pilots.main([str(runs), "--with-runs", str(earlier), "--out", str(out)]) == 0
    (cell,) = list(csv.DictReader((tmp_path / "out.csv").open()))
    assert cell["seeds"] == "2,3,11,12" and cell["converged"] == "2/4"
    assert float(cell["lambda_window"]) == pytest.approx(0.18)
    assert float(cell["ratio_C_minus_B"]) == pytest.approx(0.3)
    (runs / "R_s11").mkdir()
    with pytest.raises(SystemExit, match="seed 11 is also a folder"):
        pilots.main([str(runs), "--with-runs", str(earlier), "--out", str(out)])
