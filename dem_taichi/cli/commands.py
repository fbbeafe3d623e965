"""Command line: ``python -m dem_taichi run|protocol|sweep|snapshot|anisotropy ...``.

``run`` and ``protocol`` take ``SCENE --out DIR``; ``sweep SWEEP.toml --out DIR`` runs protocol
members on Dask (:mod:`dem_taichi.sweep.command`); ``snapshot STATE.npz --out FILE.vtu`` writes
the discs of any saved state (a checkpoint, a protocol's ``state_<label>.npz``) for ParaView;
``anisotropy RUN_DIR`` tabulates the fabrics and affine stiffness at a protocol run's labelled
states (:mod:`dem_taichi.response.anisotropy`).

``protocol`` runs the study's virtual experiments (gas -> A -> A-B, A-C, C-B, radial paths) with
elastic probes, figures and a report; it takes the options of ``python -m dem_taichi.protocol``
(see :func:`dem_taichi.protocol.runner.main`).

``run`` loads a scene (a TOML path or a built-in name: smoke, demo, default, paper, study...),
builds the gas and runs the engine's built-in loading (``protocol`` runs the study's paths):
strain-controlled isotropic compression at ``[control] compression_strain_rate`` down to
``target_specific_volume``, then ``relax_steps`` steps with the cell fixed. It writes, under
``--out``:

- ``history.nc``: the netCDF history (dem_taichi.io schema), appended every ``[output] every``
  steps and synced, so a killed run leaves a readable file;
- ``checkpoints/checkpoint_<step>.npz``: checkpoints every ``[output] checkpoint_every`` steps
  (the run's own two latest kept) and at the end; ``--resume`` continues from the latest one
  exactly, and only with the run's own scene;
- ``scene.toml``: the full scene (every key);
- ``run.json``: the run id, the scene's hash and the manifest, every file and folder the run
  wrote (:mod:`dem_taichi.io.run_directory`): a fresh run into a used ``--out`` is refused
  unless ``--overwrite``, which deletes the files of that manifest and nothing else (refused
  for a folder without ``run.json``, the current folder, the home folder and ``/``; an empty
  ``--out`` is refused always);
- ``run.lock`` while the run writes (PID, host, start time): a second run, resume or
  ``--overwrite`` of the folder is refused naming the lock and its PID; a lock left by a dead
  process is taken over with a one-line note; released on exit, on error and on SIGINT/SIGTERM;
- with ``--paraview``: ``paraview/step_<step>.vtu`` at every checkpoint and at the end, listed
  in ``paraview/run.pvd`` (:mod:`dem_taichi.io.vtk_snapshots`).

A value with a line break or other control character (``--out``, the scene, ``--stage``, any
path or label of ``run``, ``protocol``, ``snapshot``) is refused in one line naming the flag.

A run never writes through a symbolic link: a link in ``--out`` where a run writes is refused
(one line), never followed nor replaced. ``snapshot`` refuses an existing ``--out`` file unless
``--overwrite`` (then the file is replaced atomically, a link by a file, never its target).

SIGINT (Ctrl-C) or SIGTERM stops the run at the next output step: a checkpoint is written, the
history closed, and one line says how to resume; the exit code is 128 + the signal (130 for
SIGINT). The resumed run continues bit for bit.

Errors (:mod:`clay_cli`, the project's one handler): a bad option, scene, file or
directory is one line ``python -m dem_taichi: error: ...`` with exit code 2 (``--debug`` shows
the traceback); a blow-up or a capacity the engine cannot grow, exit code 3; a full disk
(ENOSPC/EDQUOT), exit code 4 (the lock is released, the history synced up to the last output
step). Checked before the
engine starts: ``--steps`` >= 0, the run directory (above), and that the built-in compression
has something to do (``[control] target_specific_volume`` below the gas's 1/initial_area_fraction).
"""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any

from clay_cli import (
    ArgumentParser,
    UsageError,
    add_common_flags,
    error_line,
    int_in_range,
    refuse_control_characters,
    replace_file,
    run_command,
)
from dem_taichi import __version__
from dem_taichi.protocol.cost import check_cost, cost_lines
from dem_taichi.protocol.run_schedule import builtin_schedule
from dem_taichi.scene.config import (
    Scene,
    builtin_scene_names,
    scene_from_toml,
    scene_to_toml,
)
from dem_taichi.scene.options import add_preset_option, scene_from_options

__all__ = ["main", "builtin_schedule"]

PROG = "python -m dem_taichi"


class _StopSignals:
    """SIGINT/SIGTERM while running: remember the first (the run stops at the next output step,
    writes a checkpoint and closes the history); a second one aborts at once."""

    def __init__(self) -> None:
        self.received: int | None = None
        self._previous: dict[int, Callable[[int, FrameType | None], Any] | int | None] = {}

    def _handle(self, signum, frame) -> None:
        if self.received is not None:
            raise KeyboardInterrupt
        self.received = signum
        print(
            f"{signal.Signals(signum).name}: stopping at the next output step with a checkpoint "
            "(send it again to abort without one)",
            file=sys.stderr,
            flush=True,
        )

    def __enter__(self) -> _StopSignals:
        for signum in (signal.SIGINT, signal.SIGTERM):
            self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)


def _say(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _checkpoint_scene(path: Path) -> str:
    """The full scene TOML of a checkpoint, rewritten by this code's ``scene_to_toml``."""
    from dem_taichi.io import checkpoint_meta

    return scene_to_toml(scene_from_toml(checkpoint_meta(path)["scene_toml"]))


def _run(args: argparse.Namespace) -> int:
    from dem_taichi.io import resume_run, start_run

    if args.resume and args.overwrite:
        raise UsageError(
            "--resume and --overwrite exclude each other: --resume continues the run in --out, "
            "--overwrite replaces it; give one of them"
        )
    scene = scene_from_options(args.scene, args.preset, args.set)
    cost = check_cost(scene, "run", args.precision)  # refuses what memory cannot hold
    v0 = 1.0 / scene.particles.initial_area_fraction
    if scene.control.target_specific_volume >= v0:
        raise UsageError(
            f"[control] target_specific_volume = {scene.control.target_specific_volume:g} is not "
            f"below the gas's specific volume 1/initial_area_fraction = {v0:.4g}: the built-in "
            "run would not compress; lower target_specific_volume or raise "
            "[particles] initial_area_fraction"
        )
    scene_toml = scene_to_toml(scene)
    if not args.out.strip():
        raise UsageError(
            "--out is empty: give the run's folder (an empty --out would mean the current folder)"
        )
    if args.resume:
        run_dir, latest = resume_run(args.out, scene.scene.name, scene_toml, _checkpoint_scene)
    else:
        run_dir = start_run(
            args.out, "run", scene.scene.name, scene_toml, args.overwrite, resume_hint=True
        )
        latest = None
    with run_dir:  # the manifest completed and the lock released, also on an error
        return _simulate(args, scene, run_dir, latest, cost)


def _snapshot(args: argparse.Namespace) -> int:
    """``snapshot STATE.npz --out FILE.vtu``: the discs of a saved state for ParaView."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.io.vtk_snapshots import write_simulation_snapshot

    source = Path(args.state)
    if not source.is_file():
        raise UsageError(
            f"{source}: no such file; give a checkpoint (checkpoints/checkpoint_<step>.npz) or "
            "a protocol state (state_<label>.npz, path_<stage>_<k>.npz)"
        )
    target = Path(args.out)
    if target.suffix != ".vtu":
        raise UsageError(f"--out {target}: the snapshot is a VTK file: give a name ending .vtu")
    if target.is_dir():
        raise UsageError(f"--out {target} is a folder: give the .vtu file to write")
    if (target.exists() or target.is_symlink()) and not args.overwrite:
        raise UsageError(
            f"--out {target} exists; add --overwrite to replace it, or choose another name"
        )
    sim = Simulation.from_checkpoint(source, arch=args.arch)
    m = sim.measure()
    fields = {k: float(m[k]) for k in ("mean_stress", "deviatoric_stress", "specific_volume")}
    target.parent.mkdir(parents=True, exist_ok=True)
    path = replace_file(
        target,
        lambda temporary: write_simulation_snapshot(
            temporary, sim, stage=args.stage, fields=fields
        ),
    )
    if not args.quiet:
        print(f"{path}: {sim.n_bodies} bodies at step {sim.step} (open it in ParaView)")
    return 0


def _paraview(sim, run_dir, stage: str) -> None:
    """``--paraview``: the discs now as ``paraview/step_<step>.vtu``, listed in ``run.pvd``
    (both registered in the run's manifest before they are written)."""
    from dem_taichi.io.vtk_snapshots import read_pvd, write_pvd, write_simulation_snapshot

    target = run_dir.output(f"paraview/step_{sim.step:010d}.vtu")
    series = run_dir.output("paraview/run.pvd")
    path = write_simulation_snapshot(target, sim, stage=stage)
    files = [(n, f) for n, f in read_pvd(series) if f != path] if series.exists() else []
    write_pvd(series, [*files, (f"step {sim.step}", path)])


def _simulate(
    args: argparse.Namespace, scene: Scene, run_dir, latest: Path | None, cost=None
) -> int:
    import taichi as ti

    from dem_taichi.engine.simulation import BlowUpError, CellControl, Simulation
    from dem_taichi.io import HistoryWriter, checkpoint_path, provenance_attrs

    out = run_dir.path
    if latest is not None:
        sim = Simulation.from_checkpoint(latest, arch=args.arch, precision=args.precision)
        if not args.quiet:
            print(f"resuming from {latest} at step {sim.step}")
    else:
        sim = Simulation(
            scene, arch=args.arch, precision=args.precision, deterministic=args.deterministic
        )
    if cost is not None and not args.quiet:  # once the engine is built: errors come first
        for line in cost_lines(cost):
            _say(line)
    replace_file(run_dir.output("scene.toml"), lambda t: t.write_text(scene_to_toml(scene)))
    attrs = provenance_attrs(
        scene_toml=scene.source_text or scene_to_toml(scene),
        arch=sim.arch,
        precision=sim.precision,
        seed=scene.scene.seed,
        command=" ".join(["python -m dem_taichi"] + sys.argv[1:]),
        taichi_version=".".join(str(v) for v in ti.__version__),
    )
    attrs["execution"] = sim.execution
    attrs["rod_model"] = scene.particles.rod_model
    attrs["run_id"] = run_dir.run_id
    schedule = builtin_schedule(scene)
    total = sum(n for _, n, _ in schedule)
    if args.steps is not None:
        total = min(total, args.steps)
    every = scene.output.every
    checkpoint_every = scene.output.checkpoint_every
    resume = latest is not None
    with (
        HistoryWriter(
            run_dir.output("history.nc"),
            attrs=attrs,
            resume=resume,
            resume_after_step=sim.step if resume else None,
            variables=sim.history_variables,
        ) as history,
        _StopSignals() as stop,
    ):
        last_record = sim.step
        if not resume:
            history.append(sim.measure())
        start = 0
        bars = args.progress and not args.quiet and total >= 20_000
        try:
            for stage, n_steps, rate in schedule:
                stage_end = min(start + n_steps, total)
                bar = _stage_bar(stage, start, stage_end, sim.step) if bars else None
                while sim.step < stage_end and stop.received is None:
                    # run to the next output / checkpoint boundary (absolute step numbers)
                    target = min(stage_end, (sim.step // every + 1) * every)
                    if checkpoint_every:
                        target = min(target, (sim.step // checkpoint_every + 1) * checkpoint_every)
                    control = CellControl.strain_rate(rate, stage=stage)
                    n = target - sim.step
                    sim.run(n, control=control, output_every=10**12)
                    if bar is not None:
                        bar.update(n)
                    if sim.step % every == 0 or sim.step == stage_end:
                        history.append(sim.measure())
                        last_record = sim.step
                    if checkpoint_every and sim.step % checkpoint_every == 0:
                        target = run_dir.output(checkpoint_path("checkpoints", sim.step))
                        run_dir.add_checkpoint(sim.save_checkpoint(target))
                        if args.paraview:
                            _paraview(sim, run_dir, stage)
                if bar is not None:
                    bar.close()
                start = start + n_steps
                if start >= total or stop.received is not None:
                    break
        except BlowUpError as error:
            print(error_line(PROG, error), file=sys.stderr)
            return 3
        if stop.received is not None and last_record != sim.step:
            history.append(sim.measure())
    path = sim.save_checkpoint(run_dir.output(checkpoint_path("checkpoints", sim.step)))
    run_dir.add_checkpoint(path)
    if args.paraview:
        _paraview(sim, run_dir, stage if schedule else "gas")  # the stage the run ended in
    if stop.received is not None:
        name = signal.Signals(stop.received).name
        print(
            f"interrupted by {name} at step {sim.step}: checkpoint {path} written, history "
            f"closed; continue with: python -m dem_taichi run {args.scene} --out {out} --resume",
            file=sys.stderr,
        )
        return 128 + stop.received
    if not args.quiet:
        m = sim.measure()
        print(
            f"done: step {sim.step}, v = {m['specific_volume']:.4g}, p = {m['mean_stress']:.4g}, "
            f"Z = {m['coordination_number']:.3g}; history in {out / 'history.nc'}"
        )
    return 0


def _stage_bar(stage: str, start: int, end: int, step: int):
    """One progress bar per stage (steps, with the estimated time left)."""
    from tqdm import tqdm

    done = min(max(step - start, 0), end - start)
    return tqdm(total=end - start, initial=done, unit="step", desc=stage, smoothing=0.1)


def _parser() -> ArgumentParser:
    parser = ArgumentParser(prog=PROG, description=__doc__.split("\n")[0])
    parser.add_argument("--version", action="version", version=f"dem_taichi {__version__}")
    add_common_flags(parser)
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser(
        "run",
        help="run a scene (gas -> isotropic compression -> relax)",
        description="Run a scene's built-in loading: gas -> isotropic compression -> relax.",
    )
    run.add_argument(
        "scene", help=f"scene TOML path or built-in name ({', '.join(builtin_scene_names())})"
    )
    run.add_argument("--out", required=True, help="output directory (one run per directory)")
    run.add_argument("--arch", choices=("cpu", "gpu"), default="cpu", help="device (cpu)")
    run.add_argument(
        "--precision", choices=("f64", "f32"), default="f64", help="floating point (f64)"
    )
    run.add_argument(
        "--steps",
        type=int_in_range(0),
        default=None,
        help="stop after this many steps in all (default: the whole schedule)",
    )
    run.add_argument(
        "--resume",
        action="store_true",
        help="continue the run in --out from its latest checkpoint (the same scene only)",
    )
    run.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the run already in --out: delete the files its run.json lists, nothing "
        "else (else a used --out is refused)",
    )
    run.add_argument("--deterministic", action="store_true", help="bitwise reproducible (CPU)")
    run.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="override a scene key, e.g. --set contact.mu=0.2 (repeatable; validated as the file)",
    )
    add_preset_option(run)
    run.add_argument(
        "--no-progress",
        dest="progress",
        action="store_false",
        help="no progress bars (default: bars on long stages)",
    )
    run.add_argument(
        "--paraview",
        action="store_true",
        help="also write the discs for ParaView at every checkpoint and at the end "
        "(paraview/step_<step>.vtu and the series paraview/run.pvd; default: off)",
    )
    add_common_flags(run, sub=True)
    snap = sub.add_parser(
        "snapshot",
        help="write the discs of a saved state (checkpoint or state_<label>.npz) for ParaView",
        description="Write the discs of a saved state as a VTK file for ParaView (rod id, "
        "orientation, charge, force, torque per disc; dem_taichi.io.vtk_snapshots).",
    )
    snap.add_argument("state", help="checkpoint_<step>.npz, state_<label>.npz or path_*.npz")
    snap.add_argument("--out", required=True, help="the .vtu file to write")
    snap.add_argument(
        "--overwrite", action="store_true", help="replace --out if it exists (else refused)"
    )
    snap.add_argument(
        "--stage",
        default="gas",
        help="stage label stored with the snapshot (default gas; e.g. A_to_C)",
    )
    snap.add_argument("--arch", choices=("cpu", "gpu"), default="cpu", help="device (cpu)")
    add_common_flags(snap, sub=True)
    sub.add_parser(
        "protocol",
        add_help=False,
        help="the study's virtual experiments with probes, figures and a report "
        "(python -m dem_taichi protocol --help)",
    )
    sub.add_parser(
        "sweep",
        add_help=False,
        help="protocol runs over a grid or list of scene changes, on Dask "
        "(python -m dem_taichi sweep --help)",
    )
    sub.add_parser(
        "anisotropy",
        add_help=False,
        help="fabrics and affine stiffness at a protocol run's labelled states "
        "(python -m dem_taichi anisotropy --help)",
    )
    return parser


def _command(argv: list[str]) -> int:
    refuse_control_characters(argv)
    args = _parser().parse_args(argv)
    return _snapshot(args) if args.command == "snapshot" else _run(args)


def main(argv: list[str] | None = None) -> int:
    """``python -m dem_taichi run|protocol|sweep|snapshot|anisotropy ...``; returns the exit code
    (module docstring)."""
    from dem_taichi.engine.failures import BlowUpError, CapacityError
    from dem_taichi.io import CheckpointError

    argv = sys.argv[1:] if argv is None else list(argv)
    # the common flags may come before the sub-command; `protocol` has its own parser
    first = next((i for i, a in enumerate(argv) if a not in ("--quiet", "--debug")), len(argv))
    if first < len(argv) and argv[first] == "protocol":
        from dem_taichi.io.run_directory import release_all
        from dem_taichi.protocol.runner import main as protocol_main

        rest = argv[:first] + argv[first + 1 :]
        try:
            code = run_command(f"{PROG} protocol", refuse_control_characters, rest)
            if code:  # a control character in a path or label: one line, exit code 2
                return code
            return protocol_main(rest, prog=f"{PROG} protocol")
        finally:
            release_all()  # the protocol's run folder: manifest completed, lock released
    if first < len(argv) and argv[first] == "sweep":
        from dem_taichi.sweep.command import main as sweep_main

        return sweep_main(argv[:first] + argv[first + 1 :], prog=f"{PROG} sweep")
    if first < len(argv) and argv[first] == "anisotropy":
        from dem_taichi.response.anisotropy import main as anisotropy_main

        return anisotropy_main(argv[:first] + argv[first + 1 :], prog=f"{PROG} anisotropy")
    return run_command(
        PROG,
        _command,
        argv,
        user_errors=(CheckpointError,),
        failures={BlowUpError: 3, CapacityError: 3},
    )


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
