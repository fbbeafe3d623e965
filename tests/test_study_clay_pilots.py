"""``benchmarks/study_clay_pilots.py``: a run's K0 path added later from its A (the JSON of
``benchmarks/paired_paths.py --from-run`` beside the run folder) fills the C and B′ columns."""

from __future__ import annotations

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
