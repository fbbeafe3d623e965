"""``benchmarks/paper_size_pareto.py``: a variant's cost is its steps from A over the base's, its
error each finding's |mean paired difference| over the base's seed-to-seed sd, the null pair is
compared on the variant's own seeds, and a failed variant is listed, not plotted."""

from __future__ import annotations

import json
import math

import pytest

from tests.scripts import load_script


@pytest.fixture(scope="module")
def pareto():
    return load_script("benchmarks/paper_size_pareto.py")


def _variant(steps: int, lam: float, k0: float) -> dict:
    return {
        "settings": [],
        "branches_wall_seconds": None,
        "branch_seconds": {},
        "branch_process_seconds": 1.0,
        "steps": {"isotropic_to_A": 999, "A_to_B": steps},
        "findings": {"mean_stress@A": 0.5, "lambda_star": lam, "k0_C": k0},
    }


def _record(seed: int, base: tuple, **variants: tuple) -> dict:
    entries = {"base": _variant(*base)}
    entries.update({name: _variant(*values) for name, values in variants.items()})
    return {"seed": seed, "variants": entries}


def test_cost_errors_and_the_null_pair_on_the_same_seeds(pareto, tmp_path):
    # base λ* 0.04, 0.05, 0.06 (sd 0.01); K0 0.6, 0.7, 0.8 (sd 0.1)
    records = [
        _record(3, (1000, 0.04, 0.6), fast=(500, 0.05, 0.6), null=(1100, 0.045, 0.65)),
        _record(4, (2000, 0.05, 0.7), fast=(1000, 0.06, 0.7), null=(1900, 0.055, 0.75)),
        _record(5, (1000, 0.06, 0.8), null=(900, 0.065, 0.85)),
    ]
    records.append({"seed": 6, "variants": {"slow": {"settings": [], "error": "stalled"}}})
    files = []
    for i, record in enumerate(records):
        files.append(tmp_path / f"r{i}.json")
        files[-1].write_text(json.dumps(record))
    seeds, failed = pareto.load_panel(files)
    assert failed == {"slow": [6]}
    points = {p["variant"]: p for p in pareto.panel_points(seeds, "base", "null")}
    fast = points["fast"]
    assert fast["seeds"] == [3, 4] and fast["cost"] == pytest.approx(0.5)
    assert fast["errors"]["λ* (A→B)"] == pytest.approx(1.0)  # +0.01 over sd 0.01
    assert fast["errors"]["K0 = σ_xx/σ_yy at C"] == pytest.approx(0.0, abs=1e-12)
    assert fast["median"] == pytest.approx(0.5) and fast["largest"] == pytest.approx(1.0)
    assert fast["null_median"] == pytest.approx(0.5)  # the null on seeds 3, 4: 0.5 and 0.5 sd
    null = points["null"]
    assert null["seeds"] == [3, 4, 5] and math.isfinite(null["cost_half"])
    lines = pareto.table({"paper": (list(points.values()), failed)}, "base", "null")
    assert any("| slow | 6 | failed" in line for line in lines)
