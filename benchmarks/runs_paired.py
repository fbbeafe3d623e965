"""Paired differences between two sets of protocol runs of the same seeds (issue 20).

Usage::

    python benchmarks/runs_paired.py BEFORE_runs.csv AFTER_runs.csv [--out FILE.md] \
        [--before-cell CELL] [--after-cell CELL]

Each file is a ``*_runs.csv`` of ``benchmarks/study_clay_pilots.py`` (one row per run: its
seed and its findings), a per-run ``.csv`` of ``benchmarks/local_compressibility.py`` (its
decade-by-decade slopes, fits and, with ``--elastic``, κ) or of ``benchmarks/compression_ends.py``
(v at 1 and 100 kPa and the chord between them), told apart by the header. A file that
holds several cells is narrowed to one by ``--before-cell``/``--after-cell`` (its ``cell``
column). The rows are paired by seed; per finding: the before and after values
of each seed, the mean paired difference (after − before) with its 95 % interval (Student t
over the seeds) and the before runs' seed-to-seed standard deviation. The runs share their
state A when the settings that differ act after it (the servo does), so the differences are
those of the paths from A; they carry the paths' own chaos (``protocol_speed.md``, the null
pair), so an interval excluding 0 on three seeds is a hint, not a verdict.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/ is not a package
from compression_ends import COLUMNS as ENDS_COLUMNS  # noqa: E402
from local_compressibility import _columns as local_columns  # noqa: E402
from paired_paths_table import interval  # noqa: E402
from study_clay_pilots import COLUMNS  # noqa: E402


def columns_of(path: Path) -> list[tuple[str, str, int]]:
    """(column, label, digits) of a runs file: study_clay_pilots.py's findings,
    local_compressibility.py's columns when the header holds its segment slopes, or
    compression_ends.py's when it holds the chord."""
    with path.open() as handle:
        header = next(csv.reader(handle))
    if "chord" in header:
        return [(key, label, 3) for key, label in ENDS_COLUMNS]
    if "seg_1_3" not in header:
        return list(COLUMNS)
    elastic = any(key.startswith("kappa_") for key in header)
    return [(key, label, 3) for key, label in local_columns(elastic)]


def read_runs(
    path: Path, cell: str | None = None, columns: list[tuple[str, str, int]] | None = None
) -> dict[int, dict[str, float]]:
    """seed → {column: value} of the converged runs of a runs file (those of ``cell`` only,
    when given); ``columns`` default to :func:`columns_of` the file."""
    columns = columns_of(path) if columns is None else columns
    out = {}
    with path.open() as handle:
        for row in csv.DictReader(handle):
            if row.get("converged", "True") not in ("True", "true", "1"):
                continue
            if cell is not None and row.get("cell") != cell:
                continue
            values = {}
            for key, _label, _digits in columns:
                try:
                    values[key] = float(row.get(key, "nan") or "nan")
                except ValueError:
                    values[key] = math.nan
            out[int(row["seed"])] = values
    return out


def table(
    before: dict[int, dict],
    after: dict[int, dict],
    columns: list[tuple[str, str, int]] | None = None,
) -> list[str]:
    """The paired table (markdown lines) over ``columns`` (default: study_clay_pilots.py's)."""
    columns = list(COLUMNS) if columns is None else columns
    seeds = sorted(set(before) & set(after))
    lines = [
        f"Seeds {', '.join(map(str, seeds))} (paired by seed).",
        "",
        "| finding | before, per seed | after, per seed | after − before: mean ± 95 % | "
        "before: seed sd |",
        "|---|---|---|---|---|",
    ]
    for key, label, digits in columns:
        b = [before[s][key] for s in seeds]
        a = [after[s][key] for s in seeds]
        if not any(math.isfinite(v) for v in a + b):
            continue
        diffs = [x - y for x, y in zip(a, b, strict=True) if math.isfinite(x - y)]
        mean, half = interval(diffs)
        change = f"{mean:+.3g}" if diffs else "—"
        if len(diffs) > 1:
            change += f" ± {half:.2g}"
        finite = [v for v in b if math.isfinite(v)]
        sd = float(np.std(finite, ddof=1)) if len(finite) > 1 else math.nan
        lines.append(
            f"| {label} | {', '.join(f'{v:.{digits}g}' for v in b)} | "
            f"{', '.join(f'{v:.{digits}g}' for v in a)} | {change} | {sd:.2g} |"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("before", type=Path)
    parser.add_argument("after", type=Path)
    parser.add_argument("--out", type=Path)
    parser.add_argument("--before-cell", help="the cell of BEFORE's rows to pair (its cell column)")
    parser.add_argument("--after-cell", help="the cell of AFTER's rows to pair (its cell column)")
    args = parser.parse_args(argv)
    columns = columns_of(args.before)
    if columns != columns_of(args.after):
        parser.error("BEFORE and AFTER are different kinds of runs file (their columns differ)")
    before = read_runs(args.before, args.before_cell, columns)
    after = read_runs(args.after, args.after_cell, columns)
    text = "\n".join(table(before, after, columns))
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
