"""The TIV model's elastic moduli at measured states (batched), for calibration and prediction.

At a measured state (σ_a, σ_r, v, β) the model's elastic strain ε^e = diag(e_a, e_r, e_r)
solves σ(ε^e; v, β) = (σ_a, σ_r, σ_r) (docs/science/tiv-model.md §2.1); it is found for all states
at once by a batched Newton iteration on (e_a, e_r) with the closed-form stiffness D = ∂σ/∂ε^e of
:func:`tiv_model.energy.stiffness`, with backtracking, started from the isotropic closed form
ε^e_v = (p/(F p_r))^(1−n)/(k(1−n)). The moduli are then the components of D (kPa):
E_oed,v = D_aaaa, E_oed,h = D_rrrr, cross term D_ra (= D_ar).

Closed form used in tests: on the isotropic axis with β = 0, D_aaaa = K + 4G/3 and
D_ra = K − 2G/3 with K = k p_r (p/p_r)^n (p_c/p_r)^r, G = g p_r (...), p_c = p_r (v/N)^(−1/λ*).

Symbols: σ_a, σ_r axial and radial stress (kPa), v specific volume, β the model's triaxial
fabric (signed like q), ε^e elastic strain (1), D elastic stiffness (Mandel, kPa).
"""

from __future__ import annotations

import numpy as np

from tiv_model.energy import (
    EnergyEvaluation,
    check_convexity,
    isotropic_elastic_volumetric_strain,
    stiffness,
)
from tiv_model.errors import TivModelError
from tiv_model.params import DEFAULT_OPTIONS, ModelOptions, Parameters
from tiv_model.tensors import TRIAXIAL_DIRECTION_MANDEL


class ModuliError(TivModelError):
    """The elastic law could not be inverted at some measured states."""


def triaxial_elastic_strain(
    axial_stress,
    radial_stress,
    specific_volume,
    fabric,
    params: Parameters,
    options: ModelOptions = DEFAULT_OPTIONS,
    tolerance: float = 1e-12,
    max_iterations: int = 60,
) -> np.ndarray:
    """Mandel elastic strains ``(n, 6)`` with σ(ε^e) = diag(σ_a, σ_r, σ_r) at each state.

    Raises :class:`ModuliError` naming the states where p ≤ 0 or Newton fails, and
    :class:`tiv_model.errors.NonConvexEnergyError` where ω β_s² ≥ 3/2.
    """
    sa = np.atleast_1d(np.asarray(axial_stress, dtype=float))
    sr = np.atleast_1d(np.asarray(radial_stress, dtype=float))
    v = np.atleast_1d(np.asarray(specific_volume, dtype=float)) * np.ones_like(sa)
    beta = np.atleast_1d(np.asarray(fabric, dtype=float)) * np.ones_like(sa)
    beta_m = beta[:, None] * TRIAXIAL_DIRECTION_MANDEL
    p = (sa + 2.0 * sr) / 3.0
    if np.any(~(p > 0)):
        raise ModuliError(f"mean stress p ≤ 0 at states {np.flatnonzero(~(p > 0)).tolist()}")
    check_convexity(beta_m, params)
    eps_v = isotropic_elastic_volumetric_strain(p, v, params)
    x = np.stack([eps_v / 3.0, eps_v / 3.0], axis=1)  # (e_a, e_r)
    target = np.stack([sa, sr], axis=1)
    scale = np.maximum(np.abs(target).max(axis=1), 1e-300)

    def strain(xx):
        out = np.zeros((xx.shape[0], 6))
        out[:, 0] = xx[:, 0]
        out[:, 1] = xx[:, 1]
        out[:, 2] = xx[:, 1]
        return out

    def residual(xx, rows):
        with np.errstate(all="ignore"):
            sig = EnergyEvaluation(strain(xx), v[rows], beta_m[rows], params, options).stress
        return np.stack([sig[:, 0], sig[:, 1]], axis=1) - target[rows]

    rows = np.arange(sa.size)
    res = residual(x, rows)
    norm = np.abs(res).max(axis=1) / scale
    for _ in range(max_iterations):
        active = np.flatnonzero(~(norm < tolerance))
        if active.size == 0:
            return strain(x)
        d = stiffness(strain(x[active]), v[active], beta_m[active], params, options)
        jac = np.empty((active.size, 2, 2))
        jac[:, 0, 0] = d[:, 0, 0]
        jac[:, 0, 1] = d[:, 0, 1] + d[:, 0, 2]
        jac[:, 1, 0] = d[:, 1, 0]
        jac[:, 1, 1] = d[:, 1, 1] + d[:, 1, 2]
        step = np.linalg.solve(jac, -res[active][:, :, None])[:, :, 0]
        alpha = np.ones(active.size)
        done = np.zeros(active.size, dtype=bool)
        new_x = x[active].copy()
        new_res = res[active].copy()
        new_norm = norm[active].copy()
        for _ in range(30):
            todo = np.flatnonzero(~done)
            if todo.size == 0:
                break
            trial = x[active[todo]] + alpha[todo, None] * step[todo]
            r_t = residual(trial, active[todo])
            n_t = np.abs(r_t).max(axis=1) / scale[active[todo]]
            ok = np.isfinite(n_t) & (n_t < (1.0 - 1e-4 * alpha[todo]) * norm[active[todo]])
            sel = todo[ok]
            new_x[sel], new_res[sel], new_norm[sel] = trial[ok], r_t[ok], n_t[ok]
            done[sel] = True
            alpha[todo[~ok]] *= 0.5
        if not np.any(done):
            break
        x[active], res[active], norm[active] = new_x, new_res, new_norm
    bad = np.flatnonzero(~(norm < 1e3 * tolerance))
    if bad.size:
        raise ModuliError(
            f"elastic law inversion failed at {bad.size} state(s), e.g. p = {p[bad[0]]:.4g} kPa, "
            f"v = {v[bad[0]]:.4g}, beta = {beta[bad[0]]:.4g} (relative residual "
            f"{norm[bad[0]]:.3g})"
        )
    return strain(x)


def moduli_at_states(
    axial_stress,
    radial_stress,
    specific_volume,
    fabric,
    params: Parameters,
    options: ModelOptions = DEFAULT_OPTIONS,
) -> dict[str, np.ndarray]:
    """Model elastic moduli (kPa) at measured states: ``e_oed_v`` = D_aaaa, ``e_oed_h`` = D_rrrr,
    ``e_cross`` = D_ra, ``stiffness_ratio`` = E_oed,h/E_oed,v, and ``stiffness`` (n, 6, 6)."""
    sa = np.atleast_1d(np.asarray(axial_stress, dtype=float))
    v = np.atleast_1d(np.asarray(specific_volume, dtype=float)) * np.ones_like(sa)
    beta = np.atleast_1d(np.asarray(fabric, dtype=float)) * np.ones_like(sa)
    eps = triaxial_elastic_strain(sa, radial_stress, v, beta, params, options)
    d = stiffness(eps, v, beta[:, None] * TRIAXIAL_DIRECTION_MANDEL, params, options)
    return {
        "e_oed_v": d[:, 0, 0],
        "e_oed_h": d[:, 1, 1],
        "e_cross": 0.5 * (d[:, 0, 1] + d[:, 1, 0]),
        "stiffness_ratio": d[:, 1, 1] / d[:, 0, 0],
        "stiffness": d,
    }
