"""Virtual experiments of the study on the DEM engine (docs/science/dem-model.md §1.6): the loading
paths.

Stages (stage labels of :data:`dem_taichi.io.schema.STAGE_CODES`):

1. ``isotropic_to_A`` — from the gas, isotropic strain-controlled compression in increments of
   per-axis logarithmic strain h, each followed by a relaxation at fixed cell. A relaxed state is
   a candidate for the fluid–solid transition when p > ``pressure_tolerance`` and
   Z_m ≥ ``coordination_min``. On a candidate found with h > ``min_compression_increment`` the
   sample is restored to the previous relaxed state and h is halved (bisection of the
   transition); at the smallest h a candidate becomes **A** when p stays above the tolerance over
   the next ``confirm_increments`` relaxed increments (then the sample is restored to the
   candidate). The rule is :func:`dem_taichi.analysis.arrays.detect_transition`, which is re-applied
   to the whole relaxed sequence and recorded (with p, Z_m and the Z_m jump) in the results.
2. ``A_to_B`` — isotropic stress path, σ_xx = σ_yy = p_k, p_k log-spaced from p_A to
   ``target_mean_stress`` (state **B**).
3. ``A_to_C`` — K0 (oedometric) path from A: L_x never changes (ε_xx = ε_xx(A) exactly),
   σ_yy servoed up log-spaced targets, the last target being p = ``target_mean_stress``
   (state **C**).
4. ``C_to_B`` — from C, both axes servoed: p = p_C constant, q decreasing linearly to 0
   (state **B'**).
5. ``radial`` — from A (the stored state), p increasing log-spaced to ``target_mean_stress`` at
   constant η = q/p: σ_yy = p (1 + η/2), σ_xx = p (1 − η/2) (states **R<k>_end**).

Where each part lives: the quasi-static building blocks in :mod:`dem_taichi.protocol.quasistatic`,
the stress servo in :mod:`dem_taichi.protocol.servo`, the paths in :mod:`dem_taichi.protocol.paths`
(:class:`ProtocolRunner`), the branches from A and their processes in
:mod:`dem_taichi.protocol.branches`, the records in :mod:`dem_taichi.protocol.records`; this module
runs the whole experiment and writes its results (:func:`run_protocol`, ``python -m
dem_taichi.protocol``). Quasi-static checks: every history record carries the inertial number and
the UFR, and
:class:`ProtocolResult` keeps their maxima per stage.

Outputs in ``out_dir``: ``history.nc`` (every loading output step and every relaxed state),
``relaxed_states.nc`` (one record per relaxed path state, same schema), ``probes.nc``,
``configuration_<label>.nc`` at A, B, C, B', R<k>_end, ``paraview/state_<label>.vtu`` (the
discs at those states, :mod:`dem_taichi.io.vtk_snapshots`) with ``paraview/states.pvd``,
``figure_paths.png`` (study Figure 1),
``figure_states.png`` (study Figure 2), ``report.md`` and ``summary.json``.

Symbols: σ stress (force/length, compression positive), p = (σ_xx+σ_yy)/2, q = σ_yy − σ_xx,
η = q/p, ε logarithmic strain (compression positive), v specific volume, Z_m mechanical
coordination number, UFR unbalanced-force ratio, I inertial number.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import signal
import sys
import time
from pathlib import Path

from dem_taichi.protocol.branches import (
    BranchOutcome,
    branch_labels,
    branch_names,
    merge_branch,
    run_branch,
    run_branch_saved,
    run_branches_in_processes,
)
from dem_taichi.protocol.paths import ProtocolRunner
from dem_taichi.protocol.quasistatic import apply_strain, relax, strain_rate_cap
from dem_taichi.protocol.records import (
    ProtocolError,
    ProtocolResult,
    RelaxedState,
    RunLog,
    StageRecord,
    _jsonable,
)
from dem_taichi.protocol.resume import (
    AgeingPoint,
    RecordingWriter,
    RunIdentity,
    StageA,
    load_ageing,
    load_branches,
    load_stage_a,
    refuse_pickles,
    save_ageing,
    save_stage_a,
    saved_summary,
)
from dem_taichi.protocol.servo import SecantStiffness
from dem_taichi.scene.config import Scene, builtin_scene_names, load_scene, scene_to_toml
from dem_taichi.scene.options import add_preset_option, scene_from_options
from dem_taichi.scene.probing_sections import probing_settings
from dem_taichi.scene.protocol_sections import protocol_settings

# the names of the protocol before it was split into rooms (issue 9) stay importable from here
__all__ = [
    "ProtocolError",
    "RelaxedState",
    "StageRecord",
    "ProtocolResult",
    "RunLog",
    "ProtocolRunner",
    "relax",
    "apply_strain",
    "strain_rate_cap",
    "SecantStiffness",
    "run_protocol",
    "run_branch",
    "branch_names",
    "BranchOutcome",
    "main",
]


def _with_pattern(scene: Scene, pattern: str | None) -> Scene:
    if pattern is None or pattern == scene.long_range.pattern:
        return scene
    if pattern not in ("acidic", "basic", "neutral"):
        raise ValueError(f"pattern = {pattern!r}: allowed values are acidic | basic | neutral")
    return scene.replace(long_range={"pattern": pattern})


def _file_label(label: str) -> str:
    return label.replace("'", "_prime")


def run_protocol(
    scene: Scene | str | Path,
    out_dir: str | Path,
    arch: str = "cpu",
    precision: str = "f64",
    progress: bool = False,
    pattern: str | None = None,
    # the run record's name (kept from the flat layout: older runs resume)
    command: str = "dem_taichi.protocol.run_protocol",
    workers: int = 1,
    overwrite: bool = False,
    resume: bool = False,
) -> ProtocolResult:
    """Run the whole protocol of a scene and write its results to ``out_dir``.

    ``scene`` is a :class:`Scene`, a TOML path or a built-in scene name; ``pattern`` overrides the
    scene's charge pattern (acidic | basic | neutral). Returns a :class:`ProtocolResult`.

    ``workers`` > 1 runs the branches that start from A (A→B; A→C with C→B; each radial path)
    in that many processes at once (see :func:`run_branch`); their results are merged in the
    order of the serial run, and equal it (the serial engine is deterministic and every branch
    starts from the same state A). Stage wall times then overlap, so they add up to more than
    the total.

    ``out_dir`` must not hold a run already (:mod:`dem_taichi.io.run_directory`: ``run.json``,
    ``history.nc`` or ``checkpoints/``) unless ``overwrite``, which deletes that run's files
    first; the run's id and scene hash are written to ``out_dir/run.json``.

    ``resume`` continues the interrupted protocol run in ``out_dir`` (the same scene only):
    from its saved state A, running only the branches without a saved outcome
    (:mod:`dem_taichi.protocol.resume`); the outputs equal those of an uninterrupted run. A run
    stopped before A goes on from its last save inside the aggregation stage (``ageing.npz``)
    when there is one, else starts again from the gas. The resume files are data only and must
    carry this run's id and scene hash; a damaged or foreign one is refused with one line naming it
    (:class:`dem_taichi.protocol.resume.ResumeFileError`).
    """
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.io import (
        HistoryWriter,
        provenance_attrs,
        start_run,
        write_configuration,
        write_dataset,
    )
    from dem_taichi.io.run_directory import reopen_run
    from dem_taichi.protocol.cost import check_cost, cost_lines
    from dem_taichi.protocol.probing import ProbeRecorder, probes_dataset

    start = time.perf_counter()
    if not (isinstance(workers, int) and workers >= 1):
        raise ValueError(f"workers = {workers!r}: allowed values are integers >= 1")
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    scene = _with_pattern(scene, pattern)
    config = protocol_settings(scene)
    probing = probing_settings(scene)
    cost = check_cost(scene, "protocol", precision)  # refuses what memory cannot hold
    if resume and overwrite:
        raise ValueError(
            "resume and overwrite exclude each other: resume continues the run in out_dir, "
            "overwrite replaces it; give one of them"
        )
    if resume:
        run_dir = reopen_run(out_dir, "protocol", scene.scene.name, scene_to_toml(scene))
    else:
        run_dir = start_run(
            out_dir, "protocol", scene.scene.name, scene_to_toml(scene), overwrite=overwrite
        )
    with run_dir:  # manifest completed, lock released when this returns or raises
        if resume:
            refuse_pickles(run_dir.path)
            identity = RunIdentity.of(run_dir)
            saved_a = load_stage_a(identity)
            done = load_branches(identity, branch_names(config)) if saved_a is not None else {}
            saved_ageing = load_ageing(identity) if saved_a is None else None
        else:
            identity = RunIdentity.of(run_dir)
            saved_a, done, saved_ageing = None, {}, None
        out = run_dir.path
        effective_pattern = scene.long_range.pattern if scene.long_range.enabled else "neutral"
        log = RunLog()  # the one log of the run: the runner and the probe recorder write it
        result = ProtocolResult(
            out_dir=out,
            scene_name=scene.scene.name,
            pattern=effective_pattern,
            n_rods=scene.particles.n_rods,
            arch=arch,
            precision=precision,
            stress_scale_kpa=config.stress_scale_kpa,
            log=log,
        )
        import taichi as ti  # after the checks above: a bad input is refused without waiting for it

        attrs = provenance_attrs(
            scene.source_text or scene_to_toml(scene),
            arch,
            precision,
            scene.scene.seed,
            command,
            taichi_version=".".join(str(x) for x in ti.__version__),
            title="DEM virtual experiments of 2D rod-shaped clay particles: protocol history",
        )
        attrs["scene_toml_effective"] = scene_to_toml(scene)
        attrs["charge_pattern"] = effective_pattern
        attrs["run_id"] = run_dir.run_id
        attrs["stress_scale_kpa"] = config.stress_scale_kpa
        attrs["stress_scale"] = (
            f"one DEM stress unit (force/length) = {config.stress_scale_kpa:g} kPa"
        )
        attrs["strain_reference"] = (
            "cell at the start of the run until state A, then the cell at state A"
        )
        sim = Simulation(scene, arch=arch, precision=precision)
        if progress:  # once the engine is built: its errors come first
            for line in cost_lines(cost):
                print(line, file=sys.stderr, flush=True)
        recorder = ProbeRecorder(probing, config, log)
        attrs["rod_model"] = scene.particles.rod_model
        variables = sim.history_variables
        history = HistoryWriter(out / "history.nc", attrs=attrs, sync_every=20, variables=variables)
        relaxed_attrs = dict(attrs, title=attrs["title"].replace("history", "relaxed path states"))
        relaxed = HistoryWriter(
            out / "relaxed_states.nc", attrs=relaxed_attrs, sync_every=1, variables=variables
        )
        recording, recording_relaxed = RecordingWriter(history), RecordingWriter(relaxed)
        runner = ProtocolRunner(
            sim, config, probing, recording, recording_relaxed, recorder, progress, log=log
        )
        runner.out_dir = out
        branches = branch_names(config)
        try:
            if saved_a is None:
                if saved_ageing is None:
                    recording.append(sim.measure() | {"stage": "gas"})
                else:
                    start -= saved_ageing.seconds  # the wall time counts the run's time so far
                    _restore_ageing(runner, saved_ageing, recording, recording_relaxed)

                def save_point(progress: dict) -> None:  # inside the aggregation stage
                    save_ageing(
                        identity,
                        AgeingPoint(
                            recording.records,
                            recording_relaxed.records,
                            log,
                            runner.sim.get_state(),
                            time.perf_counter() - start,
                            progress,
                        ),
                    )

                runner.save_point = save_point
                runner.compress_to_transition()
                runner.save_point = None
                assert runner.state_A is not None  # compress_to_transition ends at A
                save_stage_a(
                    identity,
                    StageA(
                        recording.records,
                        recording_relaxed.records,
                        log,
                        runner.state_A,
                        time.perf_counter() - start,
                    ),
                )
            else:
                start -= saved_a.seconds  # the wall time counts the run's time up to A
                _restore_stage_a(runner, saved_a, history, relaxed)
                runner._say(
                    f"[resume] from state A; branches done: {branch_labels(done) or 'none'}; to "
                    f"run: {branch_labels(b for b in branches if b not in done) or 'none'}"
                )
            runner.history, runner.relaxed_writer = history, relaxed
            if workers == 1 or len(branches) < 2:
                for index, branch in enumerate(branches):
                    if branch in done:
                        merge_branch(runner, history, relaxed, done[branch])
                    else:
                        run_branch_saved(runner, branch, index, identity)
            else:
                run_branches_in_processes(
                    runner, history, relaxed, branches, workers, arch, precision, progress,
                    identity, done,
                )  # fmt: skip
        finally:
            history.close()
            relaxed.close()
        # stage wall times exclude the probes (timed apart by the recorder)
        for label, checkpoint in log.checkpoints.items():
            result.files[f"state_{label}"] = checkpoint
        result.files["history"] = str(out / "history.nc")
        result.files["relaxed_states"] = str(out / "relaxed_states.nc")
        # configurations at the labelled states, taken when they were reached
        for label, state in log.states.items():
            positions, angles, lengths = log.configurations[label]
            m = state.measures
            geo = sim.geometry
            path = out / f"configuration_{_file_label(label)}.nc"
            write_configuration(
                path,
                positions,
                angles,
                lengths,
                attrs={
                    "title": f"DEM configuration at state {label}",
                    "state_label": label,
                    "path": state.stage,
                    "step": int(m["step"]),
                    "mean_stress": float(m["mean_stress"]),
                    "deviatoric_stress": float(m["deviatoric_stress"]),
                    "specific_volume": float(m["specific_volume"]),
                    "fabric_deviator": float(m["fabric_deviator"]),
                    "n_spheres": int(geo.n_spheres),
                    "rod_model": scene.particles.rod_model,
                    "spacing": float(geo.spacing),
                    "diameter": float(geo.diameter),
                    "charge_pattern": effective_pattern,
                    "stress_scale_kpa": float(config.stress_scale_kpa),
                },
            )
            result.files[f"configuration_{label}"] = str(path)
        _write_paraview(out, log)
        if log.snapshots:
            result.files["paraview"] = str(out / "paraview" / "states.pvd")
        if log.probes:
            probe_attrs = dict(attrs, title="DEM elastic probes at states of the loading paths")
            ds = probes_dataset(log.probes, recorder.amplitudes, probing, probe_attrs)
            write_dataset(out / "probes.nc", ds)
            result.files["probes"] = str(out / "probes.nc")
        result.workers = min(workers, len(branches)) if len(branches) > 1 else 1
        result.total_seconds = time.perf_counter() - start
        _write_figures_and_report(result, sim)
        (out / "summary.json").write_text(json.dumps(result.summary(), indent=2, default=_jsonable))
        result.files["summary"] = str(out / "summary.json")
        return result


def _restore_ageing(runner: ProtocolRunner, saved: AgeingPoint, history, relaxed) -> None:
    """Put a resumed run where it was at its last save inside the aggregation stage: the
    records so far written again (through the recording writers, so that later saves hold
    them), the run's log, the engine's state, and where the stage stood (aged: the stage is
    skipped; ageing: it goes on from that check, :func:`dem_taichi.protocol.aggregation.
    aggregate`)."""
    _restore_saved(runner, saved, history, relaxed)
    progress = saved.progress
    if progress["phase"] == "aged":
        runner.aggregation_details = dict(progress["details"])
        runner._since_output = int(progress["since_output"])
        where = "after the aggregation stage"
    else:
        runner.resume_ageing = dict(progress)
        where = f"inside the aggregation stage, at check {int(progress['check'])}"
    runner._say(f"[resume] from the save {where} (state A was not reached)")


def _restore_stage_a(runner: ProtocolRunner, saved: StageA, history, relaxed) -> None:
    """Put a resumed run where it was at state A: the history files' records up to A written
    again, the run's log at A, the engine's state at A."""
    _restore_saved(runner, saved, history, relaxed)
    runner.state_A = saved.state


def _restore_saved(runner: ProtocolRunner, saved: StageA | AgeingPoint, history, relaxed) -> None:
    """What every resume point restores: its history and relaxed-state records appended to
    ``history`` and ``relaxed`` (the files' writers, or recording writers that keep them for
    later saves), the run's log, the simulation's work ledger and the engine's state."""
    for record in saved.history:
        history.append(record)
    for record in saved.relaxed:
        relaxed.append(record)
    for f in dataclasses.fields(saved.log):
        setattr(runner.log, f.name, getattr(saved.log, f.name))
    runner.sim.work = runner.log.work  # the saved ledger goes on filling
    runner.sim.set_state(saved.state)


def _write_paraview(out: Path, log: RunLog) -> None:
    """The labelled states' discs as ParaView files: ``paraview/state_<label>.vtu`` and the
    series ``paraview/states.pvd`` in the order the states were reached (meshio needed)."""
    if not log.snapshots:
        return
    from dem_taichi.io.vtk_snapshots import write_pvd, write_snapshot

    folder = out / "paraview"
    files = []
    for label, state in log.states.items():
        if label not in log.snapshots:
            continue
        m = state.measures
        fields = {k: float(m[k]) for k in ("mean_stress", "deviatoric_stress", "specific_volume")}
        path = folder / f"state_{_file_label(label)}.vtu"
        files.append(
            (label, write_snapshot(path, **log.snapshots[label], stage=state.stage, fields=fields))
        )
    write_pvd(folder / "states.pvd", files)


def _write_figures_and_report(result: ProtocolResult, sim) -> None:
    from dem_taichi.protocol.report import write_figures, write_report

    try:
        result.files.update(write_figures(result, sim.geometry))
    except Exception as exc:  # noqa: BLE001 - figures must not lose a finished run
        result.files["figures_error"] = f"{type(exc).__name__}: {exc}"
    rods = sim.scene.particles
    shape = (rods.n_spheres, rods.spacing, rods.diameter)
    result.files["report"] = str(write_report(result, rod_shape=shape))


def _parser(prog: str) -> argparse.ArgumentParser:
    from clay_cli import ArgumentParser, add_common_flags, int_in_range

    parser = ArgumentParser(
        prog=prog,
        description="Run the study's virtual experiments (gas -> A -> A-B, A-C, C-B, radial) "
        "with elastic probes; write history, probes, configurations, figures and a report.",
    )
    parser.add_argument(
        "scene", help=f"scene TOML file or built-in name ({', '.join(builtin_scene_names())})"
    )
    parser.add_argument("--out", required=True, help="output directory (one run per directory)")
    parser.add_argument("--arch", default="cpu", choices=("cpu", "gpu"), help="device (cpu)")
    parser.add_argument(
        "--precision", default="f64", choices=("f64", "f32"), help="floating point (f64)"
    )
    parser.add_argument(
        "--pattern", default=None, choices=("acidic", "basic", "neutral"),
        help="charge pattern (overrides the scene's [long_range] pattern)",
    )  # fmt: skip
    parser.add_argument(
        "--workers", type=int_in_range(1), default=1,
        help="processes for the paths from A (A-B, A-C-B', radial) run at once (default 1)",
    )  # fmt: skip
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the run already in --out (else a used --out is refused)",
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="override a scene key, e.g. --set protocol.radial_stress_ratios='\"0.3\"' or "
        "--set scene.seed=4 (repeatable; validated as the file)",
    )
    parser.add_argument(
        "--resume",
        action="store_true",
        help="continue the interrupted run in --out (the same scene and options): from its "
        "saved state A, only the branches not finished (dem_taichi.protocol.resume)",
    )
    add_preset_option(parser)
    add_common_flags(parser)
    return parser


def _main(argv: list[str], prog: str) -> int:
    from clay_cli import UsageError, refuse_control_characters

    refuse_control_characters(argv)
    args = _parser(prog).parse_args(argv)
    command = f"{prog} " + " ".join(argv)
    scene = scene_from_options(args.scene, args.preset, args.set)
    if args.resume and args.overwrite:
        raise UsageError(
            "--resume and --overwrite exclude each other: --resume continues the run in --out, "
            "--overwrite replaces it; give one of them"
        )
    received: list[int] = []

    def on_signal(signum, frame):
        received.append(signum)
        raise KeyboardInterrupt

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        result = run_protocol(
            scene,
            args.out,
            arch=args.arch,
            precision=args.precision,
            progress=not args.quiet,
            pattern=args.pattern,
            command=command,
            workers=args.workers,
            overwrite=args.overwrite,
            resume=args.resume,
        )
    except KeyboardInterrupt:
        name = signal.Signals(received[0]).name if received else "SIGINT"
        again = [a for a in argv if a != "--overwrite"] + ([] if args.resume else ["--resume"])
        saved = saved_summary(args.out, branch_names(protocol_settings(scene)))
        print(
            f"{prog}: {name}: stopped; {saved} in {Path(args.out) / 'resume'}; continue with: "
            f"{prog} {' '.join(again)}",
            file=sys.stderr,
        )
        return 128 + (received[0] if received else signal.SIGINT)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    if args.quiet:
        return 0
    print(f"protocol done in {result.total_seconds:.1f} s; results in {result.out_dir}")
    for label, state in result.states.items():
        m = state.measures
        print(
            f"  {label:7s} p={m['mean_stress']:.5g} q={m['deviatoric_stress']:.5g} "
            f"v={m['specific_volume']:.5f} fabric={m['fabric_deviator']:+.4f}"
        )
    return 0


def main(argv: list[str] | None = None, prog: str = "python -m dem_taichi.protocol") -> int:
    """``python -m dem_taichi.protocol SCENE --out DIR [--arch] [--precision] [--pattern]
    [--workers] [--overwrite] [--quiet] [--debug]``; returns the exit code.

    One error handler (:mod:`clay_cli`): bad input is one line with exit code 2,
    a stage that cannot reach its goal (:class:`ProtocolError`) exit code 1, a blow-up exit
    code 3. SIGINT (Ctrl-C) or SIGTERM stops the run: the files written so far are closed and
    one line says what is saved and the command that resumes it (``--resume``); exit code
    128 + the signal (130, 143).
    """
    from clay_cli import run_command
    from dem_taichi.engine.failures import BlowUpError, CapacityError
    from dem_taichi.io import CheckpointError

    return run_command(
        prog,
        lambda args: _main(args, prog),
        argv,
        user_errors=(CheckpointError,),
        failures={BlowUpError: 3, CapacityError: 3, ProtocolError: 1},
    )


if __name__ == "__main__":
    sys.exit(main())
