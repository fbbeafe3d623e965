"""The study's findings across protocol runs, side by side (reads finished runs; no simulation).

Usage::

    python benchmarks/validation_summary.py RUN_DIR [RUN_DIR ...] [--out FILE.md]

Each RUN_DIR is the output of ``python -m dem_taichi protocol ...`` (its folder name labels
the row); when it also holds
``anisotropy.json`` (``python -m dem_taichi anisotropy RUN_DIR``) the interaction fabrics
at C are listed. Prints a markdown table per finding and writes it to ``--out``
(default ``benchmarks/results/protocol_validation_summary.md``).

Findings (docs/science/dem-model.md §1, the study): fabric isotropic along A→B within the sampling
noise sqrt(0.5/N) and E_oed,h ≈ E_oed,v there; along K0 the rods lie down (β_yy − β_xx falls) and
E_oed,h/E_oed,v > 1, growing; ln v linear in ln p beyond A; acidic looser than basic.
Moduli are the linear-response ones (the dynamic sweep runs only at some states on `paper`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from dem_taichi.analysis.findings import run_findings

HERE = Path(__file__).resolve().parent

# the findings of one run are computed in dem_taichi.analysis.findings (shared with the sweeps'
# replica statistics, dem_taichi.sweep.results); the old name stays for the callers of this script
_run_row = run_findings


def _f(x: float, digits: int = 3) -> str:
    return f"{x:.{digits}g}"


def table(rows: list[dict]) -> str:
    lines = [
        "# The study's findings on the DEM runs (linear-response moduli)",
        "",
        "| run | wall time | max I on the paths | p_A | v_A | v_B | v_C | fabric A → C | "
        "noise sqrt(0.5/N) | max abs fabric A→B | E_h/E_v on A→B (min–max) | "
        "E_h/E_v along K0 (p ↑) | λ* (R²) | K0 at C | E_v ∝ p^n on A→B | E_v/p at B |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['run']} | {r['seconds'] / 60:.1f} min"
            f"{' (' + str(r['workers']) + ' workers)' if r['workers'] > 1 else ''} | "
            f"{r['max_i']:.1e} | {_f(r['p_A'])} | {r['v_A']:.3f} | {r['v_B']:.3f} | "
            f"{r['v_C']:.3f} | "
            f"{r['fabric_A']:+.3f} → {r['fabric_C']:+.3f} | {r['noise']:.3f} | "
            f"{r['iso_fabric_max']:.3f} | {min(r['iso_ratio']):.2f}–{max(r['iso_ratio']):.2f} | "
            f"{' → '.join(f'{x:.2f}' for x in r['k0_ratio'])} | "
            f"{r['lambda_star']:.3g} ({r['r2']:.2f}) | {r['k0_C']:.3f} | "
            f"{r['modulus_exponent']:.2f} | {r['ev_over_p_B']:.0f} |"
        )
    lines += [
        "",
        "## Interaction fabrics at C (`python -m dem_taichi anisotropy`)",
        "",
        "| run | rod β_yy−β_xx | contact-normal φ_yy−φ_xx | force-weighted | long-range normal | "
        "affine E_h/E_v (normal springs) | contact share of affine E_v |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        a = r.get("anisotropy_C")
        if not a:
            continue
        lines.append(
            f"| {r['run']} | {a['rod_fabric_deviator']:+.3f} | "
            f"{a['contact_normal_deviator']:+.3f} | {a['contact_force_weighted_deviator']:+.3f} | "
            f"{a['long_range_normal_deviator']:+.3f} | {a['affine_ratio']:.3f} | "
            f"{a['contact_share_v']:.3f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", help="protocol output folders")
    parser.add_argument("--out", default=str(HERE / "results" / "protocol_validation_summary.md"))
    args = parser.parse_args(argv)
    text = table([_run_row(Path(f)) for f in args.runs])
    print(text)
    Path(args.out).write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
