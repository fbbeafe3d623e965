"""The study's-clay pilots (issue 19) over seeds: did the servo converge, and what material is it.

Usage::

    python benchmarks/study_clay_pilots.py RUNS_DIR [--out benchmarks/results/study_clay_pilots]

RUNS_DIR holds finished or failed protocol runs named ``<cell>_s<seed>`` (one folder per run,
as written by the commands in the output's header); runs of one cell are replicas. For every
cell: how many runs converged (a run that stops on a servo failure writes no
``summary.json``), and mean ± 95 % (Student t) over its converged seeds of the findings read by
:func:`dem_taichi.analysis.findings.run_findings`: v at A, λ* from A to B (ln v – ln p, DEM
stresses), λ* and the moduli exponent on the mapped 1–200 kPa window (the stress scale measured
where E_v/p = 125 on A→B), E_v/p at B, K0 at C, E_h/E_v at B and at C and their paired difference
C − B, E_h/E_v at B′ and B′ − B (B's probe against B′'s), the fabric deviator at C, N under both
specific-volume definitions, the largest contact overlap at the labelled states and, where the
run saved its path states, over every saved state. A run's K0 path added later from its A
(``<run>_k0.json`` beside the folder, ``benchmarks/paired_paths.py --from-run``) fills the C and
B′ columns. ``--with-runs CSV`` adds the rows of an earlier ``<out>_runs.csv`` (runs whose
folders were not kept) to the cells, so that new seeds extend earlier replicas. Writes
``<out>.md`` and ``<out>.csv`` (per cell) and ``<out>_runs.csv`` (per run).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import re
from pathlib import Path

from dem_taichi.analysis.findings import headline_findings, mean_interval

HERE = Path(__file__).resolve().parent

#: (column, label, digits) of the per-cell table.
COLUMNS = (
    ("v_A", "v_A", 3),
    ("lambda_star", "λ* A→B (DEM p)", 3),
    ("lambda_window", "λ* 1–200 kPa", 3),
    ("exponent_window_v", "E_v ∝ p^n, 1–200 kPa", 3),
    ("modulus_exponent", "E_v ∝ p^n on A→B", 3),
    ("ev_over_p_B", "E_v/p at B", 3),
    ("stress_scale_kpa_measured", "kPa per DEM unit (E_v/p = 125)", 3),
    ("k0_C", "K0 at C", 3),
    ("ratio_B", "E_h/E_v at B", 3),
    ("ratio_C", "E_h/E_v at C", 3),
    ("ratio_C_minus_B", "C − B", 3),
    ("ratio_Bp", "E_h/E_v at B′", 3),
    ("ratio_Bp_minus_B", "B′ − B", 3),
    ("fabric_C", "fabric deviator at C", 3),
    ("N_disc", "N (disc area)", 3),
    ("N_rectangle", "N (rod rectangle)", 3),
    ("max_overlap", "max overlap δ/d", 2),
    ("max_overlap_all_states", "max overlap δ/d, every saved state", 2),
    ("minutes", "wall (min)", 2),
)


def run_row(folder: Path) -> dict:
    """The findings of one run folder, or ``converged = False`` when it has no summary."""
    named = re.fullmatch(r"(.+)_s(\d+)", folder.name)
    if named is None:
        raise ValueError(f"{folder}: not a <cell>_s<seed> run folder")
    cell, seed = named.groups()
    row: dict = {"cell": cell, "seed": int(seed), "converged": False}
    if not (folder / "summary.json").exists():
        return row
    row.update(headline_findings(folder))
    row["converged"] = True
    _add_paths_from_a(folder, row)
    row["max_overlap_all_states"] = _max_overlap_all_states(folder)
    return row


def read_runs_csv(path: Path) -> list[dict]:
    """The rows of an earlier ``<out>_runs.csv``: numbers as floats (an empty field is NaN),
    ``converged`` as a bool and ``seed`` as an int, as :func:`run_row` gives them."""
    rows = []
    with path.open(newline="") as fh:
        for raw in csv.DictReader(fh):
            row: dict = {"cell": raw["cell"], "seed": int(raw["seed"])}
            row["converged"] = {"True": True, "False": False}[raw["converged"]]
            for key, _label, _digits in COLUMNS:
                text = raw.get(key, "")
                row[key] = float(text) if text not in ("", None) else math.nan
            rows.append(row)
    return rows


def _number(value) -> float:
    return math.nan if value is None else float(value)


def _add_paths_from_a(folder: Path, row: dict) -> None:
    """The K0 path and unloading added later from the run's A (``<run>_k0.json`` beside the run
    folder, written by ``benchmarks/paired_paths.py --from-run`` with one variant): K0 at C, the
    fabric at C, E_h/E_v at C and B′ and their paired changes against the run's own B, the
    largest overlap at C and B′ (with the run's), and the branch's wall time added."""
    added = folder.with_name(folder.name + "_k0.json")
    if not added.exists():
        return
    (variant,) = json.loads(added.read_text())["variants"].values()
    found = variant["findings"]
    row["k0_C"], row["fabric_C"] = _number(found["k0_C"]), _number(found["fabric_C"])
    row["ratio_C"], row["ratio_Bp"] = _number(found["e_ratio@C"]), _number(found["e_ratio@B'"])
    row["ratio_C_minus_B"] = row["ratio_C"] - row["ratio_B"]
    row["ratio_Bp_minus_B"] = row["ratio_Bp"] - row["ratio_B"]
    overlaps = [row.get("max_overlap", math.nan)]
    overlaps += [_number(found.get(f"max_overlap@{label}")) for label in ("C", "B'")]
    finite = [v for v in overlaps if math.isfinite(v)]
    row["max_overlap"] = max(finite) if finite else math.nan
    row["minutes"] += variant["branches_wall_seconds"] / 60.0


def _max_overlap_all_states(folder: Path) -> float:
    """The largest overlap over every state checkpoint of the run (``state_*.npz`` and, where
    ``save_path_states`` wrote them, ``path_*.npz``); NaN without path states."""
    paths = sorted(folder.glob("path_*.npz"))
    if not paths:
        return math.nan
    from dem_taichi.analysis.overlaps import state_max_overlap

    return max(state_max_overlap(p) for p in [*sorted(folder.glob("state_*.npz")), *paths])


def summarise(rows: list[dict]) -> tuple[str, list[dict]]:
    """Markdown table and csv rows: per cell, converged count and mean ± 95 % per column."""
    cells = sorted({r["cell"] for r in rows})
    header = "| cell | converged | " + " | ".join(c[1] for c in COLUMNS) + " |"
    lines = [header, "|" + "---|" * (len(COLUMNS) + 2)]
    table = []
    for cell in cells:
        runs = [r for r in rows if r["cell"] == cell]
        done = [r for r in runs if r["converged"]]
        seeds = ",".join(str(r["seed"]) for r in sorted(runs, key=lambda r: r["seed"]))
        out = {"cell": cell, "seeds": seeds, "converged": f"{len(done)}/{len(runs)}"}
        cols = []
        for key, _label, digits in COLUMNS:
            values = [r.get(key, math.nan) for r in done]
            values = [v for v in values if math.isfinite(v)]
            mean, half, n = mean_interval(values) if values else (math.nan, math.nan, 0)
            out[key], out[f"{key}_ci95"], out[f"{key}_n"] = mean, half, n
            cols.append(f"{mean:.{digits}g} ± {half:.{digits}g}" if n > 1 else f"{mean:.{digits}g}")
        table.append(out)
        lines.append(f"| {cell} (seeds {seeds}) | {out['converged']} | " + " | ".join(cols) + " |")
    return "\n".join(lines) + "\n", table


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, help="folder of <cell>_s<seed> run folders")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "study_clay_pilots")
    parser.add_argument(
        "--with-runs",
        type=Path,
        action="append",
        default=[],
        metavar="CSV",
        help="an earlier <out>_runs.csv whose rows join the cells (repeatable; default: none)",
    )
    args = parser.parse_args(argv)
    folders = sorted(p for p in args.runs.iterdir() if p.is_dir() and re.search(r"_s\d+$", p.name))
    rows = [run_row(p) for p in folders]
    for earlier in args.with_runs:
        known = {(r["cell"], r["seed"]) for r in rows}
        for row in read_runs_csv(earlier):
            if (row["cell"], row["seed"]) in known:
                raise SystemExit(f"{earlier}: {row['cell']} seed {row['seed']} is also a folder")
            rows.append(row)
    text, table = summarise(rows)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".md").write_text(text)
    with args.out.with_suffix(".csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(table[0]) if table else ["cell"])
        writer.writeheader()
        writer.writerows(table)
    # one row per run, so that every seed's numbers stay readable beside the cell means
    fields = ["cell", "seed", "converged", *(key for key, _label, _digits in COLUMNS)]
    with (
        args.out.with_name(args.out.name + "_runs").with_suffix(".csv").open("w", newline="") as fh
    ):
        writer = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
