"""Markdown report of a calibration and its predictions.

Sections: data and conventions; the parameter table (value ± standard error, units, stage,
starting value); fit quality per stage and series; every compared prediction with its role
(fitted or out of sample) and error; what is predicted out of sample (the back-prediction of
E_h/E_v along K0 in particular); what the data determine (profile likelihoods, when computed);
warnings; figures.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import xarray as xr

from .calibration import CalibrationResult
from .predict import summary


def _fmt(x, digits: int = 4) -> str:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return str(x)
    if not math.isfinite(x):
        return "—"
    return f"{x:.{digits}g}"


def _k0_anisotropy_lines(runs, model_probes, probes) -> list[str]:
    lines = []
    if "k0" in model_probes and "k0" in probes:
        m, d = model_probes["k0"], probes["k0"]
        parts = ("stiffness_ratio_stress_only", "stiffness_ratio_fabric_only")
        split = all(name in m for name in parts)
        header = "| p (kPa) | β (DEM) | E_h/E_v DEM | E_h/E_v TIV at DEM state |"
        lines.append(header + (" TIV, β = 0 | TIV, q = 0 |" if split else ""))
        lines.append("|---|---|---|---|" + ("---|---|" if split else ""))
        ratio = d["e_oed_h"].values / d["e_oed_v"].values
        columns = [d["mean_stress"].values, d["fabric"].values, ratio, m["stiffness_ratio"].values]
        columns += [m[name].values for name in parts] if split else []
        for p, b, *ratios in zip(*columns, strict=True):
            lines.append(f"| {_fmt(p)} | {_fmt(b, 3)} | " + " | ".join(map(_fmt, ratios)) + " |")
        if split:
            lines.append("")
            lines.append(
                "The model's ratio split by source: *β = 0*, at the DEM's stress with the fabric "
                "set to 0 (what its pressure-dependent elasticity draws from the stress alone); "
                "*q = 0*, at the DEM's fabric under the isotropic stress p."
            )
    if "k0" in runs:
        r = runs["k0"]
        k0_ratio = r["radial_stress"].values[-1] / r["axial_stress"].values[-1]
        lines.append("")
        lines.append(
            f"Model K0 run: E_h/E_v from {_fmt(r['stiffness_ratio'].values[0])} at "
            f"p = {_fmt(r['mean_stress'].values[0])} kPa to "
            f"{_fmt(r['stiffness_ratio'].values[-1])} at p = {_fmt(r['mean_stress'].values[-1])} "
            f"kPa (K0 = σ_r/σ_a = {_fmt(k0_ratio)}"
            f", β = {_fmt(r['fabric'].values[-1], 3)})."
        )
    return lines


def report_markdown(
    result: CalibrationResult,
    runs: Mapping[str, xr.Dataset],
    model_probes: Mapping[str, xr.Dataset],
    probes: Mapping[str, xr.Dataset],
    data_description: Mapping[str, object] | None = None,
    figures: Mapping[str, Path] | None = None,
    out_dir: Path | None = None,
    identifiability=None,
) -> str:
    """The report as markdown text (see the module docstring); ``identifiability`` is a
    :class:`bridge.calibration.identifiability.Identifiability` (profile table and statement)."""
    lines = ["# Calibration of the TIV model on DEM results", ""]
    if data_description:
        lines += ["## Data and conventions", ""]
        for key, value in data_description.items():
            lines.append(f"- **{key}**: {value}")
        lines.append("")
    opts = result.options
    lines += [
        "## Parameters",
        "",
        f"Model options: {opts.model_options.describe()}; passes over the stages: "
        f"{result.passes_run}; p_r fixed at {_fmt(opts.reference_pressure)} kPa.",
        "",
        "| symbol | value | std. error | units | stage | start |",
        "|---|---|---|---|---|---|",
    ]
    for row in result.parameter_table():
        lines.append(
            f"| {row['symbol']} | {_fmt(row['value'], 5)} | ± {_fmt(row['standard_error'], 3)} "
            f"| {row['units']} | {row['stage']} | {_fmt(row['initial'])} |"
        )
    lines += [
        "",
        "Standard errors: s² (JᵀJ)⁻¹ of each stage's scaled residuals at the solution, "
        "s² = 2·cost/(m − n); conditional on the other stages' parameters.",
        "",
        "## Fit quality",
        "",
        "| stage | parameters | residuals | series | RMS | seconds |",
        "|---|---|---|---|---|---|",
    ]
    for st in result.stages_:
        for i, (key, rms) in enumerate(st.residual_rms.items()):
            head = (
                (st.name, ", ".join(st.parameters) or "—", str(st.n_data))
                if i == 0
                else ("", "", "")
            )
            secs = _fmt(st.seconds, 3) if i == 0 else ""
            lines.append(f"| {head[0]} | {head[1]} | {head[2]} | {key} | {_fmt(rms)} | {secs} |")
    lines += ["", "RMS units: ln for v and moduli (≈ relative error), absolute for β and η.", ""]
    rows = summary({f"{p} (run)": ds for p, ds in runs.items()})
    rows += summary({f"{p} (probes)": ds for p, ds in model_probes.items()})
    lines += [
        "## Predictions against the DEM",
        "",
        "| path | variable | role | RMS error | measure |",
        "|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row['path']} | {row['variable']} | {row['role']} | {_fmt(row['error_rms'])} "
            f"| {row['error_measure']} |"
        )
    oos = sorted({f"{r['path']}: {r['variable']}" for r in rows if r["role"] == "out_of_sample"})
    fitted = sorted({f"{p}: {v}" for p, v in result.fitted_})
    lines += [
        "",
        "## What was fitted and what is predicted out of sample",
        "",
        "Fitted (entered a residual): " + (", ".join(fitted) or "nothing") + ".",
        "",
        "Predicted out of sample: " + (", ".join(oos) or "nothing") + ".",
        "",
        "### Back-prediction of the stiffness anisotropy along K0",
        "",
    ]
    lines += _k0_anisotropy_lines(runs, model_probes, probes) or ["No K0 probes or run."]
    if identifiability is not None:
        lines += ["", *identifiability_lines(identifiability)]
    warnings = result.warnings()
    lines += ["", "## Warnings", ""]
    lines += [f"- {w}" for w in warnings] or ["None."]
    if figures:
        lines += ["", "## Figures", ""]
        for name, path in figures.items():
            rel = Path(path).name if out_dir is None else Path(path).relative_to(out_dir)
            lines.append(f"![{name}]({rel})")
    lines.append("")
    return "\n".join(lines)


def identifiability_lines(ide) -> list[str]:
    """Markdown section: the profile-likelihood table and the statement of what is determined."""
    pct = f"{100 * ide.level:g} %"
    lines = [
        "## What the data determine",
        "",
        f"Profile likelihoods ({pct} intervals; {_fmt(ide.seconds, 3)} s): each parameter held "
        "on a grid, the other free parameters of its stage refitted; an open side gives the "
        "last point profiled.",
        "",
        "| symbol | value | interval | status | at bound | stage |",
        "|---|---|---|---|---|---|",
    ]
    for sym, p in ide.profiles.items():
        lo = _fmt(p.lower) if p.closed_lower else f"(≤ {_fmt(p.lower)})"
        hi = _fmt(p.upper) if p.closed_upper else f"(≥ {_fmt(p.upper)})"
        lines.append(
            f"| {sym} | {_fmt(p.value, 5)} | [{lo}, {hi}] | {p.status} | {p.at_bound or '—'} "
            f"| {p.stage} |"
        )
    lines += ["", *ide.statement().splitlines()]
    return lines


def write_report(path: str | Path, text: str) -> Path:
    """Write the markdown text; returns the path."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(text)
    return target


__all__ = ["identifiability_lines", "report_markdown", "write_report"]
