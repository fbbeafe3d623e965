"""Why the per-step parallel kernels lose to the fused serial kernel on a few CPU cores (issue 20,
not a test): the fixed cost of a Taichi kernel launch and of a parallel loop on this machine.

The serial execution runs ``steps_per_call`` time steps in one kernel launch on one thread
(:func:`dem_taichi.kernels.step.run_steps_serial`). The parallel execution cannot: Taichi
parallelises only a kernel's top-level loops and has no barrier inside a kernel, so every time
step is three launches (:mod:`dem_taichi.kernels.parallel`: rebuild check, kick–drift, forces),
each passing about 30 device arrays, and each parallel loop ends with the thread pool's
synchronisation. This script measures those fixed costs, per launch and per parallel loop:

- a kernel that does nothing but touch one element, with 1, 10 and 30 ndarray arguments;
- the same with a Taichi field instead of an ndarray (no argument to pass);
- a parallel loop over 100 elements (one per thread: the synchronisation alone), launched
  directly and from a compute graph (``ti.graph``: no Python per dispatch).

Usage::

    .venv/bin/python benchmarks/bench_launch.py             # the machine's cores
    .venv/bin/python benchmarks/bench_launch.py --threads 1

Writes benchmarks/results/launch_bench.csv (one row per case, microseconds per launch).
"""

import argparse
import csv
import os
import platform
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


def _per_call(call, repeats: int) -> float:
    """Microseconds per call of ``call`` (after one warm-up call), the device synchronised."""
    import taichi as ti

    call()
    ti.sync()
    start = time.perf_counter()
    for _ in range(repeats):
        call()
    ti.sync()
    return (time.perf_counter() - start) / repeats * 1e6


def measure(repeats: int) -> list[dict]:
    import taichi as ti

    nd1 = ti.types.ndarray(dtype=ti.f64, ndim=1)
    arrays = [ti.ndarray(ti.f64, shape=(100,)) for _ in range(30)]
    field = ti.field(ti.f64, shape=100)

    @ti.kernel
    def touch_1(a0: nd1):
        a0[0] += 1.0

    @ti.kernel
    def touch_10(a0: nd1, a1: nd1, a2: nd1, a3: nd1, a4: nd1, a5: nd1, a6: nd1, a7: nd1, a8: nd1,
                 a9: nd1):  # fmt: skip
        a0[0] += 1.0

    @ti.kernel
    def touch_30(a0: nd1, a1: nd1, a2: nd1, a3: nd1, a4: nd1, a5: nd1, a6: nd1, a7: nd1, a8: nd1,
                 a9: nd1, a10: nd1, a11: nd1, a12: nd1, a13: nd1, a14: nd1, a15: nd1, a16: nd1,
                 a17: nd1, a18: nd1, a19: nd1, a20: nd1, a21: nd1, a22: nd1, a23: nd1, a24: nd1,
                 a25: nd1, a26: nd1, a27: nd1, a28: nd1, a29: nd1):  # fmt: skip
        a0[0] += 1.0

    @ti.kernel
    def touch_field():
        field[0] += 1.0

    @ti.kernel
    def parallel_loop(a0: nd1):
        for i in range(100):
            a0[i] += 1.0

    graph_dispatches = 300
    symbol = ti.graph.Arg(ti.graph.ArgKind.NDARRAY, "a0", dtype=ti.f64, ndim=1)
    builder = ti.graph.GraphBuilder()
    for _ in range(graph_dispatches):
        builder.dispatch(parallel_loop, symbol)
    graph = builder.compile()
    graph_us = _per_call(lambda: graph.run({"a0": arrays[0]}), max(1, repeats // 100))

    a = arrays
    cases = [
        ("serial kernel, 1 ndarray argument", _per_call(lambda: touch_1(a[0]), repeats)),
        ("serial kernel, 10 ndarray arguments", _per_call(lambda: touch_10(*a[:10]), repeats)),
        ("serial kernel, 30 ndarray arguments", _per_call(lambda: touch_30(*a), repeats)),
        ("serial kernel, a field (no argument)", _per_call(touch_field, repeats)),
        ("parallel loop of 100, 1 ndarray argument",
         _per_call(lambda: parallel_loop(a[0]), repeats)),
        ("parallel loop of 100, from a compute graph", graph_us / graph_dispatches),
    ]  # fmt: skip
    return [{"case": name, "us_per_launch": round(us, 2)} for name, us in cases]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--threads", type=int, default=0, help="CPU threads (0: every core)")
    parser.add_argument("--repeats", type=int, default=3000)
    args = parser.parse_args()
    import taichi as ti

    kwargs = {"cpu_max_num_threads": args.threads} if args.threads else {}
    ti.init(arch=ti.cpu, default_fp=ti.f64, log_level=ti.WARN, **kwargs)
    threads = args.threads or os.cpu_count()
    rows = [dict(row, threads=threads) for row in measure(args.repeats)]
    header = (
        f"# bench_launch.py: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Taichi {'.'.join(map(str, ti.__version__))}, {threads} threads"
    )
    out = RESULTS / ("launch_bench.csv" if not args.threads else f"launch_bench_{threads}t.csv")
    with open(out, "w", newline="") as handle:
        handle.write(header + "\n")
        writer = csv.DictWriter(handle, fieldnames=["case", "threads", "us_per_launch"])
        writer.writeheader()
        writer.writerows(rows)
    print(header)
    for row in rows:
        print(f"{row['us_per_launch']:9.2f} us  {row['case']}")
    print(f"written {out}")


if __name__ == "__main__":
    main()
