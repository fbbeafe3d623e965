"""Benchmark of the elastic probes: linear response against the dynamic amplitude sweep.

For each scene: build a static packing (fast isotropic strain-controlled compression to
``--specific-volume``, then relaxation at fixed cell to UFR < 1e-9), or load a saved state
(``--state path.npz`` from a protocol run), then time

- the linear-response probe (``sim.snapshot()`` + ``linear_response``: the full 2D tensor), and
- the dynamic probe sweep it replaces (± probes on both axes over the ``[probing]`` amplitudes,
  each relaxed to ``relax_unbalanced_force``),

and report both moduli and the cost ratio. ``--protocol`` also runs the whole protocol of the
scene and reports its wall time by stage and in probing.

Not a test (not collected by pytest). Results: ``benchmarks/results/protocol_<scene>.json`` and a
markdown table on stdout. The CPU of the development machine is shared: timings are noisy.

Usage::

    python benchmarks/bench_protocol.py smoke default [--paper] [--protocol]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

RESULTS = Path(__file__).parent / "results"


def packed_simulation(scene_name: str, specific_volume: float, state: str | None):
    from dem_taichi.engine.simulation import CellControl, Simulation
    from dem_taichi.protocol.runner import relax
    from dem_taichi.scene.config import load_scene

    t0 = time.perf_counter()
    if state:
        sim = Simulation.from_checkpoint(state)
    else:
        sim = Simulation(load_scene(scene_name))
        while sim.measure()["specific_volume"] > specific_volume:
            sim.run(1000, CellControl.strain_rate(0.02, stage="isotropic_to_A"))
    measures, ok, steps = relax(sim, "relax", 1e-9, 1e-12, 500, 100_000)
    return sim, measures, ok, time.perf_counter() - t0


def bench_scene(scene_name: str, specific_volume: float, state: str | None) -> dict:
    from dem_taichi.protocol.probing import degradation_curve, linear_probe
    from dem_taichi.scene.probing_sections import probing_settings
    from dem_taichi.scene.protocol_sections import protocol_settings

    sim, measures, relaxed, build_seconds = packed_simulation(scene_name, specific_volume, state)
    probing = probing_settings(sim.scene)
    protocol = protocol_settings(sim.scene)
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        linear = linear_probe(sim, probing.sliding_contacts)
        times.append(time.perf_counter() - t0)
    linear_seconds = min(times)
    step0 = sim.step
    t0 = time.perf_counter()
    curves = {axis: degradation_curve(sim, axis, probing, protocol) for axis in ("y", "x")}
    dynamic_seconds = time.perf_counter() - t0
    steps = sum(c.steps for c in curves.values())
    assert sim.step == step0  # the state was restored
    return {
        "scene": scene_name,
        "n_rods": sim.n_rods,
        "state": state or f"packed to v < {specific_volume}",
        "build_seconds": build_seconds,
        "relaxed": bool(relaxed),
        "mean_stress": measures["mean_stress"],
        "specific_volume": measures["specific_volume"],
        "amplitudes": list(probing.amplitudes),
        "linear_seconds": linear_seconds,
        "linear_solver_seconds": linear.solver.seconds,
        "dynamic_seconds": dynamic_seconds,
        "dynamic_steps": int(steps),
        "dynamic_steps_per_second": steps / dynamic_seconds,
        "cost_ratio_dynamic_over_linear": dynamic_seconds / linear_seconds,
        "e_oed_v_linear": linear.e_oed_v,
        "e_oed_h_linear": linear.e_oed_h,
        "e_oed_v_dynamic": curves["y"].plateau.modulus,
        "e_oed_h_dynamic": curves["x"].plateau.modulus,
        "e_oed_v_curve": curves["y"].moduli.tolist(),
        "e_oed_h_curve": curves["x"].moduli.tolist(),
        "elastic_limit_v": curves["y"].plateau.elastic_limit,
        "elastic_limit_h": curves["x"].plateau.elastic_limit,
    }


def bench_protocol(scene_name: str, out: Path) -> dict:
    from dem_taichi.protocol.runner import run_protocol

    result = run_protocol(scene_name, out, progress=True, overwrite=True)
    total = result.total_seconds
    return {
        "scene": scene_name,
        "total_seconds": total,
        "stages": {
            k: {"seconds": v.seconds, "share": v.seconds / total, "steps": v.steps}
            for k, v in result.stages.items()
        },  # fmt: skip
        "probing_seconds": result.probing_seconds,
        "probing_share": result.probing_seconds / total,
        "probing_dynamic_seconds": result.probing_dynamic_seconds,
        "probing_linear_seconds": result.probing_linear_seconds,
        "report": str(result.files.get("report")),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scenes", nargs="*", default=["smoke"])
    parser.add_argument("--specific-volume", type=float, default=1.75)
    parser.add_argument("--state", default=None, help="checkpoint of a relaxed state (.npz)")
    parser.add_argument("--protocol", action="store_true", help="also time the whole protocol")
    parser.add_argument("--out", default="/tmp/bench_protocol")
    args = parser.parse_args()
    RESULTS.mkdir(parents=True, exist_ok=True)
    machine = {
        "platform": platform.platform(),
        "cpu_count": os.cpu_count(),
        "note": "shared CPU: other processes ran at the same time, timings are noisy",
    }
    print("| scene | rods | p | linear (s) | dynamic sweep (s) | ratio | E_v lin | E_v dyn "
          "| E_h lin | E_h dyn |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in args.scenes:
        row = bench_scene(name, args.specific_volume, args.state)
        if args.protocol:
            row["protocol"] = bench_protocol(name, Path(args.out) / name)
        row["machine"] = machine
        suffix = "_state" if args.state else ""
        (RESULTS / f"protocol_{name}{suffix}.json").write_text(json.dumps(row, indent=2))
        print(
            f"| {name} | {row['n_rods']} | {row['mean_stress']:.4g} | "
            f"{row['linear_seconds']:.3f} | {row['dynamic_seconds']:.1f} | "
            f"{row['cost_ratio_dynamic_over_linear']:.0f} | {row['e_oed_v_linear']:.5g} | "
            f"{row['e_oed_v_dynamic']:.5g} | {row['e_oed_h_linear']:.5g} | "
            f"{row['e_oed_h_dynamic']:.5g} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
