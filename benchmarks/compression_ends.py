"""The two ends of the isotropic compression path (issue 19): v at 1 kPa against v at 100 kPa.

Usage::

    python benchmarks/compression_ends.py RUN [RUN ...] \
        [--out benchmarks/results/compression_ends]

Each RUN is a finished protocol run folder named ``<cell>_s<seed>`` (runs of one cell are
replicas), read as :mod:`benchmarks.local_compressibility` reads it: state A and the relaxed
states of A→B, on the run's measured stress scale (E_v/p = 125 at 100 kPa; the scene's where
none is measured). Whatever the definition of the specific volume, the chord slope

    λ_1–100 = ln(v(1 kPa) / v(100 kPa)) / ln 100

is the compressibility between the window's two ends; the study's λ* = 0.25 needs v to fall by
100^0.25 = 3.16 between them. So each run is a point (v at 100 kPa, v at 1 kPa): the study's
line is v_1 = 3.16 v_100; a cell is short of it either because its gel is too dense at 1 kPa or
because it stays too loose at 100 kPa. The cohesionless packing of the same rods (a run
without the attraction, cell NA of ``study_clay_floor.sh``) marks how dense 100 kPa can be.

Per run: p_A (kPa), v_A, v at 1 kPa (NaN where A is above 1 kPa) and at 100 kPa (v
interpolated in (ln p, ln v) along the path), the chord λ_1–100. Per cell: mean ± 95 % (Student
t). Writes ``<out>.md``, ``<out>.csv`` (per run) and ``<out>.png`` (the figure).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from local_compressibility import (  # noqa: E402
    cell_and_seed,
    isotropic_path_kpa,
    main_over_runs,
    run_probes,
)
from local_compressibility import markdown as runs_markdown  # noqa: E402

from dem_taichi.analysis.mapped_window import specific_volume_at  # noqa: E402

#: The window's ends (kPa).
LOW_KPA, HIGH_KPA = 1.0, 100.0
#: The study's λ* (Table 1).
STUDY_LAMBDA = 0.25

COLUMNS = (
    ("p_A_kpa", "p_A (kPa)"),
    ("v_A", "v_A"),
    ("v_1", "v at 1 kPa"),
    ("v_100", "v at 100 kPa"),
    ("chord", "λ 1–100 (chord)"),
)


def ends(p_kpa, v) -> tuple[float, float, float]:
    """(v at 1 kPa, v at 100 kPa, the chord λ between them) along the path (p_kpa, v); v at an
    end that is not on the path (below p_A, past the path's end) is NaN, and so is the chord."""
    p_kpa = np.asarray(p_kpa, dtype=float)
    on_path = (float(np.nanmin(p_kpa)), float(np.nanmax(p_kpa)))

    def at(p):
        return specific_volume_at(p_kpa, v, p) if on_path[0] <= p <= on_path[1] else math.nan

    v_low, v_high = at(LOW_KPA), at(HIGH_KPA)
    return v_low, v_high, math.log(v_low / v_high) / math.log(HIGH_KPA / LOW_KPA)


def run_row(folder: Path) -> dict:
    """The two ends of one run folder (``<cell>_s<seed>``)."""
    cell, seed = cell_and_seed(folder)
    p, v, scale = isotropic_path_kpa(folder, run_probes(folder))
    v_1, v_100, chord = ends(p, v)
    return {
        "cell": cell,
        "seed": seed,
        "scale": scale,
        "p_A_kpa": float(p[0]),
        "v_A": float(v[0]),
        "v_1": v_1,
        "v_100": v_100,
        "chord": chord,
    }


def markdown(rows: list[dict]) -> str:
    """The per-cell table (mean ± 95 %) and the per-run table over :data:`COLUMNS`."""
    return runs_markdown(rows, list(COLUMNS))


def figure(rows: list[dict], path: Path) -> None:
    """v at 1 kPa against v at 100 kPa, one colour per cell, with lines of constant chord λ
    (the study's 0.25 dashed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, ax = plt.subplots(figsize=(6.4, 4.8), constrained_layout=True)
    colours: dict[str, str] = {}
    markers = "osD^v<>ph*"
    for row in rows:
        if not (math.isfinite(row["v_1"]) and math.isfinite(row["v_100"])):
            continue
        label = row["cell"] if row["cell"] not in colours else None
        index = len(colours) if row["cell"] not in colours else list(colours).index(row["cell"])
        colour = colours.setdefault(row["cell"], f"C{index % 10}")
        marker = markers[(index // 10) % len(markers)]
        ax.plot(row["v_100"], row["v_1"], marker, color=colour, ms=5, alpha=0.85, label=label)
    x = np.linspace(1.4, 3.4, 50)
    for lam in (0.1, 0.15, 0.2, 0.25, 0.3):
        ratio = (HIGH_KPA / LOW_KPA) ** lam
        study = lam == STUDY_LAMBDA
        colour = "k" if study else "0.6"
        ax.plot(x, x * ratio, color=colour, lw=1.2 if study else 0.8, ls="--" if study else ":")
        ax.annotate(f"λ {lam:g}", (x[-1], x[-1] * ratio), fontsize=7, color=colour,
                    xytext=(2, 0), textcoords="offset points", va="center")  # fmt: skip
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(1.4, 3.9)
    ax.set_ylim(1.4, 11.0)
    ax.set_xticks([1.5, 2.0, 2.5, 3.0, 3.5])
    ax.set_yticks([1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0])
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
        axis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel("v at 100 kPa (disc area; the run's measured stress scale)")
    ax.set_ylabel("v at 1 kPa")
    ax.set_title("the window's two ends; the study's λ* = 0.25 dashed", fontsize=9)
    ax.legend(fontsize=7, ncol=2, loc="upper left")
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    main_over_runs(__doc__, "compression_ends", run_row, list(COLUMNS), figure, argv)


if __name__ == "__main__":
    main()
