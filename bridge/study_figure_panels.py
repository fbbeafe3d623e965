"""The drawing and the table of the study's Figure 2 over replicas (:mod:`bridge.study_figure`).

:func:`figure2`: panels a–d, our replica means as markers with error bars (the half-width of
the 95 % interval of the mean, :mod:`bridge.replica_bands`) and the study's TIV curves as lines,
one colour per path as in :mod:`bridge.figures`; :func:`figure2_markdown`: at the labelled
states A, B, C, B′ (and the radial ends R<k>_end) our mean ± 95 % and the study model's value of
p (kPa), v, β, E_oed,v/p and E_h/E_v. matplotlib with the Agg backend, as :mod:`bridge.figures`.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from .figures import path_colour, path_name  # noqa: E402
from .replica_bands import path_members  # noqa: E402

__all__ = ["figure2", "figure2_markdown", "STUDY"]

#: The legend's name of the study's curves.
STUDY = "TIV, Table 1 (the study)"


def _at(bands: xr.Dataset, label: str, name: str, prefix: str = "") -> tuple[float, float]:
    """(mean, half-width) of ``name`` at the record (or probe, ``prefix="probe_"``) labelled
    ``label``; NaN when there is none."""
    if f"{prefix}state_label" not in bands:
        return np.nan, np.nan
    where = np.flatnonzero(bands[f"{prefix}state_label"].values.astype(str) == label)
    if where.size == 0:
        return np.nan, np.nan
    i = where[-1]
    return float(bands[prefix + name].values[i]), float(bands[f"{prefix}{name}_ci95"].values[i])


def _model_at(curves: dict[str, xr.Dataset], label: str, bands: xr.Dataset) -> xr.Dataset | None:
    """The study curve's point at a labelled state: A the start of the isotropic (or K0) curve;
    B, C, B′, R<k>_end the point of their path's curve at the labelled record of ``bands``
    (the curves run along our mean paths, every interval split alike), the curve's end when it
    cannot be placed. B is not the isotropic curve's end when the path went on past B."""
    path = {"B": "isotropic", "C": "k0", "B'": "unloading"}.get(label)
    if label == "A":
        path = next((p for p in ("isotropic", "k0") if p in curves), None)
    elif label.startswith("R") and label.endswith("_end"):
        path = f"radial_{label[1:-4]}"
    if path not in curves:
        return None
    curve = curves[path]
    if label == "A":
        return curve.isel(point=0)
    members = _members(bands, "").get(path)
    record = np.flatnonzero(bands["state_label"].values.astype(str) == label)
    points = curve.sizes["point"]
    if members is None or record.size == 0 or members.size < 2 or (points - 1) % (members.size - 1):
        return curve.isel(point=-1)
    position = np.flatnonzero(members == record[-1])
    if position.size == 0:
        return curve.isel(point=-1)
    return curve.isel(point=int(position[0]) * ((points - 1) // (members.size - 1)))


def _labels(bands: xr.Dataset) -> list[str]:
    return [x for x in bands["state_label"].values.astype(str) if x]


#: (variable, prefix) of the table's columns: states for p, v, β; probes for the moduli.
COLUMNS = (
    ("mean_stress", ""),
    ("specific_volume", ""),
    ("fabric", ""),
    ("e_oed_v_over_p", "probe_"),
    ("stiffness_ratio", "probe_"),
)
HEADER = (
    "| state | p DEM (kPa) | p TIV | v DEM | v TIV | β DEM | β TIV | E_oed,v/p DEM | "
    "E_oed,v/p TIV | E_h/E_v DEM | E_h/E_v TIV |\n|---|---|---|---|---|---|---|---|---|---|---|"
)


def state_means(bands: xr.Dataset) -> dict[str, dict[str, float]]:
    """The replica means of the table's DEM columns (:data:`COLUMNS`: p in kPa, v, β,
    E_oed,v/p, E_h/E_v) at each labelled state of ``bands`` (NaN where a state has none): the
    numbers of :func:`figure2_markdown`'s DEM cells, unrounded."""
    return {
        state: {name: _at(bands, state, name, prefix)[0] for name, prefix in COLUMNS}
        for state in _labels(bands)
    }


def _model_values(point: xr.Dataset | None) -> dict[str, float]:
    """The study model's values of :data:`COLUMNS` at one point of its curve ({}: none)."""
    if point is None:
        return {}
    names = ("mean_stress", "specific_volume", "fabric", "stiffness_ratio")
    out = {name: float(point[name]) for name in names}
    out["e_oed_v_over_p"] = float(point["e_oed_v"]) / out["mean_stress"]
    return out


def _ours(bands: xr.Dataset, label: str, name: str, prefix: str) -> str:
    mean, half = _at(bands, label, name, prefix)
    return "—" if not np.isfinite(mean) else f"{mean:.4g} ± {half:.2g}"


def figure2_markdown(
    bands: xr.Dataset, curves: dict[str, xr.Dataset], k0_mode: str = "stress", label: str = STUDY
) -> str:
    """The table beside the figure: at each labelled state our mean ± 95 % and the model's
    (``label``: the study's, Table 1, by default), for p (kPa), v, β, E_oed,v/p and E_h/E_v
    (the moduli from the probes there)."""
    n, attrs = int(bands["n"]), bands.attrs
    rows = []
    for state in _labels(bands):
        model = _model_values(_model_at(curves, state, bands))
        cells = [state.replace("'", "′")]
        for name, prefix in COLUMNS:
            cells += [_ours(bands, state, name, prefix), f"{model[name]:.4g}" if model else "—"]
        rows.append("| " + " | ".join(cells) + " |")
    lines = [
        f"# Figure 2 over {n} replicas: DEM mean ± 95 % and {label}",
        "",
        f"DEM: mean ± half-width of the 95 % interval of the mean over n = {n} replicas "
        "(t_{0.975, n−1} s/√n), aligned record by record (bridge.replicas); runs: "
        f"{attrs['replica_runs']}; stress scales (kPa per DEM unit): {attrs['stress_scales_kpa']};"
        f" {attrs['convention_stress']}; {attrs['convention_fabric']}, F = "
        f"{attrs['fabric_scale']:g}; moduli: {attrs['probe_method']} probes.",
        f"TIV: {label}, not a fit ({next(iter(curves.values())).attrs['parameters']}), along "
        f"our mean stress paths (K0 and unloading: {k0_mode}) from its own normally "
        "consolidated state at our p_A (bridge.study_figure.study_curves).",
        "",
        HEADER,
        *rows,
    ]
    return "\n".join(lines) + "\n"


def _bar(half) -> np.ndarray:
    return np.where(np.isfinite(half), half, 0.0)


def _dem(ax, bands, members, prefix, y, marker) -> None:
    x = prefix + "mean_stress"
    for path, i in members.items():
        ax.errorbar(
            bands[x].values[i],
            bands[prefix + y].values[i],
            fmt=marker,
            ms=4,
            xerr=_bar(bands[x + "_ci95"].values[i]),
            color=path_colour(path),
            mfc="none",
            yerr=_bar(bands[f"{prefix}{y}_ci95"].values[i]),
            capsize=2,
            elinewidth=0.7,
        )


def _members(bands: xr.Dataset, prefix: str) -> dict[str, np.ndarray]:
    if f"{prefix}state_label" not in bands:
        return {}
    stage = "probe_stage" if prefix else "stage"
    return path_members(
        bands[stage].values,
        bands[f"{prefix}state_label"].values,
        bands[prefix + "mean_stress"].values,
    )


def figure2(bands: xr.Dataset, curves: dict[str, xr.Dataset], label: str = STUDY):
    """Figure 2 a–d (module docstring) as a matplotlib Figure; ``label`` names the curves."""
    fig, axes = plt.subplots(2, 2, figsize=(11, 9))
    (a, b), (c, d) = axes
    states, probes = _members(bands, ""), _members(bands, "probe_")
    _dem(a, bands, states, "", "specific_volume", "o")
    _dem(b, bands, states, "", "fabric", "o")
    _dem(c, bands, probes, "probe_", "e_oed_v", "s")
    _dem(c, bands, probes, "probe_", "e_oed_h", "^")
    _dem(d, bands, probes, "probe_", "stiffness_ratio", "o")
    for path, r in curves.items():
        colour, p = path_colour(path), r["mean_stress"]
        a.plot(p, r["specific_volume"], "-", color=colour)
        b.plot(p, r["fabric"], "-", color=colour)
        c.plot(p, r["e_oed_v"], "-", color=colour)
        c.plot(p, r["e_oed_h"], "--", color=colour)
        d.plot(p, r["stiffness_ratio"], "-", color=colour)
    for ax, title, ylabel in (
        (a, "(a) compressibility", "v"),
        (b, "(b) fabric", "β = −F (β_yy − β_xx)"),
        (c, "(c) constrained moduli", "E_oed (kPa)"),
        (d, "(d) stiffness anisotropy", "E_oed,h / E_oed,v"),
    ):
        ax.set_xscale("log")
        ax.set(title=title, xlabel="p (kPa)", ylabel=ylabel)
    c.set_yscale("log")
    b.axhline(0.0, color="0.7", lw=0.5)
    d.axhline(1.0, color="0.7", lw=0.5)
    c.legend(
        handles=[
            Line2D([], [], color="k", marker="s", mfc="none", label="E_oed,v (solid)"),
            Line2D([], [], color="k", ls="--", marker="^", mfc="none", label="E_oed,h (dashed)"),
        ],
        fontsize=7,
    )
    n = int(bands["n"])
    handles = [
        Line2D(
            [],
            [],
            color="k",
            marker="o",
            mfc="none",
            ls="none",
            label=f"DEM, mean ± 95 % over {n} replicas",
        ),
        Line2D([], [], color="k", label=label),
    ]
    handles += [
        Line2D([], [], color=path_colour(p), lw=3, label=path_name(p))
        for p in dict.fromkeys([*states, *curves])
    ]
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 4), fontsize=8)
    fig.suptitle("Figure 2 over replicas: DEM (markers, 95 % bars) and the TIV model (lines)")
    fig.tight_layout(rect=(0, 0.07, 1, 0.97))
    return fig
