"""The TIV calibrated on the paper scene's DEM results, with what the data determine (not a test).

For each run folder (default: the paper scene ``/work/runs/paper`` and its replica of another
seed ``/work/runs/paper_reps/paper_s4``) runs :func:`bridge.pipeline.calibrate_from_results`
(every stage, profile likelihoods) into ``benchmarks/results/calibration_paper/<name>/`` and
writes ``benchmarks/results/calibration_paper.md``:

- the calibrated parameters of the first run with their 95 % profile intervals and status,
  beside the study's Table 1, the replica's values and the spread over the runs;
- the fit quality (RMS per series) of each run;
- the back-prediction of E_h/E_v along K0 (the model's elastic law at the DEM's measured K0
  probe states, out of sample) against the DEM, with the interval of the DEM over the
  replicas at the same probe;
- the statement of what the data determine.

Run: ``.venv/bin/python benchmarks/calibration_paper.py [--runs DIR ...]`` (minutes).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
import xarray as xr

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
DEFAULT_RUNS = ("/work/runs/paper", "/work/runs/paper_reps/paper_s4")


def _fmt(x, digits=4) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    return f"{x:.{digits}g}"


def calibrate_runs(runs: list[str], figures: bool) -> dict[str, dict]:
    from bridge.pipeline import calibrate_from_results

    out = {}
    for i, run in enumerate(runs):
        name = Path(run).name
        target = RESULTS / "calibration_paper" / name
        t0 = time.perf_counter()
        outcome = calibrate_from_results(Path(run) / "history.nc", Path(run) / "probes.nc",
                                         target, {"figures": figures and i == 0})  # fmt: skip
        saved = json.loads((target / "calibration.json").read_text())
        saved["seconds_total"] = time.perf_counter() - t0
        saved["seconds_calibration"] = outcome.seconds_calibration
        saved["seconds_identifiability"] = outcome.seconds_identifiability
        saved["folder"] = str(target)
        out[name] = saved
        print(f"{name}: {saved['seconds_total']:.1f} s", flush=True)
    return out


def parameter_table(results: dict[str, dict]) -> list[str]:
    from tiv_model.params import TABLE1

    names = list(results)
    first = results[names[0]]
    prof = first["identifiability"]["profiles"]
    head = ["| symbol | Table 1 | " + f"{names[0]} | 95 % interval | status | "
            + " | ".join(names[1:]) + " | spread over runs |",
            "|---|---|---|---|---|" + "---|" * (len(names) - 1) + "---|"]  # fmt: skip
    lines = head
    for sym, table1 in TABLE1.as_symbols().items():
        value = first["parameters"][sym]
        p = prof.get(sym)
        if p is None:
            interval, status = "—", "fixed"
        else:
            lo = _fmt(p["lower"]) if p["status"] in ("determined", "bounded below") else "open"
            hi = _fmt(p["upper"]) if p["status"] in ("determined", "bounded above") else "open"
            interval = f"[{lo}, {hi}]"
            status = p["status"] + (f", at {p['at_bound']} bound" if p["at_bound"] else "")
        others = [results[n]["parameters"][sym] for n in names[1:]]
        allv = np.array([value, *others])
        spread = f"{_fmt(allv.min())} – {_fmt(allv.max())}" if allv.size > 1 else "—"
        lines.append(f"| {sym} | {_fmt(table1)} | {_fmt(value, 5)} | {interval} | {status} | "
                     + " | ".join(_fmt(v, 5) for v in others) + f" | {spread} |")  # fmt: skip
    return lines


def fit_lines(results: dict[str, dict]) -> list[str]:
    lines = ["| run | stage | series | RMS | seconds |", "|---|---|---|---|---|"]
    for name, res in results.items():
        for st in res["stages"]:
            for i, (key, rms) in enumerate(st["residual_rms"].items()):
                secs = _fmt(st["seconds"], 3) if i == 0 else ""
                lines.append(f"| {name} | {st['name'] if i == 0 else ''} | {key} | {_fmt(rms)} "
                             f"| {secs} |")  # fmt: skip
    return lines


def anisotropy_lines(results: dict[str, dict]) -> list[str]:
    """E_h/E_v along K0: DEM and the model at the DEM's states, per probe of the first run,
    with the min–max of the DEM over the runs at the probe of nearest p."""
    names = list(results)
    tables = {}
    for name, res in results.items():
        ds = xr.open_dataset(Path(res["folder"]) / "prediction_probes_k0.nc")
        tables[name] = (ds["mean_stress"].values, ds["dem_stiffness_ratio"].values,
                        ds["stiffness_ratio"].values)  # fmt: skip
        ds.close()
    lines = ["| p (kPa) | E_h/E_v DEM | DEM over the runs | E_h/E_v TIV at the DEM state |",
             "|---|---|---|---|"]  # fmt: skip
    p0, dem0, model0 = tables[names[0]]
    for p, d, m in zip(p0, dem0, model0, strict=True):
        near = [tables[n][1][int(np.argmin(np.abs(np.log(tables[n][0] / p))))] for n in names]
        lines.append(f"| {_fmt(p)} | {_fmt(d)} | {_fmt(min(near))} – {_fmt(max(near))} | "
                     f"{_fmt(m)} |")  # fmt: skip
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", nargs="+", default=list(DEFAULT_RUNS))
    parser.add_argument("--no-figures", action="store_true")
    args = parser.parse_args(argv)
    results = calibrate_runs(args.runs, not args.no_figures)
    first = next(iter(results.values()))
    lines = ["# TIV calibrated on the paper scene's DEM results", "",
             f"Runs: {', '.join(args.runs)} (the same scene, other seeds: replicas). Model "
             f"options {first['model_options']}; stress scale 1 kPa per DEM unit (the scene's "
             "`stress_scale_kpa`); elastic probes: linear response. Produced by "
             "`benchmarks/calibration_paper.py`; reports and figures of each run under "
             "`calibration_paper/<run>/`.", "",
             "## Parameters", ""]  # fmt: skip
    lines += parameter_table(results)
    lines += ["", "Intervals: profile likelihood, F(1, m − n) test at 95 %, per stage (the "
              "compressibility and elastic stages jointly; the fabric stage with the others at "
              "their values). 'open': the profile does not rise enough on that side within the "
              "search range.", "", "## What the data determine", ""]  # fmt: skip
    lines += first["identifiability"]["statement"].splitlines()
    lines += ["", "## Fits", ""] + fit_lines(results)
    lines += ["", "## E_h/E_v along K0: back-prediction (out of sample) against the DEM", ""]
    lines += anisotropy_lines(results)
    lines += ["", "## Time", ""]
    for name, res in results.items():
        lines.append(f"- {name}: calibration {_fmt(res['seconds_calibration'], 3)} s, profiles "
                     f"{_fmt(res['seconds_identifiability'], 3)} s, whole pipeline "
                     f"{_fmt(res['seconds_total'], 3)} s (shared 2-core machine)")  # fmt: skip
    for name, res in results.items():
        if res.get("warnings"):
            lines += ["", f"Warnings ({name}):", ""] + [f"- {w}" for w in res["warnings"]]
    text = "\n".join(lines) + "\n"
    (RESULTS / "calibration_paper.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
