"""Time of the bridge's calibration on DEM results, now and at a baseline revision (not a test).

For each ``--dem`` folder (``history.nc`` or ``relaxed_states.nc`` and ``probes.nc`` of a DEM
protocol run) runs :func:`bridge.pipeline.calibrate_from_results` without figures, in this
checkout and, with ``--baseline REV``, on the packages ``tiv_model`` and ``bridge`` of that git
revision in a subprocess; reports wall-clock seconds per stage, the calibration's total and the
identifiability analysis (profile likelihoods, this checkout only), and writes
``benchmarks/results/calibration_bench.md``.

Run: ``.venv/bin/python benchmarks/bench_calibration.py --dem results/dem --baseline 5eb30e9``
(5eb30e9 is the last commit before issue 12; the demo writes its DEM results to results/dem).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
REPO = HERE.parent


def measure(dem: str, identifiability: bool) -> dict:
    """Stage seconds and totals of one calibration of the results in ``dem``."""
    from bridge.pipeline import calibrate_from_results

    with tempfile.TemporaryDirectory() as out:
        options = {"figures": False}
        if identifiability:
            options["identifiability"] = True
        t0 = time.perf_counter()
        outcome = calibrate_from_results(Path(dem) / "history.nc", Path(dem) / "probes.nc", out,
                                         options)  # fmt: skip
        total = time.perf_counter() - t0
        saved = json.loads((Path(out) / "calibration.json").read_text())
    return {
        "stages": {st["name"]: [st["seconds"], st["nfev"]] for st in saved["stages"]},
        "total": total,
        "calibration": outcome.seconds_calibration,
        "identifiability": outcome.seconds_identifiability,
        "parameters": saved["parameters"],
    }


def _baseline(revision: str, dem: str) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        archive = subprocess.run(
            ["git", "-C", str(REPO), "archive", revision, "tiv_model", "bridge"],
            check=True, capture_output=True,
        ).stdout  # fmt: skip
        subprocess.run(["tar", "-x", "-C", tmp], input=archive, check=True)
        env = dict(os.environ, PYTHONPATH=tmp)
        command = [sys.executable, str(Path(__file__).resolve()), "--worker", dem]
        out = subprocess.run(command, env=env, cwd=tmp, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dem", nargs="+", default=[], help="DEM result folders")
    parser.add_argument("--baseline", default=None, help="git revision to compare with")
    parser.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        print(json.dumps(measure(args.worker, identifiability=False)))
        return 0
    if not args.dem:
        parser.error("give --dem DIR [DIR ...]")
    lines = ["# Calibration time on DEM results", "",
             f"Baseline revision: {args.baseline or 'none'}; wall-clock seconds on a shared "
             "2-core machine (other jobs running: compare the columns of one row, not rows).",
             "", "| DEM results | stage | baseline s (evaluations) | now s (evaluations) | "
             "speed-up |", "|---|---|---|---|---|"]  # fmt: skip
    for dem in args.dem:
        before = _baseline(args.baseline, dem) if args.baseline else None
        now = measure(dem, identifiability=True)
        for stage, (secs, nfev) in now["stages"].items():
            old = before["stages"].get(stage) if before else None
            old_s = f"{old[0]:.2f} ({old[1]})" if old else "—"
            gain = f"{old[0] / secs:.1f}" if old and secs > 0 else "—"
            lines.append(f"| {dem} | {stage} | {old_s} | {secs:.2f} ({nfev}) | {gain} |")
        old_total = f"{before['total']:.1f}" if before else "—"
        gain = f"{before['total'] / now['calibration']:.1f}" if before else "—"
        lines.append(f"| {dem} | calibration (all stages) | {old_total} | "
                     f"{now['calibration']:.1f} | {gain} |")  # fmt: skip
        lines.append(f"| {dem} | identifiability (profiles, new) | — | "
                     f"{now['identifiability']:.1f} | — |")  # fmt: skip
        lines.append(f"| {dem} | pipeline total without figures | {old_total} | "
                     f"{now['total']:.1f} | — |")  # fmt: skip
    text = "\n".join(lines) + "\n"
    print(text)
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "calibration_bench.md").write_text(text)
    print(f"wrote {RESULTS / 'calibration_bench.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
