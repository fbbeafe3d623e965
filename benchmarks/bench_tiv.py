"""Speed of the TIV model, now and at a baseline revision (not a test).

Prints a table and writes ``benchmarks/results/tiv_bench.csv`` and ``tiv_bench.txt``.

Cases (each measured in this checkout and, with ``--baseline REV``, in a copy of the packages
``tiv_model`` and ``bridge`` of that git revision run in a subprocess with the same code):
- a K0 path of 10,000 stress-controlled increments (σ_a 5 → 250 kPa, ε_r = 0, run_path),
  scalar axisymmetric path, forms A and B: increments/s;
- the same K0 path with the dataset (``drivers.k0``: what ``python -m tiv_model k0`` does);
- a K0 path of 100 increments on the general 3×3 (Mandel) path;
- one strain-controlled plastic increment on each path;
- batched elastic stiffness D (closed form) for batches of 1, 1000 and 100,000 points;
- batched integration of many material points (:func:`tiv_model.batch.strain_path`, general
  equations), when the revision has it; compare with the single general-path increment.

Times are process CPU times (``time.process_time``), so that other jobs on a shared machine
inflate them less than wall-clock times would; single-threaded code.

Run: ``.venv/bin/python benchmarks/bench_tiv.py [--quick] [--baseline 5eb30e9]``
(5eb30e9 is the last commit before issue 12).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
REPO = HERE.parent


def _k0_controls(n: int):
    from tiv_model.integrate import Control

    targets = np.geomspace(5.0, 250.0, n + 1)[1:]
    return [Control.triaxial(axial_stress=s, radial_strain_increment=0.0) for s in targets]


def _cpu(fun, repeat: int = 1, rounds: int = 3) -> float:
    """Least CPU time per call over ``rounds`` rounds of ``repeat`` calls (after one warm-up)."""
    fun()
    best = float("inf")
    for _ in range(rounds):
        t0 = time.process_time()
        for _ in range(repeat):
            fun()
        best = min(best, (time.process_time() - t0) / repeat)
    return best


def measure(quick: bool) -> list[tuple[str, float, str]]:
    """(case, rate, unit) rows for the tiv_model importable here."""
    from tiv_model import drivers
    from tiv_model.energy import stiffness
    from tiv_model.integrate import Control, advance, initial_state
    from tiv_model.params import TABLE1, ModelOptions, SolverSettings
    from tiv_model.tensors import IDENTITY_MANDEL, deviator, triaxial

    general = SolverSettings(triaxial_fast_path=False)
    rows = []
    n = 2000 if quick else 10_000
    for form in ("A", "B"):
        options = ModelOptions(anisotropy=form)
        start = initial_state(5.0, TABLE1, options)
        controls = _k0_controls(n)
        t0 = time.process_time()
        states, term = drivers.run_path(start, controls, TABLE1, options)
        elapsed = time.process_time() - t0
        assert term is None and len(states) == n + 1
        rows.append((f"K0 path {n} stress-controlled increments, form {form}", n / elapsed,
                     "increments/s"))  # fmt: skip
    t0 = time.process_time()
    ds = drivers.k0(250.0, increments=n)
    rows.append((f"drivers.k0 {n} increments with the dataset, form A", n /
                 (time.process_time() - t0), "increments/s"))  # fmt: skip
    assert ds.sizes["step"] == n + 1
    n_general = 30 if quick else 100
    start = initial_state()
    t0 = time.process_time()
    drivers.run_path(start, _k0_controls(n_general), settings=general)
    rows.append((f"K0 path {n_general} increments, general Mandel path, form A",
                 n_general / (time.process_time() - t0), "increments/s"))  # fmt: skip
    state = drivers.run_path(start, _k0_controls(60)[:40])[0][-1]
    control = Control.strain(triaxial(1e-3, 0.0))
    for name, settings, rep in (("scalar", SolverSettings(), 300), ("general", general, 30)):
        t = _cpu(lambda s=settings: advance(state, control, TABLE1, ModelOptions(), s), rep)
        rows.append((f"one strain-controlled plastic increment, {name} path", 1.0 / t,
                     "increments/s"))  # fmt: skip
    rng = np.random.default_rng(0)
    for batch in (1, 1000, 100_000):
        eps_v = 10 ** rng.uniform(-3, -1.5, batch)
        eps = eps_v[:, None] / 3 * IDENTITY_MANDEL + 0.1 * eps_v[:, None] * rng.standard_normal(
            (batch, 6)
        )
        beta = deviator(rng.standard_normal((batch, 6)))
        beta *= (0.2 * rng.uniform(size=batch) / np.sqrt(1.5 * np.sum(beta**2, axis=1)))[:, None]
        v = rng.uniform(1.1, 2.5, batch)
        for form in ("A", "B"):
            options = ModelOptions(anisotropy=form)
            repeat = max(1, 20_000 // batch)
            t = _cpu(lambda o=options, e=eps, v=v, b=beta: stiffness(e, v, b, TABLE1, o), repeat)
            rows.append((f"elastic stiffness D, batch {batch}, form {form}", batch / t,
                         "evaluations/s"))  # fmt: skip
    rows.extend(_measure_batch(quick))
    return rows


def _measure_batch(quick: bool) -> list[tuple[str, float, str]]:
    """Batched strain-controlled integration (tiv_model.batch), when the revision has it."""
    try:
        from tiv_model import batch
    except ImportError:
        return []
    from tiv_model.drivers import run_path
    from tiv_model.integrate import initial_state

    k0 = run_path(initial_state(), _k0_controls(40))[0]
    rows = []
    steps = 10
    rng = np.random.default_rng(1)
    for points in (1, 100) if quick else (1, 100, 1000):
        start = batch.BatchState.from_states([k0[10 + i % 30] for i in range(points)])
        path = [1e-3 * np.array([1.0, -0.2, 0.1, 0.2, 0.0, 0.1]) + 2e-4 * rng.standard_normal(
            (points, 6)) for _ in range(steps)]  # fmt: skip
        t = _cpu(lambda b=start, p=path: batch.strain_path(b, p), rounds=1)
        rows.append((f"batched strain path, {points} points x {steps} plastic increments",
                     points * steps / t, "point-increments/s"))  # fmt: skip
    return rows


def _baseline_rows(revision: str, quick: bool) -> list[tuple[str, float, str]]:
    """Run :func:`measure` in a subprocess on the packages of ``revision``."""
    with tempfile.TemporaryDirectory() as tmp:
        archive = subprocess.run(
            ["git", "-C", str(REPO), "archive", revision, "tiv_model", "bridge"],
            check=True, capture_output=True,
        ).stdout  # fmt: skip
        subprocess.run(["tar", "-x", "-C", tmp], input=archive, check=True)
        env = dict(os.environ, PYTHONPATH=tmp)
        command = [sys.executable, str(Path(__file__).resolve()), "--worker"]
        if quick:
            command.append("--quick")
        out = subprocess.run(command, env=env, cwd=tmp, check=True, capture_output=True, text=True)
    return [tuple(row) for row in json.loads(out.stdout.strip().splitlines()[-1])]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs")
    parser.add_argument("--baseline", default=None, help="git revision to compare with")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        print(json.dumps(measure(args.quick)))
        return 0
    rows = measure(args.quick)
    before = {}
    if args.baseline:
        before = {case: rate for case, rate, _ in _baseline_rows(args.baseline, args.quick)}
    width = max(len(r[0]) for r in rows)
    lines = [
        f"TIV benchmark ({platform.machine()}, Python {platform.python_version()}, numpy "
        f"{np.__version__}); CPU time; baseline: {args.baseline or 'none'}",
        f"{'case':<{width}}  {'rate':>12}  {'baseline':>12}  {'speed-up':>8}  unit",
    ]
    for case, rate, unit in rows:
        base = before.get(case)
        base_s = f"{base:12.4g}" if base else f"{'—':>12}"
        gain = f"{rate / base:8.1f}" if base else f"{'—':>8}"
        lines.append(f"{case:<{width}}  {rate:12.4g}  {base_s}  {gain}  {unit}")
    text = "\n".join(lines)
    print(text)
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "tiv_bench.txt").write_text(text + "\n")
    with open(RESULTS / "tiv_bench.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["case", "rate", "baseline_rate", "unit", "baseline_revision"])
        for case, rate, unit in rows:
            base = before.get(case)
            writer.writerow([case, f"{rate:.6g}", f"{base:.6g}" if base else "", unit,
                             args.baseline or ""])  # fmt: skip
    print(f"wrote {RESULTS / 'tiv_bench.csv'} and tiv_bench.txt")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
