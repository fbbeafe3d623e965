"""Speed of the TIV model (not a test): prints a table, writes benchmarks/results/tiv_bench.csv.

Measures
- increments per second of a 1000-increment K0 path (axial stress control, ε_r = 0), for the
  scalar axisymmetric fast path and the general 3×3 (Mandel, numpy) path;
- the cost of one strain-controlled plastic increment and one elastic increment;
- batched elastic-moduli evaluations per second (closed-form D, numpy over a batch);
and writes a cProfile summary of the plastic single-point increment to tiv_bench_profile.txt.

Times are process CPU times (``time.process_time``) so that other jobs on a shared machine
inflate them less than wall-clock times would; single-threaded code, so CPU time ≈ wall time on an
idle machine.

Run: ``.venv/bin/python benchmarks/bench_tiv.py [--quick]``
"""

from __future__ import annotations

import argparse
import cProfile
import csv
import io
import platform
import pstats
import time
from pathlib import Path

import numpy as np

from tiv_model.drivers import run_path
from tiv_model.energy import stiffness
from tiv_model.integrate import Control, advance, initial_state
from tiv_model.params import TABLE1, ModelOptions, SolverSettings
from tiv_model.tensors import IDENTITY_MANDEL, deviator, triaxial

RESULTS = Path(__file__).resolve().parent / "results"
FAST = SolverSettings()
GENERAL = SolverSettings(triaxial_fast_path=False)


def k0_controls(n: int):
    targets = np.geomspace(5.0, 250.0, n + 1)[1:]
    return [Control.triaxial(axial_stress=s, radial_strain_increment=0.0) for s in targets]


def time_k0(n: int, settings: SolverSettings, options: ModelOptions) -> float:
    start = initial_state(5.0, TABLE1, options)
    t0 = time.process_time()
    states, term = run_path(start, k0_controls(n), TABLE1, options, settings)
    elapsed = time.process_time() - t0
    assert term is None and len(states) == n + 1
    return elapsed


def k0_state(options: ModelOptions):
    return run_path(initial_state(5.0, TABLE1, options), k0_controls(60)[:40], TABLE1, options)[0][
        -1
    ]


def time_single(state, deps, settings, options, repeat: int) -> float:
    control = Control.strain(deps)
    advance(state, control, TABLE1, options, settings)
    t0 = time.process_time()
    for _ in range(repeat):
        new = advance(state, control, TABLE1, options, settings)
    elapsed = (time.process_time() - t0) / repeat
    del new
    return elapsed


def time_moduli(batch: int, options: ModelOptions, repeat: int = 5) -> float:
    rng = np.random.default_rng(0)
    eps_v = 10 ** rng.uniform(-3, -1.5, batch)
    eps = eps_v[:, None] / 3 * IDENTITY_MANDEL + 0.1 * eps_v[:, None] * rng.standard_normal(
        (batch, 6)
    )
    beta = deviator(rng.standard_normal((batch, 6)))
    beta *= (0.2 * rng.uniform(size=batch) / np.sqrt(1.5 * np.sum(beta * beta, axis=1)))[:, None]
    v = rng.uniform(1.1, 2.5, batch)
    stiffness(eps, v, beta, TABLE1, options)
    t0 = time.process_time()
    for _ in range(repeat):
        d = stiffness(eps, v, beta, TABLE1, options)
    elapsed = (time.process_time() - t0) / repeat
    assert d.shape == (batch, 6, 6)
    return batch / elapsed


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs")
    args = parser.parse_args(argv)
    n_fast = 1000
    n_general = 100 if args.quick else 1000
    rows = []
    for form in ("A", "B"):
        options = ModelOptions(anisotropy=form)
        t = time_k0(n_fast, FAST, options)
        rows.append((f"K0 path {n_fast} increments, fast path, form {form}", n_fast / t,
                     "increments/s", 1e3 * t / n_fast, "ms/increment"))  # fmt: skip
        t = time_k0(n_general, GENERAL, options)
        rows.append((f"K0 path {n_general} increments, general path, form {form}",
                     n_general / t, "increments/s", 1e3 * t / n_general,
                     "ms/increment"))  # fmt: skip
    options = ModelOptions()
    state = k0_state(options)
    plastic = triaxial(1e-3, 0.0)
    elastic = triaxial(-1e-4, 0.0)
    for label, deps in (("plastic", plastic), ("elastic", elastic)):
        for name, settings, rep in (("fast", FAST, 500), ("general", GENERAL, 50)):
            t = time_single(state, deps, settings, options, rep)
            rows.append((f"one strain-controlled {label} increment, {name} path", 1.0 / t,
                         "increments/s", 1e3 * t, "ms/increment"))  # fmt: skip
    for batch in (1, 1000, 100_000):
        for form in ("A", "B"):
            rate = time_moduli(batch, ModelOptions(anisotropy=form))
            rows.append((f"elastic stiffness D, batch {batch}, form {form}", rate,
                         "evaluations/s", 1e6 / rate, "us/evaluation"))  # fmt: skip

    width = max(len(r[0]) for r in rows)
    print(f"TIV benchmark ({platform.processor() or platform.machine()}, "
          f"Python {platform.python_version()}, numpy {np.__version__})")  # fmt: skip
    print(f"{'case':<{width}}  {'rate':>12}  {'unit':<14} {'cost':>10}  unit")
    for name, rate, unit, cost, cunit in rows:
        print(f"{name:<{width}}  {rate:12.1f}  {unit:<14} {cost:10.4f}  {cunit}")
    RESULTS.mkdir(parents=True, exist_ok=True)
    with open(RESULTS / "tiv_bench.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["case", "rate", "rate_unit", "cost", "cost_unit"])
        for row in rows:
            writer.writerow([row[0], f"{row[1]:.6g}", row[2], f"{row[3]:.6g}", row[4]])

    profile = cProfile.Profile()
    control = Control.strain(plastic)
    profile.enable()
    for _ in range(300):
        advance(state, control, TABLE1, options, FAST)
    profile.disable()
    buf = io.StringIO()
    pstats.Stats(profile, stream=buf).sort_stats("tottime").print_stats(12)
    (RESULTS / "tiv_bench_profile.txt").write_text(
        "cProfile of 300 plastic single-point increments (fast path)\n" + buf.getvalue()
    )
    print(f"wrote {RESULTS / 'tiv_bench.csv'} and tiv_bench_profile.txt")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
