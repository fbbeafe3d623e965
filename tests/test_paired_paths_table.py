"""``benchmarks/paired_paths_table.py``: the speed table takes each variant's seconds as its
branches' wall time, or, where the variants shared one pool (``paired_paths.py --pool``), as the
sum of their branches' process seconds."""

from __future__ import annotations

import math

import pytest

from tests.scripts import load_script


@pytest.fixture(scope="module")
def tables():
    return load_script("benchmarks/paired_paths_table.py")


def _seed(seed: int, pooled: bool) -> dict:
    def variant(seconds: dict[str, float], steps: int) -> dict:
        return {
            "settings": [],
            "branches_wall_seconds": None if pooled else max(seconds.values()) + 1.0,
            "branch_seconds": seconds,
            "branch_process_seconds": sum(seconds.values()),
            "steps": {"isotropic_to_A": 999, "A_to_B": steps, "A_to_C": 2 * steps},
            "findings": {},
        }

    return {
        "seed": seed,
        "variants": {
            "base": variant({"A_to_B": 100.0, "A_to_C": 300.0}, 1000),
            "fast": variant({"A_to_B": 50.0, "A_to_C": 150.0}, 500),
        },
    }


def test_pooled_variants_are_timed_by_their_process_seconds(tables):
    seeds = [_seed(3, pooled=True), _seed(4, pooled=True)]
    assert tables._seconds(seeds[0], "base") == 400.0
    assert tables._steps(seeds[0], "fast") == 1500  # the stage to A is not a branch
    row = next(line for line in tables.table(seeds, "base") if line.startswith("| fast |"))
    assert "| 200, 200 |" in row and "0.50 ± 0.00" in row


def test_unpooled_variants_are_timed_by_their_wall(tables):
    seed = _seed(3, pooled=False)
    assert tables._seconds(seed, "base") == 301.0
    assert tables._seconds(seed, "fast") == 151.0


def _overlap_seed(seed: int, factors: dict[str, float]) -> dict:
    """A seed whose variants' mean and 99th-percentile overlaps at B, C, B′ are the base's
    (0.01, 0.02, 0.03; p99 three times as deep) times each variant's factor per state."""
    states = ("B", "C", "B'")
    base = {"mean_overlap": (0.01, 0.02, 0.03), "p99_overlap": (0.03, 0.06, 0.09)}

    def findings(state_factors: tuple[float, float, float]) -> dict:
        out = {}
        for measure, values in base.items():
            for state, value, f in zip(states, values, state_factors, strict=True):
                out[f"{measure}@{state}"] = value * f
                if measure == "mean_overlap":
                    out[f"max_overlap@{state}"] = 4 * value * f
        return out

    return {
        "seed": seed,
        "variants": {
            "base": {"findings": findings((1.0, 1.0, 1.0))},
            "null": {"findings": findings((factors["null"], 1.0, 1.0))},
            "dt2": {"findings": findings((factors["dt2"], factors["dt2"], 1.0))},
        },
    }


def test_overlap_ratio_is_the_geometric_mean_over_the_states(tables):
    seed = _overlap_seed(6, {"null": 1.0, "dt2": 1.21})
    # (1.21 * 1.21 * 1)^(1/3)
    assert tables.overlap_ratio(seed, "dt2", "base", "mean_overlap") == pytest.approx(
        1.21 ** (2 / 3)
    )
    del seed["variants"]["dt2"]["findings"]["p99_overlap@C"]  # a file without the measure
    assert math.isnan(tables.overlap_ratio(seed, "dt2", "base", "p99_overlap"))


def test_ratio_interval_is_a_t_interval_on_the_logarithms(tables):
    ratio, low, high = tables.ratio_interval([math.e, math.e**3])
    # logs 1 and 3: mean 2, sd sqrt(2), half-width t(0.975, 1) * sqrt(2) / sqrt(2) = 12.706
    assert ratio == pytest.approx(math.e**2)
    assert low == pytest.approx(math.exp(2 - 12.7062), rel=1e-4)
    assert high == pytest.approx(math.exp(2 + 12.7062), rel=1e-4)


def test_a_variant_that_deepens_every_seed_is_flagged_and_the_null_pair_is_not(tables):
    seeds = [_overlap_seed(s, {"null": n, "dt2": d})
             for s, n, d in ((6, 0.9, 1.30), (7, 1.1, 1.32), (8, 1.0, 1.31))]  # fmt: skip
    lines = tables.overlap_table(seeds, "base", "null")
    rows = {"".join(line.split("|")[1:3]).replace(" ", ""): line for line in lines}
    assert rows["dt2meanδ/d"].endswith("| **yes** |")
    assert rows["nullmeanδ/d"].endswith("| — |")
    # the largest overlap per seed, in per cent of d: 4 × 0.01 = 4 % at B for the base
    assert "| 6 | 4.00, 8.00, 12.00 | 3.60, 8.00, 12.00 | 5.20, 10.40, 12.00 |" in lines


def test_a_variant_within_the_null_pairs_scatter_is_not_flagged(tables):
    # deeper on every seed by 2-3 %, the null pair by as much: not more than 5 % beyond it
    seeds = [_overlap_seed(s, {"null": 1.03, "dt2": d})
             for s, d in ((6, 1.03), (7, 1.04), (8, 1.035))]  # fmt: skip
    rows = [
        line for line in tables.overlap_table(seeds, "base", "null") if line.startswith("| dt2 |")
    ]
    assert len(rows) == 2 and all(row.endswith("| no |") for row in rows)


def test_seeds_without_the_overlap_measures_are_left_out(tables):
    old = _overlap_seed(3, {"null": 1.0, "dt2": 1.0})
    for variant in old["variants"].values():
        variant["findings"] = {}
    assert tables.overlap_table([old], "base", "null") == []


def test_state_a_under_other_settings_is_shown_beside_the_base(tables):
    seed = {"seed": 6, "scene": "paper_bonded", "steps_to_A": 600_000, "seconds_to_A": 400.0,
            "variants": {"base": {"findings": {"v_A": 2.09, "p_A": 0.8}}}}  # fmt: skip
    other = {"seed": 6, "scene": "paper_bonded", "steps_to_A": 300_000, "seconds_to_A": 180.0,
             "overrides": ["integration.dt_safety=0.30"],
             "variants": {"base": {"findings": {"v_A": 2.175, "p_A": 0.611}}}}  # fmt: skip
    row = tables.a_table([seed], [other], "base")[-1]
    assert row == ("| 6 | integration.dt_safety=0.30 | 2.0900 → 2.1750 | 0.8 → 0.611 | "
                   "600,000 → 300,000 | 400 → 180 |")  # fmt: skip
    with pytest.raises(SystemExit, match="A of smoke_bonded beside paper_bonded"):
        tables.a_table([seed], [{**other, "scene": "smoke_bonded"}], "base")


def test_a_failed_branch_is_listed_and_its_variant_has_no_steps(tables):
    """A variant whose branch stopped (``paired_paths.py`` records ``failed``, its seconds, no
    steps nor findings) shows "failed" in the steps column and its error under the table."""
    seeds = [_seed(3, pooled=True), _seed(4, pooled=True)]
    seeds[1]["variants"]["fast"] = {
        "settings": [], "failed": {"k0": "[A_to_C] stress targets [7.26] not reached"},
        "branch_seconds": {"A_to_B": 50.0, "k0": 900.0}, "branch_process_seconds": 950.0,
    }  # fmt: skip
    assert math.isnan(tables._steps(seeds[1], "fast"))
    lines = tables.table(seeds, "base")
    row = next(line for line in lines if line.startswith("| fast |"))
    assert "1,500, failed" in row
    assert "- seed 4, fast: k0: [A_to_C] stress targets [7.26] not reached" in lines


def test_a_variant_not_run_on_every_seed_is_left_out_and_said_so(tables):
    seeds = [_seed(3, pooled=True), _seed(4, pooled=True)]
    seeds[0]["variants"]["extra"] = seeds[0]["variants"]["fast"]
    text = "\n".join(tables.table(seeds, "base"))
    assert "Left out (not run on every seed): extra." in text
    assert "| extra |" not in text and "| fast |" in text


def test_the_null_pairs_redraw_is_the_sd_of_its_differences_over_the_seed_sd(tables):
    """λ* of the base 0.17, 0.18, 0.19 over three seeds (sd 0.01); the null pair moves it by
    +0.02, 0, −0.02 (sd 0.02): a ratio of 2. A finding the null pair leaves alone reads 0."""
    seeds = [
        {"seed": s, "variants": {
            "base": {"findings": {"lambda_window": b, "ev_over_p_B": e}},
            "null": {"findings": {"lambda_window": b + d, "ev_over_p_B": e}},
        }}
        for s, b, d, e in ((3, 0.17, 0.02, 120.0), (4, 0.18, 0.0, 130.0), (5, 0.19, -0.02, 140.0))
    ]  # fmt: skip
    lines = tables.redraw_table(seeds, "base", "null")
    rows = {line.split("|")[1].strip(): line for line in lines if line.startswith("|")}
    assert rows["λ* on the mapped 1–200 kPa window"].endswith("| 0.01 | 0.02 | 2.00 |")
    assert rows["E_v/p at B"].endswith("| 10 | 0 | 0.00 |")
    assert "moduli exponent n on the mapped window" not in rows  # no values: no row
