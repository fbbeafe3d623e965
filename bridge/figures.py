"""Figures like the study's: DEM points against TIV lines (matplotlib, Agg backend).

Panels (each also a file of its own):

* ``stress_paths``: p–q of the three paths;
* ``compressibility``: v against p (log axis) on the isotropic, K0 and unloading paths;
* ``fabric``: the model's β (= −F (β_yy − β_xx) for the DEM) against p;
* ``moduli``: E_oed,v and E_oed,h against p (DEM probes; TIV model runs as lines, the TIV elastic
  law at the measured probe states as open markers);
* ``anisotropy``: E_oed,h/E_oed,v against p along K0 (the back-prediction) and the others.

Legends say for every TIV curve whether it was fitted or is predicted out of sample.
:func:`path_colour` and :func:`path_name` give each path its colour and legend name here and
in :mod:`bridge.study_figure_panels`.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import xarray as xr  # noqa: E402

PANELS = ("stress_paths", "compressibility", "fabric", "moduli", "anisotropy")
COLOURS = {"isotropic": "tab:blue", "k0": "tab:red", "unloading": "tab:green"}
NAMES = {"isotropic": "isotropic A→B", "k0": "K0 A→C", "unloading": "unloading C→B"}


_RADIAL_COLOURS = ("tab:purple", "tab:brown", "tab:olive", "tab:cyan", "tab:pink", "tab:gray")


def path_colour(path: str) -> str:
    """The matplotlib colour of a path: :data:`COLOURS` for ``"isotropic"``, ``"k0"`` and
    ``"unloading"``; the radial paths ``radial_k`` take purple, brown, olive, cyan, pink, grey
    in turn (k = 1 the first), so every figure of the bridge draws a path in one colour."""
    if path.startswith("radial_"):
        return _RADIAL_COLOURS[(int(path[7:]) - 1) % len(_RADIAL_COLOURS)]
    return COLOURS[path]


def path_name(path: str) -> str:
    """The legend's name of a path: :data:`NAMES` (``"K0 A→C"``…), ``radial_k`` as
    ``"radial path k"``."""
    return NAMES.get(path, path.replace("radial_", "radial path "))


def _tag(ds: xr.Dataset, name: str) -> str:
    role = ds[name].attrs.get("role", "out_of_sample")
    return {"fitted": "fitted", "input": "driven by the DEM path"}.get(role, "out of sample")


def _dem_points_and_tiv_lines(ax, series, runs, x: str, y: str, role_of: str = "") -> None:
    """Each path's DEM ``y`` against ``x`` as open circles and, where the model ran it, the TIV
    run's as a line of the same colour, its legend saying whether the run's ``role_of`` (default
    ``y``) was fitted."""
    for path, ds in series.items():
        c = path_colour(path)
        ax.plot(ds[x], ds[y], "o", color=c, ms=4, mfc="none", label=f"DEM {path_name(path)}")
        if path in runs:
            r = runs[path]
            ax.plot(r[x], r[y], "-", color=c, label=f"TIV ({_tag(r, role_of or y)})")


def _stress_paths(ax, series, runs, probes, model_probes):
    # q's legend gives the role of the run's stress ratio η = q/p
    _dem_points_and_tiv_lines(
        ax, series, runs, "mean_stress", "deviatoric_stress", role_of="stress_ratio"
    )
    ax.set_xlabel("p (kPa)")
    ax.set_ylabel("q (kPa)")
    ax.set_title("stress paths")


def _compressibility(ax, series, runs, probes, model_probes):
    _dem_points_and_tiv_lines(ax, series, runs, "mean_stress", "specific_volume")
    ax.set_xscale("log")
    ax.set_xlabel("p (kPa)")
    ax.set_ylabel("v")
    ax.set_title("compressibility")


def _fabric(ax, series, runs, probes, model_probes):
    _dem_points_and_tiv_lines(ax, series, runs, "mean_stress", "fabric")
    ax.axhline(0.0, color="0.7", lw=0.5)
    ax.set_xlabel("p (kPa)")
    ax.set_ylabel("β = −F (β_yy − β_xx)")
    ax.set_title("fabric")


def _moduli(ax, series, runs, probes, model_probes):
    for path, ds in probes.items():
        c = path_colour(path)
        ax.plot(ds["mean_stress"], ds["e_oed_v"], "s", color=c, ms=4, label=f"DEM E_oed,v {path}")
        ax.plot(ds["mean_stress"], ds["e_oed_h"], "^", color=c, ms=4, label=f"DEM E_oed,h {path}")
        if path in model_probes:
            m = model_probes[path]
            ax.plot(
                m["mean_stress"],
                m["e_oed_v"],
                "s",
                color=c,
                ms=7,
                mfc="none",
                label=f"TIV at DEM states E_v ({_tag(m, 'e_oed_v')})",
            )
            ax.plot(
                m["mean_stress"],
                m["e_oed_h"],
                "^",
                color=c,
                ms=7,
                mfc="none",
                label=f"TIV at DEM states E_h ({_tag(m, 'e_oed_h')})",
            )
    for path, r in runs.items():
        c = path_colour(path)
        ax.plot(
            r["mean_stress"],
            r["e_oed_v"],
            "-",
            color=c,
            lw=1,
            label=f"TIV run E_v {path} ({_tag(r, 'e_oed_v')})",
        )
        ax.plot(
            r["mean_stress"],
            r["e_oed_h"],
            "--",
            color=c,
            lw=1,
            label=f"TIV run E_h {path} ({_tag(r, 'e_oed_h')})",
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("p (kPa)")
    ax.set_ylabel("E_oed (kPa)")
    ax.set_title("constrained moduli")


def _anisotropy(ax, series, runs, probes, model_probes):
    for path, ds in probes.items():
        c = path_colour(path)
        ax.plot(
            ds["mean_stress"],
            ds["e_oed_h"] / ds["e_oed_v"],
            "o",
            color=c,
            ms=4,
            label=f"DEM {path_name(path)}",
        )
        if path in model_probes:
            m = model_probes[path]
            ax.plot(
                m["mean_stress"],
                m["stiffness_ratio"],
                "x",
                color=c,
                ms=7,
                label=f"TIV at DEM states ({_tag(m, 'stiffness_ratio')})",
            )
    for path, r in runs.items():
        ax.plot(
            r["mean_stress"],
            r["stiffness_ratio"],
            "-",
            color=path_colour(path),
            label=f"TIV run {path} ({_tag(r, 'stiffness_ratio')})",
        )
    ax.axhline(1.0, color="0.7", lw=0.5)
    ax.set_xscale("log")
    ax.set_xlabel("p (kPa)")
    ax.set_ylabel("E_oed,h / E_oed,v")
    ax.set_title("stiffness anisotropy (K0: back-prediction)")


_DRAW = {
    "stress_paths": _stress_paths,
    "compressibility": _compressibility,
    "fabric": _fabric,
    "moduli": _moduli,
    "anisotropy": _anisotropy,
}


def write_figures(
    series: Mapping[str, xr.Dataset],
    probes: Mapping[str, xr.Dataset],
    runs: Mapping[str, xr.Dataset],
    model_probes: Mapping[str, xr.Dataset],
    out_dir: str | Path,
    prefix: str = "bridge_",
) -> dict[str, Path]:
    """Write each panel and an overview (``<prefix>overview.png``); returns name → path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, Path] = {}
    args = (series, runs, probes, model_probes)
    for name in PANELS:
        fig, ax = plt.subplots(figsize=(6.0, 4.5))
        _DRAW[name](ax, *args)
        ax.legend(fontsize=6, loc="best")
        fig.tight_layout()
        path = out / f"{prefix}{name}.png"
        fig.savefig(path, dpi=120)
        plt.close(fig)
        files[name] = path
    fig, axes = plt.subplots(2, 3, figsize=(16, 9.5))
    for ax, name in zip(axes.ravel(), PANELS, strict=False):
        _DRAW[name](ax, *args)
        ax.legend(fontsize=5, loc="best")
    axes.ravel()[-1].axis("off")
    fig.suptitle("DEM (points) vs calibrated TIV model (lines / open markers)")
    fig.tight_layout()
    path = out / f"{prefix}overview.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    files["overview"] = path
    return files
