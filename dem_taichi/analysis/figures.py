"""Figures of DEM virtual experiments, like the study's Figures 1 and 2 (matplotlib, no Taichi).

- :func:`draw_rods` — a periodic cell with its rods drawn as chains of discs, edge discs coloured
  apart from inner discs (their charges differ in the acidic pattern);
- :func:`figure_paths` — stress paths in the p–q plane, one line per stage, with the rod
  configurations at the labelled states (A, B, C, …) drawn beside them (the study's Figure 1);
- :func:`figure_states` — specific volume against ln p, fabric deviator against p, and the
  constrained moduli E_oed,v and E_oed,h against p from both probing methods (the study's Figure 2).

All inputs are xarray Datasets with the variable names of :mod:`dem_taichi.io.schema`; stresses in
DEM units (force/length), compression positive.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402
from matplotlib.collections import PatchCollection  # noqa: E402
from matplotlib.patches import Circle, Rectangle  # noqa: E402

from dem_taichi.physics.forcelaw import disc_positions  # noqa: E402

EDGE_COLOUR = "#c0392b"
INNER_COLOUR = "#2c3e50"


def stage_labels(history: xr.Dataset) -> np.ndarray:
    """Stage name of every record, decoded from the ``stage`` flag attributes (or as strings)."""
    stage = history["stage"].values
    meanings = history["stage"].attrs.get("flag_meanings")
    values = history["stage"].attrs.get("flag_values")
    if meanings is None or values is None:
        return stage.astype(str)
    lookup = dict(zip(np.atleast_1d(values).tolist(), str(meanings).split(), strict=True))
    return np.array([lookup.get(int(s), str(s)) for s in stage])


def _scalar(conf: xr.Dataset, name: str) -> float:
    """A scalar of a configuration: a variable of that name, else a global attribute
    (``write_configuration`` stores p, q and the state label as attributes)."""
    if name in conf.variables:
        return float(conf[name])
    return float(conf.attrs[name])


def draw_rods(
    ax: plt.Axes,
    rod_position: np.ndarray,
    rod_angle: np.ndarray,
    cell_lengths: np.ndarray,
    n_spheres: int,
    spacing: float,
    diameter: float,
) -> None:
    """Draw the periodic cell and every rod as its chain of discs, wrapped into the cell."""
    lx, ly = (float(x) for x in cell_lengths)
    centres = disc_positions(rod_position, rod_angle, n_spheres, spacing)
    centres = np.mod(centres, [lx, ly])
    is_edge = np.zeros(n_spheres, dtype=bool)
    is_edge[[0, -1]] = True
    colours = np.tile(np.where(is_edge, EDGE_COLOUR, INNER_COLOUR), len(rod_angle))
    patches = [Circle((x, y), 0.5 * diameter) for x, y in centres]
    ax.add_collection(PatchCollection(patches, facecolors=colours, edgecolors="none"))
    ax.add_patch(Rectangle((0, 0), lx, ly, fill=False, lw=0.8, color="k"))
    ax.set_xlim(-0.5 * diameter, lx + 0.5 * diameter)
    ax.set_ylim(-0.5 * diameter, ly + 0.5 * diameter)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])


def figure_paths(
    history: xr.Dataset,
    configurations: Mapping[str, xr.Dataset],
    path: Path,
    geometry: Mapping[str, float],
) -> Path:
    """Stress paths p–q by stage, with rod configurations at labelled states (study's Figure 1).

    ``configurations`` maps a state label (``"A"``, ``"B"``, …) to a configuration Dataset with
    ``rod_position`` (rod, xy), ``rod_angle`` (rod), ``cell_lengths`` (xy), ``mean_stress`` and
    ``deviatoric_stress`` scalars (variables or global attributes). ``geometry`` gives
    ``n_spheres``, ``spacing``, ``diameter``.
    """
    labels = list(configurations)
    ncols = max(len(labels), 1)
    fig = plt.figure(figsize=(4.0 * ncols, 7.5), layout="constrained")
    grid = fig.add_gridspec(2, ncols, height_ratios=[1.0, 1.1])
    ax = fig.add_subplot(grid[0, :])
    stages = stage_labels(history)
    p = history["mean_stress"].values
    q = history["deviatoric_stress"].values
    for name in dict.fromkeys(stages):
        if name in ("gas", "probe", "relax"):
            continue
        mask = stages == name
        ax.plot(p[mask], q[mask], ".-", ms=2, lw=1, label=name)
    for label, conf in configurations.items():
        pa, qa = _scalar(conf, "mean_stress"), _scalar(conf, "deviatoric_stress")
        ax.plot(pa, qa, "ko", ms=5)
        ax.annotate(label, (pa, qa), textcoords="offset points", xytext=(5, 5), fontsize=11)
    ax.set_xlabel("mean stress p = (σxx+σyy)/2 (DEM units)")
    ax.set_ylabel("deviatoric stress q = σyy−σxx (DEM units)")
    ax.axhline(0.0, color="0.7", lw=0.5)
    ax.legend(fontsize=8)
    for col, (label, conf) in enumerate(configurations.items()):
        sub = fig.add_subplot(grid[1, col])
        draw_rods(
            sub,
            conf["rod_position"].values,
            conf["rod_angle"].values,
            conf["cell_lengths"].values,
            int(geometry["n_spheres"]),
            float(geometry["spacing"]),
            float(geometry["diameter"]),
        )
        sub.set_title(f"state {label}: p = {_scalar(conf, 'mean_stress'):.3g}")
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def figure_states(history: xr.Dataset, probes: xr.Dataset | None, path: Path) -> Path:
    """v–ln p, fabric deviator–p and E_oed,v, E_oed,h–p by path (the study's Figure 2)."""
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5), layout="constrained")
    stages = stage_labels(history)
    p = history["mean_stress"].values
    for name in dict.fromkeys(stages):
        if name in ("gas", "probe", "relax"):
            continue
        mask = (stages == name) & (p > 0)
        if not mask.any():
            continue
        axes[0].semilogx(p[mask], history["specific_volume"].values[mask], lw=1, label=name)
        axes[1].semilogx(p[mask], history["fabric_deviator"].values[mask], lw=1, label=name)
    axes[0].set_xlabel("p (DEM units)")
    axes[0].set_ylabel("specific volume v")
    axes[1].set_xlabel("p (DEM units)")
    axes[1].set_ylabel("fabric deviator β_yy − β_xx")
    axes[1].axhline(0.0, color="0.7", lw=0.5)
    axes[0].legend(fontsize=8)
    ax = axes[2]
    if probes is not None and probes.sizes.get("probe", 0) > 0:
        pp = probes["mean_stress"].values
        for name, marker in (("e_oed_v", "o"), ("e_oed_h", "s")):
            for method, fill in (("linear", "full"), ("dynamic", "none")):
                var = f"{name}_{method}"
                if var in probes and np.any(np.isfinite(probes[var].values)):
                    ax.loglog(pp, probes[var].values, marker, fillstyle=fill, ls="", label=var)
        for i, label in enumerate(probes["state_label"].values):
            ax.annotate(str(label), (pp[i], probes["e_oed_v_linear"].values[i]), fontsize=7)
        ax.legend(fontsize=8)
    else:
        ax.text(0.5, 0.5, "no probes", ha="center", transform=ax.transAxes)
    ax.set_xlabel("p (DEM units)")
    ax.set_ylabel("constrained modulus (DEM units)")
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path
