"""Where the calibrated TIV model's stiffness anisotropy comes from, at the DEM's states.

Usage::

    python benchmarks/tiv_anisotropy_sources.py \\
        --parameters benchmarks/results/calibration_study_sp05/replicas.json \\
        --states benchmarks/results/figure2_study_sp05/figure2_replicas.md --k0-c 0.60 \\
        --out benchmarks/results/tiv_anisotropy_sources.md

The model's E_oed,h/E_oed,v (form A unless ``--anisotropy B``) at each labelled DEM state of a
Figure-2 replica table (the mean p, v and fabric β, in the model's convention) three ways
(:func:`bridge.predict.anisotropy_parts`): at the state's stress and fabric (full), at its
stress with the fabric set to 0 (from the stress alone) and at its fabric under the isotropic
stress p (from the fabric alone), beside the DEM's measured ratio. The stress of each state is
rebuilt from its p and its path: isotropic at A, B and B′; σ_r/σ_a = ``--k0-c`` at C (the
replicas' mean K0); the radial ends from their DEM stress ratio η = 2(σ_yy − σ_xx)/(σ_xx +
σ_yy), given as ``--radial-eta`` in the order R1, R2, R3. A second table sweeps the stress
ratio at β = 0 and the fabric at q = 0, at p = 100 kPa and the v of B. A state where the model's
energy is not convex or its elastic law cannot be inverted shows as nan.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import numpy as np
import xarray as xr

from bridge.predict import anisotropy_parts, stiffness_ratio_or_nan
from bridge.study_figure_panels import state_means
from tiv_model.params import ModelOptions, Parameters


def _states(table: Path) -> dict[str, dict[str, float]]:
    """The mean p, v, β and DEM E_h/E_v at each labelled state of a Figure-2 replica output:
    its bands (``figure2_replicas.nc``, written since 2026-12-03) or, for the tables written
    before them, the rows of ``figure2_replicas.md`` (means as printed, 4 digits)."""
    if table.suffix == ".nc":
        with xr.open_dataset(table) as bands:
            means = state_means(bands.load())
        return {
            label.replace("'", "′"): {
                "p": m["mean_stress"],
                "v": m["specific_volume"],
                "beta": m["fabric"],
                "ratio": m["stiffness_ratio"],
            }
            for label, m in means.items()
        }
    rows = {}
    for line in table.read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) < 11 or not re.match(r"^[A-Z]", cells[0]) or cells[0] == "state":
            continue
        mean = [float("nan") if c == "—" else float(c.split("±")[0]) for c in cells[1:]]
        rows[cells[0]] = {"p": mean[0], "v": mean[2], "beta": mean[4], "ratio": mean[8]}
    return rows


def _stress(label: str, p: float, k0_c: float, etas: list[float]) -> tuple[float, float]:
    """(σ_a, σ_r) from p = (σ_a + 2σ_r)/3 and the state's path (module docstring)."""
    if label == "C":
        ratio = k0_c
    elif label.startswith("R") and label.endswith("_end"):
        eta = etas[int(label[1:-4]) - 1]
        ratio = (2.0 - eta) / (2.0 + eta)  # σ_xx/σ_yy = σ_r/σ_a
    else:
        ratio = 1.0
    axial = 3.0 * p / (1.0 + 2.0 * ratio)
    return axial, ratio * axial


def _ratios(sa, sr, v, beta, params, options) -> dict[str, np.ndarray]:
    """The model's E_h/E_v at the states, in full and split by source."""
    dem = xr.Dataset(
        {
            "axial_stress": ("point", np.asarray(sa, dtype=float)),
            "radial_stress": ("point", np.asarray(sr, dtype=float)),
            "specific_volume": ("point", np.asarray(v, dtype=float)),
            "fabric": ("point", np.asarray(beta, dtype=float)),
        }
    )
    parts = anisotropy_parts(dem, params, options)
    return {
        "full": stiffness_ratio_or_nan(sa, sr, v, beta, params, options),
        "stress": parts["stiffness_ratio_stress_only"][0],
        "fabric": parts["stiffness_ratio_fabric_only"][0],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--parameters", type=Path, required=True)
    parser.add_argument(
        "--states", type=Path, required=True, help="figure2_replicas.nc (or .md) of bridge figure2"
    )
    parser.add_argument("--k0-c", type=float, required=True)
    parser.add_argument("--radial-eta", default="0.2,0.35,0.5")
    parser.add_argument("--anisotropy", default="A", choices=("A", "B"))
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)

    saved = json.loads(args.parameters.read_text())
    values = saved.get("mean", saved)["parameters"]
    params = Parameters.from_symbols(values)
    options = ModelOptions(anisotropy=args.anisotropy)
    etas = [float(x) for x in args.radial_eta.split(",")]
    states = _states(args.states)
    lines = [
        "# Where the calibrated TIV model's stiffness anisotropy comes from",
        "",
        f"Generated by `python benchmarks/tiv_anisotropy_sources.py --parameters "
        f"{args.parameters} --states {args.states} --k0-c {args.k0_c} --radial-eta "
        f"{args.radial_eta} --anisotropy {args.anisotropy} --out {args.out}`.",
        "",
        "Parameters: "
        + ", ".join(f"{k} = {float(v):.4g}" for k, v in values.items())
        + f"; form {args.anisotropy}.",
        "",
        "## At the DEM's states (means over the replicas)",
        "",
        "| state | p (kPa) | σ_r/σ_a | v | β | E_h/E_v DEM | TIV | TIV, β = 0 | TIV, q = 0 |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for label, s in states.items():
        sa, sr = _stress(label, s["p"], args.k0_c, etas)
        r = _ratios([sa], [sr], [s["v"]], [s["beta"]], params, options)
        lines.append(
            f"| {label} | {s['p']:.4g} | {sr / sa:.3f} | {s['v']:.4g} | {s['beta']:.3f} | "
            f"{s['ratio']:.3f} | {r['full'][0]:.3f} | {r['stress'][0]:.3f} | {r['fabric'][0]:.3f} |"
        )
    v_b = states["B"]["v"] if "B" in states else params.ncl_intercept
    lines += [
        "",
        f"## The two sources apart, at p = 100 kPa and v = {v_b:.4g}",
        "",
        "| η = q/p | σ_r/σ_a | TIV E_h/E_v, β = 0 |   | β | TIV E_h/E_v, q = 0 |",
        "|---|---|---|---|---|---|",
    ]
    etas_q = [0.0, 0.3, 0.6, 0.9, 1.2]
    betas = [0.0, 0.1, 0.2, 0.3, 0.4]
    for eta, beta in zip(etas_q, betas, strict=True):
        sa, sr = 100.0 * (1 + 2 * eta / 3), 100.0 * (1 - eta / 3)
        stress_only = stiffness_ratio_or_nan([sa], [sr], [v_b], [0.0], params, options)[0]
        fabric_only = stiffness_ratio_or_nan([100.0], [100.0], [v_b], [beta], params, options)[0]
        lines.append(
            f"| {eta:.1f} | {sr / sa:.3f} | {stress_only:.3f} | | {beta:.1f} | {fabric_only:.3f} |"
        )
    args.out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
