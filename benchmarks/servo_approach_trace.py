"""The stress servo traced update by update on one branch from a saved state A (issue 20: where
the servo's approach to its targets spends its steps).

Usage::

    python benchmarks/servo_approach_trace.py STATE_A.npz --branch isotropic --out TRACE.tsv \\
        [--set protocol.key=value ...] [--prototype flip|window] [--window 0.01]
    python benchmarks/servo_approach_trace.py --phases TRACE.tsv

STATE_A.npz is a checkpoint of the engine at A, such as the ``<out>.state_A.npz`` that
``benchmarks/paired_paths.py`` writes beside its JSON; its scene (in the checkpoint) gives the
protocol and probing settings, and ``--set section.key=value`` changes them (validated as a
scene file is; the engine and its state are the checkpoint's). The branch runs as in a
protocol run (probes included) and, before every servo update, one row is written: the step,
what limits the rates (``cap``, ``cap_ufr``, ``approach``: the work ledger's labels), the secant
ratio s, the modal gain factors, the residual t − Wσ, the wanted rates, the rate cap, σ_xx, σ_yy
and UFR. The trace does not change the trajectory: the base run of paper seed 3 gives the
protocol's own step counts (A→B approach 191,000, cap 140,700, cap_ufr 26,200).

``--phases`` splits a trace at its relaxed checks (a gap in the steps) and prints, per servo
call, its steps, those at the cap, the steps until the largest relative residual first fell
below 5 %, 1 % and 0.2 %, and the approach steps spent at s = 1 (the elastic gain).

``--prototype`` replaces the secant estimate by one of two controllers tried and dropped
(``benchmarks/results/period_two.md``, "The approach: a diagnosis"): ``flip`` restarts s at 1 on
a residual sign change only while UFR < 100 × ``relax_unbalanced_force`` (a change of sign while
the sample moves is taken as a transient); ``window`` measures s over the trailing strain whose
elastic prediction spans ``--window`` × |t| (a tangent rather than a secant since the start).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np


def _prototype(kind: str, window: float, static_ufr: float, ufr_now: list[float]):
    """A SecantStiffness subclass for ``--prototype`` (module docstring)."""
    import dem_taichi.protocol.servo as sv

    class Prototype(sv.SecantStiffness):
        def restart(self, controlled, strains):
            super().restart(controlled, strains)
            self._history = [(controlled.copy(), strains.copy())]

        def update(self, controlled, strains, residual, scale):
            sign = np.sign(residual)
            if self._sign is None:
                self._sign = sign
            elif np.any((sign != self._sign) & (sign != 0) & (self._sign != 0)):
                if kind != "flip" or ufr_now[0] < static_ufr:
                    self.restart(controlled, strains)
                    self._sign = sign
                    return self.ratio
                self._sign = sign
            if kind != "window":
                return super().update(controlled, strains, residual, scale)
            self._history.append((controlled.copy(), strains.copy()))
            for k in range(len(self._history) - 2, -1, -1):
                y0, e0 = self._history[k]
                predicted = sv._matvec(self.jacobian, strains - e0)
                if sv._norm(predicted) > window * sv._norm(scale):
                    s = sv._dot(controlled - y0, predicted) / sv._dot(predicted, predicted)
                    self.ratio = min(max(s, self.s_min), 1.0)
                    del self._history[:k]
                    break
            return self.ratio

    return Prototype


def trace(args: argparse.Namespace) -> None:
    import dem_taichi.protocol.servo as sv
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.io.checkpoint import checkpoint_meta
    from dem_taichi.protocol.branches import run_branch_on
    from dem_taichi.protocol.paths import ProtocolRunner
    from dem_taichi.protocol.probing import ProbeRecorder
    from dem_taichi.protocol.records import Branch, ProtocolError, RelaxedState, RunLog
    from dem_taichi.scene.config import scene_from_toml, scene_with_overrides
    from dem_taichi.scene.probing_sections import probing_settings
    from dem_taichi.scene.protocol_sections import protocol_settings

    sim = Simulation.from_checkpoint(args.state)
    scene = scene_from_toml(checkpoint_meta(args.state)["scene_toml"])
    scene = scene_with_overrides(scene, args.set)  # validated as a scene file is
    config, probing = protocol_settings(scene), probing_settings(scene)
    log = RunLog()
    recorder = ProbeRecorder(probing, config, log)
    runner = ProtocolRunner(sim, config, probing, None, None, recorder, True, log=log)
    runner.state_A = sim.get_state()
    nan2 = (float("nan"), float("nan"))
    log.states["A"] = RelaxedState("A", "isotropic_to_A", 0, nan2, sim.measure().copy(), True, 0)

    ufr_now = [0.0]
    if args.prototype:
        static_ufr = 100.0 * config.relax_unbalanced_force
        # the servo builds its estimator by this module-level name
        proto = _prototype(args.prototype, args.window, static_ufr, ufr_now)
        sv.SecantStiffness = proto  # type: ignore[misc]
    seen = {"s": 1.0, "factors": np.ones(2), "residual": np.zeros(2)}
    update, scaled, drive_kind, run = (
        sv.SecantStiffness.update,
        sv.ModalGain.scaled,
        sv._drive_kind,
        sim.run,
    )

    def traced_update(self, *a):
        seen["s"] = update(self, *a)
        return seen["s"]

    def traced_scaled(self, residual, tolerance):
        out = scaled(self, residual, tolerance)
        seen["factors"], seen["residual"] = self.factors.copy(), np.asarray(residual)
        return out

    def fmt(values, digits=4):
        return " ".join(f"{float(x):.{digits}g}" for x in np.atleast_1d(values))

    def traced_kind(wanted, cap, factor):
        kind = drive_kind(wanted, cap, factor)
        m = sim.measure()
        out.write(
            f"{sim.step}\t{kind}\t{seen['s']:.4g}\t{fmt(seen['factors'], 3)}\t"
            f"{fmt(seen['residual'])}\t{fmt(wanted, 3)}\t{cap:.3g}\t{m['stress_xx']:.5g}\t"
            f"{m['stress_yy']:.5g}\t{m['unbalanced_force_ratio']:.3g}\n"
        )
        return kind

    def traced_run(*a, **k):
        measures = run(*a, **k)
        ufr_now[0] = measures["unbalanced_force_ratio"]
        return measures

    # observed, not changed: each wrapper calls the original and returns its value
    sv.SecantStiffness.update = traced_update  # type: ignore[method-assign]
    sv.ModalGain.scaled = traced_scaled  # type: ignore[method-assign]
    sv._drive_kind = traced_kind
    sim.run = traced_run  # type: ignore[method-assign]
    start = time.perf_counter()
    with open(args.out, "w") as out:
        out.write("step\tkind\ts\tfactors\tresidual\twanted\tcap\tsxx\tsyy\tufr\n")
        try:
            run_branch_on(runner, Branch.parse(args.branch))
            print(f"done: {sim.step} steps, {time.perf_counter() - start:.0f} s")
        except ProtocolError as error:
            print(f"failed: {error}")


def phases(path: Path) -> None:
    """Print the per-call summary of a trace (module docstring)."""
    calls: list[list[tuple[int, str, float, float]]] = []
    previous = None
    for line in path.read_text().splitlines()[1:]:
        step, kind, s, _, residual, _, _, sxx, syy, _ = line.split("\t")
        res = [float(x) for x in residual.split()]
        sigma = [float(sxx), float(syy)]
        targets = (
            [x + r for x, r in zip(sigma, res, strict=False)]
            if len(res) == 2
            else [sigma[1] + res[0]]
        )
        worst = max(abs(r) / abs(t) for r, t in zip(res, targets, strict=True))
        if previous is None or int(step) - previous > 100:
            calls.append([])
        calls[-1].append((int(step), kind, float(s), worst))
        previous = int(step)
    print("call\tsteps\tat cap\tto 5 %\tto 1 %\tto 0.2 %\tapproach at s=1")
    for k, rows in enumerate(calls, 1):
        first = rows[0][0]

        def reached(level, rows=rows, first=first):
            return next((str(st - first) for st, _, _, w in rows if w < level), "-")

        cap = 100 * sum(kind != "approach" for _, kind, _, _ in rows)
        elastic = 100 * sum(kind == "approach" and s >= 0.999 for _, kind, s, _ in rows)
        total = rows[-1][0] + 100 - first
        print(f"{k}\t{total}\t{cap}\t{reached(0.05)}\t{reached(0.01)}\t{reached(0.002)}\t{elastic}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("state", nargs="?", type=Path, help="checkpoint of the engine at A")
    parser.add_argument("--branch", default="isotropic")
    parser.add_argument("--out", type=Path)
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    parser.add_argument("--prototype", choices=("flip", "window"))
    parser.add_argument("--window", type=float, default=0.01)
    parser.add_argument("--phases", type=Path, metavar="TRACE.tsv")
    args = parser.parse_args(argv)
    if args.phases:
        phases(args.phases)
    elif args.state and args.out:
        trace(args)
    else:
        parser.error("give STATE_A.npz and --out, or --phases TRACE.tsv")


if __name__ == "__main__":
    main()
