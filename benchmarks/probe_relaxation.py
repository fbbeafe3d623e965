"""The probes' relaxation threshold against the moduli it gives (issue 20): paired, state by state.

Usage::

    python benchmarks/probe_relaxation.py RUN_DIR [RUN_DIR ...] \\
        --ufr 1e-4 1e-5 1e-6 1e-7 1e-8 --out FILE.json [--markdown FILE.md] \\
        [--states A C] [--repeat] [--relax-max-steps N]

Before its linear response a probe relaxes a copy of the path state further, at fixed cell, to
``[probing] relax_unbalanced_force`` (:func:`dem_taichi.protocol.probing.probe_state`); that
relaxation is 9–12 % of a paper-size protocol's steps. A probe runs on a copy of the path state
and restores it bitwise, so its own settings change the moduli only, never the paths: the cost
of a looser threshold is measured exactly here, paired, state by state, without the chaos that
decorrelates two paths.

For every run folder (a protocol run with ``[protocol] save_states = true``) and every labelled
state saved in it (``state_A.npz``, ``state_B.npz``, ``state_C.npz``, ``state_B_prime.npz``,
``state_R<k>_end.npz``), the state is loaded into a simulation with the run's own scene (the
checkpoint holds it; its hash is checked against the run's ``run.json``, as the protocol's
branch workers do) and probed with :func:`~dem_taichi.protocol.probing.probe_state` — the
protocol's own function, with the run's ``[protocol]`` and ``[probing]`` sections — once per
threshold of ``--ufr``, each time from the same saved state, with only
``relax_unbalanced_force`` changed and the dynamic sweep off (``dynamic = false``; the linear
response on). Before each probe the engine's state is checked to be bitwise the saved one, and
after it to be bitwise unchanged (``verify``); ``--repeat`` probes at the loosest threshold a
second time, after all the others, and checks that every number is bitwise the same.

Written per (run, state, threshold): the relaxation's steps (the work ledger's stage ``probe``,
:mod:`dem_taichi.engine.work_profile`), whether it reached the threshold within
``relax_max_steps`` (a state that did not is reported, never dropped) and the UFR it ended at,
its wall seconds (the probe's minus the linear response's) and kernel seconds, the linear
response's seconds, the stress change of the relaxation (``base_stress_change``: max |Δσ_aa|/p),
E_oed,v, E_oed,h and E_h/E_v, and the differences against the strictest threshold given
(relative for the moduli, absolute for the ratio). Where the run's ``probes.nc`` holds the
state, the moduli the run itself recorded (at its own threshold) are written beside, as the
check that the probe here is the protocol's. ``--markdown`` writes one summary row per threshold
over all states (median and max |relative difference| of E_v and E_h, max |Δ(E_h/E_v)|, total
steps and seconds, steps as a fraction of the strictest's) and a table per state.

Symbols: UFR unbalanced-force ratio; E_oed,v = C_22, E_oed,h = C_11 of the linear response
(force/length, DEM units); p mean stress.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import re
import statistics
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/ is not a package
from jsonable import jsonable  # noqa: E402

if TYPE_CHECKING:
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.scene.probing_sections import ProbingConfig
    from dem_taichi.scene.protocol_sections import ProtocolConfig

#: Labelled states in the order of the protocol; others (R<k>_end) follow, sorted.
STATE_ORDER = ("A", "B", "C", "B'")
_STATE_FILE = re.compile(r"^state_(.+)\.npz$")


def state_files(run_dir: Path) -> dict[str, Path]:
    """Label → checkpoint of the labelled states a run folder saved (``state_<label>.npz``,
    ``'`` written ``_prime``), in the order of the protocol."""
    found = {}
    for entry in run_dir.iterdir():
        match = _STATE_FILE.match(entry.name)
        if match and entry.is_file():
            found[match.group(1).replace("_prime", "'")] = entry
    known = [label for label in STATE_ORDER if label in found]
    return {label: found[label] for label in known + sorted(set(found) - set(known))}


def load_state(run_dir: Path, path: Path) -> tuple[Simulation, dict, str]:
    """The simulation of a saved state with the run's scene, the saved arrays and the stage.

    The checkpoint's scene must be the run's (its hash against ``run.json``'s ``scene_sha256``,
    when the folder has one): a state file copied from another run is refused."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.io.checkpoint import load_checkpoint
    from dem_taichi.io.run_directory import scene_sha256
    from dem_taichi.scene.config import scene_from_toml, scene_to_toml

    arrays, meta = load_checkpoint(path)
    record = run_dir / "run.json"
    if record.is_file():
        expected = json.loads(record.read_text())["scene_sha256"]
        found = scene_sha256(scene_to_toml(scene_from_toml(meta["scene_toml"])))
        if found != expected:
            raise SystemExit(
                f"{path}: holds another scene (sha256 {found[:12]}) than its run folder's "
                f"run.json (sha256 {expected[:12]})"
            )
    sim = Simulation.from_checkpoint(path)
    return sim, arrays, str(meta.get("stage", "other"))


def recorded_moduli(run_dir: Path) -> tuple[dict[str, tuple[float, float]], float | None]:
    """Label → (E_v, E_h) of the linear response the run recorded in ``probes.nc``, and the
    threshold it probed at (``{}``, None without the file)."""
    path = run_dir / "probes.nc"
    if not path.is_file():
        return {}, None
    import xarray as xr

    with xr.open_dataset(path) as ds:
        labels = [str(s) for s in ds["state_label"].values]
        e_v = ds["e_oed_v_linear"].values
        e_h = ds["e_oed_h_linear"].values
        threshold = ds.attrs.get("dynamic_probe_relax_unbalanced_force")
    out = {label: (float(e_v[i]), float(e_h[i])) for i, label in enumerate(labels)}
    return out, float(threshold) if threshold is not None else None


def probe_once(
    sim: Simulation,
    saved: dict,
    probing: ProbingConfig,
    protocol: ProtocolConfig,
    label: str,
    stage: str,
    ufr: float,
) -> dict[str, Any]:
    """One probe of the saved state at the threshold ``ufr``, as the protocol probes it.

    The engine is set to ``saved`` and checked to hold it bitwise before, and to hold it still
    after (``probe_state``'s ``verify`` and a comparison with ``saved``)."""
    from dem_taichi.engine.state import states_equal
    from dem_taichi.engine.work_profile import stage_totals
    from dem_taichi.protocol.probing import probe_state

    config = dataclasses.replace(probing, relax_unbalanced_force=ufr, dynamic=False, linear=True)
    sim.set_state(saved)
    starts_saved = states_equal(saved, sim.get_state())
    if not starts_saved:
        raise RuntimeError(f"state {label}: the engine does not hold the saved state bitwise")
    # the last measures of the relaxation (probe_state keeps only the stress change): the UFR it
    # ended at, reported where it did not reach the threshold
    last: dict[str, Any] = {}
    run = sim.run

    def recording_run(*args, **kwargs):
        measures = run(*args, **kwargs)
        last["measures"] = measures
        return measures

    sim.run = recording_run  # type: ignore[method-assign]
    sim.work = {}
    try:
        t0 = time.perf_counter()
        result = probe_state(sim, config, protocol, label, stage, verify=True)
        seconds = time.perf_counter() - t0
    finally:
        del sim.run  # the class's method again
    steps, kernel_seconds, measure_seconds, _ = stage_totals(sim.work, "probe")
    sim.work = None
    unchanged = states_equal(saved, sim.get_state())
    if not unchanged:
        raise RuntimeError(f"state {label}: probing changed the saved state")
    linear = result.linear
    assert linear is not None  # config.linear
    e_v, e_h = float(linear.e_oed_v), float(linear.e_oed_h)
    final = last.get("measures")
    return {
        "ufr": ufr,
        "relax_steps": int(steps),
        "relaxed": bool(result.base_relaxed),
        "final_ufr": float(final["unbalanced_force_ratio"]) if final is not None else None,
        "relax_seconds": seconds - result.linear_seconds,
        "relax_kernel_seconds": kernel_seconds + measure_seconds,
        "linear_seconds": result.linear_seconds,
        "base_stress_change": result.base_stress_change,
        "e_oed_v": e_v,
        "e_oed_h": e_h,
        "ratio": e_h / e_v,
        "mean_stress": float(result.measures["mean_stress"]),
        "restored_bitwise": bool(result.state_restored_bitwise) and unchanged,
        "started_bitwise": starts_saved,
    }


#: The numbers of a probe that a repeat must give bit for bit.
REPEATED = ("relax_steps", "relaxed", "final_ufr", "base_stress_change", "e_oed_v", "e_oed_h")


def probe_run(
    run_dir: Path,
    thresholds: list[float],
    states: list[str] | None,
    repeat: bool,
    max_steps: int | None,
    say=print,
) -> Iterator[list[dict[str, Any]]]:
    """The rows of one run folder, state by state: each saved state at every threshold
    (strictest first)."""
    from dem_taichi.scene.probing_sections import probing_settings
    from dem_taichi.scene.protocol_sections import protocol_settings

    files = state_files(run_dir)
    if states:
        missing = [s for s in states if s not in files]
        if missing:
            raise SystemExit(f"{run_dir}: no saved state {', '.join(missing)} (has {list(files)})")
        files = {label: files[label] for label in states}
    if not files:
        raise SystemExit(
            f"{run_dir}: no state_<label>.npz (run the protocol with "
            "--set protocol.save_states=true)"
        )
    recorded, run_threshold = recorded_moduli(run_dir)
    strictest = min(thresholds)
    for label, path in files.items():
        rows: list[dict[str, Any]] = []
        t0 = time.perf_counter()
        sim, saved, stage = load_state(run_dir, path)
        load_seconds = time.perf_counter() - t0
        probing, protocol = probing_settings(sim.scene), protocol_settings(sim.scene)
        if max_steps is not None:
            probing = dataclasses.replace(probing, relax_max_steps=max_steps)
        common = {
            "run": str(run_dir),
            "state": label,
            "stage": stage,
            "n_rods": int(sim.n_rods),
            "load_seconds": load_seconds,
            "relax_max_steps": probing.relax_max_steps,
            "run_ufr": run_threshold,
            "recorded_e_oed_v": recorded.get(label, (math.nan, math.nan))[0],
            "recorded_e_oed_h": recorded.get(label, (math.nan, math.nan))[1],
        }
        results = {}
        for ufr in sorted(thresholds):
            results[ufr] = probe_once(sim, saved, probing, protocol, label, stage, ufr)
            r = results[ufr]
            say(
                f"{run_dir.name} {label} UFR {ufr:g}: {r['relax_steps']} steps"
                f"{'' if r['relaxed'] else ' (NOT REACHED)'}, {r['relax_seconds']:.2f} s; "
                f"E_v {r['e_oed_v']:.6g} E_h {r['e_oed_h']:.6g} E_h/E_v {r['ratio']:.5f}"
            )
        reference = results[strictest]
        for r in results.values():
            r["d_e_oed_v"] = r["e_oed_v"] / reference["e_oed_v"] - 1.0
            r["d_e_oed_h"] = r["e_oed_h"] / reference["e_oed_h"] - 1.0
            r["d_ratio"] = r["ratio"] - reference["ratio"]
            r["reference_relaxed"] = reference["relaxed"]
            r["steps_fraction"] = (
                r["relax_steps"] / reference["relax_steps"] if reference["relax_steps"] else None
            )
            r["repeat_identical"] = None
            rows.append({**common, **r})
        if repeat:
            loosest = max(thresholds)
            again = probe_once(sim, saved, probing, protocol, label, stage, loosest)
            same = all(_same(again[k], results[loosest][k]) for k in REPEATED)
            for row in rows:
                if row["ufr"] == loosest:
                    row["repeat_identical"] = same
            say(f"{run_dir.name} {label} UFR {loosest:g} again: identical = {same}")
        del sim
        yield rows


def _same(a, b) -> bool:
    """Bitwise equality of two probe numbers (NaN equals NaN)."""
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    return a == b


def summary(rows: list[dict[str, Any]], thresholds: list[float]) -> list[dict[str, Any]]:
    """Per threshold, over all states of all runs: the statistics of the markdown table."""
    strict_steps = sum(r["relax_steps"] for r in rows if r["ufr"] == min(thresholds))
    out = []
    for ufr in sorted(thresholds, reverse=True):
        mine = [r for r in rows if r["ufr"] == ufr]
        d_v = [abs(r["d_e_oed_v"]) for r in mine]
        d_h = [abs(r["d_e_oed_h"]) for r in mine]
        steps = sum(r["relax_steps"] for r in mine)
        out.append(
            {
                "ufr": ufr,
                "states": len(mine),
                "not_reached": sum(not r["relaxed"] for r in mine),
                "median_abs_d_e_oed_v": statistics.median(d_v) if d_v else math.nan,
                "max_abs_d_e_oed_v": max(d_v, default=math.nan),
                "median_abs_d_e_oed_h": statistics.median(d_h) if d_h else math.nan,
                "max_abs_d_e_oed_h": max(d_h, default=math.nan),
                "max_abs_d_ratio": max((abs(r["d_ratio"]) for r in mine), default=math.nan),
                "max_base_stress_change": max(
                    (r["base_stress_change"] for r in mine), default=math.nan
                ),
                "relax_steps": steps,
                "steps_fraction": steps / strict_steps if strict_steps else math.nan,
                "relax_seconds": sum(r["relax_seconds"] for r in mine),
                "linear_seconds": sum(r["linear_seconds"] for r in mine),
            }
        )
    return out


def markdown(rows: list[dict[str, Any]], table: list[dict[str, Any]], command: str) -> str:
    """The summary table per threshold and the table per state."""
    strictest = min(r["ufr"] for r in rows)
    lines = [
        "# Probe relaxation threshold against the moduli (issue 20)",
        "",
        f"Command: `{command}`",
        "",
        f"Differences against the strictest threshold, UFR {strictest:g}, at the same saved state "
        "(relative for E_v and E_h, absolute for E_h/E_v). Steps and seconds: the probes' "
        "relaxation; lin s: the linear response. Not reached: relaxations that stopped at "
        "relax_max_steps above the threshold.",
        "",
        "| UFR | states | not reached | median |ΔE_v/E_v| | max |ΔE_v/E_v| | median |ΔE_h/E_h| "
        "| max |ΔE_h/E_h| | max |Δ(E_h/E_v)| | max base Δσ/p | steps | steps / strictest "
        "| relax s | lin s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for s in table:
        lines.append(
            f"| {s['ufr']:g} | {s['states']} | "
            f"{f'**{n}**' if (n := s['not_reached']) else '0'} | "
            f"{s['median_abs_d_e_oed_v']:.2e} | {s['max_abs_d_e_oed_v']:.2e} | "
            f"{s['median_abs_d_e_oed_h']:.2e} | {s['max_abs_d_e_oed_h']:.2e} | "
            f"{s['max_abs_d_ratio']:.2e} | {s['max_base_stress_change']:.1e} | "
            f"{s['relax_steps']:,} | {s['steps_fraction']:.3f} | {s['relax_seconds']:.1f} | "
            f"{s['linear_seconds']:.2f} |"
        )
    unrelaxed = sorted({f"{Path(r['run']).name} {r['state']}" for r in rows
                        if not r["reference_relaxed"]})  # fmt: skip
    if unrelaxed:
        lines += [
            "",
            f"**The strictest threshold was not reached at {', '.join(unrelaxed)}**: the "
            "differences there are against a reference that is not relaxed to it.",
        ]
    lines += [
        "",
        "## Per state",
        "",
        "Recorded: the E_v and E_h the run's own probe recorded in probes.nc (at its threshold), "
        "relative to the value here at the same threshold; repeat: the loosest threshold probed "
        "again after the others gave bitwise the same numbers.",
        "",
        "| run | state | n rods | p | UFR | steps | reached | final UFR | relax s | lin s "
        "| base Δσ/p | E_v | E_h | E_h/E_v | ΔE_v/E_v | ΔE_h/E_h | Δ(E_h/E_v) | recorded "
        "| repeat |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        recorded = ""
        if r["run_ufr"] == r["ufr"] and math.isfinite(r["recorded_e_oed_v"]):
            recorded = (
                f"{r['recorded_e_oed_v'] / r['e_oed_v'] - 1:+.1e} / "
                f"{r['recorded_e_oed_h'] / r['e_oed_h'] - 1:+.1e}"
            )
        repeat = {None: "", True: "identical", False: "**differs**"}[r["repeat_identical"]]
        final = f"{r['final_ufr']:.2e}" if r["final_ufr"] is not None else "—"
        lines.append(
            f"| {Path(r['run']).name} | {r['state']} | {r['n_rods']} | {r['mean_stress']:.4g} | "
            f"{r['ufr']:g} | {r['relax_steps']:,} | {'yes' if r['relaxed'] else '**no**'} | "
            f"{final} | {r['relax_seconds']:.2f} | {r['linear_seconds']:.3f} | "
            f"{r['base_stress_change']:.1e} | {r['e_oed_v']:.6g} | {r['e_oed_h']:.6g} | "
            f"{r['ratio']:.5f} | {r['d_e_oed_v']:+.2e} | {r['d_e_oed_h']:+.2e} | "
            f"{r['d_ratio']:+.2e} | {recorded} | {repeat} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", type=Path, nargs="+", metavar="RUN_DIR")
    parser.add_argument(
        "--ufr", type=float, nargs="+", required=True, help="probe relax_unbalanced_force values"
    )
    parser.add_argument("--out", type=Path, required=True, help="JSON file of the rows")
    parser.add_argument("--markdown", type=Path, help="also write the tables here")
    parser.add_argument("--states", nargs="+", help="only these labels (A B C B' ...)")
    parser.add_argument(
        "--repeat", action="store_true", help="probe the loosest threshold again (bitwise check)"
    )
    parser.add_argument(
        "--relax-max-steps", type=int, help="most steps of a relaxation (default: the run's)"
    )
    args = parser.parse_args(argv)
    thresholds = sorted(set(args.ufr))
    if not all(0 < u < 1 for u in thresholds):
        raise SystemExit(f"--ufr {args.ufr}: allowed values in (0, 1)")
    command = "python benchmarks/probe_relaxation.py " + " ".join(argv or [])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    for run_dir in args.runs:
        states = probe_run(run_dir, thresholds, args.states, args.repeat, args.relax_max_steps)
        for state_rows in states:
            rows += state_rows
            # written after each state: a run stopped half-way keeps what it measured
            table = summary(rows, thresholds)
            report = {"command": command, "thresholds": thresholds, "summary": table, "rows": rows}
            args.out.write_text(json.dumps(jsonable(report), indent=1))
            if args.markdown is not None:
                args.markdown.write_text(markdown(rows, table, command))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
