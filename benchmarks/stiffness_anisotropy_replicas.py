"""Replica statistics of the frozen-network stiffness-anisotropy matrix (issue 8).

Reads the ``stiffness_anisotropy_matrix.csv`` that ``benchmarks/stiffness_anisotropy.py`` wrote
for each run of a group of replicas (same scene, other seeds) and gives, per variant, the mean
± 95 % interval over the replicas (Student t, n − 1 dof) of E_h/E_v at C, B′ and B, of the
fabric-induced part B′ − B, of E_v at C relative to the rigid rods of the same network, of
E_v/p at B and of the p-exponent of E_v along the isotropic path; and the same-network paired
difference to the rigid rods (the packing noise of a seed cancels in it). Unstable responses
(negative modes) are left out and counted.

    python benchmarks/stiffness_anisotropy_replicas.py --group paper=DIR,DIR,DIR \\
        [--group paper_kt1=DIR,DIR] [--out benchmarks/results]

Each DIR holds a ``stiffness_anisotropy_matrix.csv`` (or is such a csv file, e.g. the paper-size
runs kept in ``benchmarks/results/stiffness_anisotropy_runs/``). Writes
``<out>/stiffness_anisotropy_replicas.md`` and ``.png``.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from pathlib import Path

import numpy as np

from dem_taichi.analysis.findings import mean_interval

KEYS = ("ratio_C", "ratio_Bp", "ratio_B", "fabric_part", "ev_C_rel", "ev_over_p_B", "exponent")
LABELS = {
    "ratio_C": "E_h/E_v at C",
    "ratio_Bp": "E_h/E_v at B′",
    "ratio_B": "E_h/E_v at B",
    "fabric_part": "B′ − B",
    "ev_C_rel": "E_v(C)/E_v,rigid(C)",
    "ev_over_p_B": "E_v/p at B",
    "exponent": "n: E_v ∝ p^n (A→B)",
}
ISOTROPIC = ("A", "A_to_B", "B")


def read_matrix(folder: Path) -> list[dict]:
    """Rows of one run's matrix, numbers parsed."""
    path = folder / "stiffness_anisotropy_matrix.csv" if folder.is_dir() else folder
    with open(path) as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        for k, v in r.items():
            if k in ("state", "path", "variant", "family", "sliding"):
                continue
            if v in ("True", "False"):
                r[k] = v == "True"
            else:
                try:
                    r[k] = float(v)
                except ValueError:
                    pass
    return rows


def run_findings(rows: list[dict]) -> dict[str, dict]:
    """Per variant, the findings of one run (NaN where the response is unstable)."""
    at = {(r["state"], r["variant"]): r for r in rows}
    out = {}
    for name in dict.fromkeys(r["variant"] for r in rows):

        def ratio(state, name=name):
            r = at.get((state, name))
            return r["ratio"] if r is not None and r["stable"] else math.nan

        iso = [r for r in rows if r["variant"] == name and r["path"] in ISOTROPIC and r["stable"]]
        # the fit is over the states where p and E_v are positive (a variant that frees a
        # mechanism can give E_v <= 0 on a small sample: stiffness_anisotropy.variant_summary)
        iso = [r for r in iso if r["p"] > 0 and r["e_v"] > 0]
        exponent = math.nan
        if len(iso) >= 3:
            exponent = float(
                np.polyfit(np.log([r["p"] for r in iso]), np.log([r["e_v"] for r in iso]), 1)[0]
            )
        c, b = at.get(("C", name)), at.get(("B", name))
        out[name] = dict(
            ratio_C=ratio("C"),
            ratio_Bp=ratio("B'"),
            ratio_B=ratio("B"),
            fabric_part=ratio("B'") - ratio("B"),
            ev_C_rel=c["e_v_over_rigid"] if c is not None and c["stable"] else math.nan,
            ev_over_p_B=b["e_v"] / b["p"] if b is not None and b["stable"] else math.nan,
            exponent=exponent,
            unstable=sum(1 for r in rows if r["variant"] == name and not r["stable"]),
        )
    return out


def interval(values) -> tuple[float, float, int]:
    """Mean, 95 % half-width (Student t) and count of the finite values."""
    return mean_interval(values)


def _pm(mean, half, n, digits=3):
    if not np.isfinite(mean):
        return "–"
    text = f"{mean:.{digits}g}"
    return text + (f" ± {half:.2g}" if np.isfinite(half) else "") + f" ({n})"


def summarise(groups: dict[str, list[Path]], only: tuple[str, ...] = ()) -> tuple[str, dict]:
    """Markdown tables and the per-group statistics (``only``: the variants to tabulate)."""
    lines = ["# Frozen-network stiffness anisotropy over replicas", ""]
    lines += [
        "Mean ± 95 % interval over replica runs (n in brackets); unstable responses (negative",
        "modes of the frozen network) left out. Paired: variant − rigid on the same network.",
        "",
    ]
    result = {}
    for group, folders in groups.items():
        runs = [run_findings(read_matrix(f)) for f in folders]
        names = [n for n in runs[0] if not only or n in only]
        names_ = ", ".join(f.parent.name if f.name == "matrix" else f.stem for f in folders)
        lines += [f"## {group}: {len(folders)} runs ({names_})", ""]
        head = (
            ["variant"]
            + [LABELS[k] for k in KEYS]
            + ["paired Δ at C", "paired Δ at B′", "unstable states"]
        )
        lines.append("| " + " | ".join(head) + " |")
        lines.append("|" + "---|" * len(head))
        stats_group = {}
        for name in names:
            cells, entry = [name], {}
            for k in KEYS:
                entry[k] = interval([run[name][k] for run in runs if name in run])
                cells.append(_pm(*entry[k]))
            for k, label in (("ratio_C", "dC"), ("ratio_Bp", "dBp")):
                entry[label] = interval(
                    [run[name][k] - run["rigid"][k] for run in runs if name in run]
                )
                cells.append(_pm(*entry[label], digits=2))
            cells.append(str(sum(run[name]["unstable"] for run in runs if name in run)))
            stats_group[name] = entry
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
        result[group] = stats_group
    return "\n".join(lines) + "\n", result


def figure(result: dict, path: Path) -> None:
    """E_h/E_v at C and B′ (mean ± 95 %) against κ_b for the chain and bending-only bonds."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n_cols = min(3, len(result))
    n_rows = -(-len(result) // n_cols)
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(5.5 * n_cols, 4.2 * n_rows), squeeze=False)
    for ax in axes.ravel()[len(result) :]:
        ax.set_visible(False)
    for ax, (group, entries) in zip(axes.ravel(), result.items(), strict=False):
        if "rigid" not in entries:
            continue
        for family, marker in (("chain_kb", "o"), ("bend_kb", "s"), ("chainkt1_kb", "^")):
            for key, colour in (
                ("ratio_C", "tab:blue"),
                ("ratio_Bp", "tab:red"),
                ("ratio_B", "0.5"),
            ):
                xs, ys, es = [3.0], [entries["rigid"][key][0]], [entries["rigid"][key][1]]
                for name, e in entries.items():
                    if name.startswith(family) and not name.endswith("nopre"):
                        xs.append(float(name[len(family) :]))
                        ys.append(e[key][0])
                        es.append(e[key][1])
                if len(xs) == 1:
                    continue
                order = np.argsort(xs)
                label = f"{LABELS[key]}, {family.rstrip('_kb')}"
                ax.errorbar(
                    np.array(xs)[order],
                    np.array(ys)[order],
                    yerr=np.nan_to_num(np.array(es)[order]),
                    marker=marker,
                    ms=4,
                    color=colour,
                    capsize=2,
                    lw=1,
                    label=label,
                    ls="-" if family == "chain_kb" else ":",
                )
        ax.axhline(1.0, color="k", lw=0.6)
        ax.set_xscale("log")
        ax.set_xticks([0.01, 0.03, 0.1, 0.3, 1.0, 3.0])
        ax.set_xticklabels(["0.01", "0.03", "0.1", "0.3", "1", "∞"])
        ax.set_xlabel("κ_b / (k_n d²)   (∞: rigid rods)")
        ax.set_ylabel("E_oed,h / E_oed,v")
        ax.set_title(f"{group}: mean ± 95 % over replicas", fontsize=10)
        ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--group",
        action="append",
        required=True,
        help="NAME=DIR,DIR,... (folders holding stiffness_anisotropy_matrix.csv)",
    )
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results"))
    parser.add_argument("--variants", default="", help="comma list of variants to tabulate")
    args = parser.parse_args(argv)
    groups = {}
    for spec in args.group:
        name, _, dirs = spec.partition("=")
        folders = [Path(d) for d in dirs.split(",") if d.strip()]
        if not name or not folders:
            parser.error(f"--group {spec!r}: expected NAME=DIR,DIR,...")
        for f in folders:
            if not (f.is_file() or (f / "stiffness_anisotropy_matrix.csv").is_file()):
                parser.error(
                    f"{f}: no stiffness_anisotropy_matrix.csv (run stiffness_anisotropy.py)"
                )
        groups[name] = folders
    only = tuple(v.strip() for v in args.variants.split(",") if v.strip())
    text, result = summarise(groups, only)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "stiffness_anisotropy_replicas.md").write_text(text)
    figure(result, args.out / "stiffness_anisotropy_replicas.png")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
