"""Path settings compared from one state A: the same gas, the same A, each variant's branches.

Usage::

    python benchmarks/paired_paths.py --scene paper --seed 3 \\
        --variant base= --variant safety1=protocol.inertial_number_safety=1.0 \\
        [--set section.key=value ...] [--branches isotropic,k0] [--workers 2] [--pool] \\
        --out FILE.json
    python benchmarks/paired_paths.py --from-run RUN_DIR \\
        --variant "k0=protocol.run_k0=true;protocol.run_unloading=true" --branches k0 \\
        --out FILE.json

The gas of the scene (with ``--set`` and the seed) is compressed to state A once, in this
process, and probed there; then, for each variant (``NAME=key=value;key=value``, ``NAME=`` for
the scene as given), the branches from A (A→B; A→C with C→B; each radial path, or those of
``--branches``) run in ``--workers`` processes from a checkpoint of A, with the variant's
``[protocol]``/``[probing]`` settings (the engine is the scene's: a variant may change only
those two sections, ``integration.dt_safety``, whose branches then run at the scaled Δt, and
``control.inertial_number_max``, the servo's rate cap, so every variant starts from the bitwise
same A). Writes, per variant: the
wall time of its branches, the steps and the work ledger (:mod:`dem_taichi.engine.work_profile`) per
stage, and the findings: those a run folder gives (λ*, the moduli exponent and E_v/p at B along
A→B; K0 = σ_xx/σ_yy at C; fabric and E_h/E_v along the paths; the mapped window...) and, at
each labelled state, its measures and moduli (v, p, q, fabric, E_v, E_h, E_h/E_v as
``<key>@<label>``), assembled by :mod:`dem_taichi.analysis.findings` from the same arrays as a
run folder's (:func:`~dem_taichi.analysis.findings.findings_from_arrays`), and the contact
overlaps δ/d of each labelled state's discs, rigid or bonded: the largest
(``max_overlap@<label>``), the mean and the 99th percentile over the touching pairs
(``mean_overlap@<label>``, ``p99_overlap@<label>``).
A finding a variant lacks (no A→B, no C) is null.

With ``--from-run RUN_DIR`` the gas is not compressed again: state A is a finished or interrupted
protocol run's (its ``resume/A.npz``, the run log, records and probes at A, and its
``state_A.npz``, the engine at A), and the base scene is that run's (``--scene``, ``--seed`` and
``--set`` are refused beside it). So paths a run did not take (its K0 path, a radial path) are
added from its A without the preparation again; a variant with no change (``base=``) gives the
run's own branches bit for bit (tested on the smoke protocol).

The paired differences over seeds are tabulated by ``benchmarks/paired_paths_table.py``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from multiprocessing import get_context
from pathlib import Path
from typing import TYPE_CHECKING

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/ is not a package
from jsonable import jsonable  # noqa: E402

if TYPE_CHECKING:
    from dem_taichi.protocol.records import RunLog

VARIANT_SECTIONS = ("protocol", "probing")
#: engine keys a variant may change as well, from the bitwise same A: with ``dt_safety`` the
#: branches integrate with the variant's Δt (the checkpoint's Δt × the ratio of dt_safety); with
#: ``inertial_number_max`` the stress servo's rate cap is the variant's (times the protocol's
#: servo safety), as a preset's is (``fast`` raises it to 3e-3)
VARIANT_KEYS = ("integration.dt_safety", "control.inertial_number_max")
#: the stages before A (run once per seed, shared by every variant)
BEFORE_A = ("aggregation", "isotropic_to_A")


def _branch(
    checkpoint: str, toml: str, label: str, state_a
) -> tuple[str, RunLog | None, float, float, str]:
    """Run one branch from the checkpoint of A with the variant's settings (a worker); returns
    its label, log, seconds, the Δt it integrated with and "" (or, when the branch stopped
    with a :class:`~dem_taichi.protocol.records.ProtocolError`, e.g. a servo that did not
    reach its target, or a :class:`~dem_taichi.engine.failures.BlowUpError`, e.g. a relaxation
    past the local stability limit: no log and the error's message, so the other branches are
    kept)."""
    from dem_taichi.engine.failures import BlowUpError
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.protocol.branches import run_branch_on
    from dem_taichi.protocol.paths import ProtocolRunner
    from dem_taichi.protocol.probing import ProbeRecorder
    from dem_taichi.protocol.records import Branch, ProtocolError, RunLog
    from dem_taichi.scene.config import scene_from_toml
    from dem_taichi.scene.probing_sections import probing_settings
    from dem_taichi.scene.protocol_sections import protocol_settings

    start = time.perf_counter()
    sim = Simulation.from_checkpoint(checkpoint)
    scene = scene_from_toml(toml)
    prepared = sim.scene.integration.dt_safety  # the scene that reached A
    if scene.integration.dt_safety != prepared:  # a time-step variant (VARIANT_KEYS)
        sim.set_parameters(time_step=sim.time_step * scene.integration.dt_safety / prepared)
    cap = scene.control.inertial_number_max
    if cap != sim.scene.control.inertial_number_max:  # a rate-cap variant: the servo reads it
        sim.scene = replace(sim.scene, control=replace(sim.scene.control, inertial_number_max=cap))
    config, probing = protocol_settings(scene), probing_settings(scene)
    log = RunLog()
    recorder = ProbeRecorder(probing, config, log)
    runner = ProtocolRunner(sim, config, probing, None, None, recorder, False, log=log)
    runner.state_A = sim.get_state()
    log.states["A"] = state_a
    try:
        run_branch_on(runner, Branch.parse(label))
    except (ProtocolError, BlowUpError) as error:
        return label, None, time.perf_counter() - start, sim.time_step, str(error)
    del log.states["A"]
    return label, log, time.perf_counter() - start, sim.time_step, ""


def _findings(result, particles) -> dict:
    """The findings of a variant's merged run (a ``ProtocolResult`` in memory): those a run
    folder gives (:func:`dem_taichi.analysis.findings.findings_from_arrays`, over the same
    arrays) and, for every labelled state, its measures and moduli as ``<key>@<label>``
    (:func:`dem_taichi.analysis.findings.states_from_arrays`). ``particles``: the scene's
    ``[particles]`` (the rod shape)."""
    from dem_taichi.analysis.findings import findings_from_arrays, states_from_arrays
    from dem_taichi.protocol.report import path_arrays, probe_arrays

    path, probes = path_arrays(result), probe_arrays(result)
    shape = (particles.n_spheres, particles.spacing, particles.diameter)
    out = findings_from_arrays(path, probes, result.n_rods, result.stress_scale_kpa, shape)
    for label, entry in states_from_arrays(path.states, probes).items():
        out.update({f"{key}@{label}": value for key, value in entry.items()})
    import numpy as np

    from dem_taichi.analysis.overlaps import disc_overlaps

    for label, snapshot in result.log.snapshots.items():  # the discs at each labelled state
        overlaps = disc_overlaps(
            snapshot["disc_positions"], particles.n_spheres, snapshot["cell_lengths"],
            particles.diameter,
        )  # fmt: skip
        out[f"max_overlap@{label}"] = float(overlaps.max()) if overlaps.size else 0.0
        # the distribution's mean and 99th percentile: far less noisy than its maximum
        out[f"mean_overlap@{label}"] = float(overlaps.mean()) if overlaps.size else 0.0
        out[f"p99_overlap@{label}"] = float(np.percentile(overlaps, 99)) if overlaps.size else 0.0
    return out


def _stage_a_of_run(folder: Path):
    """A protocol run's scene, its log at A (stages, path states and probes up to A), the
    checkpoint of its engine at A and the seconds it took to reach A (``--from-run``)."""
    from dem_taichi.io.checkpoint import checkpoint_meta
    from dem_taichi.protocol.resume import RunIdentity, load_stage_a
    from dem_taichi.scene.config import scene_from_toml

    record = json.loads((folder / "run.json").read_text())
    identity = RunIdentity(folder, record["run_id"], record["scene_sha256"])
    stage = load_stage_a(identity)
    checkpoint = folder / "state_A.npz"
    if stage is None or not checkpoint.exists():
        raise SystemExit(f"{folder}: no saved state A (resume/A.npz and state_A.npz)")
    scene = scene_from_toml(checkpoint_meta(checkpoint)["scene_toml"])
    return scene, stage.log, checkpoint, stage.seconds


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="paper")
    parser.add_argument("--set", action="append", default=[], dest="overrides")
    parser.add_argument("--variant", action="append", required=True)
    parser.add_argument("--branches", default="", help="comma-separated kinds to keep")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--from-run", type=Path, default=None, help="take A from this run")
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument(
        "--pool", action="store_true",
        help="run every variant's branches in one pool of --workers processes (the cores stay "
        "busy; per-variant wall time is then not measured, only each branch's seconds)",
    )  # fmt: skip
    args = parser.parse_args(argv)
    if args.from_run is None and args.seed is None:
        parser.error("--seed is required (or --from-run)")
    if args.from_run is not None and (args.seed is not None or args.overrides):
        parser.error("--from-run takes the run's scene: no --seed or --set beside it")

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
            path = key.split("=", 1)[0].strip()
            if path.split(".", 1)[0] not in VARIANT_SECTIONS and path not in VARIANT_KEYS:
                raise SystemExit(
                    f"variant {name}: {key}: only {VARIANT_SECTIONS} and {VARIANT_KEYS} may change"
                )
        variants[name] = keys
    args.out.parent.mkdir(parents=True, exist_ok=True)
    if args.from_run is not None:
        base, log, checkpoint, seconds_a = _stage_a_of_run(args.from_run)
        args.seed, args.scene = base.scene.seed, str(args.from_run)
        n_rods = base.particles.n_rods
    else:
        overrides = [*args.overrides, f"scene.seed={args.seed}"]
        base = scene_with_overrides(load_scene(args.scene), overrides)
        checkpoint = args.out.with_suffix(".state_A.npz")
        start = time.perf_counter()
        sim = Simulation(base)
        log = RunLog()
        config, probing = protocol_settings(base), probing_settings(base)
        recorder = ProbeRecorder(probing, config, log)
        runner = ProtocolRunner(sim, config, probing, None, None, recorder, False, log=log)
        runner.compress_to_transition()  # ends with the engine at A (as the protocol's workers)
        seconds_a = time.perf_counter() - start
        sim.save_checkpoint(checkpoint)
        n_rods = sim.n_rods
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
    plans = {}
    for name, keys in variants.items():
        scene = scene_with_overrides(base, keys)
        branches = branch_names(protocol_settings(scene))
        if args.branches:
            keep = set(args.branches.split(","))
            branches = [b for b in branches if b.kind in keep]
        plans[name] = (keys, scene, branches, scene_to_toml(scene))
    pooled: dict[tuple[str, str], tuple] = {}
    if args.pool:  # every variant's branches in one pool, the K0 branches (the longest) first
        jobs = [(name, b) for name, plan in plans.items() for b in plan[2]]
        jobs.sort(key=lambda job: job[1].kind != "k0")
        t0 = time.perf_counter()
        with ProcessPoolExecutor(args.workers, mp_context=context) as pool:
            submitted = [
                (name, pool.submit(_branch, str(checkpoint), plans[name][3], b.label, state_a))
                for name, b in jobs
            ]
            for name, future in submitted:
                outcome = future.result()
                pooled[(name, outcome[0])] = outcome
        print(f"[seed {args.seed}] all variants: {time.perf_counter() - t0:.0f} s", flush=True)
    for name, (keys, scene, branches, toml) in plans.items():
        if args.pool:
            outcomes = [pooled[(name, b.label)] for b in branches]  # the branches' own order
            wall = None  # the pool's wall is shared by the variants
        else:
            t0 = time.perf_counter()
            with ProcessPoolExecutor(args.workers, mp_context=context) as pool:
                futures = [
                    pool.submit(_branch, str(checkpoint), toml, b.label, state_a) for b in branches
                ]
                outcomes = [f.result() for f in futures]
            wall = time.perf_counter() - t0
        branch_seconds = {label: seconds for label, _, seconds, _, _ in outcomes}
        failed = {label: error for label, _, _, _, error in outcomes if error}
        if failed:  # a failed branch: its seconds up to the failure, no findings
            report["variants"][name] = {
                "settings": keys, "failed": failed, "branch_seconds": branch_seconds,
                "branch_process_seconds": sum(branch_seconds.values()),
            }  # fmt: skip
            print(f"[seed {args.seed}] {name}: FAILED {failed}", flush=True)
            args.out.write_text(json.dumps(jsonable(report), indent=1))
            continue
        merged = RunLog()
        merged.stages = {k: v for k, v in log.stages.items()}
        merged.states = {"A": state_a}
        merged.path_states = list(log.path_states)
        merged.probes = list(log.probes)
        merge_work(merged.work, log.work)  # a copy: the stage to A's ledger
        for _, branch_log, _, _, _ in outcomes:
            merged.merge(branch_log)
        result = ProtocolResult(
            out_dir=args.out.parent, scene_name=args.scene, pattern="", n_rods=n_rods,
            arch="cpu", precision="f64", log=merged,
            stress_scale_kpa=protocol_settings(scene).stress_scale_kpa,
        )  # fmt: skip
        report["variants"][name] = {
            "settings": keys,
            "branches_wall_seconds": wall,
            "branch_seconds": branch_seconds,
            "branch_process_seconds": sum(branch_seconds.values()),
            "time_step": sorted({o[3] for o in outcomes}),
            "steps": {k: v.steps for k, v in merged.stages.items()},
            "max_inertial_number": {k: v.max_inertial_number for k, v in merged.stages.items()},
            "work": merged.work,
            "findings": _findings(result, scene.particles),
        }
        process_seconds = sum(branch_seconds.values())
        shown = f"{wall:.0f} s" if wall is not None else f"{process_seconds:.0f} process-s"
        print(f"[seed {args.seed}] {name}: branches {shown}, steps "
              f"{sum(v.steps for k, v in merged.stages.items() if k not in BEFORE_A):,}",
              flush=True)  # fmt: skip
        args.out.write_text(json.dumps(jsonable(report), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
