"""``benchmarks/paired_paths_table.py``: the speed table takes each variant's seconds as its
branches' wall time, or, where the variants shared one pool (``paired_paths.py --pool``), as the
sum of their branches' process seconds."""

from __future__ import annotations

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
