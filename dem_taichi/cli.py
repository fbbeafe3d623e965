"""Command line: ``python -m dem_taichi run|protocol SCENE --out DIR [options]``.

``protocol`` runs the study's virtual experiments (gas -> A -> A-B, A-C, C-B, radial paths) with
elastic probes, figures and a report; it takes the options of ``python -m dem_taichi.protocol``
(see :func:`dem_taichi.protocol.main`).

``run`` loads a scene (a TOML path or a built-in name: smoke, demo, default, paper), builds the
gas and runs the engine's built-in loading (``protocol`` runs the study's paths):
strain-controlled isotropic compression at ``[control] compression_strain_rate`` down to
``target_specific_volume``, then ``relax_steps`` steps with the cell fixed. It writes, under
``--out``:

- ``history.nc``: the netCDF history (dem_taichi.io schema), appended every ``[output] every``
  steps and synced, so a killed run leaves a readable file;
- ``checkpoints/step_*.npz``: checkpoints every ``[output] checkpoint_every`` steps (two kept)
  and at the end; ``--resume`` continues from the latest one exactly;
- ``scene.toml``: the full scene (every key).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from dem_taichi.config import Scene, SceneError, load_scene, scene_to_toml

__all__ = ["main", "builtin_schedule"]


def builtin_schedule(scene: Scene) -> list[tuple[str, int, float]]:
    """Stages of the built-in run: (stage label, steps, strain rate of both axes).

    The compression lasts t = ln(v_0 / v_target) / (2 ε̇) (area A ∝ exp(−2 ε̇ t)).
    """
    v0 = 1.0 / scene.particles.initial_area_fraction
    target = scene.control.target_specific_volume
    rate = scene.control.compression_strain_rate
    stages = []
    if target < v0:
        duration = math.log(v0 / target) / (2.0 * rate)
        stages.append(("isotropic_to_A", int(math.ceil(duration / scene.time_step)), rate))
    stages.append(("relax", scene.control.relax_steps, 0.0))
    return stages


def _run(args: argparse.Namespace) -> int:
    import taichi as ti

    from dem_taichi.engine import BlowUpError, CellControl, Simulation
    from dem_taichi.io import (
        HistoryWriter,
        checkpoint_path,
        latest_checkpoint,
        provenance_attrs,
        rotate_checkpoints,
    )

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    checkpoints = out / "checkpoints"
    if args.resume:
        latest = latest_checkpoint(checkpoints)
        if latest is None:
            print(f"error: --resume but no checkpoint in {checkpoints}", file=sys.stderr)
            return 2
        sim = Simulation.from_checkpoint(latest, arch=args.arch, precision=args.precision)
        scene = sim.scene
        print(f"resuming from {latest} at step {sim.step}")
    else:
        scene = load_scene(args.scene)
        sim = Simulation(
            scene, arch=args.arch, precision=args.precision, deterministic=args.deterministic
        )
    (out / "scene.toml").write_text(scene_to_toml(scene))
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
    schedule = builtin_schedule(scene)
    total = sum(n for _, n, _ in schedule)
    if args.steps is not None:
        total = min(total, args.steps)
    every = scene.output.every
    checkpoint_every = scene.output.checkpoint_every
    with HistoryWriter(
        out / "history.nc",
        attrs=attrs,
        resume=args.resume,
        resume_after_step=sim.step if args.resume else None,
        variables=sim.history_variables,
    ) as history:
        if not args.resume:
            history.append(sim.measure())
        start = 0
        try:
            for stage, n_steps, rate in schedule:
                stage_end = min(start + n_steps, total)
                while sim.step < stage_end:
                    # run to the next output / checkpoint boundary (absolute step numbers)
                    target = min(stage_end, (sim.step // every + 1) * every)
                    if checkpoint_every:
                        target = min(target, (sim.step // checkpoint_every + 1) * checkpoint_every)
                    control = CellControl.strain_rate(rate, stage=stage)
                    sim.run(
                        target - sim.step,
                        control=control,
                        output_every=10**12,
                        progress=args.progress and total >= 20_000,
                    )
                    if sim.step % every == 0 or sim.step == stage_end:
                        history.append(sim.measure())
                    if checkpoint_every and sim.step % checkpoint_every == 0:
                        sim.save_checkpoint(checkpoint_path(checkpoints, sim.step))
                        rotate_checkpoints(checkpoints, keep=2)
                start = start + n_steps
                if start >= total:
                    break
        except BlowUpError as error:
            print(f"error: {error}", file=sys.stderr)
            return 3
    sim.save_checkpoint(checkpoint_path(checkpoints, sim.step))
    rotate_checkpoints(checkpoints, keep=2)
    m = sim.measure()
    print(
        f"done: step {sim.step}, v = {m['specific_volume']:.4g}, p = {m['mean_stress']:.4g}, "
        f"Z = {m['coordination_number']:.3g}; history in {out / 'history.nc'}"
    )
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m dem_taichi", description=__doc__.split("\n")[0]
    )
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a scene (gas -> isotropic compression -> relax)")
    run.add_argument("scene", help="scene TOML path or built-in name (smoke, demo, default, paper)")
    run.add_argument("--out", required=True, help="output directory")
    run.add_argument("--arch", choices=("cpu", "gpu"), default="cpu")
    run.add_argument("--precision", choices=("f64", "f32"), default="f64")
    run.add_argument("--steps", type=int, default=None, help="stop after this many steps in all")
    run.add_argument("--resume", action="store_true", help="continue from the latest checkpoint")
    run.add_argument("--deterministic", action="store_true", help="bitwise reproducible (CPU)")
    run.add_argument("--no-progress", dest="progress", action="store_false")
    sub.add_parser(
        "protocol",
        add_help=False,
        help="the study's virtual experiments with probes, figures and a report "
        "(python -m dem_taichi protocol --help)",
    )
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] == "protocol":
        return _protocol(argv[1:])
    args = parser.parse_args(argv)
    try:
        return _run(args)
    except SceneError as error:
        print(f"scene error: {error}", file=sys.stderr)
        return 2


def _protocol(argv: list[str]) -> int:
    """Delegate to :func:`dem_taichi.protocol.main`; scene errors exit 2, blow-ups exit 3."""
    from dem_taichi.engine import BlowUpError
    from dem_taichi.protocol import main as protocol_main

    try:
        return protocol_main(argv)
    except SceneError as error:
        print(f"scene error: {error}", file=sys.stderr)
        return 2
    except BlowUpError as error:
        print(f"error: {error}", file=sys.stderr)
        return 3


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
