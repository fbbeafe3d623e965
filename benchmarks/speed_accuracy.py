"""The speed–accuracy trade, measured: wall time against the error of each finding (issue 13).

Knobs varied one at a time from the ``balanced`` preset (:mod:`dem_taichi.scene.presets`) on the
isotropic and K0 paths of the validation scene (``default``: 300 rods of 5 discs, seed 2,
linear-response probes at A, B, C): the inertial-number cap (loading rate), ``dt_safety``,
the neighbour-list skin, local damping, the servo's stiffness, the relaxation tolerance, f32
against f64, and the three presets. The sweep files are ``benchmarks/sweeps/speed_accuracy.toml``
and ``speed_accuracy_f32.toml``. The reference is the ``accurate`` preset (every knob at its
finest value), so its own error is not measured here: how far the knobs' sequences flatten
towards it shows how converged it is.

Also, from other measurements:

- the sampling noise against n_rods: the seed-to-seed spread (SD and 95 % interval of the mean)
  of each finding over the replicas of sweeps given with ``--replicas`` (100 rods: three seeds
  in this sweep; 300 rods: ``default_seeds``; 1520 rods: ``paper_seeds``), with their wall time;
- the probe method and amplitude: the dynamic probe sweep against the linear response on a
  packed state of the same scene (``benchmarks/results/protocol_default.json``, written by
  ``benchmarks/bench_protocol.py default``);
- ``tiv_model``'s increment size: a K0 path to σ_v = 250 kPa in n increments against 10,000
  (CPU time, errors of v, E_h/E_v and fabric at the end), measured when summarising.

A note on the errors: with one seed, a change of any knob changes the particle trajectories
(the dynamics are chaotic), so each error holds a part that is sampling noise, not bias. The
skin is a knob that changes no physics (only when the neighbour list is rebuilt, hence the
order of the sums): its errors measure that floor.

Usage::

    python benchmarks/speed_accuracy.py run [--root runs]        # both sweeps, ~35 min, 2 cores
    python benchmarks/speed_accuracy.py summarise [--root runs] \\
        [--replicas runs/default_seeds runs/paper_seeds]

Writes ``benchmarks/results/speed_accuracy.md``, ``speed_accuracy.csv`` and
``speed_accuracy.png`` (the Pareto figure). Not a test (not collected by pytest). Wall times
are those of members run two at a time on a shared 2-core machine (one core each).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
SWEEPS = (HERE / "sweeps" / "speed_accuracy.toml", HERE / "sweeps" / "speed_accuracy_f32.toml")
REFERENCE = "accurate"

#: (key, label, error kind): "rel" relative error, "abs" absolute (fabric, near zero at A/B).
FINDINGS = (
    ("v_A", "v at A", "rel"),
    ("v_B", "v at B", "rel"),
    ("v_C", "v at C", "rel"),
    ("fabric_C", "β_yy−β_xx at C", "abs"),
    ("ratio_B", "E_h/E_v at B", "rel"),
    ("ratio_C", "E_h/E_v at C", "rel"),
    ("ev_B", "E_oed,v at B", "rel"),
    ("ev_C", "E_oed,v at C", "rel"),
    ("k0_C", "K0 at C", "rel"),
    ("lambda_star", "λ*", "rel"),
)
#: The findings of the Pareto figure's panels.
PANELS = ("v_C", "ratio_C", "ev_B", "lambda_star")

#: member name → (knob, value) in the table.
KNOBS = {
    "accurate": ("preset", "accurate (reference)"),
    "balanced": ("preset", "balanced"),
    "fast": ("preset", "fast"),
    "inertial_2.5e-4": ("inertial number cap", "2.5e-4"),
    "inertial_3e-3": ("inertial number cap", "3e-3"),
    "dt_0.075": ("dt_safety", "0.075"),
    "dt_0.25": ("dt_safety", "0.25"),
    "skin_0.1": ("skin", "0.1"),
    "skin_0.6": ("skin", "0.6"),
    "damping_0.1": ("local damping", "0.1"),
    "damping_0.4": ("local damping", "0.4"),
    "servo_elastic": ("servo stiffness", "elastic"),
    "relax_1e-5": ("relax UFR", "1e-5"),
    "relax_1e-3": ("relax UFR", "1e-3"),
    "balanced_f32": ("precision", "f32"),
}
BALANCED_VALUES = {
    "inertial number cap": "1e-3",
    "dt_safety": "0.15",
    "skin": "0.3",
    "local damping": "0.2",
    "servo stiffness": "secant",
    "relax UFR": "1e-4",
    "precision": "f64",
}


# -- reading runs -------------------------------------------------------------------------------
def member_findings(folder: Path) -> dict:
    """The findings of one finished member (``summary.json`` present) and its cost."""
    from dem_taichi.analysis.findings import run_findings, state_findings

    run = run_findings(folder)
    states = state_findings(folder)
    record = (
        json.loads((folder / "member.json").read_text())
        if (folder / "member.json").exists()
        else {}
    )
    summary = json.loads((folder / "summary.json").read_text())
    steps = sum(int(st.get("steps", 0)) for st in summary["stages"].values())

    def at(label, key):
        return states.get(label, {}).get(key, math.nan)

    return {
        "member": folder.name,
        "n_rods": run["n_rods"],
        "seconds": float(record.get("seconds", run["seconds"])),
        "steps": steps,
        "v_A": at("A", "specific_volume"),
        "v_B": at("B", "specific_volume"),
        "v_C": at("C", "specific_volume"),
        "fabric_C": at("C", "fabric_deviator"),
        "ratio_B": at("B", "e_ratio"),
        "ratio_C": at("C", "e_ratio"),
        "ev_B": at("B", "e_oed_v"),
        "ev_C": at("C", "e_oed_v"),
        "k0_C": run["k0_C"],
        "lambda_star": run["lambda_star"],
    }


def finished_members(sweep_dir: Path) -> list[dict]:
    members = sweep_dir / "members"
    if not members.is_dir():
        return []
    return [
        member_findings(d)
        for d in sorted(members.iterdir())
        if (d / "summary.json").exists()
        and json.loads((d / "member.json").read_text()).get("status") == "done"
    ]


#: What was done to members that did not finish (shown beside their recorded error).
NOTES = {
    "balanced_f32": "cancelled by hand (Dask future cancelled, its worker restarted) after 37 "
    "compression increments: in f32 no state along the compression relaxed to UFR 1e-4 "
    "(relaxed=False at every increment from p ≈ 0.2 to 740, where f64 relaxes from p ≈ 0.4), "
    "so no state A was accepted and the sample was compressed far past jamming (p = 1379 at "
    "v = 1.57; f64 finds A at p = 0.9, v = 2.09). f32 positions resolve ~4e-6 d at the box size "
    "near A, L ≈ 55 d, while the overlaps there are δ = f/k_n ~ 1e-5 d: the contact forces "
    "carry tens of per cent of round-off noise",
}


def unfinished_members(sweep_dir: Path) -> list[tuple[str, str, str]]:
    """(member, its error, the last line of its progress log) of each member not done."""
    out = []
    members = sweep_dir / "members"
    for d in sorted(members.iterdir()) if members.is_dir() else []:
        record = json.loads((d / "member.json").read_text()) if (d / "member.json").exists() else {}
        if record.get("status") == "done":
            continue
        log = (
            (d / "progress.log").read_text().strip().splitlines()
            if (d / "progress.log").exists()
            else []
        )
        last = next((line for line in reversed(log) if "inc " in line or "[A]" in line), "")
        why = record.get("error", record.get("status", "?"))
        if d.name in NOTES:
            why = f"{why}; {NOTES[d.name]}"
        out.append((d.name, why, last.strip()))
    return out


def error(value: float, reference: float, kind: str) -> float:
    if kind == "abs":
        return abs(value - reference)
    return abs(value - reference) / abs(reference) if reference else math.nan


# -- the other trades ---------------------------------------------------------------------------
def replica_rows(rows: list[dict]) -> list[dict]:
    """Seed-to-seed spread of each finding, per n_rods: mean, SD, 95 % half-width, wall time."""
    from dem_taichi.analysis.findings import mean_interval

    out = []
    for n in sorted({r["n_rods"] for r in rows}):
        group = [r for r in rows if r["n_rods"] == n]
        entry = {"n_rods": n, "replicas": len(group)}
        entry["seconds"] = float(np.mean([r["seconds"] for r in group]))
        for key, _, _ in FINDINGS:
            values = [r[key] for r in group]
            mean, half, count = mean_interval(values)
            finite = [v for v in values if np.isfinite(v)]
            entry[key] = (mean, float(np.std(finite, ddof=1)) if count > 1 else math.nan, half)
        out.append(entry)
    return out


def probe_rows(path: Path) -> list[tuple[str, float, float, float]]:
    """(method, seconds, error E_v, error E_h) of the linear response and of each dynamic
    amplitude against the linear response (the same packed state)."""
    if not path.exists():
        return []
    d = json.loads(path.read_text())
    rows = [("linear response", d["linear_seconds"], 0.0, 0.0)]
    per_amplitude = d["dynamic_seconds"] / len(d["amplitudes"])
    for a, ev, eh in zip(d["amplitudes"], d["e_oed_v_curve"], d["e_oed_h_curve"], strict=True):
        rows.append(
            (
                f"dynamic ± probe, amplitude {a:.0e}",
                per_amplitude,
                abs(ev - d["e_oed_v_linear"]) / d["e_oed_v_linear"],
                abs(eh - d["e_oed_h_linear"]) / d["e_oed_h_linear"],
            )
        )
    return rows


def tiv_rows(counts=(10, 30, 100, 300, 1000, 3000), reference: int = 10_000) -> list[tuple]:
    """(increments, CPU s, error v, error E_h/E_v, error fabric) of a TIV K0 path."""
    from tiv_model import drivers

    def end(n):
        t0 = time.process_time()
        ds = drivers.k0(250.0, increments=n)
        seconds = time.process_time() - t0
        last = ds.isel({ds["specific_volume"].dims[0]: -1})
        fabric = np.asarray(last["fabric"].values).ravel()
        return seconds, float(last["specific_volume"]), float(last["stiffness_ratio"]), fabric

    _, v_ref, r_ref, f_ref = end(reference)
    rows = []
    for n in counts:
        seconds, v, r, f = end(n)
        rows.append(
            (
                n,
                seconds,
                abs(v - v_ref) / v_ref,
                abs(r - r_ref) / r_ref,
                float(np.max(abs(f - f_ref))),
            )
        )
    return rows


# -- writing ------------------------------------------------------------------------------------
def _g(x: float, digits: int = 3) -> str:
    return "" if x is None or not np.isfinite(x) else f"{x:.{digits}g}"


def _percent(e: float) -> str:
    """A relative error in per cent; below 1e-8 (the same state to round-off) as 0."""
    return "0 %" if abs(e) < 1e-8 else f"{100 * e:.2g} %"


def knob_table(rows: list[dict], ref: dict) -> tuple[list[str], list[list]]:
    head = ["knob", "value", "member", "wall s", "steps"] + [label for _, label, _ in FINDINGS]
    table = []
    order = list(KNOBS)
    for r in sorted(rows, key=lambda r: order.index(r["member"]) if r["member"] in order else 99):
        if r["member"] not in KNOBS:
            continue
        knob, value = KNOBS[r["member"]]
        errors = [error(r[k], ref[k], kind) for k, _, kind in FINDINGS]
        table.append([knob, value, r["member"], r["seconds"], r["steps"], *errors])
    return head, table


def write_markdown(path, ref, head, table, replicas, probes, tiv, noise, unfinished=()) -> None:
    lines = ["# The speed–accuracy trade (issue 13)", ""]
    lines.append(
        "Produced by `benchmarks/speed_accuracy.py summarise` from the sweeps "
        "`benchmarks/sweeps/speed_accuracy{,_f32}.toml` (isotropic and K0 paths of the `default` "
        "scene, 300 rods, seed 2, linear-response probes at A, B, C). One knob at a time from "
        "the `balanced` preset; errors against the `accurate` preset (relative, fabric "
        "absolute). Wall times: members run two at a time, one core each, on a shared "
        "2-core machine."
    )
    lines += [
        "",
        "Reference values (`accurate`): "
        + ", ".join(f"{label} = {_g(ref[k], 4)}" for k, label, _ in FINDINGS)
        + f"; wall time {ref['seconds']:.0f} s.",
        "",
    ]
    lines += ["## Knobs", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in table:
        cells = (
            row[:3]
            + [f"{row[3]:.0f}", f"{row[4]:,}"]
            + [
                _percent(e) if kind == "rel" else _g(e, 2)
                for e, (_, _, kind) in zip(row[5:], FINDINGS, strict=True)
            ]
        )
        lines.append("| " + " | ".join(str(c) for c in cells) + " |")
    lines += [
        "",
        f"Balanced values: {', '.join(f'{k} {v}' for k, v in BALANCED_VALUES.items())}.",
        "",
    ]
    presets = {row[2]: row for row in table if row[0] == "preset"}
    if "balanced" in presets:
        lines += ["## Presets", "", "| preset | wall s | × balanced's time | steps | largest "
                  "relative error (finding) | error of E_h/E_v at C | error of v at C |",
                  "|---|---|---|---|---|---|---|"]  # fmt: skip
        base = presets["balanced"][3]
        keys = [k for k, _, _ in FINDINGS]
        for name in ("fast", "balanced", "accurate"):
            if name not in presets:
                continue
            row = presets[name]
            rel = [(e, label) for e, (_, label, kind) in zip(row[5:], FINDINGS, strict=True)
                   if kind == "rel" and np.isfinite(e)]  # fmt: skip
            worst = max(rel) if rel else (math.nan, "")
            ratio_c, v_c = row[5 + keys.index("ratio_C")], row[5 + keys.index("v_C")]
            lines.append(
                f"| {name} | {row[3]:.0f} | {row[3] / base:.2f} | {row[4]:,} | "
                f"{100 * worst[0]:.2g} % ({worst[1]}) | {100 * ratio_c:.2g} % | {100 * v_c:.2g} % |"
            )
        lines += ["", "`accurate` is the reference: its errors are zero by construction.", ""]
    if noise:
        lines.append(
            "Sampling-noise yardsticks: the skin members (no physics changed) differ from the "
            "balanced one by "
            + ", ".join(
                f"{lab} {_g(100 * noise[k], 2)} %"
                for k, lab in [("v_C", "v_C"), ("ratio_C", "E_h/E_v at C"), ("ev_B", "E_v at B")]
                if k in noise
            )
            + " (max over the two skins)."
        )
        lines.append("")
    if unfinished:
        lines += ["## Members that did not finish", "", "| member | why | last progress line |",
                  "|---|---|---|"]  # fmt: skip
        for name, why, last in unfinished:
            lines.append(f"| {name} | {why} | `{last}` |")
        lines.append("")
    if replicas:
        lines += ["## Sampling noise against n_rods (replicas over seeds)", ""]
        head_r = ["n_rods", "replicas", "wall s / member"] + [label for _, label, _ in FINDINGS]
        lines += ["| " + " | ".join(head_r) + " |", "|" + "---|" * len(head_r)]
        for e in replicas:
            cells = [str(e["n_rods"]), str(e["replicas"]), f"{e['seconds']:.0f}"]
            for key, _, _ in FINDINGS:
                mean, sd, half = e[key]
                cells.append(f"{_g(mean)} ± {_g(half, 2)} (SD {_g(sd, 2)})")
            lines.append("| " + " | ".join(cells) + " |")
        lines += [
            "",
            "mean ± 95 % interval of the mean (Student t); SD the seed-to-seed "
            "standard deviation. The 300- and 1520-rod replicas ran the whole protocol of "
            "their scene (default settings), the 100-rod ones the trade sweep's paths.",
            "",
        ]
    if probes:
        lines += [
            "## Probe method and amplitude (same packed state of `default`)",
            "",
            "| method | seconds | error E_oed,v | error E_oed,h |",
            "|---|---|---|---|",
        ]
        for name, seconds, ev, eh in probes:
            lines.append(f"| {name} | {seconds:.3g} | {100 * ev:.2g} % | {100 * eh:.2g} % |")
        lines += [
            "",
            "Dynamic seconds: the sweep's total over its amplitudes (each relaxed to "
            "the probe UFR); errors against the linear response of the same state.",
            "",
        ]
    if tiv:
        lines += [
            "## tiv_model: increment size (K0 to σ_v = 250 kPa, against 10,000 increments)",
            "",
            "| increments | CPU s | error v | error E_h/E_v | max error fabric |",
            "|---|---|---|---|---|",
        ]
        for n, s, ev, er, ef in tiv:
            lines.append(f"| {n:,} | {s:.3g} | {ev:.2e} | {er:.2e} | {ef:.2e} |")
        lines.append("")
    Path(path).write_text("\n".join(lines))


def write_csv(path, head, table) -> None:
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(head)
        writer.writerows(table)


def pareto_figure(path, table, replicas, noise) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = [k for k, _, _ in FINDINGS]
    labels = {k: lab for k, lab, _ in FINDINGS}
    fig, axes = plt.subplots(2, 2, figsize=(10, 8), constrained_layout=True)
    sd300 = next((e for e in replicas if e["n_rods"] == 300), None)
    for ax, key in zip(axes.ravel(), PANELS, strict=True):
        col = 5 + keys.index(key)
        points = [(row[3], max(row[col], 1e-6), row) for row in table if row[2] != REFERENCE]
        for seconds, err, row in points:
            preset = row[0] == "preset"
            ax.scatter(seconds, err, s=60 if preset else 25, marker="*" if preset else "o",
                       color="C3" if preset else "C0", zorder=3)  # fmt: skip
            ax.annotate(row[2], (seconds, err), fontsize=7, xytext=(3, 3),
                        textcoords="offset points")  # fmt: skip
        front, best = [], math.inf
        for seconds, err, _ in sorted(points):
            if err < best:
                best = err
                front.append((seconds, err))
        if front:
            ax.step(*zip(*front, strict=True), where="post", color="C2", lw=1, label="Pareto front")
        if sd300 and np.isfinite(sd300[key][1]) and sd300[key][0]:
            scale = abs(sd300[key][0]) if FINDINGS[keys.index(key)][2] == "rel" else 1.0
            ax.axhline(sd300[key][1] / scale, color="0.5", ls="--", lw=1,
                       label="seed-to-seed SD, 300 rods")  # fmt: skip
        if key in noise:
            ax.axhline(max(noise[key], 1e-6), color="0.5", ls=":", lw=1, label="skin (no physics)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time of the member (s, one core)")
        ax.set_ylabel(f"error of {labels[key]} vs accurate")
        ax.legend(fontsize=7)
    fig.suptitle("Speed–accuracy trade: default scene, isotropic and K0 paths (issue 13)")
    fig.savefig(path, dpi=130)
    plt.close(fig)


# -- commands -----------------------------------------------------------------------------------
def run(root: Path, scheduler: str | None = None) -> int:
    from dem_taichi.sweep.command import run_sweep
    from dem_taichi.sweep.spec import load_sweep

    code = 0
    for file in SWEEPS:
        spec = load_sweep(file)
        outcome = run_sweep(spec, root / spec.name, scheduler=scheduler)
        code |= bool(outcome.failed)
    return code


def summarise(root: Path, replica_dirs: list[Path], with_tiv: bool = True) -> int:
    rows = [r for file in SWEEPS for r in finished_members(root / file.stem)]
    by_name = {r["member"]: r for r in rows}
    if REFERENCE not in by_name:
        raise SystemExit(f"no finished reference member {REFERENCE!r} under {root}")
    ref = by_name[REFERENCE]
    head, table = knob_table(rows, ref)
    noise = {}
    base = by_name.get("balanced")
    for key, _, kind in FINDINGS:
        skins = [by_name[s] for s in ("skin_0.1", "skin_0.6") if s in by_name]
        if base and skins:
            noise[key] = max(error(s[key], base[key], kind) for s in skins)
    replica_members = [r for r in rows if r["member"].startswith("n100_")]
    for d in replica_dirs:
        replica_members += finished_members(d)
    replicas = replica_rows(replica_members)
    probes = probe_rows(RESULTS / "protocol_default.json")
    tiv = tiv_rows() if with_tiv else []
    RESULTS.mkdir(exist_ok=True)
    unfinished = [u for file in SWEEPS for u in unfinished_members(root / file.stem)]
    write_markdown(
        RESULTS / "speed_accuracy.md", ref, head, table, replicas, probes, tiv, noise, unfinished
    )
    write_csv(RESULTS / "speed_accuracy.csv", head, table)
    pareto_figure(RESULTS / "speed_accuracy.png", table, replicas, noise)
    print((RESULTS / "speed_accuracy.md").read_text())
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run both sweep files (members already done are skipped)")
    r.add_argument("--root", type=Path, default=Path("runs"), help="folder of the sweeps (runs)")
    r.add_argument("--scheduler", default=None, help="a running Dask scheduler (default: local)")
    s = sub.add_parser("summarise", help="tables and the Pareto figure from the finished members")
    s.add_argument("--root", type=Path, default=Path("runs"), help="folder of the sweeps (runs)")
    s.add_argument("--replicas", type=Path, nargs="*", default=[], help="sweep dirs of replicas")
    s.add_argument("--no-tiv", dest="tiv", action="store_false", help="skip the TIV rows")
    args = parser.parse_args(argv)
    if args.command == "run":
        return run(args.root, args.scheduler)
    return summarise(args.root, args.replicas, args.tiv)


if __name__ == "__main__":
    raise SystemExit(main())
