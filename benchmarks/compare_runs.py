"""Speed against accuracy: two protocol runs of one scene side by side (no simulation).

Usage::

    python benchmarks/compare_runs.py REFERENCE CANDIDATE [--out FILE.md]

REFERENCE and CANDIDATE are outputs of ``python -m dem_taichi protocol`` of the same scene with
different settings (e.g. ``[protocol] servo_stiffness`` elastic vs secant). Prints, per stage,
steps, wall time and the largest inertial number, and per labelled state the relative change of
v, p, q, the fabric deviator and both linear-response moduli; writes the same markdown to
``--out`` when given.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from dem_taichi.io import open_probes


def _load(folder: Path) -> tuple[dict, dict]:
    summary = json.loads((folder / "summary.json").read_text())
    probes = open_probes(folder / "probes.nc")
    labels = probes["state_label"].values.astype(str)
    moduli = {
        label: (
            float(probes["e_oed_v_linear"].values[i]),
            float(probes["e_oed_h_linear"].values[i]),
        )
        for i, label in enumerate(labels)
    }
    return summary, moduli


def compare(reference: Path, candidate: Path) -> str:
    ref, ref_mod = _load(reference)
    new, new_mod = _load(candidate)
    lines = [
        f"# `{candidate}` against `{reference}`",
        "",
        f"Wall time {ref['total_seconds']:.0f} s → {new['total_seconds']:.0f} s "
        f"(workers {ref.get('workers', 1)} → {new.get('workers', 1)}).",
        "",
        "| stage | steps | wall time (s) | max I |",
        "|---|---|---|---|",
    ]
    nan = float("nan")
    for name, st in ref["stages"].items():
        other = new["stages"].get(name, {})
        lines.append(
            f"| {name} | {st['steps']:,} → {other.get('steps', 0):,} | "
            f"{st['seconds']:.0f} → {other.get('seconds', nan):.0f} | "
            f"{st['max_inertial_number']:.2g} → {other.get('max_inertial_number', nan):.2g} |"
        )
    lines += [
        "",
        "| state | v | Δv/v | q | fabric β_yy−β_xx | E_oed,v lin | ΔE_v/E_v | E_oed,h lin "
        "| ΔE_h/E_h | E_h/E_v |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for label, s in ref["states"].items():
        t = new["states"].get(label)
        if t is None:
            continue
        ev, eh = ref_mod.get(label, (np.nan, np.nan))
        fv, fh = new_mod.get(label, (np.nan, np.nan))
        lines.append(
            f"| {label} | {s['specific_volume']:.4f} → {t['specific_volume']:.4f} | "
            f"{t['specific_volume'] / s['specific_volume'] - 1:+.2%} | "
            f"{s['deviatoric_stress']:.3g} → {t['deviatoric_stress']:.3g} | "
            f"{s['fabric_deviator']:+.3f} → {t['fabric_deviator']:+.3f} | "
            f"{ev:.4g} → {fv:.4g} | {fv / ev - 1:+.1%} | {eh:.4g} → {fh:.4g} | "
            f"{fh / eh - 1:+.1%} | {eh / ev:.3f} → {fh / fv:.3f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("reference")
    parser.add_argument("candidate")
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    text = compare(Path(args.reference), Path(args.candidate))
    print(text)
    if args.out:
        Path(args.out).write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
