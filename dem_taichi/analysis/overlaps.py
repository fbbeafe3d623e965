"""The largest contact overlap of a saved configuration, as a fraction of the disc diameter.

A soft-contact DEM is quasi-static and rigid-grained only while the overlaps stay small against
the grain: the study's-clay issue asks for a maximum overlap below 1 % of d at its states. The
overlap of two discs of different rods is δ = d − |x_i − x_j| (minimum image in the periodic
cell) when positive; discs of one rod are excluded (with spacing < d they overlap by
construction, the lens of the rod's outline). Disc centres of a rigid rod: X_r + (s − (n_s −
1)/2)·spacing·a_r (:func:`dem_taichi.physics.forcelaw.disc_positions`).

A bonded rod's saved configuration (``configuration_<label>.nc``) is its fitted axis, not its
discs, so its overlaps are taken from the run's state checkpoints (``state_<label>.npz``, and
``path_*.npz`` where the run saved its path states), whose bodies are the discs themselves,
rod-major (disc s of rod r is body r·n_s + s).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from dem_taichi.physics.forcelaw import disc_positions

__all__ = [
    "disc_overlaps",
    "disc_max_overlap",
    "max_overlap",
    "configuration_max_overlap",
    "state_max_overlap",
    "run_max_overlap",
]

_NAN = float("nan")


def max_overlap(
    rod_position: np.ndarray,
    rod_angle: np.ndarray,
    cell_lengths: np.ndarray,
    n_spheres: int,
    spacing: float,
    diameter: float,
) -> float:
    """Largest δ/d over pairs of discs of different rods (0 when no pair touches).

    ``rod_position`` (N, 2) and ``rod_angle`` (N,) the rigid rods' centroids and axis angles,
    ``cell_lengths`` (L_x, L_y) of the periodic rectangular cell, lengths in the DEM unit.
    """
    centres = disc_positions(rod_position, rod_angle, n_spheres, spacing)
    return disc_max_overlap(centres, n_spheres, cell_lengths, diameter)


def disc_overlaps(
    centres: np.ndarray, n_spheres: int, cell_lengths: np.ndarray, diameter: float
) -> np.ndarray:
    """δ/d of every touching pair of discs of different rods (empty when none touches).

    ``centres`` (M, 2) disc centres, rod-major (disc s of rod r at row r·n_s + s; pairs within
    one rod are excluded), wrapped here into the periodic cell ``cell_lengths``. The whole
    distribution, not only its maximum: the largest overlap of a packing is an extreme value
    that moves by tens of per cent between two runs that should not differ
    (``benchmarks/results/bonded_time_step.md``), its mean and upper percentiles much less.
    """
    lengths = np.asarray(cell_lengths, dtype=float)
    rods = np.arange(len(centres)) // n_spheres
    wrapped = np.mod(np.asarray(centres, dtype=float), lengths)
    wrapped = np.where(wrapped >= lengths, wrapped - lengths, wrapped)  # mod's rounding to L
    pairs = cKDTree(wrapped, boxsize=lengths).query_pairs(diameter, output_type="ndarray")
    if pairs.size == 0:
        return np.zeros(0)
    pairs = pairs[rods[pairs[:, 0]] != rods[pairs[:, 1]]]
    if pairs.size == 0:
        return np.zeros(0)
    gap = wrapped[pairs[:, 0]] - wrapped[pairs[:, 1]]
    gap -= lengths * np.round(gap / lengths)  # minimum image
    distance = np.sqrt((gap**2).sum(axis=1))
    overlap = (diameter - distance) / diameter
    return overlap[overlap > 0.0]


def disc_max_overlap(
    centres: np.ndarray, n_spheres: int, cell_lengths: np.ndarray, diameter: float
) -> float:
    """Largest δ/d over pairs of discs of different rods (0 when no pair touches):
    the maximum of :func:`disc_overlaps`."""
    overlaps = disc_overlaps(centres, n_spheres, cell_lengths, diameter)
    return float(overlaps.max()) if overlaps.size else 0.0


def configuration_max_overlap(path: str | Path) -> float:
    """:func:`max_overlap` of a ``configuration_<label>.nc`` file; NaN for bonded rods (the file
    holds their fitted axes, not their discs)."""
    from dem_taichi.io import open_configuration

    with open_configuration(path) as conf:
        if str(conf.attrs.get("rod_model", "rigid")) != "rigid":
            return _NAN
        return max_overlap(
            conf["rod_position"].values,
            conf["rod_angle"].values,
            conf["cell_lengths"].values,
            int(conf.attrs["n_spheres"]),
            float(conf.attrs["spacing"]),
            float(conf.attrs["diameter"]),
        )


def state_max_overlap(path: str | Path) -> float:
    """:func:`max_overlap` of a state checkpoint (``state_<label>.npz`` or ``path_*.npz`` of a
    protocol run, :meth:`dem_taichi.engine.simulation.Simulation.save_checkpoint`), rigid or
    bonded rods: the bodies' centroids are ``reduced_position`` × (L_x, L_y) of ``cell``."""
    from dem_taichi.io.checkpoint import load_checkpoint
    from dem_taichi.scene.config import scene_from_toml

    arrays, meta = load_checkpoint(path)
    particles = scene_from_toml(meta["scene_toml"]).particles
    lengths = np.asarray(arrays["cell"][:2], dtype=float)
    bodies = np.asarray(arrays["reduced_position"], dtype=float) * lengths
    n_spheres, diameter = int(particles.n_spheres), float(particles.diameter)
    if particles.rod_model == "rigid":
        return max_overlap(
            bodies, arrays["angle"], lengths, n_spheres, float(particles.spacing), diameter
        )
    return disc_max_overlap(bodies, n_spheres, lengths, diameter)


def run_max_overlap(folder: str | Path) -> float:
    """The largest overlap over a protocol run's labelled states: of its ``configuration_*.nc``
    (rigid rods), or, where those hold bonded rods, of its ``state_*.npz`` checkpoints; NaN when
    it has neither."""
    folder = Path(folder)
    values = [configuration_max_overlap(p) for p in sorted(folder.glob("configuration_*.nc"))]
    finite = [v for v in values if np.isfinite(v)]
    if not finite:
        finite = [state_max_overlap(p) for p in sorted(folder.glob("state_*.npz"))]
    return max(finite) if finite else _NAN
