"""TIV model runs along the DEM's paths, sampled at the DEM's points.

Every run starts, like the DEM, at state A: the model's isotropic state at the DEM's p_A on the
yield surface, with isotropic fabric (default, :func:`tiv_model.integrate.initial_state`) or a
given fabric β_A such as the DEM's measured one (:func:`start_state`). The paths are
driven with the model's own controls (:class:`tiv_model.integrate.Control`):

* :func:`isotropic_run`: σ_a = σ_r = p_k at the DEM's isotropic-path p_k (stress control);
* :func:`k0_run`: ε_r = 0 with σ_a = the DEM's σ_a,k (axial stress control): the K0 ratio,
  v and β are the model's answers at the DEM's vertical stresses;
* :func:`stress_path_run`: both σ_a and σ_r follow the DEM's stress history (stress control);
* :func:`unloading_run`: from the model's own state C (end of its K0 run) along the DEM's
  unloading path scaled onto it: p_k = p_C^model p_k^DEM/p_C^DEM and
  q_k = q_C^model q_k^DEM/q_C^DEM (so C ↦ C and the end q = 0 ↦ q = 0).

When a path has more points than ``max_increments``, the model takes ``max_increments`` of them
(evenly spread, always the last) as targets and its results are interpolated linearly in
ln σ_a (K0) or along the increment index to the others. Results are dictionaries of arrays at
the DEM points (first point = the start state).
"""

from __future__ import annotations

from typing import Literal, overload

import numpy as np

from tiv_model.drivers import record, run_path
from tiv_model.errors import TivModelError
from tiv_model.integrate import Control, initial_state
from tiv_model.params import DEFAULT_OPTIONS, ModelOptions, Parameters, SolverSettings
from tiv_model.state import IncrementGuess, State

#: Names of the per-point results (tiv_model.drivers.VARIABLES subset).
RUN_VARIABLES = (
    "axial_stress",
    "radial_stress",
    "mean_stress",
    "deviatoric_stress",
    "stress_ratio",
    "specific_volume",
    "fabric",
    "e_oed_v",
    "e_oed_h",
    "stiffness_ratio",
    "preconsolidation_pressure",
    "plastic",
)


def _subsample(n_points: int, max_increments: int) -> np.ndarray:
    """Indices 1..n−1 of the points used as targets (all when few enough)."""
    if n_points - 1 <= max_increments:
        return np.arange(1, n_points)
    idx = np.unique(np.round(np.linspace(1, n_points - 1, max_increments)).astype(int))
    return idx


def _collect(states: list[State], params, options) -> dict[str, np.ndarray]:
    rows = [record(s, params, options) for s in states]
    return {name: np.array([r[name] for r in rows]) for name in RUN_VARIABLES}


def _interpolate(results, used: np.ndarray, n_points: int, coordinate: np.ndarray):
    if used.size == n_points - 1:
        return results
    x_known = coordinate[np.concatenate([[0], used])]
    out = {}
    for name, values in results.items():
        out[name] = np.interp(coordinate, x_known, values)
    return out


class WarmStart:
    """Starting values for repeated runs of one path with nearby parameters (a calibration's
    evaluations and finite differences): the increments of the last run
    (:class:`tiv_model.state.IncrementGuess`), used only as the Newton's starting points.

    Started next to the solution, the Newton stops at the first iterate below its tolerance,
    so a warm run differs from a cold one by up to that tolerance; the runs use a tolerance
    100× tighter (``settings``) so that the optimiser's finite differences (steps 1e-6) do not
    see it (with the default tolerance the paper scene's fabric stage wandered for 1000
    evaluations instead of stopping at 60)."""

    settings = SolverSettings(tolerance=1e-13)

    def __init__(self) -> None:
        self.guesses: list[IncrementGuess] | None = None

    def update(self, states: list[State]) -> None:
        pairs = zip(states[:-1], states[1:], strict=True)
        self.guesses = [IncrementGuess.between(a, b) for a, b in pairs]


def _run(start: State, controls, params, options, settings=None, warm: WarmStart | None = None):
    if settings is None and warm is not None:
        settings = warm.settings
    kwargs = {} if settings is None else {"settings": settings}
    guesses = warm.guesses if warm is not None else None
    states, term = run_path(start, controls, params, options, on_error="raise",
                            guesses=guesses, **kwargs)  # fmt: skip
    if warm is not None:
        warm.update(states)
    return states, term


def start_state(
    mean_stress: float, params: Parameters, options: ModelOptions, fabric: float = 0.0
) -> State:
    """State A of the model at isotropic stress p_A (kPa), on the yield surface.

    ``fabric`` = 0 (default): the model's normally consolidated isotropic state
    (:func:`tiv_model.integrate.initial_state`). Otherwise the triaxial fabric β_A (e.g. the
    DEM's measured one): p_c is the root of y(p_c) = 0 at σ = p_A I with v = N (p_c/p_r)^(−λ*)
    (the rotated ellipse puts p_c above its isotropic value), found by Brent's method.
    """
    p = float(mean_stress)
    if fabric == 0.0:
        return initial_state(p, params, options)
    from scipy.optimize import brentq

    from tiv_model.dissipation import YieldEvaluation, specific_volume_for_preconsolidation
    from tiv_model.integrate import normally_consolidated_preconsolidation, state_from_stress
    from tiv_model.tensors import TRIAXIAL_DIRECTION_MANDEL

    beta = float(fabric) * TRIAXIAL_DIRECTION_MANDEL
    stress = np.array([p, p, p, 0.0, 0.0, 0.0])

    def state(pc: float) -> State:
        v = float(specific_volume_for_preconsolidation(pc, params))
        return state_from_stress(stress, v, beta, params, options)

    def y(pc: float) -> float:
        st = state(pc)
        ye = YieldEvaluation(st.elastic_strain, st.specific_volume, st.fabric, params, options)
        return float(ye.value) / pc**2

    # bracket the root: y > 0 (outside) below it, y < 0 (inside) above it
    low = high = normally_consolidated_preconsolidation(p, params, options)
    factor = 1.5
    for _ in range(80):
        if y(low) > 0:
            break
        high, low = low, low / factor
    else:
        raise TivModelError(f"no yield point found below p_c = {low:g} kPa at fabric {fabric:g}")
    for _ in range(80):
        if y(high) < 0:
            break
        low, high = high, high * factor
    else:
        raise TivModelError(f"no yield point found above p = {p:g} kPa at fabric {fabric:g}")
    pc = brentq(y, low, high, xtol=1e-13 * high, rtol=1e-13)
    return state(pc)


def isotropic_run(
    mean_stress,
    params: Parameters,
    options: ModelOptions = DEFAULT_OPTIONS,
    max_increments=40,
    start_fabric: float = 0.0,
) -> dict[str, np.ndarray]:
    """Model isotropic compression through the DEM's p_k (kPa; the first is p_A), from the
    state A of :func:`start_state` with fabric ``start_fabric``."""
    p = np.asarray(mean_stress, dtype=float)
    start = start_state(p[0], params, options, start_fabric)
    used = _subsample(p.size, max_increments)
    controls = [Control.triaxial(axial_stress=x, radial_stress=x) for x in p[used]]
    states, _ = _run(start, controls, params, options)
    return _interpolate(_collect(states, params, options), used, p.size, np.log(p))


def k0_run(
    axial_stress,
    start_mean_stress: float,
    params: Parameters,
    options: ModelOptions = DEFAULT_OPTIONS,
    max_increments: int = 40,
    return_state: bool = False,
    start_fabric: float = 0.0,
    warm: WarmStart | None = None,
):
    """Model K0 loading (ε_r = 0) through the DEM's σ_a,k (kPa) from state A at p_A.

    The first entry of ``axial_stress`` is the start point (its value is replaced by p_A).
    With ``return_state`` also returns the model's last State (C); ``start_fabric`` is the
    model's β at A (:func:`start_state`); ``warm`` carries starting values between runs.
    """
    sa = np.asarray(axial_stress, dtype=float).copy()
    sa[0] = float(start_mean_stress)
    start = start_state(start_mean_stress, params, options, start_fabric)
    used = _subsample(sa.size, max_increments)
    controls = [Control.triaxial(axial_stress=x, radial_strain_increment=0.0) for x in sa[used]]
    states, _ = _run(start, controls, params, options, warm=warm)
    coordinate = np.log(np.maximum.accumulate(sa))
    out = _interpolate(_collect(states, params, options), used, sa.size, coordinate)
    return (out, states[-1]) if return_state else out


@overload
def stress_path_run(
    axial_stress,
    radial_stress,
    params: Parameters,
    options: ModelOptions = ...,
    start: State | None = ...,
    max_increments: int = ...,
    start_fabric: float = ...,
    warm: WarmStart | None = ...,
    return_state: Literal[False] = ...,
) -> dict[str, np.ndarray]: ...


@overload
def stress_path_run(
    axial_stress,
    radial_stress,
    params: Parameters,
    options: ModelOptions = ...,
    start: State | None = ...,
    max_increments: int = ...,
    start_fabric: float = ...,
    warm: WarmStart | None = ...,
    *,
    return_state: Literal[True],
) -> tuple[dict[str, np.ndarray], State]: ...


def stress_path_run(
    axial_stress,
    radial_stress,
    params: Parameters,
    options: ModelOptions = DEFAULT_OPTIONS,
    start: State | None = None,
    max_increments: int = 40,
    start_fabric: float = 0.0,
    warm: WarmStart | None = None,
    return_state: bool = False,
) -> dict[str, np.ndarray] | tuple[dict[str, np.ndarray], State]:
    """Model run following the DEM's (σ_a, σ_r) history (kPa), from ``start`` or from state A
    (:func:`start_state` at the first point's p with ``start_fabric``); ``warm`` carries
    starting values between runs. With ``return_state`` also returns the model's last State
    (C when the history is K0's), as :func:`k0_run` does."""
    sa = np.asarray(axial_stress, dtype=float)
    sr = np.asarray(radial_stress, dtype=float)
    if start is None:
        start = start_state((sa[0] + 2.0 * sr[0]) / 3.0, params, options, start_fabric)
    used = _subsample(sa.size, max_increments)
    controls = [
        Control.triaxial(axial_stress=a, radial_stress=r)
        for a, r in zip(sa[used], sr[used], strict=True)
    ]
    states, _ = _run(start, controls, params, options, warm=warm)
    out = _interpolate(
        _collect(states, params, options), used, sa.size, np.arange(sa.size, dtype=float)
    )
    return (out, states[-1]) if return_state else out


def unloading_run(
    mean_stress,
    deviatoric_stress,
    state_c: State,
    params: Parameters,
    options: ModelOptions = DEFAULT_OPTIONS,
    max_increments: int = 40,
) -> dict[str, np.ndarray]:
    """Model unloading from its own state C along the DEM's (p, q) path scaled onto it."""
    p = np.asarray(mean_stress, dtype=float)
    q = np.asarray(deviatoric_stress, dtype=float)
    p_c = state_c.mean_stress
    q_c = float(state_c.stress[0] - state_c.stress[1])
    p_m = p_c * p / p[0]
    q_m = q_c * q / q[0] if q[0] != 0 else np.zeros_like(q)
    return stress_path_run(
        p_m + 2.0 * q_m / 3.0, p_m - q_m / 3.0, params, options, state_c, max_increments
    )
