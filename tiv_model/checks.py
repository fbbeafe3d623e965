"""Reusable thermodynamic checks of the TIV model (used by the tests, usable by anyone).

Each function returns numbers (errors, residuals, work) rather than asserting, so callers choose
their tolerances.

- :func:`stiffness_error`: analytic D vs central differences of σ(ε^e);
- :func:`legendre_consistency`: χ = ∂d/∂ε̇^p lies on y = 0 and ∂y/∂χ ∥ ε̇^p;
- :func:`closed_loop_work`: net work of a closed elastic strain loop (zero for a potential);
- :func:`mechanical_dissipation`: σ:Δε^p − (v φ_v) Δln v − φ_β:Δβ of an increment, which equals
  the dissipation function d ≥ 0 when the constraint forces are included;
- :func:`fabric_within_bounds`: β_{n+1} lies on the segment between β_n and β_b.
"""

from __future__ import annotations

import math

import numpy as np

from .dissipation import (
    YieldEvaluation,
    bounding_fabric,
    dissipation_rate,
    dissipative_stress,
    flow_direction,
    yield_function,
)
from .energy import EnergyEvaluation, _fabric_derivative, stiffness
from .integrate import Control, advance
from .params import DEFAULT_OPTIONS, DEFAULT_SETTINGS, ModelOptions, Parameters
from .state import State


def stiffness_error(
    elastic_strain_m,
    specific_volume,
    fabric_m,
    params,
    options=DEFAULT_OPTIONS,
    relative_step: float = 1e-6,
) -> float:
    """max |D − D_fd| / max |D| with D_fd from central differences of the stress."""
    eps = np.asarray(elastic_strain_m, dtype=float)
    h = relative_step * max(float(np.max(np.abs(eps))), 1e-12)
    pert = np.concatenate([eps + h * np.eye(6), eps - h * np.eye(6)])
    sig = EnergyEvaluation(pert, specific_volume, fabric_m, params, options).stress
    d_fd = (sig[:6] - sig[6:]).T / (2.0 * h)
    d = stiffness(eps, specific_volume, fabric_m, params, options)
    return float(np.max(np.abs(d - d_fd)) / np.max(np.abs(d)))


def legendre_consistency(
    plastic_rate_m, fabric_m, preconsolidation, params, size=None, shift=0.0
) -> tuple[float, float]:
    """(|y(χ)| / p_c², 1 − cos angle(∂y/∂χ, ε̇^p)) for χ = ∂d/∂ε̇^p (both ≈ 0 when consistent)."""
    chi = dissipative_stress(plastic_rate_m, fabric_m, preconsolidation, params, size, shift)
    y = float(yield_function(chi, fabric_m, preconsolidation, params, size, shift))
    n = flow_direction(chi, fabric_m, preconsolidation, params, shift)
    rate = np.asarray(plastic_rate_m, dtype=float)
    cos = float(n @ rate / (np.linalg.norm(n) * np.linalg.norm(rate)))
    return abs(y) / float(preconsolidation) ** 2, 1.0 - cos


def closed_loop_work(
    state: State,
    loop_strains,
    params: Parameters,
    options: ModelOptions = DEFAULT_OPTIONS,
    settings=DEFAULT_SETTINGS,
) -> tuple[float, float, State]:
    """Drive ``state`` through strain increments that sum to zero; returns (net work, gross
    work, final state), with the work per unit volume by the trapezoidal rule (kPa)."""
    current = state
    net = 0.0
    gross = 0.0
    for deps in loop_strains:
        new = advance(current, Control.strain(deps), params, options, settings)
        w = 0.5 * float((current.stress + new.stress) @ np.asarray(deps))
        net += w
        gross += abs(w)
        current = new
    return net, gross, current


def mechanical_dissipation(
    old: State, new: State, params: Parameters, options: ModelOptions = DEFAULT_OPTIONS
) -> tuple[float, float]:
    """(σ:Δε^p − (v φ_v) Δln v − φ_β:Δβ, d(Δε^p)) for one increment, both at the end state (kPa).

    Δε^p = Δε − Δε^e. With the constraint forces the two are equal (the thermodynamic
    identity of docs/science/tiv-model.md §2.2) and non-negative; without them only d is
    guaranteed ≥ 0.
    """
    dep = (new.strain - old.strain) - (new.elastic_strain - old.elastic_strain)
    ev = EnergyEvaluation(new.elastic_strain, new.specific_volume, new.fabric, params, options)
    v_phi_v = params.energy_exponent * float(ev.energy)
    phi_beta = _fabric_derivative(ev, new.elastic_strain, new.fabric, params, options)
    dlnv = math.log(new.specific_volume / old.specific_volume)
    work = float(new.stress @ dep) - v_phi_v * dlnv - float(phi_beta @ (new.fabric - old.fabric))
    d = float(dissipation_rate(dep, new.fabric, new.preconsolidation_pressure, params))
    return work, d


def fabric_within_bounds(
    old: State, new: State, params: Parameters, options: ModelOptions = DEFAULT_OPTIONS
) -> float:
    """Distance of β_{n+1} from the segment [β_n, β_b(σ_{n+1})] (0 when inside)."""
    bound = bounding_fabric(new.stress, params, options)
    seg = bound - old.fabric
    den = float(seg @ seg)
    t = 0.0 if den == 0.0 else float((new.fabric - old.fabric) @ seg) / den
    t = min(max(t, 0.0), 1.0)
    return float(np.linalg.norm(new.fabric - (old.fabric + t * seg)))


def yield_value(state: State, params: Parameters, options: ModelOptions = DEFAULT_OPTIONS) -> float:
    """y / p_c² at a state (≤ 0 inside the elastic domain, 0 on plastic states)."""
    ye = YieldEvaluation(state.elastic_strain, state.specific_volume, state.fabric, params, options)
    return float(ye.value) / state.preconsolidation_pressure**2
