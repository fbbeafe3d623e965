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

from dem_taichi.protocol.runner import ProtocolError, ProtocolRunner
from dem_taichi.scene.probing_sections import ProbingConfig
from dem_taichi.scene.protocol_sections import ProtocolConfig

DELAY_STEPS = 400  # D = 4 time units at dt = 0.01
TIME_STEP = 0.01


class DelayedPlant:
    """Stand-in for the engine: what ProtocolRunner.servo/relax use of a Simulation."""

    DELAY = DELAY_STEPS

    def __init__(self, stress0: float) -> None:
        self.stiffness = np.array([[20.0, 5.0], [5.0, 20.0]]) * stress0
        self.strain_history = [np.linalg.solve(self.stiffness, [stress0, stress0])] * (
            self.DELAY + 1
        )
        self.step = 0
        self.n_rods = 100
        self.time_step = TIME_STEP
        self.scene = SimpleNamespace(
            time_step=TIME_STEP,
            control=SimpleNamespace(inertial_number_max=1.0),
            output=SimpleNamespace(every=10**9),
            contact=SimpleNamespace(cap_force="contact"),  # the study's caps throughout
        )
        self.geometry = SimpleNamespace(mass=1.0, solid_area=1.0, diameter=1.0)

    def snapshot(self):
        raise RuntimeError("no network: the servo falls back to its stiffness guess")

    def _stress(self) -> np.ndarray:
        return self.stiffness @ self.strain_history[-1 - self.DELAY]

    def _after_step(self) -> None:
        """Called once the strain of a new step is appended (plastic plants update here)."""

    def measure(self) -> dict:
        now, then = self.strain_history[-1], self.strain_history[-1 - self.DELAY]
        stress = self._stress()
        return {
            "step": self.step,
            "stress_xx": float(stress[0]),
            "stress_yy": float(stress[1]),
            "mean_stress": float(stress.mean()),
            "unbalanced_force_ratio": float(1e3 * np.max(np.abs(now - then))),
            "kinetic_energy": 0.0,
            "inertial_number": float("nan"),
            "strain_xx": float(now[0]),
            "strain_yy": float(now[1]),
        }

    def run(self, n, control, output_every=None, writer=None):
        rates = np.array([control.x.value, control.y.value])
        for _ in range(n):
            self.strain_history.append(self.strain_history[-1] + rates * TIME_STEP)
            self._after_step()
        del self.strain_history[: -self.DELAY - 1]
        self.step += n
        return self.measure()


def servo_on_delayed_plant(max_steps: int, plant_class=DelayedPlant, **settings):
    plant = plant_class(10.0)
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


class PlasticPlant(DelayedPlant):
    """Elastic–plastic plant with a short delay (stable loop): σ = C (ε(t − d) − ε_p); while the
    mean stress is at its largest value so far and the strain keeps loading, only 1/SOFTENING
    of each increment is elastic (tangent C/SOFTENING, like K0 loading beyond A); unloading and
    reloading below that stress are elastic."""

    SOFTENING = 20.0
    DELAY = 20

    def __init__(self, stress0: float) -> None:
        super().__init__(stress0)
        self.plastic = np.zeros(2)
        self.delayed = self.strain_history[0].copy()
        self.yield_stress = stress0

    def _stress(self) -> np.ndarray:
        return self.stiffness @ (self.delayed - self.plastic)

    def _after_step(self) -> None:
        new = self.strain_history[-1 - self.DELAY]
        increment = new - self.delayed
        self.delayed = new.copy()
        if self._stress().mean() > self.yield_stress and increment.sum() > 0:
            self.plastic += (1.0 - 1.0 / self.SOFTENING) * increment
            self.yield_stress = max(self.yield_stress, self._stress().mean())


def servo_on_plastic_plant(stiffness: str, max_steps: int = 2_000_000):
    runner, plant, measures, _ = servo_on_delayed_plant(
        max_steps, PlasticPlant, servo_stiffness=stiffness
    )
    return runner, plant, measures


def test_secant_servo_loads_a_softening_plant_much_faster():
    """On plastic loading (tangent = elastic/20) the elastic-stiffness servo approaches the
    target with time constant ~20 T; the secant servo measures the softening and reaches the
    same targets, within the tolerance at a relaxed state, in a fraction of the steps."""
    results = {}
    for stiffness in ("elastic", "secant"):
        runner, plant, m = servo_on_plastic_plant(stiffness)
        tol = runner.config.stress_tolerance
        assert abs(m["stress_xx"] / 15.0 - 1) <= tol and abs(m["stress_yy"] / 15.0 - 1) <= tol
        assert np.all(plant.plastic > 0)  # the path was plastic
        results[stiffness] = plant.step
    assert results["secant"] < results["elastic"] / 4, results


def test_secant_estimate_restarts_on_overshoot():
    """A residual that changes sign restarts s at 1 (reversal is elastic); s stays in
    [s_min, 1] and is not estimated from a change below min_change of the target."""
    from dem_taichi.protocol.runner import SecantStiffness

    est = SecantStiffness(np.eye(1) * 100.0, s_min=0.01, min_change=0.05)
    scale = np.array([10.0])
    est.restart(np.array([10.0]), np.array([0.0]))
    assert est.update(np.array([10.1]), np.array([0.004]), np.array([4.9]), scale) == 1.0
    assert est.update(np.array([10.5]), np.array([0.05]), np.array([4.5]), scale) == (
        pytest.approx(0.1)
    )
    assert est.update(np.array([10.5]), np.array([5.0]), np.array([4.5]), scale) == 0.01
    assert est.update(np.array([15.2]), np.array([5.1]), np.array([-0.2]), scale) == 1.0


class StiffenedPlant(DelayedPlant):
    """A network far stiffer in its deviatoric mode than the servo's stiffness (a loose gel
    loaded beyond A, issue 19: ~80 × measured there): σ = C ε with C − C_guess = k [[1, −1],
    [−1, 1]], so the deviatoric stiffness C_xx − C_xy is 80 × the guess's and the mean one the
    same; a one-step delay (a stable loop for the right gain). It starts off the isotropic axis
    (σ = (10, 9)) so the deviatoric mode is loaded."""

    DELAY = 1

    def __init__(self, stress0: float) -> None:
        super().__init__(stress0)
        guess = self.stiffness  # the servo's fallback guess [[20, 5], [5, 20]] p
        k = 79.0 * (guess[0, 0] - guess[0, 1]) / 2.0
        self.stiffness = guess + k * np.array([[1.0, -1.0], [-1.0, 1.0]])
        start = np.linalg.solve(self.stiffness, [stress0, 0.9 * stress0])
        self.strain_history = [start] * (self.DELAY + 1)


def test_servo_converges_where_the_network_is_far_stiffer_than_its_gain():
    """The servo corrects its gain mode by mode where it overshoots (ModalGain) and reaches the
    targets at a relaxed state, in a fraction of the budget."""
    runner, plant, measures, _ = servo_on_delayed_plant(400_000, StiffenedPlant)
    tol = runner.config.stress_tolerance
    assert abs(measures["stress_xx"] / 15.0 - 1) <= tol
    assert abs(measures["stress_yy"] / 15.0 - 1) <= tol
    assert plant.step < 100_000


def test_without_the_modal_correction_the_servo_bangs_between_its_caps(monkeypatch):
    """The plant is a real test: with the residual passed through unchanged (the servo before
    issue 19's fix) the rates bang between the caps and the targets are never reached."""
    from dem_taichi.protocol.servo import ModalGain

    monkeypatch.setattr(ModalGain, "scaled", lambda self, residual, tolerance: residual)
    with pytest.raises(ProtocolError, match="not reached"):
        servo_on_delayed_plant(400_000, StiffenedPlant)


def test_modal_gain_halves_an_overshooting_mode_only():
    """Mean and difference modes: a deviator that flips sign without shrinking halves the
    deviatoric factor; the mean, approaching monotonically, stays at 1; a mode within the
    tolerance never counts as overshooting; one control is its own mode."""
    from dem_taichi.protocol.servo import ModalGain

    gain = ModalGain(2)
    r = gain.scaled(np.array([1.0, 3.0]), tolerance=1e-3)  # p-mode 2, q-mode 2
    assert r == pytest.approx([1.0, 3.0])  # factors 1: the residual itself
    gain.scaled(np.array([1.9, -0.1]), tolerance=1e-3)  # q flips 2 → −2: overshoot
    assert gain.factors.tolist() == [1.0, 0.5] and gain.overshoots == 1
    gain.scaled(np.array([0.8, 0.6]), tolerance=1e-3)  # q −2 → −0.2: shrank, no flip
    assert gain.factors.tolist() == [1.0, pytest.approx(0.55)]
    tiny = ModalGain(1)
    tiny.scaled(np.array([1e-4]), tolerance=1e-3)
    tiny.scaled(np.array([-1e-4]), tolerance=1e-3)
    assert tiny.factors.tolist() == [1.0] and tiny.overshoots == 0


def test_an_inner_path_state_stops_at_the_path_tolerance_and_an_end_at_the_strict_one():
    """``path_stress_tolerance``: a state inside a path (``last=False``) is accepted within it,
    in fewer steps (the approach costs ∝ ln(1/tolerance)); the state ending a path keeps
    ``stress_tolerance``; unset, both use ``stress_tolerance``."""
    results = {}
    for inner, last in ((None, False), (0.02, False), (0.02, True)):
        plant = DelayedPlant(10.0)
        config = ProtocolConfig(
            servo_time=8.0, servo_max_steps=400_000, path_stress_tolerance=inner
        )
        runner = ProtocolRunner(plant, config, ProbingConfig(enabled=False))
        targets = np.array([15.0, 15.0])
        measures, _ = runner.servo("A_to_B", (0, 1), np.eye(2), targets, plant.measure(), last)
        error = max(abs(measures["stress_xx"] / 15.0 - 1), abs(measures["stress_yy"] / 15.0 - 1))
        results[inner, last] = (error, plant.step)
    strict = ProtocolConfig().stress_tolerance
    assert results[None, False][0] <= strict
    assert results[0.02, True][0] <= strict
    assert strict < results[0.02, False][0] <= 0.02  # stopped early, within the path tolerance
    assert results[0.02, False][1] < 0.8 * results[None, False][1]
    assert ProtocolConfig(path_stress_tolerance=0.02).inner_stress_tolerance() == 0.02
    assert ProtocolConfig().inner_stress_tolerance() == strict


def test_a_path_from_A_starts_the_servo_afresh():
    """Serial, parallel and resumed runs agree: each path from A resets the servo's memory
    (the time constants it doubled while hunting)."""
    plant = DelayedPlant(10.0)
    runner = ProtocolRunner(plant, ProtocolConfig(), ProbingConfig(enabled=False))
    runner.stress_servo.memory.times["radial"] = 8.0
    runner.state_A = {"dummy": True}
    plant.set_state = lambda state: None
    runner.log.states["A"] = SimpleNamespace(measures=plant.measure())
    runner._restore_A()
    assert runner.stress_servo.memory.times == {}


class RateRecordingPlant(PlasticPlant):
    """The plastic plant, keeping the largest |rate| / sqrt(p) the servo asked for (the cap of
    the model is safety × I_max × sqrt(p/ρ)/d with I_max = ρ = d = 1)."""

    def __init__(self, stress0: float) -> None:
        super().__init__(stress0)
        self.largest = 0.0

    def run(self, n, control, output_every=None, writer=None):
        p = max(self.measure()["mean_stress"], ProtocolConfig().pressure_tolerance)
        rates = np.abs([control.x.value, control.y.value])
        self.largest = max(self.largest, float(rates.max()) / math.sqrt(p))
        return super().run(n, control, output_every, writer)


@pytest.mark.parametrize("servo_safety", [None, 0.005])
def test_the_servo_rate_cap_has_its_own_key_and_the_compression_to_A_keeps_the_other(
    monkeypatch, servo_safety
):
    """``servo_inertial_number_safety`` caps the servo's rates alone (unset: the shared
    ``inertial_number_safety``); the compression to A keeps ``inertial_number_safety``, so a
    scene can load its paths faster with A bit for bit the same (study_servo.md)."""
    from dem_taichi.protocol import transition

    shared = 0.02  # the plant's servo asks for ~0.08 sqrt(p) uncapped: both caps bind
    runner, plant, measures, _ = servo_on_delayed_plant(
        2_000_000, RateRecordingPlant, servo_stiffness="secant",
        inertial_number_safety=shared, servo_inertial_number_safety=servo_safety,
    )  # fmt: skip
    used = shared if servo_safety is None else servo_safety
    assert runner.config.servo_safety() == used
    assert abs(measures["stress_yy"] / 15.0 - 1) <= runner.config.stress_tolerance
    # the cap binds at the key's value (halved at most once by the UFR rule on this plant)
    assert 0.45 * used <= plant.largest <= used * (1 + 1e-9)

    seen = []

    def cap(sim, p, floor, safety=1.0):
        seen.append(safety)
        return 1.0

    monkeypatch.setattr(transition, "strain_rate_cap", cap)
    monkeypatch.setattr(transition, "apply_strain", lambda *a, **k: {"mean_stress": 1.0})
    record = SimpleNamespace(steps=0, note=lambda *a, **k: None)
    compression_runner = SimpleNamespace(
        config=runner.config, sim=SimpleNamespace(step=0, scene=plant.scene),
        history=None, _record=lambda stage: record,
    )  # fmt: skip
    transition.load_compression(compression_runner, "isotropic_to_A", 1e-3, 1.0, 0.5)
    assert seen == [shared]
