"""The confirmation of state A with a smaller increment (``[protocol] confirm_increment``):
the same A, in how many fewer steps.

Usage::

    python benchmarks/confirm_a.py --scene paper --seeds 3 4 5 --value 1e-3 \\
        [--set section.key=value ...] --out FILE.json

For each seed the gas of the scene (with ``--set``) is compressed to state A twice in this
process, each time from the scene's own gas: once with the scene's confirmation (``base``) and
once with ``confirm_increment = VALUE``. The confirmation only decides whether a candidate is
A and the sample then goes back to the candidate, so when both decide alike the two A are bit
for bit the same state (checked: :func:`dem_taichi.engine.state.states_equal`) and every later
stage is too; the saving is then free of any accuracy cost. Written per seed and variant: the
stage's steps, the confirmation's steps (work labels ``confirm/*``), the wall time, p, v and
Z_m at A, and whether A is the base's. ``--markdown FILE.md`` also writes the table.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path


def run_to_a(scene) -> dict:
    """Compress the scene's gas to A in a fresh simulation: its state and numbers."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.protocol.paths import ProtocolRunner
    from dem_taichi.scene.probing_sections import ProbingConfig
    from dem_taichi.scene.protocol_sections import protocol_settings

    start = time.perf_counter()
    sim = Simulation(scene)
    runner = ProtocolRunner(sim, protocol_settings(scene), ProbingConfig(enabled=False))
    runner.compress_to_transition()
    seconds = time.perf_counter() - start
    work = runner.log.work["isotropic_to_A"]
    a = runner.log.states["A"].measures
    return {
        "state": runner.state_A,
        "steps": int(runner.log.stages["isotropic_to_A"].steps),
        "confirm_steps": int(sum(e[0] for k, e in work.items() if k.startswith("confirm"))),
        "seconds": seconds,
        "p_A": float(a["mean_stress"]),
        "v_A": float(a["specific_volume"]),
        "Zm_A": float(a["mechanical_coordination_number"]),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="paper")
    parser.add_argument("--seeds", type=int, nargs="+", required=True)
    parser.add_argument("--value", type=float, required=True, help="confirm_increment to try")
    parser.add_argument("--set", action="append", default=[], dest="overrides")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--markdown", type=Path)
    args = parser.parse_args(argv)

    from dem_taichi.engine.state import states_equal
    from dem_taichi.scene.config import load_scene, scene_with_overrides

    rows = []
    for seed in args.seeds:
        base = scene_with_overrides(load_scene(args.scene), [*args.overrides, f"scene.seed={seed}"])
        variant = scene_with_overrides(base, [f"protocol.confirm_increment={args.value}"])
        first = run_to_a(base)
        second = run_to_a(variant)
        same = bool(states_equal(first.pop("state"), second.pop("state")))
        for name, result in (("base", first), (f"confirm_increment={args.value:g}", second)):
            rows.append({"seed": seed, "variant": name, "same_A": same, **result})
            print(json.dumps(rows[-1]), flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    meta = {"scene": args.scene, "overrides": args.overrides, "value": args.value}
    args.out.write_text(json.dumps({**meta, "rows": rows}, indent=1))
    if args.markdown is not None:
        lines = [
            "| seed | variant | same A | steps to A | confirmation steps | wall (s) | p_A | v_A |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for r in rows:
            lines.append(
                f"| {r['seed']} | {r['variant']} | {'yes' if r['same_A'] else '**no**'} | "
                f"{r['steps']:,} | {r['confirm_steps']:,} | {r['seconds']:.0f} | "
                f"{r['p_A']:.4g} | {r['v_A']:.4f} |"
            )
        args.markdown.write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
