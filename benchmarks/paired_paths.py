"""Path settings compared from one state A: the same gas, the same A, each variant's branches.

Usage::

    python benchmarks/paired_paths.py --scene paper --seed 3 \\
        --variant base= --variant safety1=protocol.inertial_number_safety=1.0 \\
        [--set section.key=value ...] [--branches isotropic,k0] [--workers 2] --out FILE.json

The gas of the scene (with ``--set`` and the seed) is compressed to state A once, in this
process, and probed there; then, for each variant (``NAME=key=value;key=value``, ``NAME=`` for
the scene as given), the branches from A (A→B; A→C with C→B; each radial path, or those of
``--branches``) run in ``--workers`` processes from a checkpoint of A, with the variant's
``[protocol]``/``[probing]`` settings (the engine is the scene's: a variant may change only
those two sections, so every variant starts from the bitwise same A). Writes, per variant: the
wall time of its branches, the steps and the work ledger (:mod:`dem_taichi.engine.work_profile`) per
stage, and the findings (v, p, q, fabric, E_v, E_h, E_h/E_v at each labelled state; λ*, the
moduli exponent and E_v/p at B along A→B; K0 = σ_xx/σ_yy at C), computed by the functions of
:mod:`dem_taichi.analysis.arrays` that the run reports use.

The paired differences over seeds are tabulated by ``benchmarks/paired_paths_table.py``.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from dem_taichi.protocol.records import RunLog

VARIANT_SECTIONS = ("protocol", "probing")


def _branch(checkpoint: str, toml: str, label: str, state_a) -> tuple[str, RunLog, float]:
    """Run one branch from the checkpoint of A with the variant's settings (a worker)."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.protocol.branches import run_branch_on
    from dem_taichi.protocol.paths import ProtocolRunner
    from dem_taichi.protocol.probing import ProbeRecorder
    from dem_taichi.protocol.records import Branch, RunLog
    from dem_taichi.scene.config import scene_from_toml
    from dem_taichi.scene.probing_sections import probing_settings
    from dem_taichi.scene.protocol_sections import protocol_settings

    start = time.perf_counter()
    sim = Simulation.from_checkpoint(checkpoint)
    scene = scene_from_toml(toml)
    config, probing = protocol_settings(scene), probing_settings(scene)
    log = RunLog()
    recorder = ProbeRecorder(probing, config, log)
    runner = ProtocolRunner(sim, config, probing, None, None, recorder, False, log=log)
    runner.state_A = sim.get_state()
    log.states["A"] = state_a
    run_branch_on(runner, Branch.parse(label))
    del log.states["A"]
    return label, log, time.perf_counter() - start


def _findings(result) -> dict:
    from dem_taichi.analysis.arrays import (
        compressibility_slope,
        modulus_over_p_at,
        power_law_exponent,
        stiffness_ratio,
        stress_ratio_at,
    )
    from dem_taichi.protocol.report import path_arrays, probe_arrays

    path, probes = path_arrays(result), probe_arrays(result)
    on_iso = probes.isotropic()
    out: dict = {}
    if path.from_a("A_to_B", "mean_stress").size > 1:
        fit = compressibility_slope(
            path.from_a("A_to_B", "mean_stress"), path.from_a("A_to_B", "specific_volume")
        )
        out["lambda_star"] = fit["lambda_star"]
        out["modulus_exponent"] = power_law_exponent(
            probes.mean_stress[on_iso], probes.e_oed_v[on_iso]
        )
        out["ev_over_p_B"] = modulus_over_p_at(probes, "B")
    if "C" in path.states:
        out["k0_C"] = stress_ratio_at(path, "C")
    for label, state in result.states.items():
        m = state.measures
        e_v, e_h = probes.moduli_at(label)
        for key in ("specific_volume", "mean_stress", "deviatoric_stress", "fabric_deviator"):
            out[f"{key}@{label}"] = float(m[key])
        out[f"e_oed_v@{label}"] = e_v
        out[f"e_oed_h@{label}"] = e_h
        out[f"e_ratio@{label}"] = float(stiffness_ratio(e_h, e_v))
    return out


def _jsonable(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    return value


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="paper")
    parser.add_argument("--seed", type=int, required=True)
    parser.add_argument("--set", action="append", default=[], dest="overrides")
    parser.add_argument("--variant", action="append", required=True)
    parser.add_argument("--branches", default="", help="comma-separated kinds to keep")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)

    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.engine.work_profile import merge_work
    from dem_taichi.protocol.branches import branch_names
    from dem_taichi.protocol.paths import ProtocolRunner
    from dem_taichi.protocol.probing import ProbeRecorder
    from dem_taichi.protocol.records import ProtocolResult, RunLog
    from dem_taichi.scene.config import load_scene, scene_to_toml, scene_with_overrides
    from dem_taichi.scene.probing_sections import probing_settings
    from dem_taichi.scene.protocol_sections import protocol_settings

    variants: dict[str, list[str]] = {}
    for item in args.variant:
        name, _, settings = item.partition("=")
        keys = [s for s in settings.split(";") if s]
        for key in keys:
            if key.split(".", 1)[0] not in VARIANT_SECTIONS:
                raise SystemExit(f"variant {name}: {key}: only {VARIANT_SECTIONS} may change")
        variants[name] = keys
    overrides = [*args.overrides, f"scene.seed={args.seed}"]
    base = scene_with_overrides(load_scene(args.scene), overrides)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    checkpoint = args.out.with_suffix(".state_A.npz")

    start = time.perf_counter()
    sim = Simulation(base)
    log = RunLog()
    config, probing = protocol_settings(base), probing_settings(base)
    recorder = ProbeRecorder(probing, config, log)
    runner = ProtocolRunner(sim, config, probing, None, None, recorder, False, log=log)
    runner.compress_to_transition()  # ends with the engine at A (as the protocol's workers use)
    seconds_a = time.perf_counter() - start
    sim.save_checkpoint(checkpoint)
    state_a = log.states["A"]
    print(
        f"[seed {args.seed}] A: p={state_a.measures['mean_stress']:.4g} "
        f"v={state_a.measures['specific_volume']:.4f} in {seconds_a:.0f} s",
        flush=True,
    )

    report = {"scene": args.scene, "seed": args.seed, "overrides": args.overrides,
              "seconds_to_A": seconds_a, "steps_to_A": log.stages["isotropic_to_A"].steps,
              "variants": {}}  # fmt: skip
    context = get_context("spawn")
    for name, keys in variants.items():
        scene = scene_with_overrides(base, keys)
        branches = branch_names(protocol_settings(scene))
        if args.branches:
            keep = set(args.branches.split(","))
            branches = [b for b in branches if b.kind in keep]
        toml = scene_to_toml(scene)
        t0 = time.perf_counter()
        with ProcessPoolExecutor(args.workers, mp_context=context) as pool:
            futures = [
                pool.submit(_branch, str(checkpoint), toml, b.label, state_a) for b in branches
            ]
            outcomes = [f.result() for f in futures]
        wall = time.perf_counter() - t0
        merged = RunLog()
        merged.stages = {k: v for k, v in log.stages.items()}
        merged.states = {"A": state_a}
        merged.path_states = list(log.path_states)
        merged.probes = list(log.probes)
        merge_work(merged.work, log.work)  # a copy: the stage to A's ledger
        branch_seconds = {}
        for label, branch_log, seconds in outcomes:
            merged.merge(branch_log)
            branch_seconds[label] = seconds
        result = ProtocolResult(
            out_dir=args.out.parent, scene_name=args.scene, pattern="", n_rods=sim.n_rods,
            arch="cpu", precision="f64", log=merged,
        )  # fmt: skip
        report["variants"][name] = {
            "settings": keys,
            "branches_wall_seconds": wall,
            "branch_seconds": branch_seconds,
            "steps": {k: v.steps for k, v in merged.stages.items()},
            "max_inertial_number": {k: v.max_inertial_number for k, v in merged.stages.items()},
            "work": merged.work,
            "findings": _findings(result),
        }
        print(f"[seed {args.seed}] {name}: branches {wall:.0f} s, steps "
              f"{sum(v.steps for k, v in merged.stages.items() if k != 'isotropic_to_A'):,}",
              flush=True)  # fmt: skip
        args.out.write_text(json.dumps(_jsonable(report), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
