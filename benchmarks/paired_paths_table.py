"""Paired differences of path settings over seeds: the tables of ``protocol_speed.md``.

Usage::

    python benchmarks/paired_paths_table.py SEED.json [SEED.json ...] [--base base] [--out FILE.md]

Each SEED.json is written by ``benchmarks/paired_paths.py`` (one seed, every variant from the
same state A; files of the same seed, run at different times from the same A, are merged).
For each variant against ``--base``: the wall time and steps of the branches (per seed and
their ratio to the base), and, per finding, the base's mean and seed-to-seed standard
deviation (the replica noise), the mean paired difference (variant − base) with its 95 %
interval (Student t over the seeds) and whether the variant passes the criterion stated
before the runs: |mean paired difference| ≤ 0.5 × the base's seed-to-seed standard deviation.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
from scipy import stats

#: the findings compared, with their labels
FINDINGS = (
    ("lambda_star", "λ* (A→B)"),
    ("modulus_exponent", "moduli exponent n (A→B)"),
    ("ev_over_p_B", "E_v/p at B"),
    ("k0_C", "K0 = σ_xx/σ_yy at C"),
    ("specific_volume@B", "v at B"),
    ("specific_volume@C", "v at C"),
    ("specific_volume@B'", "v at B′"),
    ("fabric_deviator@B", "fabric deviator at B"),
    ("fabric_deviator@C", "fabric deviator at C"),
    ("fabric_deviator@B'", "fabric deviator at B′"),
    ("e_oed_v@B", "E_v at B"),
    ("e_oed_v@C", "E_v at C"),
    ("e_oed_h@C", "E_h at C"),
    ("e_ratio@B", "E_h/E_v at B"),
    ("e_ratio@C", "E_h/E_v at C"),
    ("e_ratio@B'", "E_h/E_v at B′"),
    ("e_ratio@R1_end", "E_h/E_v at R1_end"),
    ("e_ratio@R2_end", "E_h/E_v at R2_end"),
    ("e_ratio@R3_end", "E_h/E_v at R3_end"),
)


def interval(values: list[float]) -> tuple[float, float]:
    """Mean and the half-width of its 95 % interval (NaN below two values)."""
    x = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if x.size == 0:
        return math.nan, math.nan
    if x.size == 1:
        return float(x[0]), math.nan
    t = stats.t.ppf(0.975, x.size - 1)
    return float(x.mean()), float(t * x.std(ddof=1) / math.sqrt(x.size))


def _value(seed: dict, variant: str, key: str) -> float:
    value = seed["variants"].get(variant, {}).get("findings", {}).get(key)
    return math.nan if value is None else float(value)


def _steps(seed: dict, variant: str) -> int:
    steps = seed["variants"][variant]["steps"]
    return int(sum(v for k, v in steps.items() if k != "isotropic_to_A"))


def table(seeds: list[dict], base: str) -> list[str]:
    variants = [v for v in seeds[0]["variants"] if v != base]
    labels = ", ".join(str(s["seed"]) for s in seeds)
    lines = [
        f"Seeds {labels} ({len(seeds)}); each variant's branches start from the seed's state A.",
        "",
        "### Speed (branches from A)",
        "",
        "| variant | settings | wall (s) per seed | steps per seed | wall / base | steps / base |",
        "|---|---|---|---|---|---|",
    ]
    for name in [base, *variants]:
        walls = [s["variants"][name]["branches_wall_seconds"] for s in seeds]
        steps = [_steps(s, name) for s in seeds]
        wall_ratio = np.mean([w / s["variants"][base]["branches_wall_seconds"]
                              for w, s in zip(walls, seeds, strict=True)])  # fmt: skip
        step_ratio = np.mean([n / _steps(s, base) for n, s in zip(steps, seeds, strict=True)])
        settings = "; ".join(seeds[0]["variants"][name]["settings"]) or "(the scene's)"
        lines.append(
            f"| {name} | {settings} | {', '.join(f'{w:.0f}' for w in walls)} | "
            f"{', '.join(f'{n:,}' for n in steps)} | {wall_ratio:.2f} | {step_ratio:.2f} |"
        )
    for name in variants:
        lines += [
            "",
            f"### Findings: {name} − {base}",
            "",
            f"| finding | {base}: mean ± seed sd | paired difference: mean ± 95 % | "
            "|difference| / seed sd | within 0.5 sd |",
            "|---|---|---|---|---|",
        ]
        for key, label in FINDINGS:
            base_values = [_value(s, base, key) for s in seeds]
            if not any(math.isfinite(v) for v in base_values):
                continue
            finite = [v for v in base_values if math.isfinite(v)]
            sd = float(np.std(finite, ddof=1)) if len(finite) > 1 else math.nan
            diffs = [_value(s, name, key) - b for s, b in zip(seeds, base_values, strict=True)]
            mean, half = interval(diffs)
            ratio = abs(mean) / sd if sd > 0 else math.nan
            ok = "yes" if ratio <= 0.5 else ("no" if math.isfinite(ratio) else "—")
            lines.append(
                f"| {label} | {np.mean(finite):.4g} ± {sd:.2g} | {mean:+.3g} ± {half:.2g} | "
                f"{ratio:.2f} | {ok} |"
            )
    return lines


def merge_by_seed(files: list[dict]) -> list[dict]:
    """One entry per seed: the variants of several files of the same seed (and the same state
    A, checked by its p and v) put together, in the order given."""
    seeds: dict[int, dict] = {}
    for data in files:
        seed = seeds.get(data["seed"])
        if seed is None:
            seeds[data["seed"]] = {**data, "variants": dict(data["variants"])}
            continue
        for name, variant in data["variants"].items():
            a_here = variant["findings"].get("mean_stress@A")
            a_there = next(iter(seed["variants"].values()))["findings"].get("mean_stress@A")
            if a_here != a_there:
                raise SystemExit(f"seed {data['seed']}: files with different states A")
            seed["variants"][name] = variant
    return list(seeds.values())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("seeds", nargs="+", type=Path)
    parser.add_argument("--base", default="base")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    seeds = merge_by_seed([json.loads(p.read_text()) for p in args.seeds])
    text = "\n".join(table(seeds, args.base))
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
