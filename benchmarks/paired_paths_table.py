"""Paired differences of path settings over seeds: the tables of ``protocol_speed.md``.

Usage::

    python benchmarks/paired_paths_table.py SEED.json [SEED.json ...] [--base base] [--null NAME]
        [--out FILE.md]

Each SEED.json is written by ``benchmarks/paired_paths.py`` (one seed, every variant from the
same state A; files of the same seed, run at different times from the same A, are merged).
For each variant against ``--base``: the wall time and steps of the branches (per seed and
their ratio to the base), and, per finding, the base's mean and seed-to-seed standard
deviation (the replica noise), the mean paired difference (variant − base) with its 95 %
interval (Student t over the seeds) and whether the variant passes the criterion stated
before the runs: |mean paired difference| ≤ 0.5 × the base's seed-to-seed standard deviation
(``protocol_speed.md``), or, with ``--null NAME``, beside the null pair's differences, flagged
where the variant's interval excludes 0 and the null pair's does not (``study_servo.md``).

With ``--null``, the overlaps too (``bonded_time_step.md``, second pairing): per seed, the ratio
variant/base of the mean overlap of the touching disc pairs and of their 99th percentile at
each of B, C and B′, their geometric mean over the states, and over the seeds that recorded them
the mean of its logarithm ± 95 % (Student t) shown as a ratio, beside the null pair's; flagged
where the variant's interval lies wholly above 1 and its ratio exceeds the null pair's by more
than 5 %; and the null pair's redraw per finding: the sd of its paired differences against the
base's seed sd (about √2 where the paths decorrelate completely). With ``--a-files FILE.json
...`` (``paired_paths.py --branches none`` runs: the same gases compressed to A with other
settings), state A of each seed beside the base's.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from dem_taichi.analysis.findings import mean_interval

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/ is not a package
from paired_paths import BEFORE_A  # noqa: E402

#: the findings compared, with their labels
FINDINGS = (
    ("lambda_window", "λ* on the mapped 1–200 kPa window"),
    ("exponent_window_v", "moduli exponent n on the mapped window"),
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
    ("C-B", "C − B (E_h/E_v at C minus at B)"),
    ("B'-B", "B′ − B (E_h/E_v at B′ minus at B)"),
)

#: findings derived from two others: key -> (minuend, subtrahend)
DIFFERENCES = {"C-B": ("e_ratio@C", "e_ratio@B"), "B'-B": ("e_ratio@B'", "e_ratio@B")}


def interval(values: list[float]) -> tuple[float, float]:
    """Mean and the half-width of its 95 % interval (Student t; NaN below two values), of the
    finite values (None skipped): :func:`dem_taichi.analysis.findings.mean_interval`."""
    mean, half, _ = mean_interval([math.nan if v is None else v for v in values])
    return mean, half


def _value(seed: dict, variant: str, key: str) -> float:
    if key in DIFFERENCES:
        first, second = DIFFERENCES[key]
        return _value(seed, variant, first) - _value(seed, variant, second)
    value = seed["variants"].get(variant, {}).get("findings", {}).get(key)
    return math.nan if value is None else float(value)


def _seconds(seed: dict, name: str) -> float:
    """A variant's seconds for its branches: their wall time, or, where the variants shared one
    pool (``paired_paths.py --pool``), the sum of the branches' process seconds."""
    entry = seed["variants"][name]
    if entry.get("branches_wall_seconds") is not None:
        return entry["branches_wall_seconds"]
    return entry["branch_process_seconds"]


def _steps(seed: dict, variant: str) -> float:
    """A variant's steps from A; NaN where a branch failed (``paired_paths.py`` records no
    steps then)."""
    steps = seed["variants"][variant].get("steps")
    if steps is None:
        return math.nan
    return int(sum(v for k, v in steps.items() if k not in BEFORE_A))


def _differences(seeds: list[dict], name: str, base: str, key: str) -> list[float]:
    return [_value(s, name, key) - _value(s, base, key) for s in seeds]


def _excludes_zero(mean: float, half: float) -> bool:
    return math.isfinite(half) and abs(mean) > half


def common_variants(seeds: list[dict]) -> list[str]:
    """The variants every seed ran, in the first seed's order: a variant run on some seeds only
    has no paired interval over the seeds."""
    return [v for v in seeds[0]["variants"] if all(v in s["variants"] for s in seeds)]


def table(seeds: list[dict], base: str, null: str | None = None) -> list[str]:
    """The speed and findings tables of every variant against ``base``; with ``null`` (the name
    of a variant that should change nothing), each variant's paired differences are shown
    beside the null pair's, and a finding is flagged when the variant's 95 % interval excludes 0
    while the null pair's does not (the criterion of ``study_servo.md``); without it, the
    criterion |mean difference| ≤ 0.5 × the base's seed standard deviation."""
    common = common_variants(seeds)
    variants = [v for v in common if v != base]
    labels = ", ".join(str(s["seed"]) for s in seeds)
    left_out = sorted({v for s in seeds for v in s["variants"]} - set(common))
    lines = [
        f"Seeds {labels} ({len(seeds)}); each variant's branches start from the seed's state A.",
        *([f"Left out (not run on every seed): {', '.join(left_out)}."] if left_out else []),
        "",
        "### Speed (branches from A)",
        "",
        "| variant | settings | wall (s) per seed (process seconds with `--pool`) | "
        "steps per seed | wall / base: mean ± 95 % | "
        "steps / base: mean ± 95 % |",
        "|---|---|---|---|---|---|",
    ]
    for name in [base, *variants]:
        walls = [_seconds(s, name) for s in seeds]
        steps = [_steps(s, name) for s in seeds]
        wall_ratio = interval([w / _seconds(s, base)
                               for w, s in zip(walls, seeds, strict=True)])  # fmt: skip
        step_ratio = interval([n / _steps(s, base) for n, s in zip(steps, seeds, strict=True)])
        settings = "; ".join(seeds[0]["variants"][name]["settings"]) or "(the scene's)"
        lines.append(
            f"| {name} | {settings} | {', '.join(f'{w:.0f}' for w in walls)} | "
            f"{', '.join(f'{n:,}' if math.isfinite(n) else 'failed' for n in steps)} | "
            f"{wall_ratio[0]:.2f} ± {wall_ratio[1]:.2f} | "
            f"{step_ratio[0]:.2f} ± {step_ratio[1]:.2f} |"
        )
    failures = [
        f"- seed {s['seed']}, {name}: {label}: {error}"
        for s in seeds
        for name, entry in s["variants"].items()
        for label, error in entry.get("failed", {}).items()
    ]
    if failures:
        lines += ["", "Failed branches (no steps, no findings; seconds up to the failure):", "",
                  *failures]  # fmt: skip
    for name in variants:
        if name == null:
            continue
        lines += ["", f"### Findings: {name} − {base}", ""]
        if null is None:
            lines += [
                f"| finding | {base}: mean ± seed sd | paired difference: mean ± 95 % | "
                "|difference| / seed sd | within 0.5 sd |",
                "|---|---|---|---|---|",
            ]
        else:
            lines += [
                f"| finding | {base}: mean ± seed sd | {name} − {base}: mean ± 95 % | "
                f"{null} − {base}: mean ± 95 % | half-width / seed sd | bias flagged |",
                "|---|---|---|---|---|---|",
            ]
        for key, label in FINDINGS:
            base_values = [_value(s, base, key) for s in seeds]
            if not any(math.isfinite(v) for v in base_values):
                continue
            finite = [v for v in base_values if math.isfinite(v)]
            sd = float(np.std(finite, ddof=1)) if len(finite) > 1 else math.nan
            mean, half = interval(_differences(seeds, name, base, key))
            if null is None:
                ratio = abs(mean) / sd if sd > 0 else math.nan
                ok = "yes" if ratio <= 0.5 else ("no" if math.isfinite(ratio) else "—")
                lines.append(
                    f"| {label} | {np.mean(finite):.4g} ± {sd:.2g} | {mean:+.3g} ± {half:.2g} | "
                    f"{ratio:.2f} | {ok} |"
                )
                continue
            null_mean, null_half = interval(_differences(seeds, null, base, key))
            flagged = _excludes_zero(mean, half) and not _excludes_zero(null_mean, null_half)
            lines.append(
                f"| {label} | {np.mean(finite):.4g} ± {sd:.2g} | {mean:+.3g} ± {half:.2g} | "
                f"{null_mean:+.3g} ± {null_half:.2g} | "
                f"{half / sd if sd > 0 else math.nan:.2f} | {'**yes**' if flagged else 'no'} |"
            )
    return lines


def redraw_table(seeds: list[dict], base: str, null: str) -> list[str]:
    """How much the null pair redraws each finding: the sd of its paired differences (null −
    base) over the seeds against the base's seed-to-seed sd. About √2 where the paths from A
    decorrelate completely (the null pair's trajectory as independent of the base's as another
    seed's), 0 where the finding does not depend on the trajectory from A."""
    lines = [
        "", f"### The null pair's redraw: sd of {null} − {base} against the seed sd", "",
        f"| finding | {base}: seed sd | sd of {null} − {base} | ratio (√2 ≈ 1.41: decorrelated) |",
        "|---|---|---|---|",
    ]  # fmt: skip
    for key, label in FINDINGS:
        base_values = [v for v in (_value(s, base, key) for s in seeds) if math.isfinite(v)]
        differences = [d for d in _differences(seeds, null, base, key) if math.isfinite(d)]
        if len(base_values) < 2 or len(differences) < 2:
            continue
        sd = float(np.std(base_values, ddof=1))
        spread = float(np.std(differences, ddof=1))
        ratio = f"{spread / sd:.2f}" if sd > 0 else "—"
        lines.append(f"| {label} | {sd:.3g} | {spread:.3g} | {ratio} |")
    return lines


#: the labelled states whose overlaps are compared, and the overlap measures
OVERLAP_STATES = ("B", "C", "B'")
OVERLAP_MEASURES = (("mean_overlap", "mean δ/d"), ("p99_overlap", "99th percentile of δ/d"))
#: a variant deepens the overlaps when its ratio's interval lies above 1 and the ratio exceeds
#: the null pair's by more than this factor
OVERLAP_MARGIN = 1.05


def overlap_ratio(seed: dict, variant: str, base: str, measure: str) -> float:
    """The geometric mean over :data:`OVERLAP_STATES` of ``measure@state`` variant/base (NaN
    where a state lacks it: files written before the measure was recorded)."""
    logs = []
    for state in OVERLAP_STATES:
        here = _value(seed, variant, f"{measure}@{state}")
        there = _value(seed, base, f"{measure}@{state}")
        if not (math.isfinite(here) and math.isfinite(there) and here > 0 and there > 0):
            return math.nan
        logs.append(math.log(here / there))
    return math.exp(float(np.mean(logs)))


def ratio_interval(ratios: list[float]) -> tuple[float, float, float]:
    """The geometric mean of finite ratios and its 95 % interval (Student t on the logarithms):
    (ratio, low, high); NaN bounds below two values."""
    logs = [math.log(r) for r in ratios if math.isfinite(r)]
    mean, half = interval(logs) if logs else (math.nan, math.nan)
    if not math.isfinite(half):
        return math.exp(mean), math.nan, math.nan
    return math.exp(mean), math.exp(mean - half), math.exp(mean + half)


def overlap_table(seeds: list[dict], base: str, null: str) -> list[str]:
    """Each variant's overlap ratios to ``base`` beside the null pair's, and whether the
    variant deepens the overlaps (criterion O of ``bonded_time_step.md``'s second pairing);
    then the largest overlap per seed and state (no criterion)."""
    have = [s for s in seeds if math.isfinite(overlap_ratio(s, null, base, "mean_overlap"))]
    if not have:
        return []
    labels = ", ".join(str(s["seed"]) for s in have)
    states = ", ".join(OVERLAP_STATES)
    lines = [
        "", f"### Overlaps against the null pair (seeds {labels}; states {states})", "",
        "| variant | measure | ratio to base per seed | ratio: geometric mean [95 %] | "
        "deepened |",
        "|---|---|---|---|---|",
    ]  # fmt: skip
    null_ratios = {m: ratio_interval([overlap_ratio(s, null, base, m) for s in have])[0]
                   for m, _ in OVERLAP_MEASURES}  # fmt: skip
    common = common_variants(have)
    for name in [v for v in common if v != base]:
        for measure, label in OVERLAP_MEASURES:
            per_seed = [overlap_ratio(s, name, base, measure) for s in have]
            ratio, low, high = ratio_interval(per_seed)
            deepened = (name != null and low > 1.0
                        and ratio > OVERLAP_MARGIN * null_ratios[measure])  # fmt: skip
            shown = "—" if name == null else ("**yes**" if deepened else "no")
            lines.append(
                f"| {name} | {label} | {', '.join(f'{r:.3f}' for r in per_seed)} | "
                f"{ratio:.3f} [{low:.3f}, {high:.3f}] | {shown} |"
            )
    lines += ["", "Largest overlap (per cent of d) at " + states + ":", "",
              "| seed | " + " | ".join(common) + " |",
              "|---|" + "---|" * len(common)]  # fmt: skip
    for s in have:
        cells = [", ".join(f"{100 * _value(s, v, f'max_overlap@{st}'):.2f}"
                           for st in OVERLAP_STATES) for v in common]  # fmt: skip
        lines.append(f"| {s['seed']} | " + " | ".join(cells) + " |")
    return lines


def a_table(seeds: list[dict], others: list[dict], base: str) -> list[str]:
    """State A of each seed as the base compressed it beside ``others``' (the same gas
    compressed to A with other settings, ``paired_paths.py --branches none``)."""
    by_seed = {s["seed"]: s for s in seeds}
    lines = [
        "", "### State A under other settings (the same gas)", "",
        "| seed | settings | v_A: base → other | p_A: base → other | steps to A | seconds to A |",
        "|---|---|---|---|---|---|",
    ]  # fmt: skip
    for other in sorted(others, key=lambda o: o["seed"]):
        mine = by_seed.get(other["seed"])
        if mine is None:
            continue
        if other.get("scene") != mine.get("scene"):
            raise SystemExit(
                f"seed {other['seed']}: A of {other.get('scene')} beside {mine.get('scene')}"
            )
        finding = next(iter(other["variants"].values()))["findings"]
        base_finding = mine["variants"][base]["findings"]
        lines.append(
            f"| {other['seed']} | {'; '.join(other['overrides'])} | "
            f"{base_finding['v_A']:.4f} → {finding['v_A']:.4f} | "
            f"{base_finding['p_A']:.4g} → {finding['p_A']:.4g} | "
            f"{mine['steps_to_A']:,} → {other['steps_to_A']:,} | "
            f"{mine['seconds_to_A']:.0f} → {other['seconds_to_A']:.0f} |"
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
    parser.add_argument("--null", default=None, help="the variant that should change nothing")
    parser.add_argument(
        "--a-files",
        nargs="*",
        type=Path,
        default=[],
        help="paired_paths.py --branches none runs: A under other settings",
    )
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    seeds = merge_by_seed([json.loads(p.read_text()) for p in args.seeds])
    lines = table(seeds, args.base, args.null)
    if args.null is not None:
        lines += redraw_table(seeds, args.base, args.null)
        lines += overlap_table(seeds, args.base, args.null)
    if args.a_files:
        lines += a_table(seeds, [json.loads(p.read_text()) for p in args.a_files], args.base)
    text = "\n".join(lines)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
