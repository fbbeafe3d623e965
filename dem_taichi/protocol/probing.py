"""Elastic probes at relaxed states of the loading paths (docs/science/dem-model.md §1.6, step 4).

Two methods, reported side by side:

- **Dynamic strain probe** (what the study did): from the relaxed state, apply Δε on one axis
  affinely (the cell is strain-controlled, the rods follow the affine flow plus their own
  dynamics) with the other axis fixed, relax at fixed cell to static equilibrium
  (UFR < ``[probing] relax_unbalanced_force``) and take the secant constrained modulus
  E(Δε) = (σ_aa(+Δε) − σ_aa(−Δε)) / (ε_aa(+) − ε_aa(−)) (average of the ± probes; the strains are
  the logarithmic strains actually applied, −ln(L/L_0)). Axis y → E_oed,v, axis x → E_oed,h.
  Sweeping Δε over ``[probing]`` amplitudes gives the stiffness-degradation curve; the elastic
  modulus is its plateau picked by :func:`dem_taichi.analysis.arrays.elastic_plateau` (rule stored
  in the probes dataset as ``plateau_rule``).
- **Linear-response probe**: :func:`dem_taichi.response.linear.linear_response` of
  ``sim.snapshot()`` — the full 2D stiffness tensor C (Voigt xx, yy, xy) at zero amplitude from the
  network Hessian with non-affine relaxation; E_oed,v = C_22, E_oed,h = C_11, bulk, shear.

Before probing, the copy of the path state is relaxed further at fixed cell to the probes' UFR
threshold (its stress change is kept as ``base_stress_change``), and both methods probe that
state. Probes never change the path: every probe runs on the same engine from a copy of the state
(``sim.get_state()``) and the state is restored with ``sim.set_state`` afterwards; the restored
state is bitwise identical (checked by :func:`probe_state` when ``verify=True`` and by the tests).

Symbols: σ_aa normal stress on axis a (force/length, compression positive), ε_aa logarithmic
strain (compression positive), E_oed,v = dσ_yy/dε_yy|ε_xx=0, E_oed,h = dσ_xx/dε_xx|ε_yy=0,
K = (C11+C12+C21+C22)/4 bulk, G = C33 shear, UFR unbalanced-force ratio.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal, TypeGuard

import numpy as np
import xarray as xr

from dem_taichi.analysis.arrays import Plateau, elastic_plateau
from dem_taichi.engine.measures import Measures
from dem_taichi.protocol.quasistatic import apply_strain, relax, strain_rate_cap
from dem_taichi.protocol.records import RunLog
from dem_taichi.scene.probing_sections import ProbingConfig
from dem_taichi.scene.protocol_sections import ProtocolConfig

if TYPE_CHECKING:
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.response.linear import LinearResponse

__all__ = [
    "DegradationCurve",
    "ProbeResult",
    "ProbeRecorder",
    "dynamic_modulus",
    "degradation_curve",
    "linear_probe",
    "probe_state",
    "probes_dataset",
    "AXES",
]

#: Probe axes: name → (axis index, name of the modulus).
AXES = {"x": (0, "e_oed_h"), "y": (1, "e_oed_v")}


@dataclass(frozen=True)
class DegradationCurve:
    """Secant constrained modulus against amplitude on one axis, with its elastic plateau.

    ``amplitudes`` (n,), ``moduli`` (n,) in force/length; ``stress_plus``/``stress_minus`` the
    relaxed σ_aa after ±Δε; ``strain_plus``/``strain_minus`` the applied strains; ``relaxed``
    whether both relaxations converged; ``steps`` engine steps used; ``seconds`` wall time.
    """

    axis: str
    amplitudes: np.ndarray
    moduli: np.ndarray
    stress_plus: np.ndarray
    stress_minus: np.ndarray
    strain_plus: np.ndarray
    strain_minus: np.ndarray
    relaxed: np.ndarray
    plateau: Plateau
    steps: int
    seconds: float


@dataclass
class ProbeResult:
    """Both probes at one relaxed path state."""

    label: str
    path: str
    increment: int
    measures: Measures
    curves: dict[str, DegradationCurve] = field(default_factory=dict)
    linear: LinearResponse | None = None
    dynamic_seconds: float = 0.0
    linear_seconds: float = 0.0
    state_restored_bitwise: bool | None = None
    base_relaxed: bool | None = None
    base_stress_change: float = 0.0

    def modulus(self, name: str, method: str) -> float:
        """``name`` in e_oed_v | e_oed_h, ``method`` in dynamic | linear (NaN if not run)."""
        if method == "linear":
            return float(getattr(self.linear, name)) if self.linear is not None else math.nan
        axis = "y" if name == "e_oed_v" else "x"
        curve = self.curves.get(axis)
        return curve.plateau.modulus if curve is not None else math.nan


def _relax_strict(
    sim: Simulation, config: ProbingConfig, check_steps: int, ufr: float | None = None
) -> tuple[Measures, bool, int]:
    """Relax at fixed cell to ``ufr`` (default ``[probing] relax_unbalanced_force``)."""
    return relax(
        sim,
        "probe",
        config.relax_unbalanced_force if ufr is None else ufr,
        math.inf,
        check_steps,
        config.relax_max_steps,
    )


def dynamic_modulus(
    sim: Simulation,
    axis: str,
    amplitude: float,
    config: ProbingConfig,
    protocol: ProtocolConfig,
    base_state: dict | None = None,
) -> tuple[float, dict]:
    """Secant constrained modulus of a ± strain probe of ``amplitude`` on ``axis`` (x | y).

    Runs on ``sim`` from ``base_state`` (default: the current state, copied) and restores it.
    Returns (E, details) with the relaxed stresses and applied strains of both signs.
    """
    if axis not in AXES:
        raise ValueError(f"axis = {axis!r}: allowed values are x | y")
    if not amplitude > 0:
        raise ValueError(f"amplitude must be > 0, got {amplitude!r}")
    index, _ = AXES[axis]
    base = sim.get_state() if base_state is None else base_state
    sim.set_state(base)
    p0 = sim.measure()["mean_stress"]
    lengths0 = sim.cell_lengths.copy()
    rate = strain_rate_cap(sim, p0, protocol.pressure_tolerance)
    out: dict[str, Any] = {"stress": [], "strain": [], "relaxed": [], "steps": 0}
    for sign in (1.0, -1.0):
        sim.set_state(base)
        strain = [0.0, 0.0]
        strain[index] = sign * amplitude
        start = sim.step
        apply_strain(sim, (strain[0], strain[1]), "probe", rate, config.apply_steps)
        measures, ok, _ = _relax_strict(sim, config, protocol.relax_check_steps)
        out["steps"] += sim.step - start
        applied = -math.log(float(sim.cell_lengths[index]) / float(lengths0[index]))
        out["stress"].append(measures["stress_xx"] if index == 0 else measures["stress_yy"])
        out["strain"].append(applied)
        out["relaxed"].append(ok)
    sim.set_state(base)
    modulus = (out["stress"][0] - out["stress"][1]) / (out["strain"][0] - out["strain"][1])
    return float(modulus), out


def degradation_curve(
    sim: Simulation,
    axis: str,
    config: ProbingConfig,
    protocol: ProtocolConfig,
    amplitudes: tuple[float, ...] | None = None,
) -> DegradationCurve:
    """Dynamic probes on ``axis`` over the amplitudes (default ``config.amplitudes``)."""
    t0 = time.perf_counter()
    amps = np.asarray(amplitudes if amplitudes is not None else config.amplitudes, dtype=float)
    base = sim.get_state()
    moduli, sp, sm, ep, em, relaxed = [], [], [], [], [], []
    steps = 0
    for a in amps:
        e, d = dynamic_modulus(sim, axis, float(a), config, protocol, base)
        moduli.append(e)
        sp.append(d["stress"][0])
        sm.append(d["stress"][1])
        ep.append(d["strain"][0])
        em.append(d["strain"][1])
        relaxed.append(all(d["relaxed"]))
        steps += d["steps"]
    sim.set_state(base)
    moduli_a = np.array(moduli)
    finite = np.isfinite(moduli_a)
    if finite.any():
        plateau = elastic_plateau(amps[finite], moduli_a[finite], config.plateau_tolerance)
    else:
        plateau = Plateau(math.nan, math.nan, 0, "no finite modulus")
    return DegradationCurve(
        axis, amps, moduli_a, np.array(sp), np.array(sm), np.array(ep), np.array(em),
        np.array(relaxed), plateau, steps, time.perf_counter() - t0,
    )  # fmt: skip


def _is_sliding_contacts(name: str) -> TypeGuard[Literal["free", "stuck"]]:
    return name in ("free", "stuck")


def linear_probe(sim: Simulation, sliding_contacts: str = "stuck") -> LinearResponse:
    """Linear-response stiffness of the current network (no change to the state); rigid or
    bonded rods (:func:`dem_taichi.response.bonded.network_response`)."""
    from dem_taichi.response.bonded import network_response

    if not _is_sliding_contacts(sliding_contacts):  # as network_response checks it
        raise ValueError(f"sliding_contacts = {sliding_contacts!r}: allowed 'free' or 'stuck'")
    return network_response(sim.snapshot(), sliding_contacts=sliding_contacts)


def probe_state(
    sim: Simulation,
    config: ProbingConfig,
    protocol: ProtocolConfig,
    label: str = "",
    path: str = "other",
    increment: int = 0,
    measures: Measures | None = None,
    verify: bool = True,
) -> ProbeResult:
    """Both probes at the current (relaxed) state of ``sim``; the state is restored exactly.

    With ``verify`` the state after the probes is compared bit for bit with the state before
    (``ProbeResult.state_restored_bitwise``; a mismatch raises ``RuntimeError``).
    """
    from dem_taichi.engine.state import states_equal

    before = sim.get_state()
    measures = measures.copy() if measures is not None else sim.measure()
    result = ProbeResult(label, path, increment, measures)
    # relax the copy further, to the probes' own threshold: a path state relaxed only to the
    # path's UFR still creeps, and on a marginal state (K0 near C on the default scene) the
    # creep differs between the + and − probes and swamps the response to small amplitudes
    # (to linear_relax_unbalanced_force when set and only the linear response probes here)
    dynamic = config.runs_dynamic(label)
    t0 = time.perf_counter()
    relaxed, ok, _ = _relax_strict(
        sim, config, protocol.relax_check_steps, config.base_relax_unbalanced_force(label)
    )
    result.base_relaxed = ok
    result.base_stress_change = float(
        max(abs(relaxed["stress_xx"] - measures["stress_xx"]),
            abs(relaxed["stress_yy"] - measures["stress_yy"]))
        / max(abs(measures["mean_stress"]), 1e-300)
    )  # fmt: skip
    # the strict relaxation is part of the dynamic sweep's cost (the linear response alone
    # would not need it) only where the sweep runs
    if dynamic:
        result.dynamic_seconds += time.perf_counter() - t0
    if config.linear:
        t0 = time.perf_counter()
        result.linear = linear_probe(sim, config.sliding_contacts)
        result.linear_seconds = time.perf_counter() - t0
    if dynamic:
        t0 = time.perf_counter()
        for axis in ("y", "x"):
            result.curves[axis] = degradation_curve(sim, axis, config, protocol)
        result.dynamic_seconds += time.perf_counter() - t0
    sim.set_state(before)
    if verify:
        result.state_restored_bitwise = states_equal(before, sim.get_state())
        if not result.state_restored_bitwise:
            raise RuntimeError(f"probing changed the path state at {label or path}")
    return result


class ProbeRecorder:
    """Probe hook of :class:`dem_taichi.protocol.paths.ProtocolRunner`: probes and keeps the
    results.

    The results and the probing times (in total, per method and per stage; the paths time their
    stages without the probes, so stage times and probing time add up) go to ``log``, the run's
    :class:`dem_taichi.protocol.records.RunLog` (a new one unless given); ``results``,
    ``seconds``, ``dynamic_seconds``, ``linear_seconds`` and ``seconds_by_stage`` read them.
    """

    def __init__(
        self, probing: ProbingConfig, protocol: ProtocolConfig, log: RunLog | None = None
    ) -> None:
        self.probing = probing
        self.protocol = protocol
        self.log = log if log is not None else RunLog()

    @property
    def results(self) -> list[ProbeResult]:
        return self.log.probes

    @property
    def seconds(self) -> float:
        return self.log.probing_seconds

    @property
    def dynamic_seconds(self) -> float:
        return self.log.probing_dynamic_seconds

    @property
    def linear_seconds(self) -> float:
        return self.log.probing_linear_seconds

    @property
    def seconds_by_stage(self) -> dict[str, float]:
        return self.log.probing_seconds_by_stage

    @property
    def amplitudes(self) -> tuple[float, ...]:
        return self.probing.amplitudes

    def __call__(self, runner, state) -> None:
        t0 = time.perf_counter()
        label = state.label or f"{state.stage}_{state.increment}"
        result = probe_state(
            runner.sim, self.probing, self.protocol, label, state.stage, state.increment,
            state.measures,
        )  # fmt: skip
        seconds = time.perf_counter() - t0
        log = self.log
        log.probes.append(result)
        log.probing_seconds += seconds
        log.probing_dynamic_seconds += result.dynamic_seconds
        log.probing_linear_seconds += result.linear_seconds
        by_stage = log.probing_seconds_by_stage
        by_stage[state.stage] = by_stage.get(state.stage, 0.0) + seconds
        runner._say(
            f"  probe {label}: E_v dyn={result.modulus('e_oed_v', 'dynamic'):.5g} "
            f"lin={result.modulus('e_oed_v', 'linear'):.5g}; E_h dyn="
            f"{result.modulus('e_oed_h', 'dynamic'):.5g} lin="
            f"{result.modulus('e_oed_h', 'linear'):.5g} ({seconds:.1f} s)"
        )


def probes_dataset(
    results: list[ProbeResult],
    amplitudes: tuple[float, ...],
    config: ProbingConfig,
    attrs: dict | None = None,
) -> xr.Dataset:
    """The probes dataset (names and attributes of :data:`dem_taichi.io.schema.PROBE_VARIABLES`)."""
    from dem_taichi.io import make_dataset

    n, m = len(results), len(amplitudes)
    values: dict[str, np.ndarray] = {
        "state_label": np.array([r.label for r in results], dtype=object),
        "path": np.array([r.path for r in results], dtype=object),
        "step": np.array([int(r.measures["step"]) for r in results], dtype=np.int64),
        "amplitude": np.asarray(amplitudes, dtype=float),
    }
    for name in ("stress_xx", "stress_yy", "mean_stress", "deviatoric_stress",
                 "specific_volume", "fabric_deviator"):  # fmt: skip
        values[name] = np.array([float(r.measures[name]) for r in results])
    nan = np.full(n, np.nan)
    for name in ("e_oed_v", "e_oed_h"):
        values[f"{name}_dynamic"] = np.array([r.modulus(name, "dynamic") for r in results])
        values[f"{name}_linear"] = np.array([r.modulus(name, "linear") for r in results])
        curve = np.full((n, m), np.nan)
        limit = nan.copy()
        axis = "y" if name == "e_oed_v" else "x"
        for i, r in enumerate(results):
            c = r.curves.get(axis)
            if c is not None and len(c.moduli) == m:
                curve[i] = c.moduli
                limit[i] = c.plateau.elastic_limit
        values[f"{name}_of_amplitude"] = curve
        values[f"{name}_elastic_limit"] = limit
    tensor = np.full((n, 3, 3), np.nan)
    bulk, shear, pure = nan.copy(), nan.copy(), nan.copy()
    for i, r in enumerate(results):
        if r.linear is not None:
            tensor[i] = r.linear.stiffness
            bulk[i] = r.linear.bulk_modulus
            shear[i] = r.linear.voigt_shear_modulus
            pure[i] = r.linear.pure_shear_modulus
    values["stiffness_tensor_linear"] = tensor
    values["bulk_modulus_linear"] = bulk
    values["shear_modulus_linear"] = shear
    values["pure_shear_modulus_linear"] = pure
    rule = next(
        (c.plateau.rule for r in results for c in r.curves.values() if c.plateau.n_points),
        f"elastic_plateau, relative tolerance {config.plateau_tolerance:g}",
    )
    merged = dict(attrs or {})
    merged.update(
        plateau_rule=rule,
        linear_sliding_contacts=config.sliding_contacts,
        dynamic_probe_relax_unbalanced_force=config.relax_unbalanced_force,
        linear_probe_relax_unbalanced_force=config.linear_only_relax_unbalanced_force,
        dynamic_seconds_total=float(sum(r.dynamic_seconds for r in results)),
        linear_seconds_total=float(sum(r.linear_seconds for r in results)),
    )
    return make_dataset(values, attrs=merged)
