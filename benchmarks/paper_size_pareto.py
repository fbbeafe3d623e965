"""Cost against accuracy of the path settings measured at the paper size (issue 20): the Pareto.

Usage::

    python benchmarks/paper_size_pareto.py \
        --panel paper benchmarks/results/paired_paths/*.json \
            benchmarks/results/paper_path_time_step/*.json \
            benchmarks/results/paper_path_no_dashpot/*.json \
            benchmarks/results/paper_path_five_thirds/*.json \
        --panel paper_bonded benchmarks/results/bonded_time_step/seed*.json \
        --panel study benchmarks/results/study_fast_preset/seed*.json \
        [--out benchmarks/results/paper_size_pareto]

Every file is a ``benchmarks/paired_paths.py`` record of one seed: the variants' branches
from that seed's state A (files of the same seed and A are merged; a variant whose branch
failed has no findings and is listed as failed). For each variant against ``base``, over the
seeds it ran:

- **cost**: the steps of its branches from A over the base's, mean ± 95 % (Student t). Steps
  are used rather than seconds because the records come from several days and machines; the
  steps are deterministic, and a step costs the same in every variant of a scene;
- **error**: for every finding of ``paired_paths_table.FINDINGS`` with a base value on at
  least two seeds (18–23 here: the radial ends are not in these records), |mean paired
  difference| over the base's seed-to-seed standard deviation (the replica noise at the paper
  size); the median over the findings, and the largest.

The null pair (``--null``, default ``null101``: ``servo_check_steps`` 101 instead of 100, a
change that should change nothing) gives the band a variant's errors must be judged against:
one path from the same A is chaotic, so its findings differ by about a replica's spread under
any change. Writes ``<out>.md`` (the table) and ``<out>.png`` (per panel: cost on x, each
finding's error as a small marker and the median as a large one, hollow for a variant run on
fewer than three seeds; the null pair's median and largest over its seeds as a band).
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
from paired_paths_table import FINDINGS, _differences, _steps, _value, merge_by_seed  # noqa: E402


def load_panel(files: list[Path]) -> tuple[list[dict], dict[str, list[int]]]:
    """The merged seeds of ``files`` (variants with findings only) and, per failed variant,
    the seeds where a branch of it failed."""
    records: list[dict] = []
    failed: dict[str, list[int]] = {}
    for path in files:
        data = json.loads(path.read_text())
        kept = {}
        for name, variant in data["variants"].items():
            if "findings" in variant and variant.get("steps") is not None:
                kept[name] = variant
            else:
                failed.setdefault(name, []).append(int(data["seed"]))
        if kept:
            records.append({**data, "variants": kept})
    return merge_by_seed(records), failed


def variant_point(seeds: list[dict], name: str, base: str, only: list[int] | None = None) -> dict:
    """Cost and errors of ``name`` against ``base`` over the seeds that ran both (and are in
    ``only``, when given); the replica noise is the base's over every seed."""
    both = [s for s in seeds if name in s["variants"] and base in s["variants"]]
    if only is not None:
        both = [s for s in both if int(s["seed"]) in only]
    ratios = [_steps(s, name) / _steps(s, base) for s in both]
    cost, cost_half, _ = mean_interval(ratios)
    errors = {}
    for key, label in FINDINGS:
        base_values = np.asarray([_value(s, base, key) for s in seeds], dtype=float)
        if np.isfinite(base_values).sum() < 2:
            continue
        noise = float(np.nanstd(base_values, ddof=1))
        diffs = np.asarray(_differences(both, name, base, key), dtype=float)
        if not math.isfinite(noise) or noise <= 0.0 or not np.isfinite(diffs).any():
            continue
        errors[label] = abs(float(np.nanmean(diffs))) / noise
    values = np.asarray(list(errors.values()))
    return {
        "variant": name,
        "seeds": [int(s["seed"]) for s in both],
        "cost": cost,
        "cost_half": cost_half,
        "errors": errors,
        "median": float(np.median(values)) if values.size else math.nan,
        "largest": float(values.max()) if values.size else math.nan,
    }


def panel_points(seeds: list[dict], base: str, null: str) -> list[dict]:
    """Every variant's point, with the null pair's median and largest error on the same seeds
    (``null_median``, ``null_largest``: a mean over fewer seeds is noisier, so a variant is
    compared with the null pair over its own seeds)."""
    names = []
    for seed in seeds:
        names += [n for n in seed["variants"] if n != base and n not in names]
    points = [variant_point(seeds, name, base) for name in names]
    for p in points:
        ref = variant_point(seeds, null, base, only=p["seeds"])
        p["null_median"], p["null_largest"] = ref["median"], ref["largest"]
    return points


def table(panels: dict, base: str, null: str) -> list[str]:
    lines = [
        "| scene | variant | seeds | steps from A / base's (mean ± 95 %) "
        "| median error (replica sd) | largest error "
        "| the null pair on the same seeds: median / largest | findings |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for title, (points, failed) in panels.items():
        for p in points:
            half = "" if not math.isfinite(p["cost_half"]) else f" ± {p['cost_half']:.2f}"
            name = p["variant"] + (" (the null pair)" if p["variant"] == null else "")
            lines.append(
                f"| {title} | {name} | {', '.join(map(str, p['seeds']))} | {p['cost']:.2f}{half} "
                f"| {p['median']:.2f} | {p['largest']:.2f} "
                f"| {p['null_median']:.2f} / {p['null_largest']:.2f} | {len(p['errors'])} |"
            )
        for name, where in failed.items():
            seeds = ", ".join(map(str, sorted(set(where))))
            lines.append(f"| {title} | {name} | {seeds} | failed (a branch stopped) | | | | |")
    return lines


def figure(panels: dict, null: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 4.2), squeeze=False)
    for ax, (title, (points, failed)) in zip(axes[0], panels.items(), strict=True):
        ref = next((p for p in points if p["variant"] == null), None)
        if ref is not None:
            ax.axhspan(0.0, ref["median"], color="0.85", label=f"{null}: median error")
            ax.axhline(ref["largest"], color="0.5", ls=":", label=f"{null}: largest error")
        ax.axvline(1.0, color="0.6", lw=0.8)
        for p in points:
            x = p["cost"]
            ax.scatter([x] * len(p["errors"]), list(p["errors"].values()), s=8, color="0.35")
            several = len(p["seeds"]) >= 3  # hollow: fewer seeds (compare in the table)
            ax.scatter([x], [p["median"]], s=60, zorder=3, facecolors=None if several else "none",
                       edgecolors=f"C{points.index(p)}", color=f"C{points.index(p)}")  # fmt: skip
            offset = (5, 4 + 10 * (points.index(p) % 3))  # neighbours' labels apart
            ax.annotate(p["variant"], (x, p["median"]), textcoords="offset points", xytext=offset)
        if failed:
            ax.text(0.02, 0.97, "failed: " + ", ".join(failed), transform=ax.transAxes, va="top")
        ax.set_xscale("log")
        ax.set_xlabel("steps of the branches from A / the base's")
        ax.set_ylabel("|paired difference| / replica sd")
        ax.set_title(title)
        ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--panel",
        nargs="+",
        action="append",
        required=True,
        metavar=("TITLE", "FILE"),
        help="a title and its paired_paths records",
    )
    parser.add_argument("--base", default="base")
    parser.add_argument("--null", default="null101")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/paper_size_pareto"))
    args = parser.parse_args(argv)
    panels = {}
    for title, *files in args.panel:
        seeds, failed = load_panel([Path(f) for f in files])
        panels[title] = (panel_points(seeds, args.base, args.null), failed)
    lines = table(panels, args.base, args.null)
    args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    figure(panels, args.null, args.out.with_suffix(".png"))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
