"""Residuals of the general (Mandel) backward-Euler increment and their exact Jacobian, batched.

Unknowns x = (ε^e, μ, β, ln v) (14 per point: 6, 1, 6, 1), residuals
(docs/science/tiv-model.md §2.4)
  R_ε = ε^e − ε^e_tr + μ n/p_c,  R_y = y/p_c²,  R_β = β(1 + cΔD̄) − β_n − cΔD̄ β_b,
  R_v = ln v − ln v_n + tr Δε^p,
all evaluated at the end of the increment for a batch of points ``(B, 14)``.

:meth:`LocalProblem.evaluate_jacobian` adds ∂R/∂x ``(B, 14, 14)`` and ∂σ/∂x ``(B, 6, 14)`` by
the chain rule through the same intermediates (forward mode written out): gradients over
s = (ε^e, β, ln v) (13 columns) of the mapped strain ε̃ = P(β)ε^e, the HAR stress
σ̃ = ∂Ψ/∂ε̃ (its derivative D̃ of :mod:`tiv_model.energy`), σ = Pσ̃, φ, the fabric derivative
φ_β (second derivatives of φ), the bounding fabric β_b(σ) (with f′(η) of the bound law), the
yield function and the flow direction; μ enters only through Δε^p = (μ/p_c) n and
ΔD̄ = |μ/p_c| D̄₁(n, β) (d|μ|/dμ = 1 at μ = 0: the derivative the Newton starts with).
At β_s = 0 the derivative of β_s is taken as 0 (it multiplies terms that vanish there).
Tested against finite differences in ``tests/tiv_model/test_jacobian.py``.

Symbols: see :mod:`tiv_model.energy` and :mod:`tiv_model.dissipation`.
"""

from __future__ import annotations

import math

import numpy as np

from .dissipation import YieldEvaluation, normalised_dissipation
from .energy import SYMMETRIC_PRODUCT_BASIS, energy_exponent, log_energy_constant
from .params import exponential_bound
from .tensors import DEVIATORIC_PROJECTOR_MANDEL, IDENTITY_MANDEL, deviator, trace

E = slice(0, 6)
MU = 6
B = slice(7, 13)
LNV = 13
SIZE = 14
_EYE6 = np.eye(6)
_TINY_Q = 1e-300
#: columns of x (14) for the 13 state columns s = (ε^e, β, ln v)
_STATE_COLUMNS = np.r_[0:6, 7:13, 13]


def _sym(vectors: np.ndarray) -> np.ndarray:
    """Mandel matrices ``(n, 6, 6)`` of ε ↦ sym(a·ε) for Mandel vectors a ``(n, 6)``."""
    return (vectors @ SYMMETRIC_PRODUCT_BASIS).reshape(-1, 6, 6)


def _mv(matrix: np.ndarray, vector: np.ndarray) -> np.ndarray:
    return (matrix @ vector[:, :, None])[:, :, 0]


def _vm(vector: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """Row vector times matrix per point: (n, i), (n, i, j) → (n, j)."""
    return (vector[:, None, :] @ matrix)[:, 0, :]


def _in_beta(vector: np.ndarray) -> np.ndarray:
    """A row vector times ∂β/∂s = [0 | I | 0]: its 13 state columns (n, 13)."""
    out = np.zeros((vector.shape[0], 13))
    out[:, 6:12] = vector
    return out


def _outer(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[:, :, None] * b[:, None, :]


def bound_factor_derivative(eta: np.ndarray, params, options) -> np.ndarray:
    """df/dη of the bound law: closed form for the exponential law, central differences else."""
    eta = np.asarray(eta, dtype=float)
    if options.bound_law is exponential_bound:
        a = params.s / params.M
        x = a * eta
        small = x < 1e-4
        safe = np.where(small, 1.0, eta)
        exact = (a * np.exp(-x) + np.expm1(-np.where(small, 0.0, x)) / safe) / safe
        series = a * a * (-0.5 + x / 3.0 - x * x / 8.0)
        return params.maximum_fabric * np.where(small, series, exact)
    h = 1e-6 * np.maximum(eta, 1e-3)
    lo = np.maximum(eta - h, 0.0)
    law = options.bound_law
    return (law(eta + h, params) - law(lo, params)) / (eta + h - lo)


class LocalProblem:
    """Residual of the implicit plastic increment for a batch of points.

    trial: ε^e_n + Δε ``(B, 6)``; beta_n ``(B, 6)``; lnv_n ``(B,)``; strain_scale ``(B,)``
    (the scale of the strain-like residuals in :meth:`norm`).
    """

    def __init__(self, trial, beta_n, lnv_n, params, options, strain_scale):
        self.params = params
        self.options = options
        self.trial = np.atleast_2d(np.asarray(trial, dtype=float))
        self.beta_n = np.atleast_2d(np.asarray(beta_n, dtype=float))
        self.lnv_n = np.atleast_1d(np.asarray(lnv_n, dtype=float))
        scale = np.ones((self.trial.shape[0], SIZE))
        strain_scale = np.atleast_1d(np.asarray(strain_scale, dtype=float))
        scale[:, E] = strain_scale[:, None]
        scale[:, LNV] = strain_scale
        self.scale = scale

    def evaluate(self, x: np.ndarray, rows=None):
        """Residuals (n, 14), stresses (n, 6) and plastic strain increments (n, 6) for x (n, 14);
        ``rows`` selects the points of the batch x belongs to (default: all, or point 0 for a
        single-point problem evaluated at several x)."""
        params = self.params
        trial, beta_n, lnv_n = self._rows(rows, x.shape[0])
        eps, mu, beta = x[:, E], x[:, MU], x[:, B]
        v = np.exp(x[:, LNV])
        ye = YieldEvaluation(eps, v, beta, params, self.options)
        pc = ye.preconsolidation
        dep = (mu / pc)[:, None] * ye.flow
        dbar = normalised_dissipation(dep, beta, params)
        res = np.empty_like(x)
        res[:, E] = eps - trial + dep
        res[:, MU] = ye.value / pc**2
        cd = params.c * dbar
        res[:, B] = beta * (1.0 + cd)[:, None] - beta_n - cd[:, None] * ye.bound
        res[:, LNV] = x[:, LNV] - lnv_n + trace(dep)
        p = trace(ye.stress) / 3.0
        bad = ~(p > 0.0)
        if np.any(bad):
            res[bad] = np.inf
        return res, ye.stress, dep

    def _rows(self, rows, n):
        if rows is None:
            rows = np.zeros(n, dtype=int) if self.trial.shape[0] == 1 else slice(None)
        return self.trial[rows], self.beta_n[rows], self.lnv_n[rows]

    def norm(self, res: np.ndarray, rows=None) -> np.ndarray:
        """Scaled max-norm of residuals ``(..., 14)`` (of point 0 for a single-point problem)."""
        scale = self.scale if rows is None else self.scale[rows]
        if self.scale.shape[0] == 1:
            scale = scale[0]
        return np.max(np.abs(res / scale), axis=-1)

    def evaluate_jacobian(self, x: np.ndarray, rows=None):
        """(res, σ, Δε^p, ∂R/∂x (n, 14, 14), ∂σ/∂x (n, 6, 14)) at x (n, 14), exact."""
        par, opt = self.params, self.options
        trial, beta_n, lnv_n = self._rows(rows, x.shape[0])
        n = x.shape[0]
        eps, mu, beta, lnv = x[:, E], x[:, MU], x[:, B], x[:, LNV]
        om, xx = par.omega, par.energy_exponent
        a = energy_exponent(par)
        lam = par.k * (1.0 - par.n) - 2.0 * par.g / 3.0
        g2 = 2.0 * par.g
        eye = np.broadcast_to(_EYE6, (n, 6, 6))
        devb = deviator(beta)
        bs2 = 1.5 * np.sum(devb * devb, axis=1)
        # -- mapped strain ε̃ = P ε^e and ∂ε̃/∂β ----------------------------------------------
        if opt.anisotropy == "A":
            bs = np.sqrt(bs2)
            safe = np.where(bs > 0.0, bs, 1.0)
            dbs = np.where(bs[:, None] > 0.0, 1.5 * devb / safe[:, None], 0.0)
            s_beta, s_eps = _sym(beta), _sym(eps)
            pmat = eye - om * bs[:, None, None] * s_beta
            sbe = _mv(s_beta, eps)
            mapped = eps - om * bs[:, None] * sbe
            dm_db = -om * (_outer(sbe, dbs) + bs[:, None, None] * s_eps)
        else:
            be = np.sum(beta * eps, axis=1)
            pmat = eye - om * _outer(beta, beta)
            mapped = eps - om * be[:, None] * beta
            dm_db = -om * (_outer(beta, eps) + be[:, None, None] * eye)
        c_eps = g2 * mapped
        c_eps[:, :3] += (lam * trace(mapped))[:, None]
        quad = np.maximum(np.sum(mapped * c_eps, axis=1), _TINY_Q)
        factor = np.exp(xx * (lnv - math.log(par.N)))
        ln_q = np.log(quad)
        kp = 2.0 * a * factor * np.exp(log_energy_constant(par) + (a - 1.0) * ln_q)
        phi = factor * np.exp(log_energy_constant(par) + a * ln_q)
        st = kp[:, None] * c_eps
        cmat = lam * np.outer(IDENTITY_MANDEL, IDENTITY_MANDEL) + g2 * _EYE6
        d_t = kp[:, None, None] * cmat + (2.0 * (a - 1.0) * kp / quad)[:, None, None] * _outer(
            c_eps, c_eps
        )
        # -- stress σ = P σ̃ and its gradient ------------------------------------------------
        if opt.anisotropy == "A":
            s_st = _sym(st)
            sst = _mv(s_beta, st)
            sigma = st - om * bs[:, None] * sst
            dpst_db = -om * (_outer(sst, dbs) + bs[:, None, None] * s_st)
        else:
            bst = np.sum(beta * st, axis=1)
            sigma = st - om * bst[:, None] * beta
            dpst_db = -om * (_outer(beta, st) + bst[:, None, None] * eye)
        pdt = pmat @ d_t
        dsig = np.concatenate([pdt @ pmat, pdt @ dm_db + dpst_db, (xx * sigma)[:, :, None]], axis=2)
        # -- φ, φ_β (deviatoric) and their gradients ----------------------------------------
        fb_raw = _vm(st, dm_db)
        dmt = np.swapaxes(dm_db, 1, 2)
        if opt.anisotropy == "A":
            e2 = -om * (_outer(dbs, sst) + bs[:, None, None] * s_st)
            u = _mv(s_eps, st)
            hess = 1.5 * DEVIATORIC_PROJECTOR_MANDEL[None] - _outer(dbs, dbs)
            hess = np.where(bs[:, None, None] > 0.0, hess / safe[:, None, None], 0.0)
            e3 = -om * (hess * np.sum(beta * u, axis=1)[:, None, None] + _outer(dbs, u)
                        + _outer(u, dbs))  # fmt: skip
        else:
            e2 = -om * (bst[:, None, None] * eye + _outer(st, beta))
            e3 = -om * (_outer(eps, st) + _outer(st, eps))
        dfb_raw = np.concatenate(
            [dmt @ d_t @ pmat + e2, dmt @ d_t @ dm_db + e3, (xx * fb_raw)[:, :, None]], axis=2
        )
        fb = deviator(fb_raw)
        dfb = DEVIATORIC_PROJECTOR_MANDEL[None] @ dfb_raw
        dphi = np.concatenate([sigma, fb_raw, (xx * phi)[:, None]], axis=1)
        # -- p_c, bounding fabric -----------------------------------------------------------
        pc = par.p_r * np.exp(-(lnv - math.log(par.N)) / par.lambda_star)
        dpc = np.zeros((n, 13))
        dpc[:, 12] = -pc / par.lambda_star
        p = trace(sigma) / 3.0
        s_dev = deviator(sigma)
        q = np.sqrt(1.5 * np.sum(s_dev * s_dev, axis=1))
        pos = p > 0.0
        p_safe = np.where(pos, p, 1.0)
        eta = q / p_safe
        f = np.asarray(opt.bound_law(eta, par), dtype=float)
        fp = bound_factor_derivative(eta, par, opt)
        bound = (f / p_safe)[:, None] * s_dev
        q_safe = np.where(q > 0.0, q, 1.0)
        deta = np.where(q[:, None] > 0.0, 1.5 * s_dev / (q_safe * p_safe)[:, None], 0.0)
        deta -= (eta / (3.0 * p_safe))[:, None] * IDENTITY_MANDEL
        dbound_dsig = (f / p_safe)[:, None, None] * DEVIATORIC_PROJECTOR_MANDEL[None] + _outer(
            s_dev, fp[:, None] * deta / p_safe[:, None] - (f / p_safe**2 / 3.0)[:, None]
            * IDENTITY_MANDEL
        )  # fmt: skip
        dbound = dbound_dsig @ dsig
        dbeta = np.zeros((n, 6, 13))
        dbeta[:, :, 6:12] = _EYE6
        # -- yield function and flow direction ---------------------------------------------
        if opt.constraint_forces:
            shift, dshift = -xx * phi, -xx * dphi
            gap = bound - beta
            size = 0.5 * pc + par.c * np.sum(fb * gap, axis=1)
            dsize = 0.5 * dpc + par.c * (_vm(gap, dfb) + _vm(fb, dbound) - _in_beta(fb))
        else:
            shift, dshift = np.zeros(n), np.zeros((n, 13))
            size, dsize = 0.5 * pc, 0.5 * dpc
        dp = (dsig[:, 0] + dsig[:, 1] + dsig[:, 2]) / 3.0
        ph = p - shift
        dph = dp - dshift
        rel = s_dev - ph[:, None] * beta
        drel = DEVIATORIC_PROJECTOR_MANDEL[None] @ dsig - _outer(beta, dph)
        drel -= ph[:, None, None] * dbeta
        m2 = par.M**2 - bs2
        dm2 = np.zeros((n, 13))
        dm2[:, 6:12] = -3.0 * devb
        hh = ph - 0.5 * pc
        dhh = dph - 0.5 * dpc
        gap2 = size * size - hh * hh
        y = 1.5 * np.sum(rel * rel, axis=1) - m2 * gap2
        dy = (3.0 * _vm(rel, drel) - dm2 * gap2[:, None]
              - 2.0 * m2[:, None] * (size[:, None] * dsize - hh[:, None] * dhh))  # fmt: skip
        rb = np.sum(rel * beta, axis=1)
        iso = 2.0 / 3.0 * m2 * hh - rb
        diso = 2.0 / 3.0 * (dm2 * hh[:, None] + m2[:, None] * dhh) - (
            _vm(beta, drel) + _in_beta(rel)
        )
        flow = 3.0 * rel + iso[:, None] * IDENTITY_MANDEL
        dflow = 3.0 * drel + IDENTITY_MANDEL[None, :, None] * diso[:, None, :]
        # -- plastic increment, dissipation, residuals --------------------------------------
        sc = mu / pc
        dsc = -(sc / pc)[:, None] * dpc
        dep = sc[:, None] * flow
        ddep = sc[:, None, None] * dflow + _outer(flow, dsc)
        wn = trace(flow) + np.sum(beta * flow, axis=1)
        en = deviator(flow)
        ee = np.sum(en * en, axis=1)
        d1 = np.sqrt(wn * wn + 2.0 / 3.0 * m2 * ee)
        dwn = (dflow[:, 0] + dflow[:, 1] + dflow[:, 2] + _vm(beta, dflow)
               + _in_beta(flow))  # fmt: skip
        den = DEVIATORIC_PROJECTOR_MANDEL[None] @ dflow
        dee = 2.0 * _vm(en, den)
        dd1 = (wn[:, None] * dwn + (dm2 * ee[:, None] + m2[:, None] * dee) / 3.0) / d1[:, None]
        sign = np.where(sc >= 0.0, 1.0, -1.0)
        dbar = np.abs(sc) * d1
        ddbar = np.abs(sc)[:, None] * dd1 + (sign * d1)[:, None] * dsc
        dbar_mu = sign * d1 / pc
        cd = par.c * dbar
        res = np.empty((n, SIZE))
        res[:, E] = eps - trial + dep
        res[:, MU] = y / pc**2
        res[:, B] = beta * (1.0 + cd)[:, None] - beta_n - cd[:, None] * bound
        res[:, LNV] = lnv - lnv_n + trace(dep)
        jac = np.zeros((n, SIZE, SIZE))
        ds_rows = np.zeros((n, SIZE, 13))
        ds_rows[:, E] = ddep
        ds_rows[:, E, 0:6] += _EYE6
        ds_rows[:, MU] = dy / (pc**2)[:, None] - (2.0 * y / pc**3)[:, None] * dpc
        ds_rows[:, B] = (1.0 + cd)[:, None, None] * dbeta - cd[:, None, None] * dbound
        ds_rows[:, B] += par.c * _outer(beta - bound, ddbar)
        ds_rows[:, LNV] = ddep[:, 0] + ddep[:, 1] + ddep[:, 2]
        ds_rows[:, LNV, 12] += 1.0
        jac[:, :, _STATE_COLUMNS] = ds_rows
        jac[:, E, MU] = flow / pc[:, None]
        jac[:, B, MU] = par.c * (beta - bound) * dbar_mu[:, None]
        jac[:, LNV, MU] = trace(flow) / pc
        dsig_x = np.zeros((n, 6, SIZE))
        dsig_x[:, :, _STATE_COLUMNS] = dsig
        bad = ~pos
        if np.any(bad):
            res[bad] = np.inf
        return res, sigma, dep, jac, dsig_x
