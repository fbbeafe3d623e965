"""Dissipation, yield surface, flow rule, hardening and bounding fabric
(docs/science/tiv-model.md §2.2–2.3).

d = (p_c/2)[D̄ + ε̇^p_v + β:ε̇^p] + I_K(v̇/v + ε̇^p_v) + I_L(β̇ − c(β_b − β)D̄)
D̄ = sqrt((ε̇^p_v + β:ε̇^p)² + (2/3)(M² − β_s²) ė^p:ė^p),   p_c = p_r (v/N)^(−1/λ*)

Evolution laws imposed by the indicator functions: v̇ = −v ε̇^p_v, β̇ = c(β_b − β) D̄.
Legendre transform (rotated ellipse, Dafalias 1986):
  y = (3/2)(s − p̂β):(s − p̂β) − (M² − β_s²)[A² − (p̂ − p_c/2)²]
  constraint forces on:  p̂ = p − Λ_K, Λ_K = −X φ,  A = p_c/2 + c φ_β:(β_b − β)
  constraint forces off: p̂ = p,       A = p_c/2
Flow ε̇^p = λ̇ n, n = ∂y/∂σ at fixed (Λ_K, A, β, p_c):
  n = 3 r + [(2/3)(M² − β_s²)(p̂ − p_c/2) − r:β] I,   r = s − p̂ β
Bounding fabric: β_b = f(η) s/p with f from the option ``bound_law`` (default
f = (M/z)(1 − e^(−sη/M))/η, i.e. β_b = (M/z)(1 − e^(−sη/M)) r̂).

Symbols: σ stress (kPa), s its deviator, p mean stress, q deviatoric stress, η = q/p,
p_c preconsolidation pressure (kPa), v specific volume (1), β fabric (1), φ free energy (kPa),
ε̇^p plastic strain rate (1/time or an increment), ė^p its deviator, λ̇ plastic multiplier.
All tensors are Mandel vectors with an optional leading batch shape.
"""

from __future__ import annotations

import numpy as np

from .energy import EnergyEvaluation, _fabric_derivative, constraint_pressure
from .params import DEFAULT_OPTIONS, ModelOptions, Parameters
from .tensors import IDENTITY_MANDEL, deviator, deviatoric_invariant, trace


def preconsolidation_pressure(specific_volume, params: Parameters):
    """p_c = p_r (v/N)^(−1/λ*) (kPa)."""
    return params.p_r * (np.asarray(specific_volume, dtype=float) / params.N) ** (
        -1.0 / params.lambda_star
    )


def specific_volume_for_preconsolidation(preconsolidation, params: Parameters):
    """Inverse of :func:`preconsolidation_pressure`: v = N (p_c/p_r)^(−λ*) (1)."""
    return params.N * (np.asarray(preconsolidation, dtype=float) / params.p_r) ** (
        -params.lambda_star
    )


def bounding_fabric(stress_m, params: Parameters, options: ModelOptions = DEFAULT_OPTIONS):
    """β_b = f(η) s/p (Mandel, 1) for a single stress or a batch; p must be > 0."""
    stress_m = np.asarray(stress_m, dtype=float)
    p = trace(stress_m) / 3.0
    s = deviator(stress_m)
    eta = deviatoric_invariant(stress_m) / p
    f = np.asarray(options.bound_law(eta, params), dtype=float)
    return (f / p)[..., None] * s


def normalised_dissipation(plastic_rate_m, fabric_m, params: Parameters):
    """D̄ = sqrt((ε̇^p_v + β:ε̇^p)² + (2/3)(M² − β_s²) ė^p:ė^p) (1/time)."""
    plastic_rate_m = np.asarray(plastic_rate_m, dtype=float)
    fabric_m = np.asarray(fabric_m, dtype=float)
    w = trace(plastic_rate_m) + np.sum(fabric_m * plastic_rate_m, axis=-1)
    e = deviator(plastic_rate_m)
    beta_s2 = deviatoric_invariant(fabric_m) ** 2
    return np.sqrt(w * w + (2.0 / 3.0) * (params.M**2 - beta_s2) * np.sum(e * e, axis=-1))


def dissipation_rate(plastic_rate_m, fabric_m, preconsolidation, params: Parameters):
    """d = (p_c/2)[D̄ + ε̇^p_v + β:ε̇^p] (kPa/time), constraints satisfied; ≥ 0 for β_s < M."""
    plastic_rate_m = np.asarray(plastic_rate_m, dtype=float)
    fabric_m = np.asarray(fabric_m, dtype=float)
    w = trace(plastic_rate_m) + np.sum(fabric_m * plastic_rate_m, axis=-1)
    dbar = normalised_dissipation(plastic_rate_m, fabric_m, params)
    return 0.5 * np.asarray(preconsolidation) * (dbar + w)


def dissipative_stress(
    plastic_rate_m, fabric_m, preconsolidation, params: Parameters, size=None, shift=0.0
):
    """χ = ∂d/∂ε̇^p (kPa) including the constraint-force terms.

    χ = A ∂D̄/∂ε̇^p + (p_c/2)(I + β) + Λ_K I, with A = ``size`` (default p_c/2, i.e. no
    fabric constraint force) and Λ_K = ``shift`` (default 0). By construction y(χ) = 0 and
    ∂y/∂χ ∥ ε̇^p (the Legendre consistency checked in :mod:`tiv_model.checks`).
    """
    rate = np.asarray(plastic_rate_m, dtype=float)
    beta = np.asarray(fabric_m, dtype=float)
    pc = np.asarray(preconsolidation, dtype=float)
    size = 0.5 * pc if size is None else np.asarray(size, dtype=float)
    w = trace(rate) + np.sum(beta * rate, axis=-1)
    e = deviator(rate)
    beta_s2 = deviatoric_invariant(beta) ** 2
    dbar = normalised_dissipation(rate, beta, params)
    grad = (
        w[..., None] * (IDENTITY_MANDEL + beta)
        + ((2.0 / 3.0) * (params.M**2 - beta_s2))[..., None] * e
    ) / dbar[..., None]
    return (
        size[..., None] * grad
        + (0.5 * pc)[..., None] * (IDENTITY_MANDEL + beta)
        + np.asarray(shift)[..., None] * IDENTITY_MANDEL
    )


def yield_function(stress_m, fabric_m, preconsolidation, params, size=None, shift=0.0):
    """y = (3/2)(s − p̂β):(s − p̂β) − (M² − β_s²)[A² − (p̂ − p_c/2)²] (kPa²).

    ``size`` is A (default p_c/2) and ``shift`` is Λ_K (default 0), so the defaults give the
    form without constraint forces, (q − pβ)² = (M² − β²) p (p_c − p) in triaxial conditions.
    """
    stress_m = np.asarray(stress_m, dtype=float)
    beta = np.asarray(fabric_m, dtype=float)
    pc = np.asarray(preconsolidation, dtype=float)
    size = 0.5 * pc if size is None else np.asarray(size, dtype=float)
    p_hat = trace(stress_m) / 3.0 - np.asarray(shift)
    rel = deviator(stress_m) - p_hat[..., None] * beta
    beta_s2 = deviatoric_invariant(beta) ** 2
    return 1.5 * np.sum(rel * rel, axis=-1) - (params.M**2 - beta_s2) * (
        size**2 - (p_hat - 0.5 * pc) ** 2
    )


def flow_direction(stress_m, fabric_m, preconsolidation, params, shift=0.0):
    """n = ∂y/∂σ at fixed Λ_K, A, β, p_c (Mandel, kPa)."""
    stress_m = np.asarray(stress_m, dtype=float)
    beta = np.asarray(fabric_m, dtype=float)
    pc = np.asarray(preconsolidation, dtype=float)
    p_hat = trace(stress_m) / 3.0 - np.asarray(shift)
    rel = deviator(stress_m) - p_hat[..., None] * beta
    beta_s2 = deviatoric_invariant(beta) ** 2
    iso = (2.0 / 3.0) * (params.M**2 - beta_s2) * (p_hat - 0.5 * pc) - np.sum(rel * beta, axis=-1)
    return 3.0 * rel + iso[..., None] * IDENTITY_MANDEL


class YieldEvaluation:
    """Yield quantities at a state (ε^e, v, β), batched; reuses an :class:`EnergyEvaluation`.

    Attributes: ``energy`` (EnergyEvaluation), ``stress`` σ, ``preconsolidation`` p_c,
    ``shift`` Λ_K, ``size`` A, ``bound`` β_b, ``value`` y (kPa²), ``flow`` n (kPa).
    """

    def __init__(self, elastic_strain_m, specific_volume, fabric_m, params, options, energy=None):
        ev = energy or EnergyEvaluation(
            elastic_strain_m, specific_volume, fabric_m, params, options
        )
        self.energy = ev
        self.stress = ev.stress
        self.preconsolidation = preconsolidation_pressure(specific_volume, params)
        self.bound = bounding_fabric(ev.stress, params, options)
        if options.constraint_forces:
            self.shift = constraint_pressure(ev.energy, params)
            phi_beta = _fabric_derivative(ev, elastic_strain_m, fabric_m, params, options)
            self.size = 0.5 * self.preconsolidation + params.c * np.sum(
                phi_beta * (self.bound - np.asarray(fabric_m)), axis=-1
            )
        else:
            self.shift = np.zeros_like(self.preconsolidation)
            self.size = 0.5 * self.preconsolidation
        self.value = yield_function(
            ev.stress, fabric_m, self.preconsolidation, params, self.size, self.shift
        )
        self.flow = flow_direction(ev.stress, fabric_m, self.preconsolidation, params, self.shift)
