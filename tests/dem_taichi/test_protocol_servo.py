"""The protocol's stress servo on a model plant with a transport delay (no Taichi, < 1 s).

Plant: σ(t) = C ε(t − D), the cell strain ε driven by the servo's rates; with the servo law
ε̇ = C⁻¹ (t − σ) / T the loop e' = −e(t − D)/T is unstable for D/T > π/2 (it hunts around the
target, like a soft repulsive packing whose stress waves cross the cell slower than the servo
acts) and stable below. UFR of the model = 10³ max|ε(t) − ε(t − D)| (the stress change still on
its way), 0 once the cell has been fixed for longer than D.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from dem_taichi.protocol import ProtocolError, ProtocolRunner
from dem_taichi.protocol_config import ProbingConfig, ProtocolConfig

DELAY_STEPS = 400  # D = 4 time units at dt = 0.01
TIME_STEP = 0.01


class DelayedPlant:
    """Stand-in for the engine: what ProtocolRunner.servo/relax use of a Simulation."""

    def __init__(self, stress0: float) -> None:
        self.stiffness = np.array([[20.0, 5.0], [5.0, 20.0]]) * stress0
        self.strain_history = [np.linalg.solve(self.stiffness, [stress0, stress0])] * (
            DELAY_STEPS + 1
        )
        self.step = 0
        self.n_rods = 100
        self.scene = SimpleNamespace(
            time_step=TIME_STEP,
            control=SimpleNamespace(inertial_number_max=1.0),
            output=SimpleNamespace(every=10**9),
        )
        self.geometry = SimpleNamespace(mass=1.0, solid_area=1.0, diameter=1.0)

    def snapshot(self):
        raise RuntimeError("no network: the servo falls back to its stiffness guess")

    def measure(self) -> dict:
        now, then = self.strain_history[-1], self.strain_history[-1 - DELAY_STEPS]
        stress = self.stiffness @ then
        return {
            "step": self.step,
            "stress_xx": float(stress[0]),
            "stress_yy": float(stress[1]),
            "mean_stress": float(stress.mean()),
            "unbalanced_force_ratio": float(1e3 * np.max(np.abs(now - then))),
            "kinetic_energy": 0.0,
            "inertial_number": float("nan"),
        }

    def run(self, n, control, output_every=None, writer=None):
        rates = np.array([control.x.value, control.y.value])
        for _ in range(n):
            self.strain_history.append(self.strain_history[-1] + rates * TIME_STEP)
        del self.strain_history[: -DELAY_STEPS - 1]
        self.step += n
        return self.measure()


def servo_on_delayed_plant(max_steps: int, **settings):
    plant = DelayedPlant(10.0)
    config = ProtocolConfig(servo_time=2.0, servo_max_steps=max_steps, **settings)
    runner = ProtocolRunner(plant, config, ProbingConfig(enabled=False))
    targets = np.array([15.0, 15.0])
    measures, checks = runner.servo("A_to_B", (0, 1), np.eye(2), targets, plant.measure())
    return runner, plant, measures, checks


def test_servo_settles_on_a_plant_slower_than_its_loop():
    """D/T = 2 > π/2 at the configured T: the servo must detect the hunting, slow down and hold
    the targets within the tolerance at a relaxed (static) state."""
    runner, plant, measures, checks = servo_on_delayed_plant(400_000)
    tolerance = runner.config.stress_tolerance
    assert abs(measures["stress_xx"] / 15.0 - 1) <= tolerance
    assert abs(measures["stress_yy"] / 15.0 - 1) <= tolerance
    assert measures["unbalanced_force_ratio"] < runner.config.relax_unbalanced_force
    slowed = runner.servo_times["A_to_B"]
    assert slowed > runner.config.servo_time
    # stable once D/T < π/2 (T doubles, so it stops below 2 D/(π/2) with one spare doubling)
    assert DELAY_STEPS * TIME_STEP / slowed < math.pi / 2
    assert slowed <= 4 * DELAY_STEPS * TIME_STEP


def test_fixed_gain_servo_hunts_on_that_plant():
    """The model is a real test: with the slowing disabled (the servo before the fix; also
    ``servo_time_max_factor = 1``) the loop hunts around the targets and never reaches a relaxed
    state within the same budget."""
    with pytest.raises(ProtocolError, match="not reached"):
        servo_on_delayed_plant(400_000, servo_stall_times=1e12)
    with pytest.raises(ProtocolError, match="not reached"):
        servo_on_delayed_plant(400_000, servo_time_max_factor=1.0)
