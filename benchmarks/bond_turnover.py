"""Which of a gel's bonds at state B were already there at state A (issue 19)?

Usage::

    python benchmarks/bond_turnover.py RUN [RUN ...] [--out benchmarks/results/bond_turnover]

Each RUN is a finished protocol run folder named ``<cell>_s<seed>`` (runs of one cell are
replicas) with ``state_A.npz`` and ``state_B.npz``: the engine's states, rigid or bonded rods
(bonded: the discs where they are, the rods bent or not), and the scene (the rods, the charges
and the range g_max = F_max/k_a). A *bond* is a pair of discs
of two rods with opposite charges (an attractive pair of the long-range law) within the range:
surface gap g <= g_max. Two rods are *bonded* if at least one pair of their discs is. From A to B
the script counts, per run:

- bonds and bonded rod pairs per rod at A and at B (each counted at both its rods);
- the share of A's bonded rod pairs still bonded at B, and of its disc bonds;
- the share of B's bonded rod pairs that were bonded at A (the rest formed on the way).

A gel that densifies by breaking its bonds keeps few of A's; one that keeps them and adds new
ones hardens with the bonds it forms on the way, which ``[long_range] attraction_pairs =
"bonded_at_A"`` switches off. Per cell: mean ± 95 % (Student t). Writes ``<out>.md`` and
``<out>.csv`` (per run) and ``<out>.png``.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from local_compressibility import cell_and_seed, main_over_runs  # noqa: E402

COLUMNS = (
    ("v_A", "v_A"),
    ("v_B", "v_B"),
    ("bonds_A", "bonds per rod, A"),
    ("bonds_B", "bonds per rod, B"),
    ("rod_pairs_A", "bonded rods per rod, A"),
    ("rod_pairs_B", "bonded rods per rod, B"),
    ("kept", "A's bonded rod pairs kept at B"),
    ("kept_bonds", "A's disc bonds kept at B"),
    ("old_at_B", "B's bonded rod pairs bonded at A"),
)


def bonds(
    discs: np.ndarray,
    lengths: np.ndarray,
    charge: np.ndarray,
    diameter: float,
    g_max: float,
) -> np.ndarray:
    """The bonds of a configuration of rods: (P, 2) disc indices (i < j, disc s of rod r is
    r n_s + s, ``discs`` (M, 2) their centres) of the pairs of discs of two different rods whose
    charges (``charge``, per place in a rod) have a negative product and whose surface gap is at
    most ``g_max``, in the periodic cell ``lengths``."""
    from scipy.spatial import cKDTree

    n_s = len(charge)
    lengths = np.asarray(lengths, dtype=float)
    x = np.mod(np.asarray(discs, dtype=float), lengths)
    x[x >= lengths] = 0.0  # mod can round up to the length itself
    pairs = cKDTree(x, boxsize=lengths).query_pairs(diameter + g_max, output_type="ndarray")
    if len(pairs) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    i, j = np.minimum(pairs[:, 0], pairs[:, 1]), np.maximum(pairs[:, 0], pairs[:, 1])
    attract = (i // n_s != j // n_s) & (charge[i % n_s] * charge[j % n_s] < 0)
    i, j = i[attract], j[attract]
    r = x[i] - x[j]
    r -= lengths * np.round(r / lengths)
    near = np.hypot(r[:, 0], r[:, 1]) - diameter <= g_max
    return np.stack([i[near], j[near]], axis=1).astype(np.int64)


def disc_centres(state: dict[str, np.ndarray], n_spheres: int, spacing: float, bonded: bool):
    """(disc centres (M, 2), cell lengths (2,)) of a saved engine state
    (:mod:`dem_taichi.engine.state`): rigid rods' discs placed along each rod's axis; bonded
    rods' bodies are their discs (rod-major), their centres as they are, bent or not."""
    from dem_taichi.kernels import layout
    from dem_taichi.physics.forcelaw import disc_positions

    lengths = np.array([state["cell"][layout.C_LX], state["cell"][layout.C_LY]], dtype=float)
    bodies = np.asarray(state["reduced_position"], dtype=float) * lengths
    if bonded:
        return bodies, lengths
    discs = disc_positions(bodies, np.asarray(state["angle"], dtype=float), n_spheres, spacing)
    return discs.reshape(-1, 2), lengths


def rod_pairs(disc_pairs: np.ndarray, n_spheres: int) -> np.ndarray:
    """The rod pairs (a < b, once each) that the disc pairs join, (P, 2)."""
    rods = np.sort(disc_pairs // n_spheres, axis=1)
    return np.unique(rods, axis=0).reshape(-1, 2)


def _keys(pairs: np.ndarray, n: int) -> np.ndarray:
    return pairs[:, 0] * n + pairs[:, 1]


def turnover(at_a: np.ndarray, at_b: np.ndarray, n_rods: int, n_spheres: int) -> dict:
    """The counts of the module docstring from the bonds at A and at B (:func:`bonds`)."""
    n_discs = n_rods * n_spheres
    rods_a, rods_b = rod_pairs(at_a, n_spheres), rod_pairs(at_b, n_spheres)
    both_rods = np.isin(_keys(rods_a, n_rods), _keys(rods_b, n_rods)).sum()
    both_bonds = np.isin(_keys(at_a, n_discs), _keys(at_b, n_discs)).sum()

    def share(part, whole):
        return part / whole if whole else math.nan

    return {
        "bonds_A": 2 * len(at_a) / n_rods,
        "bonds_B": 2 * len(at_b) / n_rods,
        "rod_pairs_A": 2 * len(rods_a) / n_rods,
        "rod_pairs_B": 2 * len(rods_b) / n_rods,
        "kept": share(both_rods, len(rods_a)),
        "kept_bonds": share(both_bonds, len(at_a)),
        "old_at_B": share(both_rods, len(rods_b)),
    }


def run_row(folder: Path) -> dict:
    """The bond turnover from A to B of one run folder (``<cell>_s<seed>``), read from its
    ``state_A.npz`` and ``state_B.npz`` (rigid or bonded rods)."""
    from dem_taichi.io.checkpoint import load_checkpoint
    from dem_taichi.scene.config import scene_from_toml
    from dem_taichi.scene.geometry import species_parameters
    from dem_taichi.scene.protocol_sections import protocol_settings

    cell, seed = cell_and_seed(folder)
    states = {label: load_checkpoint(folder / f"state_{label}.npz") for label in ("A", "B")}
    scene = scene_from_toml(states["A"][1]["scene_toml"])
    charge, f_max, k_a = species_parameters(scene)
    ranges = {f / k for f, k in zip(f_max, k_a, strict=True) if k > 0}
    if len(ranges) > 1:
        raise SystemExit(f"{folder}: the species have different ranges {sorted(ranges)}")
    g_max = ranges.pop() if ranges else 0.0
    p = scene.particles
    disc_area = p.n_rods * p.n_spheres * math.pi * p.diameter**2 / 4
    found, volume = {}, {}
    for label, (state, _) in states.items():
        discs, lengths = disc_centres(state, p.n_spheres, p.spacing, scene.bonded)
        found[label] = bonds(discs, lengths, charge, p.diameter, g_max)
        volume[label] = float(lengths[0] * lengths[1] / disc_area)
    row = {"cell": cell, "seed": seed, "scale": protocol_settings(scene).stress_scale_kpa}
    row |= {"v_A": volume["A"], "v_B": volume["B"]}
    return row | turnover(found["A"], found["B"], p.n_rods, p.n_spheres)


def figure(rows: list[dict], path: Path) -> None:
    """Per run: the share of A's bonded rod pairs kept at B, and of B's that were bonded at A,
    against the fall of v from A to B."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.4), constrained_layout=True)
    fall = [r["v_A"] / r["v_B"] for r in rows]
    ax.plot(fall, [r["kept"] for r in rows], "o", label="A's bonded rod pairs kept at B")
    ax.plot(fall, [r["old_at_B"] for r in rows], "s", label="B's bonded rod pairs bonded at A")
    ax.set_xlabel("v_A / v_B (the fall of v from A to B)")
    ax.set_ylabel("share")
    ax.set_ylim(0.0, 1.05)
    ax.legend(fontsize=8, loc="lower left")
    ax.set_title("the gel's bonds from A to B, one point per run", fontsize=9)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    main_over_runs(__doc__, "bond_turnover", run_row, list(COLUMNS), figure, argv)


if __name__ == "__main__":
    main()
