"""Free energy, stress and closed-form elastic stiffness (docs/science/tiv-model.md §2.1).

φ(ε^e, v, β) = F(v) Ψ(ε̃),   F(v) = (v/N)^X,   X = r / ((n − 1) λ*)
Ψ(ε̃) = p_r / (k(2 − n)) · [k(1 − n)]^a · Q̃^a,   a = (2 − n) / (2(1 − n))
Q̃ = [k(1 − n) − 2g/3] (tr ε̃)² + 2g tr(ε̃²) = ε̃ : C : ε̃,   C = [k(1−n) − 2g/3] I⊗I + 2g 𝕀

Fabric map ε̃ = P(β) : ε^e, P symmetric (option ``anisotropy``):
  "A": ε̃ = ε^e − ω β_s sym(β·ε^e)          "B": ε̃ = ε^e − ω (β:ε^e) β

Stress σ = ∂φ/∂ε^e = P : σ̃ with σ̃ = ∂φ/∂ε̃ = 2 a F C₀ Q̃^(a−1) C:ε̃, and the elastic stiffness
D = ∂²φ/∂ε^e∂ε^e = P : D̃ : P with
  D̃ = a F C₀ Q̃^(a−2) [4(a − 1) (C:ε̃)⊗(C:ε̃) + 2 Q̃ C]
(the Houlsby–Amorosi–Rojas 2005 stiffness, written with C₀ = p_r [k(1−n)]^a / (k(2−n))).
On the isotropic axis with β = 0 this gives K = k p_r (p/p_r)^n (p_c/p_r)^r, G = g p_r (...)
likewise, since F^(1−n) = (v/N)^(−r/λ*) = (p_c/p_r)^r.

Symbols: ε^e elastic strain (1, compression positive), v specific volume (internal variable of the
model, 1), β fabric (deviatoric, 1), φ free energy per unit volume (kPa), σ stress (kPa).
All arrays are Mandel (see :mod:`tiv_model.tensors`) with an optional leading batch shape.
Strict convexity of φ in ε^e needs P(β) positive definite; ω β_s² < 3/2 guarantees it for both
forms (exact for "B" and for form "A" in triaxial compression), and is what is checked.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import NonConvexEnergyError, TivModelError
from .params import DEFAULT_OPTIONS, ModelOptions, Parameters
from .tensors import (
    IDENTITY_MANDEL,
    deviator,
    deviatoric_invariant,
    from_mandel,
    symmetric_product_matrix,
    to_mandel,
    trace,
)

#: S_a = matrix of ε ↦ sym(e_a·ε) for the six Mandel basis tensors, as ``(6, 36)``: the
#: Mandel matrix of ε ↦ sym(β·ε) is β @ SYMMETRIC_PRODUCT_BASIS reshaped to 6×6.
SYMMETRIC_PRODUCT_BASIS = symmetric_product_matrix(np.eye(6)).reshape(6, 36)
#: Largest ω β_s² allowed (strict convexity of φ needs ω β_s² < 3/2).
CONVEXITY_LIMIT = 1.5
_TINY_Q = 1e-300


def energy_exponent(params: Parameters) -> float:
    """a = (2 − n) / (2(1 − n)), exponent of Q̃ in Ψ."""
    return (2.0 - params.n) / (2.0 * (1.0 - params.n))


def log_energy_constant(params: Parameters) -> float:
    """ln C₀ with C₀ = p_r [k(1 − n)]^a / (k(2 − n)) (kPa)."""
    a = energy_exponent(params)
    k, n = params.k, params.n
    return math.log(params.p_r / (k * (2.0 - n))) + a * math.log(k * (1.0 - n))


def isotropic_matrix(params: Parameters) -> np.ndarray:
    """Mandel matrix of C = [k(1−n) − 2g/3] I⊗I + 2g 𝕀 (1)."""
    lam = params.k * (1.0 - params.n) - 2.0 * params.g / 3.0
    return lam * np.outer(IDENTITY_MANDEL, IDENTITY_MANDEL) + 2.0 * params.g * np.eye(6)


def volume_factor(specific_volume, params: Parameters):
    """F(v) = (v/N)^X with X = r/((n − 1)λ*) (1)."""
    return (np.asarray(specific_volume, dtype=float) / params.N) ** params.energy_exponent


def fabric_invariant(fabric_m: np.ndarray) -> np.ndarray:
    """β_s = sqrt(3/2 β:β) (1)."""
    return deviatoric_invariant(fabric_m)


def convexity_measure(fabric_m: np.ndarray, params: Parameters) -> np.ndarray:
    """ω β_s² (1); the energy is strictly convex when it is below 3/2."""
    return params.omega * fabric_invariant(fabric_m) ** 2


def check_convexity(fabric_m: np.ndarray, params: Parameters, state=None) -> None:
    """Raise :class:`NonConvexEnergyError` if ω β_s² ≥ 3/2 anywhere in the batch."""
    measure = np.asarray(convexity_measure(fabric_m, params))
    if np.any(~(measure < CONVEXITY_LIMIT)):
        worst = float(np.max(measure))
        raise NonConvexEnergyError(
            f"free energy not strictly convex: ω β_s² = {worst:.6g} ≥ 3/2 "
            f"(ω = {params.omega:g}, β_s = {math.sqrt(max(worst, 0.0) / params.omega):.6g}); "
            "reduce ω or the bounding fabric M/z",
            state,
        )


def mapping_matrix(fabric_m: np.ndarray, params: Parameters, options: ModelOptions) -> np.ndarray:
    """Mandel matrix ``(..., 6, 6)`` of P(β), with ε̃ = P(β):ε^e (symmetric)."""
    fabric_m = np.asarray(fabric_m, dtype=float)
    eye = np.broadcast_to(np.eye(6), fabric_m.shape[:-1] + (6, 6))
    if options.anisotropy == "A":
        beta_s = fabric_invariant(fabric_m)
        return eye - params.omega * beta_s[..., None, None] * symmetric_product_matrix(fabric_m)
    return eye - params.omega * fabric_m[..., :, None] * fabric_m[..., None, :]


def mapped_strain(elastic_strain_m, fabric_m, params: Parameters, options: ModelOptions):
    """ε̃ = P(β):ε^e (Mandel, 1)."""
    elastic_strain_m = np.asarray(elastic_strain_m, dtype=float)
    fabric_m = np.asarray(fabric_m, dtype=float)
    if options.anisotropy == "A":
        eps = from_mandel(elastic_strain_m)
        beta = from_mandel(fabric_m)
        beta_s = fabric_invariant(fabric_m)
        return elastic_strain_m - params.omega * beta_s[..., None] * to_mandel(beta @ eps)
    dot = np.sum(fabric_m * elastic_strain_m, axis=-1)
    return elastic_strain_m - params.omega * dot[..., None] * fabric_m


class EnergyEvaluation:
    """Everything the integrator needs from φ at one (batched) point, computed once.

    Attributes (Mandel, batch shape ``(...)``): ``mapped`` ε̃, ``quadratic`` Q̃, ``factor`` F(v),
    ``energy`` φ (kPa), ``mapped_stress`` σ̃ (kPa), ``stress`` σ (kPa).
    """

    __slots__ = ("mapped", "quadratic", "factor", "energy", "mapped_stress", "stress", "_c")

    def __init__(self, elastic_strain_m, specific_volume, fabric_m, params, options):
        eps = np.asarray(elastic_strain_m, dtype=float)
        beta = np.asarray(fabric_m, dtype=float)
        a = energy_exponent(params)
        ln_c0 = log_energy_constant(params)
        cmat = isotropic_matrix(params)
        self._c = cmat
        mapped = mapped_strain(eps, beta, params, options)
        c_eps = mapped @ cmat
        quad = np.maximum(np.sum(mapped * c_eps, axis=-1), _TINY_Q)
        factor = volume_factor(specific_volume, params)
        ln_q = np.log(quad)
        self.mapped = mapped
        self.quadratic = quad
        self.factor = factor
        self.energy = factor * np.exp(ln_c0 + a * ln_q)
        mapped_stress = (2.0 * a * factor * np.exp(ln_c0 + (a - 1.0) * ln_q))[..., None] * c_eps
        self.mapped_stress = mapped_stress
        if options.anisotropy == "A":
            eps_t = from_mandel(mapped_stress)
            bt = from_mandel(beta)
            beta_s = fabric_invariant(beta)
            self.stress = mapped_stress - params.omega * beta_s[..., None] * to_mandel(bt @ eps_t)
        else:
            dot = np.sum(beta * mapped_stress, axis=-1)
            self.stress = mapped_stress - params.omega * dot[..., None] * beta


def free_energy(elastic_strain_m, specific_volume, fabric_m, params, options=DEFAULT_OPTIONS):
    """φ(ε^e, v, β) (kPa)."""
    return EnergyEvaluation(elastic_strain_m, specific_volume, fabric_m, params, options).energy


def stress(elastic_strain_m, specific_volume, fabric_m, params, options=DEFAULT_OPTIONS):
    """σ = ∂φ/∂ε^e (Mandel, kPa)."""
    return EnergyEvaluation(elastic_strain_m, specific_volume, fabric_m, params, options).stress


def stiffness(elastic_strain_m, specific_volume, fabric_m, params, options=DEFAULT_OPTIONS):
    """Elastic stiffness D = ∂²φ/∂ε^e∂ε^e as a Mandel matrix ``(..., 6, 6)`` (kPa).

    Closed form D = P D̃ P (see module docstring), evaluated as
    D = 4(a − 1) s (P c)⊗(P c) + 2 s Q̃ [λ (P 1)⊗(P 1) + 2g P P], s = a F C₀ Q̃^(a−2),
    c = C:ε̃ (the same terms, without forming D̃), batched in chunks of
    ``STIFFNESS_CHUNK`` points so that the temporaries stay in cache. Use
    :func:`tiv_model.tensors.mandel_to_tensor4` for the 3×3×3×3 tensor.
    """
    eps = np.asarray(elastic_strain_m, dtype=float)
    beta = np.asarray(fabric_m, dtype=float)
    volume = np.asarray(specific_volume, dtype=float)
    shape = eps.shape[:-1]
    if beta.shape[:-1] != shape or volume.shape != shape:
        shape = np.broadcast_shapes(shape, beta.shape[:-1], volume.shape)
        eps = np.broadcast_to(eps, shape + (6,))
        beta = np.broadcast_to(beta, shape + (6,))
        volume = np.broadcast_to(volume, shape)
    eps, beta, volume = eps.reshape(-1, 6), beta.reshape(-1, 6), volume.reshape(-1)
    out = np.empty((eps.shape[0], 6, 6))
    if eps.shape[0] <= STIFFNESS_CHUNK:
        _stiffness_block(eps, volume, beta, params, options, out)
        return out.reshape(shape + (6, 6))
    for start in range(0, eps.shape[0], STIFFNESS_CHUNK):
        part = slice(start, start + STIFFNESS_CHUNK)
        _stiffness_block(eps[part], volume[part], beta[part], params, options, out[part])
    return out.reshape(shape + (6, 6))


#: Points per block of the batched stiffness (temporaries of ~1 MB).
STIFFNESS_CHUNK = 2048
_DIAGONAL = (np.arange(6), np.arange(6))


def _stiffness_block(eps, volume, beta, params, options, out) -> None:
    """D of a block of points ``(n, 6)`` written into ``out`` ``(n, 6, 6)``.

    Form "B" has P = I − ω β⊗β, so Pε, Pc, P1 and PP = I + (ω²β:β − 2ω) β⊗β are written out
    (no 6×6 products); form "A" forms P."""
    a = energy_exponent(params)
    lam = params.k * (1.0 - params.n) - 2.0 * params.g / 3.0
    g2 = 2.0 * params.g
    om = params.omega
    form_b = options.anisotropy == "B"
    if form_b:
        mapped = eps - (om * np.sum(beta * eps, axis=1))[:, None] * beta
    else:
        pmat = _mapping_block(beta, params, options)
        mapped = (pmat @ eps[:, :, None])[:, :, 0]
    c_eps = g2 * mapped
    c_eps[:, :3] += (lam * (mapped[:, 0] + mapped[:, 1] + mapped[:, 2]))[:, None]
    quad = np.maximum(np.sum(mapped * c_eps, axis=1), _TINY_Q)
    ln_scale = log_energy_constant(params) + (a - 2.0) * np.log(quad)
    scale = a * volume_factor(volume, params) * np.exp(ln_scale)
    if form_b:
        p_c = c_eps - (om * np.sum(beta * c_eps, axis=1))[:, None] * beta
        p_one = IDENTITY_MANDEL - (om * (beta[:, 0] + beta[:, 1] + beta[:, 2]))[:, None] * beta
    else:
        p_c = (pmat @ c_eps[:, :, None])[:, :, 0]
        p_one = pmat[:, :, 0] + pmat[:, :, 1] + pmat[:, :, 2]
    np.multiply((4.0 * (a - 1.0) * scale)[:, None, None] * p_c[:, :, None], p_c[:, None, :], out)
    s2 = 2.0 * scale * quad
    out += (s2 * lam)[:, None, None] * p_one[:, :, None] * p_one[:, None, :]
    if form_b:
        kappa = om * om * np.sum(beta * beta, axis=1) - 2.0 * om
        out += (s2 * g2 * kappa)[:, None, None] * beta[:, :, None] * beta[:, None, :]
        out[:, _DIAGONAL[0], _DIAGONAL[1]] += (s2 * g2)[:, None]
    else:
        out += (s2 * g2)[:, None, None] * (pmat @ pmat)


def _mapping_block(beta, params, options) -> np.ndarray:
    """P(β) of a block ``(n, 6)`` as ``(n, 6, 6)``: S(β) = Σ_a β_a S_a from the constant
    basis of :func:`tiv_model.tensors.symmetric_product_matrix`."""
    if options.anisotropy == "A":
        pmat = (beta @ SYMMETRIC_PRODUCT_BASIS).reshape(-1, 6, 6)
        pmat *= (-params.omega * fabric_invariant(beta))[:, None, None]
    else:
        pmat = -params.omega * beta[:, :, None] * beta[:, None, :]
    pmat[:, _DIAGONAL[0], _DIAGONAL[1]] += 1.0
    return pmat


def fabric_derivative(elastic_strain_m, specific_volume, fabric_m, params, options=DEFAULT_OPTIONS):
    """φ_β = ∂φ/∂β restricted to deviatoric β (Mandel, kPa).

    "A": φ_β = −ω [ (3/(2β_s)) (σ̃ : sym(β ε^e)) β + β_s sym(σ̃ ε^e) ]
    "B": φ_β = −ω [ (σ̃:β) ε^e + (β:ε^e) σ̃ ]
    (deviatoric parts); the first term of "A" vanishes smoothly at β_s → 0.
    """
    ev = EnergyEvaluation(elastic_strain_m, specific_volume, fabric_m, params, options)
    return _fabric_derivative(ev, elastic_strain_m, fabric_m, params, options)


def _fabric_derivative(ev: EnergyEvaluation, eps_m, beta_m, params, options) -> np.ndarray:
    eps_m = np.asarray(eps_m, dtype=float)
    beta_m = np.asarray(beta_m, dtype=float)
    st = ev.mapped_stress
    if options.anisotropy == "A":
        eps = from_mandel(eps_m)
        beta = from_mandel(beta_m)
        sig_t = from_mandel(st)
        beta_s = fabric_invariant(beta_m)
        sym_beta_eps = to_mandel(beta @ eps)
        proj = np.sum(st * sym_beta_eps, axis=-1)
        safe = np.where(beta_s > 1e-300, beta_s, 1.0)
        first = np.where(beta_s > 1e-300, 1.5 * proj / safe, 0.0)[..., None] * beta_m
        second = beta_s[..., None] * to_mandel(sig_t @ eps)
        out = -params.omega * (first + second)
    else:
        s_beta = np.sum(st * beta_m, axis=-1)
        b_eps = np.sum(beta_m * eps_m, axis=-1)
        out = -params.omega * (s_beta[..., None] * eps_m + b_eps[..., None] * st)
    return deviator(out)


def constraint_pressure(energy, params: Parameters):
    """Λ_K = −v ∂φ/∂v = −X φ (kPa): the constraint force of the volume law
    (docs/science/tiv-model.md §2.2)."""
    return -params.energy_exponent * np.asarray(energy)


def isotropic_elastic_volumetric_strain(mean_stress, specific_volume, params: Parameters):
    """Closed-form ε^e_v on the isotropic axis with β = 0: ((p/(F p_r))^(1−n)) / (k(1−n))."""
    factor = volume_factor(specific_volume, params)
    ratio = np.asarray(mean_stress, dtype=float) / (factor * params.p_r)
    return ratio ** (1.0 - params.n) / (params.k * (1.0 - params.n))


def elastic_strain_for_stress(
    stress_m,
    specific_volume: float,
    fabric_m,
    params: Parameters,
    options: ModelOptions = DEFAULT_OPTIONS,
    tolerance: float = 1e-13,
    max_iterations: int = 60,
) -> np.ndarray:
    """Invert σ(ε^e) for one point by Newton with backtracking (φ is strictly convex).

    Starts from the isotropic closed form; raises :class:`TivModelError` if p ≤ 0 or the
    iteration fails.
    """
    target = np.asarray(stress_m, dtype=float)
    fabric_m = np.asarray(fabric_m, dtype=float)
    p = float(trace(target)) / 3.0
    if not p > 0.0:
        raise TivModelError(f"cannot invert the elastic law at mean stress p = {p:g} kPa ≤ 0")
    check_convexity(fabric_m, params)
    eps_v = float(isotropic_elastic_volumetric_strain(p, specific_volume, params))
    eps = eps_v / 3.0 * IDENTITY_MANDEL
    scale = max(float(np.max(np.abs(target))), 1e-300)

    def residual(e):
        return EnergyEvaluation(e, specific_volume, fabric_m, params, options).stress - target

    res = residual(eps)
    norm = float(np.max(np.abs(res))) / scale
    for _ in range(max_iterations):
        if norm < tolerance:
            return eps
        d = stiffness(eps, specific_volume, fabric_m, params, options)
        step = np.linalg.solve(d, -res)
        alpha = 1.0
        for _ in range(40):
            trial = eps + alpha * step
            with np.errstate(all="ignore"):
                res_t = residual(trial)
            norm_t = float(np.max(np.abs(res_t))) / scale
            if np.isfinite(norm_t) and norm_t < (1.0 - 1e-4 * alpha) * norm:
                break
            alpha *= 0.5
        else:
            break
        eps, res, norm = trial, res_t, norm_t
    if norm < 1e3 * tolerance:
        return eps
    raise TivModelError(
        f"elastic law inversion failed at p = {p:g} kPa, v = {specific_volume:g} "
        f"(relative residual {norm:.3g})"
    )
