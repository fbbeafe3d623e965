"""The protocol's stress servo: stress targets held at relaxed states
(docs/science/dem-model.md §1.6).

Between relaxed states the cell is strain-controlled: a strain correction on the servoed axes is
applied at a rate capped by the inertial number, ε̇ ≤ I_max sqrt(p/ρ)/d (p the current mean
stress, ρ = rod mass / rod area), and the sample is relaxed at fixed cell until UFR <
``relax_unbalanced_force`` and the kinetic energy per rod < ``relax_kinetic_energy_per_rod``.
The rate law is ε̇ = (s W C_a)⁻¹ (t − W σ)/T: W maps (σ_xx, σ_yy) to the controlled quantities
(σ_xx, σ_yy, or p), C_a is the linear-response stiffness of the relaxed network at the start,
s = 1 (``servo_stiffness = "elastic"``) or the measured secant/elastic ratio
(:class:`SecantStiffness`, ``"secant"``). A target is reached when |t − Wσ|/|t| ≤
``stress_tolerance`` (1e-3) at a relaxed state; only such states are recorded as path states.
:class:`StressServo` is the loop; :class:`ServoMemory` what it keeps from one call to the next
(the time constant T of each stage, doubled while the servo hunts).

Portable arithmetic: the servo's output (the strain rates) steers the trajectory, which the
serial engine keeps bit for bit, on any machine. So the servo's small linear algebra (the 1×1 or
2×2 gain, its products with residuals, the secant estimate) is plain Python float arithmetic
(IEEE double, no BLAS: OpenBLAS picks its kernels by CPU, with or without fused multiply-add,
which changes last bits), and the linear-response stiffness, computed by sparse solvers whose
last bits depend on the BLAS kernels, is rounded to ``JACOBIAN_DIGITS`` significant digits
before use (a controller gain needs no more; the rounding absorbs the kernels' differences
except for a value within ~1e-15 of a rounding boundary). Tested by running the smoke
references with OpenBLAS forced onto other kernels (``tests/test_portable_suite.py``).

Symbols: σ stress (force/length, compression positive), p = (σ_xx+σ_yy)/2, ε logarithmic strain
(compression positive), t the targets, UFR unbalanced-force ratio, I inertial number.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from dem_taichi.engine.measures import Measures
from dem_taichi.engine.work_profile import doing
from dem_taichi.protocol.quasistatic import _control, strain_rate_cap
from dem_taichi.protocol.records import ProtocolError, StageRecord
from dem_taichi.scene.protocol_sections import ProtocolConfig

if TYPE_CHECKING:
    from dem_taichi.engine.simulation import Simulation

__all__ = [
    "JACOBIAN_DIGITS",
    "ModalGain",
    "SecantStiffness",
    "ServoMemory",
    "StressServo",
    "initial_jacobian",
    "rate_factor",
]

#: Significant digits kept of the linear-response stiffness in the servo's gain (module docstring).
JACOBIAN_DIGITS = 6


def _matvec(matrix: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """matrix @ vector in Python floats, each row's sum correctly rounded (no BLAS: portable)."""
    return np.array([_dot(row, vector) for row in matrix])


def _matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a @ b of small matrices in Python floats (no BLAS: portable)."""
    return np.array([_matvec(a, column) for column in np.asarray(b).T]).T


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """a · b of two small vectors in Python floats (no BLAS: portable)."""
    return math.fsum([float(x) * float(y) for x, y in zip(a, b, strict=True)])


def _norm(a: np.ndarray) -> float:
    return math.sqrt(_dot(a, a))


def _inverse(matrix: np.ndarray) -> np.ndarray | None:
    """Inverse of a 1×1 or 2×2 matrix by the explicit formula (no LAPACK: portable); None when
    singular."""
    if matrix.shape == (1, 1):
        a = float(matrix[0, 0])
        return np.array([[1.0 / a]]) if a != 0.0 else None
    (a, b), (c, d) = ((float(v) for v in row) for row in matrix)
    det = a * d - b * c
    if det == 0.0 or not math.isfinite(det):
        return None
    return np.array([[d / det, -b / det], [-c / det, a / det]])


def _rounded(matrix: np.ndarray, digits: int) -> np.ndarray:
    """``matrix`` with each entry rounded to ``digits`` significant digits."""
    return np.array([[float(f"{float(v):.{digits - 1}e}") for v in row] for row in matrix])


def _stress(measures: Measures) -> np.ndarray:
    """(σ_xx, σ_yy) of a record."""
    return np.array([measures["stress_xx"], measures["stress_yy"]])


def _controlled(weights: np.ndarray, measures: Measures) -> np.ndarray:
    return _matvec(weights, _stress(measures))


def _strains(measures: Measures, axes: list[int]) -> np.ndarray:
    strain = np.array([measures["strain_xx"], measures["strain_yy"]], dtype=float)
    return strain[axes]


class SecantStiffness:
    """Secant/elastic stiffness ratio s of the servoed response since loading began in the
    current direction (``[protocol] servo_stiffness = "secant"``).

    The servo's rate law is ε̇ = (s J)⁻¹ (t − Wσ)/T with J = W C_a the elastic (linear-response)
    stiffness. On a plastic path the material's tangent stiffness is far below J (K0 on the
    paper scene near A: ~1/20), so with s = 1 the stress approaches its target with the time
    constant T J/J_tangent instead of T, and the loading runs an order of magnitude below the
    inertial-number cap. s is the projection of the measured change of the controlled stresses
    on the elastic prediction, s = (Δy·J Δε)/|J Δε|², both Δ since the start, used once
    |J Δε| exceeds ``min_change`` × |t| (below that, waves and noise dominate), clipped to
    [``s_min``, 1]. A residual that changes sign (overshoot: the response reverses, and a
    reversal is elastic) restarts the estimate at s = 1.
    """

    def __init__(self, jacobian: np.ndarray, s_min: float, min_change: float) -> None:
        self.jacobian = np.atleast_2d(np.asarray(jacobian, dtype=float))
        self.s_min = float(s_min)
        self.min_change = float(min_change)
        self.ratio = 1.0
        self._y0: np.ndarray | None = None
        self._e0: np.ndarray | None = None
        self._sign: np.ndarray | None = None

    def restart(self, controlled: np.ndarray, strains: np.ndarray) -> None:
        """Start a new estimate from the current controlled stresses and strains (s = 1)."""
        self.ratio = 1.0
        self._y0, self._e0, self._sign = controlled.copy(), strains.copy(), None

    def update(
        self, controlled: np.ndarray, strains: np.ndarray, residual: np.ndarray, scale: np.ndarray
    ) -> float:
        """Take the state after a servo update; return the new s."""
        sign = np.sign(residual)
        if self._sign is None:
            self._sign = sign
        elif np.any((sign != self._sign) & (sign != 0) & (self._sign != 0)):
            self.restart(controlled, strains)
            self._sign = sign
            return self.ratio
        predicted = _matvec(self.jacobian, strains - self._e0)
        if _norm(predicted) > self.min_change * _norm(scale):
            measured = controlled - self._y0
            s = _dot(measured, predicted) / _dot(predicted, predicted)
            self.ratio = min(max(s, self.s_min), 1.0)
        return self.ratio


def initial_jacobian(sim: Simulation, pressure_tolerance: float) -> np.ndarray:
    """dσ/dε (2×2, axial part) of the relaxed network from the linear-response probe, rounded
    to ``JACOBIAN_DIGITS`` significant digits (module docstring: portable trajectories)."""
    from dem_taichi.response.bonded import network_response

    try:
        response = network_response(sim.snapshot(), sliding_contacts="free")
        c = _rounded(np.asarray(response.stiffness[:2, :2], dtype=float), JACOBIAN_DIGITS)
        if np.all(np.isfinite(c)) and c[0, 0] * c[1, 1] - c[0, 1] * c[1, 0] > 0:
            return c
    except Exception:  # noqa: BLE001 - a guess only; fall back below
        pass
    p = max(sim.measure()["mean_stress"], pressure_tolerance)
    return np.array([[20.0 * p, 5.0 * p], [5.0 * p, 20.0 * p]])


def _drive_kind(wanted: np.ndarray, rate_cap: float, factor: float) -> str:
    """What limits the servo's rates over a check (the profile's work label,
    :mod:`dem_taichi.engine.work_profile`): ``cap`` the inertial-number cap on some axis,
    ``cap_ufr`` the same cap lowered while UFR is high, ``approach`` the gain (the rates are the
    residual's share, below the cap: the exponential approach to the target)."""
    if np.any(np.abs(wanted) >= rate_cap):
        return "cap" if factor >= 1.0 else "cap_ufr"
    return "approach"


def rate_factor(factor: float, ufr: float, unbalanced_force_max: float) -> float:
    """Halve the loading rate while UFR > ``unbalanced_force_max``; recover ×1.25 below."""
    if math.isfinite(ufr) and ufr > unbalanced_force_max:
        # floor 0.1: in a packing held by soft repulsion (basic pattern, default scene) UFR
        # stays above 0.1 while loading at any rate, and a lower floor stalled the servo
        return max(0.5 * factor, 0.1)
    return min(1.25 * factor, 1.0)


class ModalGain:
    """Gain factors of the servo's modes, halved where the loop overshoots (loose structures).

    The servo's gain is the inverse of the linear-response stiffness C_a of the relaxed network
    at the start of the target. On a loose, attraction-stabilised network (a fresh gel near A)
    the network the servo then loads is far stiffer than C_a in some mode: measured on the
    stalling state of issue 19 (default scene, F_max = 300, seed 11) the deviatoric tangent was
    ~80 × that of C_a, so each servo update overshot the deviator by more than it corrected,
    and the rates banged between the inertial-number caps with period two updates (σ_xx and
    σ_yy ±9 % around the target, the cell not moving on average) for 2,000,000 steps.

    The residual is split into modes: with two controls, the mean and the difference of the
    two controlled stresses (for (σ_xx, σ_yy): p and q, controlled separately); with one, the
    control itself. When a mode's residual changes sign between two updates without having
    shrunk below half its former size, and it was above the stress tolerance, the loop is
    unstable in that mode: its factor is halved (down to ``FLOOR``). A mode that does not
    overshoot recovers ×``RECOVERY`` per update, up to 1 (the network may soften again, e.g.
    when the gel collapses). The rate law becomes ε̇ = G B⁻¹ (f ∘ B r): r the residual in the
    controlled space, m = B r its modes, f the factors, G the gain (W C_a)⁻¹/T. With all factors
    1 this is G r, so a servo that never overshoots runs as before.
    """

    FLOOR = 1e-4
    RECOVERY = 1.1

    def __init__(self, n_controls: int) -> None:
        if n_controls == 1:
            self.basis, self.inverse = np.array([[1.0]]), np.array([[1.0]])
        else:
            self.basis = np.array([[0.5, 0.5], [-1.0, 1.0]])  # mean, difference
            self.inverse = np.array([[1.0, -0.5], [1.0, 0.5]])
        self.factors = np.ones(n_controls)
        self.overshoots = 0
        self._previous: np.ndarray | None = None

    def restart(self) -> None:
        """Forget the previous residual (after a relaxation at fixed cell)."""
        self._previous = None

    def scaled(self, residual: np.ndarray, tolerance: float) -> np.ndarray:
        """Update the factors from this residual and return B⁻¹ (f ∘ B r). ``tolerance``: the
        absolute stress below which a mode's residual counts as on target."""
        modes = _matvec(self.basis, residual)
        previous, self._previous = self._previous, modes
        if previous is not None:
            for k, (now, before) in enumerate(zip(modes, previous, strict=True)):
                flipped = now * before < 0.0 and abs(before) > tolerance
                if flipped and abs(now) > 0.5 * abs(before):
                    self.factors[k] = max(0.5 * self.factors[k], self.FLOOR)
                    self.overshoots += 1
                else:
                    self.factors[k] = min(self.RECOVERY * self.factors[k], 1.0)
        return _matvec(self.inverse, self.factors * modes)


@dataclass
class ServoMemory:
    """What the servo keeps between its calls on one branch: the time constant T of each stage
    (absent: ``[protocol] servo_time``), doubled while the servo hunts."""

    times: dict[str, float] = field(default_factory=dict)


class StressServo:
    """The servo loop on a :class:`dem_taichi.engine.simulation.Simulation` (or any object with its
    ``run``/``measure``/``snapshot``/``step``/``scene``/``geometry``).

    ``relax(stage)`` relaxes at fixed cell and returns (measures, relaxed); ``output(measures,
    steps)`` takes every loading check (the history cadence is the caller's); ``say(text)``
    reports progress.
    """

    def __init__(
        self,
        sim: Simulation,
        config: ProtocolConfig,
        relax: Callable[[str], tuple[Measures, bool]],
        output: Callable[[Measures, int], None],
        say: Callable[[str], None],
        memory: ServoMemory | None = None,
    ) -> None:
        self.sim = sim
        self.config = config
        self.relax = relax
        self.output = output
        self.say = say
        self.memory = memory if memory is not None else ServoMemory()

    @doing("servo")
    def __call__(
        self,
        stage: str,
        axes: tuple[int, ...],
        weights: np.ndarray,
        targets: np.ndarray,
        measures: Measures,
        record: StageRecord,
        tolerance: float | None = None,
    ) -> tuple[Measures, int]:
        """Reach W σ = targets at a relaxed state by servo-controlled strain rates on ``axes``,
        within ``tolerance`` relative (default ``stress_tolerance``).

        ``weights`` (n_ctrl × 2) maps (σ_xx, σ_yy) to the controlled quantities; ``axes`` lists
        the axes (0 = x, 1 = y) driven by the servo (as many as controls), the others are held
        fixed. Rate law, updated every ``servo_check_steps``: ε̇ = (W C_a)⁻¹ (t − W σ) / T with
        C_a the columns ``axes`` of the linear-response stiffness C of the relaxed network at the
        start, T = ``servo_time``, each rate capped by the inertial-number limit (and halved
        while UFR > ``unbalanced_force_max``). When every error is below half the tolerance and
        UFR below 100 × the relaxation threshold, the cell is fixed and the sample relaxed; the
        target is reached when the relaxed state is within ``stress_tolerance``, else the servo
        goes on. Hunting: when the servo has not settled ``servo_stall_times`` × T after first
        coming within ``servo_near_target`` of the targets and UFR is still ≥ 100 × the
        relaxation threshold, T is doubled for the rest of the stage (kept in ``memory``), at most
        to ``servo_time_max_factor`` × ``servo_time``: in soft repulsive
        packings (basic pattern, 300 rods) the loop at T = 2 is faster than the slow soft network
        (cell transit time L/c ≈ 1.5–2.5) and the stress hunts ±10 % around the target with
        UFR ≈ 0.05–0.1 forever; a slow but static approach (creep) does not change T.
        With ``servo_stiffness = "secant"`` the rate law uses s C_a, s the secant/elastic ratio
        measured since loading began in the current direction (:class:`SecantStiffness`).
        (A quasi-Newton correction between relaxed states was tried and dropped: on
        the smoke scene near A each correction triggers rearrangements and the relaxed stress
        jumps by ±2 %, so it alternated around the target without converging.) Overshoot: the
        residual is corrected mode by mode (:class:`ModalGain`: mean and deviator of two
        controls), each mode's gain halved while it overshoots, so a network much stiffer than
        C_a in one mode (a loose gel being loaded) does not bang between the rate caps. Returns
        the relaxed measures and the number of relaxations.
        """
        c = self.config
        sim = self.sim
        times = self.memory.times
        weights = np.atleast_2d(np.asarray(weights, dtype=float))
        targets = np.atleast_1d(np.asarray(targets, dtype=float))
        control_axes = list(axes)

        def inverse(stiffness: np.ndarray) -> np.ndarray:
            jac = _matmul(weights, stiffness[:, control_axes])
            inv = _inverse(jac)
            return inv if inv is not None else np.diag(1.0 / np.abs(np.diag(jac)))

        elastic = initial_jacobian(sim, c.pressure_tolerance)
        inverse_jacobian = inverse(elastic)
        servo_time = times.get(stage, c.servo_time)
        gain = inverse_jacobian / servo_time
        secant = SecantStiffness(
            _matmul(weights, elastic[:, control_axes]),
            c.servo_softening_min,
            c.servo_near_target,
        )
        secant.restart(_controlled(weights, measures), _strains(measures, control_axes))
        steps = 0
        checks = 0
        factor = 1.0
        scale = np.abs(targets)
        residual = targets - _controlled(weights, measures)
        near_steps = 0  # steps since the residual first came near the target (or last doubling)
        modal = ModalGain(len(targets))
        relative = c.stress_tolerance if tolerance is None else float(tolerance)
        tolerance = relative * float(np.mean(scale))
        while steps < c.servo_max_steps:
            residual = targets - _controlled(weights, measures)
            ufr = measures["unbalanced_force_ratio"]
            if np.all(np.abs(residual) <= 0.5 * relative * scale) and (
                math.isfinite(ufr) and ufr < 100.0 * c.relax_unbalanced_force
            ):
                # close and nearly static: fix the cell, relax, and check the relaxed state
                before = sim.step
                measures, ok = self.relax(stage)
                steps += sim.step - before
                checks += 1
                residual = targets - _controlled(weights, measures)
                self.say(
                    f"    [{stage}] relaxed check {checks}: residual/target "
                    f"{np.round(residual / scale, 5).tolist()} relaxed={ok} steps={steps}"
                )
                if ok and np.all(np.abs(residual) <= relative * scale):
                    return measures, checks
                modal.restart()
                continue
            if near_steps > 0 or np.all(np.abs(residual) <= c.servo_near_target * scale):
                near_steps += c.servo_check_steps
                stalled = near_steps * sim.time_step > c.servo_stall_times * servo_time
                hunting = not (math.isfinite(ufr) and ufr < 100.0 * c.relax_unbalanced_force)
                if stalled and not hunting:
                    near_steps = 0  # slow but static (creep): the gain is not the problem
                elif stalled and servo_time < c.servo_time_max_factor * c.servo_time:
                    # hunting around the target without settling: the loop is faster than the
                    # network (soft repulsive packings): halve the gain for the rest of the stage
                    servo_time *= 2.0
                    times[stage] = servo_time
                    gain = inverse_jacobian / (servo_time * secant.ratio)
                    near_steps = 0
                    self.say(
                        f"    [{stage}] servo not settling near the target "
                        f"(residual/target {np.round(residual / scale, 4).tolist()}, UFR "
                        f"{ufr:.3g}): servo time doubled to {servo_time:g}"
                    )
            factor = rate_factor(factor, ufr, c.unbalanced_force_max)
            rate_cap = factor * strain_rate_cap(
                sim, measures["mean_stress"], c.pressure_tolerance, c.servo_safety()
            )
            rates = np.zeros(2)
            corrected = modal.scaled(residual, tolerance)
            wanted = _matvec(gain, corrected)
            rates[control_axes] = np.clip(wanted, -rate_cap, rate_cap)
            with doing(_drive_kind(wanted, rate_cap, factor)):
                measures = sim.run(
                    c.servo_check_steps, _control(stage, float(rates[0]), float(rates[1]))
                )
            if c.servo_stiffness == "secant":
                controlled = _controlled(weights, measures)
                secant.update(
                    controlled, _strains(measures, control_axes), targets - controlled, scale
                )
                gain = inverse_jacobian / (servo_time * secant.ratio)
            steps += c.servo_check_steps
            record.steps += c.servo_check_steps
            record.note(measures, False, c.unbalanced_force_max)
            self.output(measures, c.servo_check_steps)
        raise ProtocolError(
            f"[{stage}] stress targets {targets.tolist()} not reached within "
            f"{c.servo_max_steps} steps (residual {residual.tolist()}, tolerance "
            f"{relative:g} relative); raise [protocol] servo_max_steps, or lower "
            "servo_time for a faster servo"
        )
