"""Where the compressibility goes along the isotropic path (issue 19): λ* decade by decade.

Usage::

    python benchmarks/local_compressibility.py RUN [RUN ...] \
        [--out benchmarks/results/local_compressibility] [--elastic]

Each RUN is a finished protocol run folder named ``<cell>_s<seed>`` (runs of one cell are
replicas). The study's normal compression line is straight in ln v – ln p (λ* = 0.25 over the
whole window); the DEM gel's is not, and the windowed λ* (one least-squares slope over 1–200 kPa)
hides where the gap sits. For every run, on the mapped stresses (the run's measured stress scale,
E_v/p = 125 at 100 kPa; the scene's where none is measured):

- p_A (kPa) and v_A;
- the segment slopes λ_seg = −ln(v(p₂)/v(p₁))/ln(p₂/p₁) between the edges 1, 3, 10, 30, 100
  and 200 kPa, v interpolated in (ln p, ln v) along A→B (the segment that holds p_A starts
  there; NaN below p_A and past the path's end);
- λ* fitted (least squares, :func:`dem_taichi.analysis.mapped_window.windowed_compressibility`)
  on 1–200, 3–200 and 10–200 kPa;
- with ``--elastic``, the elastic share of each segment: κ = p/K, the slope of ln v on ln p that
  the probes' 2D bulk modulus K = dp/dε_vol (``bulk_modulus_linear`` of ``probes.nc``, at A and
  every relaxed state of A→B) would give alone, interpolated in ln p at the segment's geometric
  middle (NaN outside the probed states). κ ≪ λ_seg means the segment's compression is plastic.

Per cell: mean ± 95 % (Student t) over its runs. Writes ``<out>.md`` (the tables), ``<out>.csv``
(per run) and ``<out>.png`` (the local −d ln v/d ln p between consecutive states against p, every
run, with the study's 0.25).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

from dem_taichi.analysis.findings import (
    mapped_window_findings,
    mean_interval,
    path_arrays,
    probe_arrays,
)
from dem_taichi.analysis.mapped_window import (
    local_compressibility,
    specific_volume_at,
    windowed_compressibility,
)
from dem_taichi.io import open_history, open_probes

#: Segment edges (kPa) of the decade-by-decade slopes.
EDGES_KPA = (1.0, 3.0, 10.0, 30.0, 100.0, 200.0)
#: Lower ends (kPa) of the windows fitted up to 200 kPa.
WINDOW_STARTS_KPA = (1.0, 3.0, 10.0)
#: The study's λ* (Table 1).
STUDY_LAMBDA = 0.25


def run_probes(folder: Path):
    """The run's ``probes.nc`` dataset, or None without one (read once per run: the stress
    scale and the elastic slopes both come from it)."""
    probes_file = folder / "probes.nc"
    return open_probes(probes_file) if probes_file.exists() else None


def isotropic_path_kpa(folder: Path, probes) -> tuple[np.ndarray, np.ndarray, float]:
    """(p in kPa, v) of state A and the relaxed states of A→B, and the stress scale used
    (kPa per DEM unit: the run's measured one where it has one, else its scene's), read as
    :func:`dem_taichi.analysis.findings.run_findings` reads them; ``probes`` is the run's
    probes dataset (:func:`run_probes`) or None."""
    summary = json.loads((folder / "summary.json").read_text())
    relaxed = open_history(folder / "relaxed_states.nc")
    path = path_arrays(summary, relaxed)
    p = path.from_a("A_to_B", "mean_stress")
    v = path.from_a("A_to_B", "specific_volume")
    found = mapped_window_findings(summary, relaxed.attrs, probe_arrays(probes), p, v)
    scale = float(found["stress_scale_kpa_used"])
    return p * scale, v, scale


def segment_slopes(p_kpa, v, edges=EDGES_KPA) -> list[float]:
    """λ_seg between consecutive ``edges`` (kPa) along the path (p_kpa, v): minus the slope of
    ln v on ln p between v interpolated at the two edges; the segment that holds p_A (the path's
    lowest p) starts there; NaN where an end is not on the path (below p_A, past its end)."""
    p_a = float(np.nanmin(p_kpa))
    slopes = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        start = p_a if lo < p_a < hi else lo
        v_lo = specific_volume_at(p_kpa, v, start)  # orders the path by p itself
        v_hi = specific_volume_at(p_kpa, v, hi)
        slopes.append(-math.log(v_hi / v_lo) / math.log(hi / start))
    return slopes


def isotropic_bulk_compliance(probes, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """(p in kPa, κ = p/K) at the probes of state A and of A→B's relaxed states, from a run's
    probes dataset (:func:`run_probes`; empty arrays for None, or for probes that hold no bulk
    modulus), ordered by p; ``scale`` in kPa per DEM unit."""
    if probes is None or "bulk_modulus_linear" not in probes:
        return np.empty(0), np.empty(0)
    labels = probes["state_label"].values.astype(str)
    paths = probes["path"].values.astype(str)
    keep = (labels == "A") | (paths == "A_to_B")
    p = np.asarray(probes["mean_stress"].values, dtype=float)[keep]
    bulk = np.asarray(probes["bulk_modulus_linear"].values, dtype=float)[keep]
    order = np.argsort(p)
    return p[order] * scale, p[order] / bulk[order]


def segment_elastic_slopes(p_kpa, kappa, edges=EDGES_KPA) -> list[float]:
    """κ = p/K at the geometric middle of each segment between consecutive ``edges`` (kPa),
    interpolated linearly in ln p between the probed states (p_kpa increasing); NaN where the
    middle is outside them."""
    p_kpa, kappa = np.asarray(p_kpa, dtype=float), np.asarray(kappa, dtype=float)
    slopes = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        middle = math.sqrt(lo * hi)
        inside = p_kpa.size and p_kpa[0] <= middle <= p_kpa[-1]
        slopes.append(
            float(np.interp(math.log(middle), np.log(p_kpa), kappa)) if inside else math.nan
        )
    return slopes


def cell_and_seed(folder: Path) -> tuple[str, int]:
    """(cell, seed) of a run folder named ``<cell>_s<seed>``; ValueError for another name."""
    named = re.fullmatch(r"(.+)_s(\d+)", folder.name)
    if named is None:
        raise ValueError(f"{folder}: not a <cell>_s<seed> run folder")
    return named.group(1), int(named.group(2))


def run_row(folder: Path, elastic: bool = False) -> dict:
    """The λ profile of one run folder (``<cell>_s<seed>``), with the arrays for the figure;
    with ``elastic``, the segments' κ too (:func:`segment_elastic_slopes`)."""
    cell, seed = cell_and_seed(folder)
    probes = run_probes(folder)
    p, v, scale = isotropic_path_kpa(folder, probes)
    row: dict = {"cell": cell, "seed": seed, "scale": scale}
    row["p_A_kpa"], row["v_A"] = float(p[0]), float(v[0])
    for (lo, hi), slope in zip(_segments(), segment_slopes(p, v), strict=True):
        row[f"seg_{lo:g}_{hi:g}"] = slope
    for lo in WINDOW_STARTS_KPA:
        row[f"fit_{lo:g}_200"] = windowed_compressibility(p, v, (lo, 200.0)).slope
    if elastic:
        kappas = segment_elastic_slopes(*isotropic_bulk_compliance(probes, scale))
        for (lo, hi), kappa in zip(_segments(), kappas, strict=True):
            row[f"kappa_{lo:g}_{hi:g}"] = kappa
    row["_p"], row["_v"] = p, v
    return row


def _segments() -> list[tuple[float, float]]:
    return list(zip(EDGES_KPA[:-1], EDGES_KPA[1:], strict=True))


def _columns(elastic: bool = False) -> list[tuple[str, str]]:
    cols = [("p_A_kpa", "p_A (kPa)"), ("v_A", "v_A")]
    cols += [(f"seg_{lo:g}_{hi:g}", f"λ {lo:g}–{hi:g}") for lo, hi in _segments()]
    cols += [(f"fit_{lo:g}_200", f"λ* fit {lo:g}–200") for lo in WINDOW_STARTS_KPA]
    if elastic:
        cols += [(f"kappa_{lo:g}_{hi:g}", f"κ = p/K {lo:g}–{hi:g}") for lo, hi in _segments()]
    return cols


def _elastic(rows: list[dict]) -> bool:
    return any(key.startswith("kappa_") for row in rows for key in row)


def _cell_rows(rows: list[dict], cols: list[tuple[str, str]]) -> list[dict]:
    cells: dict[str, list[dict]] = {}
    for row in rows:
        cells.setdefault(row["cell"], []).append(row)
    out = []
    for cell, members in cells.items():
        entry: dict = {"cell": cell, "seeds": ",".join(str(r["seed"]) for r in members)}
        for key, _ in cols:
            entry[key] = mean_interval([r[key] for r in members])
        out.append(entry)
    return out


def _fmt(mean: float, half: float, n: int) -> str:
    if n == 0 or not math.isfinite(mean):
        return "—"
    return f"{mean:.3g}" if not math.isfinite(half) else f"{mean:.3g} ± {half:.2g}"


def markdown(rows: list[dict], cols: list[tuple[str, str]] | None = None) -> str:
    """The per-cell table (mean ± 95 %) and the per-run table over ``cols`` ((key, label);
    default: this script's columns)."""
    cols = _columns(_elastic(rows)) if cols is None else cols
    lines = ["| cell (seeds) | " + " | ".join(label for _, label in cols) + " |"]
    lines.append("|---" * (len(cols) + 1) + "|")
    for entry in _cell_rows(rows, cols):
        cells = [_fmt(*entry[key]) for key, _ in cols]
        lines.append(f"| {entry['cell']} ({entry['seeds']}) | " + " | ".join(cells) + " |")
    lines += ["", "| run | " + " | ".join(label for _, label in cols) + " |"]
    lines.append("|---" * (len(cols) + 1) + "|")
    for row in rows:
        cells = [f"{row[key]:.3g}" if math.isfinite(row[key]) else "—" for key, _ in cols]
        lines.append(f"| {row['cell']}_s{row['seed']} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def figure(rows: list[dict], path: Path) -> None:
    """Local −d ln v/d ln p against p (kPa) for every run, one colour per cell."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    colours: dict[str, str] = {}
    for row in rows:
        label = row["cell"] if row["cell"] not in colours else None
        colour = colours.setdefault(row["cell"], f"C{len(colours)}")
        p_mid, local = local_compressibility(row["_p"], row["_v"])
        ax.plot(p_mid, local, "o-", color=colour, alpha=0.8, ms=3, label=label)
    ax.axhline(STUDY_LAMBDA, color="k", ls="--", lw=1, label="the study (λ* = 0.25)")
    ax.axvspan(1.0, 200.0, color="0.92", zorder=0)
    ax.set_xscale("log")
    ax.set_xlabel("p (kPa, the run's measured stress scale)")
    ax.set_ylabel("local λ = −d ln v / d ln p")
    ax.set_ylim(bottom=0.0)
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="finished run folders <cell>_s<seed>")
    parser.add_argument("--out", type=Path, default=Path("local_compressibility"))
    parser.add_argument(
        "--elastic", action="store_true", help="add each segment's κ = p/K from the probes"
    )
    args = parser.parse_args(argv)
    rows = [run_row(folder, args.elastic) for folder in args.runs]
    write_outputs(rows, args.out, _columns(args.elastic), figure)


def main_over_runs(
    doc: str,
    default_out: str,
    run_row: Callable[[Path], dict],
    cols: list[tuple[str, str]],
    draw: Callable[[list[dict], Path], None],
    argv: list[str] | None = None,
) -> None:
    """The command line of a script that reads finished run folders ``<cell>_s<seed>`` into one
    row each (``run_row``) and writes them (:func:`write_outputs` over ``cols``, the figure
    ``draw``) to ``--out`` (default ``default_out``); ``doc``: the script's docstring."""
    parser = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="finished run folders <cell>_s<seed>")
    parser.add_argument("--out", type=Path, default=Path(default_out))
    args = parser.parse_args(argv)
    write_outputs([run_row(folder) for folder in args.runs], args.out, cols, draw)


def write_outputs(
    rows: list[dict],
    out: Path,
    cols: list[tuple[str, str]],
    draw: Callable[[list[dict], Path], None],
) -> None:
    """``<out>.md`` (:func:`markdown` over ``cols``), ``<out>.csv`` (per run: cell, seed, scale
    and ``cols``) and ``<out>.png`` (``draw(rows, path)``); prints the tables."""
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".md").write_text(markdown(rows, cols))
    keys = ["cell", "seed", "scale"] + [key for key, _ in cols]
    with out.with_suffix(".csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=keys, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    draw(rows, out.with_suffix(".png"))
    print(markdown(rows, cols))


if __name__ == "__main__":
    main()
