"""Axisymmetric (triaxial) form of the TIV equations in ``math`` scalars, with the exact Jacobian.

The general integrator (:mod:`tiv_model.integrate`) works on 3×3 tensors in Mandel form with
vectorised numpy; each numpy call costs ~1–5 µs. On the element-test paths every tensor stays
diag(a, r, r) and the same backward-Euler problem reduces to five scalar unknowns
x = (ε^e_a, ε^e_r, μ, β, ln v) with closed-form scalar expressions:

  form A: ε̃_a = (1 − 2b/3) ε_a, ε̃_r = (1 + b/3) ε_r, b = ω |β| β
  form B: ε̃_a = ε_a − (4/9) ω β² (ε_a − ε_r), ε̃_r = ε_r + (2/9) ω β² (ε_a − ε_r)
  y = (q − p̂β)² − (M² − β²)[A² − (p̂ − p_c/2)²]
  n_a = 2(q − p̂β) + ι, n_r = −(q − p̂β) + ι, ι = (2/3)(M² − β²)(p̂ − p_c/2) − (2/3)(q − p̂β)β
  ΔD̄ = sqrt(w² + (4/9)(M² − β²)(Δε^p_a − Δε^p_r)²), w = Δε^p_v + (2/3) β (Δε^p_a − Δε^p_r)

(the triaxial reductions of :mod:`tiv_model.energy` and :mod:`tiv_model.dissipation`; the tests
check that both paths give the same states). β here is the signed scalar β_a − β_r.

:meth:`TriaxialModel.evaluate_jacobian` gives the residuals *and* their exact derivatives
∂R/∂x (5×5) and ∂(σ_a, σ_r)/∂x (2×5) by the chain rule through the same intermediate
quantities (forward mode written out; gradients over (ε^e_a, ε^e_r, β, ln v), μ separately).
Two conventions at non-differentiable points follow the forward differences used before:
d|β|/dβ = 1 at β = 0, and ΔD̄ = |μ| D̄₁ with d|μ|/dμ = 1 at μ = 0. The tests check the Jacobian
against finite differences. The solvers are in :mod:`tiv_model.triaxial_solver`.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from .energy import energy_exponent, log_energy_constant
from .params import ModelOptions, Parameters, exponential_bound

_TINY_Q = 1e-300
_FD = 1e-7
_THIRD = 1.0 / 3.0


class TriaxialModel:
    """Scalar residuals, stresses and their exact derivatives of the axisymmetric increment."""

    def __init__(self, params: Parameters, options: ModelOptions) -> None:
        self.params = params
        self.options = options
        self.a = energy_exponent(params)
        self.ln_c0 = log_energy_constant(params)
        self.lam = params.k * (1.0 - params.n) - 2.0 * params.g / 3.0
        self.g2 = 2.0 * params.g
        self.x = params.energy_exponent
        self.ln_n = math.log(params.N)
        self.form_a = options.anisotropy == "A"
        self.cf = options.constraint_forces
        self.exponential = options.bound_law is exponential_bound
        self.bound_a = params.s / params.M
        self.bound_scale = params.maximum_fabric
        self.c = params.c
        self.m2 = params.M * params.M
        self.p_r = params.p_r
        self.inv_lambda = 1.0 / params.lambda_star
        self.omega = params.omega

    # -- bound law ------------------------------------------------------------------------------
    def bound_factor(self, eta: float) -> float:
        """f(η) of the bound law (β_b = f(η) q/p in triaxial terms)."""
        if self.exponential:
            xa = self.bound_a * eta
            if xa < 1e-4:
                return self.bound_scale * self.bound_a * (1 - xa / 2 + xa * xa / 6 - xa**3 / 24)
            return self.bound_scale * -math.expm1(-xa) / eta
        return float(self.options.bound_law(np.array(eta), self.params))

    def bound_factor_derivative(self, eta: float) -> float:
        """df/dη: closed form for the exponential law, central difference for any other."""
        if self.exponential:
            a = self.bound_a
            xa = a * eta
            if xa < 1e-4:
                return self.bound_scale * a * a * (-0.5 + xa / 3.0 - xa * xa / 8.0)
            return self.bound_scale * (a * math.exp(-xa) + math.expm1(-xa) / eta) / eta
        h = 1e-6 * max(eta, 1e-3)
        lo = max(eta - h, 0.0)
        return (self.bound_factor(eta + h) - self.bound_factor(lo)) / (eta + h - lo)

    # -- energy ---------------------------------------------------------------------------------
    def stress(self, ea: float, er: float, beta: float, lnv: float):
        """(σ_a, σ_r, σ̃_a, σ̃_r, Q̃, F) at elastic strains (ε_a, ε_r), fabric β, ln v."""
        om = self.omega
        if self.form_a:
            b = om * abs(beta) * beta
            ta = (1.0 - 2.0 * b / 3.0) * ea
            tr = (1.0 + b / 3.0) * er
        else:
            k4 = om * beta * beta
            d = ea - er
            ta = ea - 4.0 / 9.0 * k4 * d
            tr = er + 2.0 / 9.0 * k4 * d
        tv = ta + 2.0 * tr
        quad = max(self.lam * tv * tv + self.g2 * (ta * ta + 2.0 * tr * tr), _TINY_Q)
        factor = math.exp(self.x * (lnv - self.ln_n))
        kp = 2.0 * self.a * factor * math.exp(self.ln_c0 + (self.a - 1.0) * math.log(quad))
        sta = kp * (self.lam * tv + self.g2 * ta)
        st_r = kp * (self.lam * tv + self.g2 * tr)
        if self.form_a:
            sa = (1.0 - 2.0 * b / 3.0) * sta
            sr = (1.0 + b / 3.0) * st_r
        else:
            ds = sta - st_r
            sa = sta - 4.0 / 9.0 * k4 * ds
            sr = st_r + 2.0 / 9.0 * k4 * ds
        return sa, sr, sta, st_r, quad, factor

    def stress_gradient(self, ea: float, er: float, beta: float, lnv: float):
        """Stresses and their gradients over (ε^e_a, ε^e_r, β, ln v).

        Returns (σ_a, σ_r, ∇σ_a, ∇σ_r, parts) where ``parts`` holds the mapped quantities the
        yield function needs: σ̃_a, σ̃_r with gradients, ∂ε̃/∂β with its gradient, Q̃ and F.
        """
        om, lam, g2, xx = self.omega, self.lam, self.g2, self.x
        if self.form_a:
            ab = abs(beta)
            b = om * ab * beta
            db = 2.0 * om * ab
            sgn2 = 2.0 * om if beta >= 0.0 else -2.0 * om  # d(db)/dβ, +1 convention at β = 0
            fa = 1.0 - 2.0 * b / 3.0
            fr = 1.0 + b / 3.0
            ta, tr = fa * ea, fr * er
            ta_g = (fa, 0.0, -2.0 / 3.0 * db * ea)
            tr_g = (0.0, fr, db / 3.0 * er)
            # ∂ε̃/∂β and its gradient over (ε_a, ε_r, β)
            ta_b, tr_b = ta_g[2], tr_g[2]
            ta_b_g = (-2.0 / 3.0 * db, 0.0, -2.0 / 3.0 * sgn2 * ea)
            tr_b_g = (0.0, db / 3.0, sgn2 / 3.0 * er)
        else:
            k4 = om * beta * beta
            dk4 = 2.0 * om * beta
            d = ea - er
            ta = ea - 4.0 / 9.0 * k4 * d
            tr = er + 2.0 / 9.0 * k4 * d
            ta_g = (1.0 - 4.0 / 9.0 * k4, 4.0 / 9.0 * k4, -4.0 / 9.0 * dk4 * d)
            tr_g = (2.0 / 9.0 * k4, 1.0 - 2.0 / 9.0 * k4, 2.0 / 9.0 * dk4 * d)
            ta_b, tr_b = ta_g[2], tr_g[2]
            ta_b_g = (-8.0 / 9.0 * om * beta, 8.0 / 9.0 * om * beta, -8.0 / 9.0 * om * d)
            tr_b_g = (4.0 / 9.0 * om * beta, -4.0 / 9.0 * om * beta, 4.0 / 9.0 * om * d)
        tv = ta + 2.0 * tr
        ca = lam * tv + g2 * ta
        cr = lam * tv + g2 * tr
        quad = max(lam * tv * tv + g2 * (ta * ta + 2.0 * tr * tr), _TINY_Q)
        factor = math.exp(xx * (lnv - self.ln_n))
        kp = 2.0 * self.a * factor * math.exp(self.ln_c0 + (self.a - 1.0) * math.log(quad))
        kq = (self.a - 1.0) * kp / quad  # ∂kp/∂Q̃
        sta, st_r = kp * ca, kp * cr
        # Hessian of Ψ in (ε̃_a, ε̃_r) (radial counted twice: ∂σ̃_a/∂ε̃_r = 2 ∂σ̃_r/∂ε̃_a)
        h_aa = kp * (lam + g2) + 2.0 * kq * ca * ca
        h_ar = 2.0 * kp * lam + 4.0 * kq * ca * cr
        h_ra = kp * lam + 2.0 * kq * ca * cr
        h_rr = kp * (2.0 * lam + g2) + 4.0 * kq * cr * cr
        sta_g = [
            h_aa * ta_g[0] + h_ar * tr_g[0],
            h_aa * ta_g[1] + h_ar * tr_g[1],
            h_aa * ta_g[2] + h_ar * tr_g[2],
        ] + [xx * sta]
        str_g = [
            h_ra * ta_g[0] + h_rr * tr_g[0],
            h_ra * ta_g[1] + h_rr * tr_g[1],
            h_ra * ta_g[2] + h_rr * tr_g[2],
        ] + [xx * st_r]
        if self.form_a:
            sa, sr = fa * sta, fr * st_r
            sa_g = [fa * sta_g[0], fa * sta_g[1], fa * sta_g[2] - 2.0 / 3.0 * db * sta, xx * sa]
            sr_g = [fr * str_g[0], fr * str_g[1], fr * str_g[2] + db / 3.0 * st_r, xx * sr]
        else:
            ds = sta - st_r
            sa = sta - 4.0 / 9.0 * k4 * ds
            sr = st_r + 2.0 / 9.0 * k4 * ds
            dsg = [
                sta_g[0] - str_g[0],
                sta_g[1] - str_g[1],
                sta_g[2] - str_g[2],
                sta_g[3] - str_g[3],
            ]
            sa_g = [
                sta_g[0] - 4.0 / 9.0 * k4 * dsg[0],
                sta_g[1] - 4.0 / 9.0 * k4 * dsg[1],
                sta_g[2] - 4.0 / 9.0 * k4 * dsg[2],
                sta_g[3] - 4.0 / 9.0 * k4 * dsg[3],
            ]
            sr_g = [
                str_g[0] + 2.0 / 9.0 * k4 * dsg[0],
                str_g[1] + 2.0 / 9.0 * k4 * dsg[1],
                str_g[2] + 2.0 / 9.0 * k4 * dsg[2],
                str_g[3] + 2.0 / 9.0 * k4 * dsg[3],
            ]
            sa_g[2] -= 4.0 / 9.0 * dk4 * ds
            sr_g[2] += 2.0 / 9.0 * dk4 * ds
        parts = (sta, st_r, sta_g, str_g, ta_b, tr_b, ta_b_g, tr_b_g, ta_g, tr_g, quad, factor)
        return sa, sr, sa_g, sr_g, parts

    # -- residuals ------------------------------------------------------------------------------
    def evaluate(self, x, trial_a, trial_r, beta_n, lnv_n):
        """Residuals (5), stresses (σ_a, σ_r) and (p_c, Δε^p_a, Δε^p_r, ΔD̄, w) at x.

        Residuals are None where the point is inadmissible (p ≤ 0, β_s > M, overflow), which
        the Newton line search treats as a rejected step.
        """
        try:
            return self._evaluate(x, trial_a, trial_r, beta_n, lnv_n)
        except (ValueError, OverflowError, ZeroDivisionError):
            return None, math.nan, math.nan, None

    def _evaluate(self, x, trial_a, trial_r, beta_n, lnv_n):
        ea, er, mu, beta, lnv = x
        sa, sr, sta, st_r, quad, factor = self.stress(ea, er, beta, lnv)
        p = (sa + 2.0 * sr) / 3.0
        q = sa - sr
        pc = self.p_r * math.exp(-(lnv - self.ln_n) * self.inv_lambda)
        if not p > 0.0:
            return None, sa, sr, None
        eta = abs(q) / p
        bb = self.bound_factor(eta) * q / p
        if self.cf:
            phi = factor * math.exp(self.ln_c0 + self.a * math.log(quad))
            shift = -self.x * phi
            om = self.omega
            if self.form_a:
                dta = -4.0 / 3.0 * om * abs(beta) * ea
                dtr = 2.0 / 3.0 * om * abs(beta) * er
            else:
                d = ea - er
                dta = -8.0 / 9.0 * om * beta * d
                dtr = 4.0 / 9.0 * om * beta * d
            size = 0.5 * pc + self.c * (sta * dta + 2.0 * st_r * dtr) * (bb - beta)
        else:
            shift = 0.0
            size = 0.5 * pc
        ph = p - shift
        rq = q - ph * beta
        m2 = self.m2 - beta * beta
        y = rq * rq - m2 * (size * size - (ph - 0.5 * pc) ** 2)
        iso = 2.0 / 3.0 * m2 * (ph - 0.5 * pc) - 2.0 / 3.0 * rq * beta
        scale = mu / pc
        dpa = scale * (2.0 * rq + iso)
        dpr = scale * (-rq + iso)
        dd = dpa - dpr
        w = dpa + 2.0 * dpr + 2.0 / 3.0 * beta * dd
        dbar = math.sqrt(w * w + 4.0 / 9.0 * m2 * dd * dd)
        cd = self.c * dbar
        res = (
            ea - trial_a + dpa,
            er - trial_r + dpr,
            y / (pc * pc),
            beta * (1.0 + cd) - beta_n - cd * bb,
            lnv - lnv_n + dpa + 2.0 * dpr,
        )
        return res, sa, sr, (pc, dpa, dpr, dbar, w)

    def evaluate_jacobian(self, x, trial_a, trial_r, beta_n, lnv_n):
        """As :meth:`evaluate`, plus ∂R/∂x (5×5 rows) and ∂(σ_a, σ_r)/∂x (2×5 rows), exact.

        Returns (res, σ_a, σ_r, aux, jac, dsig); res is None where the point is inadmissible.
        """
        try:
            return self._evaluate_jacobian(x, trial_a, trial_r, beta_n, lnv_n)
        except (ValueError, OverflowError, ZeroDivisionError):
            return None, math.nan, math.nan, None, None, None

    def _evaluate_jacobian(self, x, trial_a, trial_r, beta_n, lnv_n):
        ea, er, mu, beta, lnv = x
        sa, sr, sa_g, sr_g, parts = self.stress_gradient(ea, er, beta, lnv)
        sta, st_r, sta_g, str_g, ta_b, tr_b, ta_b_g, tr_b_g, ta_g, tr_g, quad, factor = parts
        # gradients below are over s = (ε^e_a, ε^e_r, β, ln v); index 2 is β, 3 is ln v
        p = (sa + 2.0 * sr) * _THIRD
        q = sa - sr
        p_g = [
            (sa_g[0] + 2.0 * sr_g[0]) * _THIRD,
            (sa_g[1] + 2.0 * sr_g[1]) * _THIRD,
            (sa_g[2] + 2.0 * sr_g[2]) * _THIRD,
            (sa_g[3] + 2.0 * sr_g[3]) * _THIRD,
        ]
        q_g = [sa_g[0] - sr_g[0], sa_g[1] - sr_g[1], sa_g[2] - sr_g[2], sa_g[3] - sr_g[3]]
        pc = self.p_r * math.exp(-(lnv - self.ln_n) * self.inv_lambda)
        pc_v = -pc * self.inv_lambda
        if not p > 0.0:
            return None, sa, sr, None, None, None
        eta = abs(q) / p
        f = self.bound_factor(eta)
        fp = self.bound_factor_derivative(eta)
        bb = f * q / p
        bb_q = f / p + fp * abs(q) / (p * p)
        bb_p = -q / (p * p) * (f + fp * eta)
        bb_g = [
            bb_q * q_g[0] + bb_p * p_g[0],
            bb_q * q_g[1] + bb_p * p_g[1],
            bb_q * q_g[2] + bb_p * p_g[2],
            bb_q * q_g[3] + bb_p * p_g[3],
        ]
        if self.cf:
            phi = factor * math.exp(self.ln_c0 + self.a * math.log(quad))
            # ∂φ/∂ε^e_a = σ_a, ∂φ/∂ε^e_r = 2σ_r (two radial directions), ∂φ/∂β = G, ∂φ/∂ln v = Xφ
            gfab = sta * ta_b + 2.0 * st_r * tr_b
            gfab_g = [
                sta_g[k] * ta_b + 2.0 * str_g[k] * tr_b + sta * ta_b_g[k] + 2.0 * st_r * tr_b_g[k]
                for k in range(3)
            ]
            gfab_g.append(self.x * gfab)
            shift_g = [-self.x * sa, -self.x * 2.0 * sr, -self.x * gfab, -self.x * self.x * phi]
            shift = -self.x * phi
            gap = bb - beta
            size = 0.5 * pc + self.c * gfab * gap
            size_g = [
                self.c * (gfab_g[0] * gap + gfab * bb_g[0]),
                self.c * (gfab_g[1] * gap + gfab * bb_g[1]),
                self.c * (gfab_g[2] * gap + gfab * bb_g[2]),
                self.c * (gfab_g[3] * gap + gfab * bb_g[3]),
            ]
            size_g[2] -= self.c * gfab
            size_g[3] += 0.5 * pc_v
        else:
            shift = 0.0
            shift_g = [0.0, 0.0, 0.0, 0.0]
            size = 0.5 * pc
            size_g = [0.0, 0.0, 0.0, 0.5 * pc_v]
        ph = p - shift
        ph_g = [p_g[0] - shift_g[0], p_g[1] - shift_g[1], p_g[2] - shift_g[2], p_g[3] - shift_g[3]]
        rq = q - ph * beta
        rq_g = [
            q_g[0] - beta * ph_g[0],
            q_g[1] - beta * ph_g[1],
            q_g[2] - beta * ph_g[2],
            q_g[3] - beta * ph_g[3],
        ]
        rq_g[2] -= ph
        m2 = self.m2 - beta * beta
        hh = ph - 0.5 * pc
        hh_g = [ph_g[0], ph_g[1], ph_g[2], ph_g[3] - 0.5 * pc_v]
        gap2 = size * size - hh * hh
        y = rq * rq - m2 * gap2
        y_g = [
            2.0 * rq * rq_g[0] - 2.0 * m2 * (size * size_g[0] - hh * hh_g[0]),
            2.0 * rq * rq_g[1] - 2.0 * m2 * (size * size_g[1] - hh * hh_g[1]),
            2.0 * rq * rq_g[2] - 2.0 * m2 * (size * size_g[2] - hh * hh_g[2]),
            2.0 * rq * rq_g[3] - 2.0 * m2 * (size * size_g[3] - hh * hh_g[3]),
        ]
        y_g[2] += 2.0 * beta * gap2
        iso = 2.0 / 3.0 * (m2 * hh - rq * beta)
        iso_g = [
            2.0 / 3.0 * (m2 * hh_g[0] - beta * rq_g[0]),
            2.0 / 3.0 * (m2 * hh_g[1] - beta * rq_g[1]),
            2.0 / 3.0 * (m2 * hh_g[2] - beta * rq_g[2]),
            2.0 / 3.0 * (m2 * hh_g[3] - beta * rq_g[3]),
        ]
        iso_g[2] -= 2.0 / 3.0 * (2.0 * beta * hh + rq)
        na, nr = 2.0 * rq + iso, -rq + iso
        na_g = [
            2.0 * rq_g[0] + iso_g[0],
            2.0 * rq_g[1] + iso_g[1],
            2.0 * rq_g[2] + iso_g[2],
            2.0 * rq_g[3] + iso_g[3],
        ]
        nr_g = [iso_g[0] - rq_g[0], iso_g[1] - rq_g[1], iso_g[2] - rq_g[2], iso_g[3] - rq_g[3]]
        # plastic strain increments Δε^p = (μ/p_c) n and ΔD̄ = |μ/p_c| D̄₁(n, β)
        sc = mu / pc
        sc_v = -sc * pc_v / pc
        dpa, dpr = sc * na, sc * nr
        dpa_g = [sc * na_g[0], sc * na_g[1], sc * na_g[2], sc * na_g[3]]
        dpr_g = [sc * nr_g[0], sc * nr_g[1], sc * nr_g[2], sc * nr_g[3]]
        dpa_g[3] += sc_v * na
        dpr_g[3] += sc_v * nr
        dpa_mu, dpr_mu = na / pc, nr / pc
        ddn = na - nr
        wn = na + 2.0 * nr + 2.0 / 3.0 * beta * ddn
        ddn_g = [na_g[0] - nr_g[0], na_g[1] - nr_g[1], na_g[2] - nr_g[2], na_g[3] - nr_g[3]]
        wn_g = [
            na_g[0] + 2.0 * nr_g[0] + 2.0 / 3.0 * beta * ddn_g[0],
            na_g[1] + 2.0 * nr_g[1] + 2.0 / 3.0 * beta * ddn_g[1],
            na_g[2] + 2.0 * nr_g[2] + 2.0 / 3.0 * beta * ddn_g[2],
            na_g[3] + 2.0 * nr_g[3] + 2.0 / 3.0 * beta * ddn_g[3],
        ]
        wn_g[2] += 2.0 / 3.0 * ddn
        d1 = math.sqrt(wn * wn + 4.0 / 9.0 * m2 * ddn * ddn)
        d1_g = [
            (wn * wn_g[0] + 4.0 / 9.0 * m2 * ddn * ddn_g[0]) / d1,
            (wn * wn_g[1] + 4.0 / 9.0 * m2 * ddn * ddn_g[1]) / d1,
            (wn * wn_g[2] + 4.0 / 9.0 * m2 * ddn * ddn_g[2]) / d1,
            (wn * wn_g[3] + 4.0 / 9.0 * m2 * ddn * ddn_g[3]) / d1,
        ]
        d1_g[2] -= 4.0 / 9.0 * beta * ddn * ddn / d1
        asc = abs(sc)
        ssc = 1.0 if sc >= 0.0 else -1.0
        dbar = asc * d1
        dbar_g = [asc * d1_g[0], asc * d1_g[1], asc * d1_g[2], asc * d1_g[3]]
        dbar_g[3] += ssc * sc_v * d1
        dbar_mu = ssc * d1 / pc
        cd = self.c * dbar
        w = sc * wn
        res = (
            ea - trial_a + dpa,
            er - trial_r + dpr,
            y / (pc * pc),
            beta * (1.0 + cd) - beta_n - cd * bb,
            lnv - lnv_n + dpa + 2.0 * dpr,
        )
        pc2 = pc * pc
        r2_g = [y_g[0] / pc2, y_g[1] / pc2, y_g[2] / pc2, y_g[3] / pc2]
        r2_g[3] -= 2.0 * y * pc_v / (pc2 * pc)
        cgap = self.c * (beta - bb)
        r3_g = [
            cgap * dbar_g[0] - cd * bb_g[0],
            cgap * dbar_g[1] - cd * bb_g[1],
            cgap * dbar_g[2] - cd * bb_g[2],
            cgap * dbar_g[3] - cd * bb_g[3],
        ]
        r3_g[2] += 1.0 + cd
        rows_g = (
            [dpa_g[0] + 1.0, dpa_g[1], dpa_g[2], dpa_g[3]],
            [dpr_g[0], dpr_g[1] + 1.0, dpr_g[2], dpr_g[3]],
            r2_g,
            r3_g,
            [
                dpa_g[0] + 2.0 * dpr_g[0],
                dpa_g[1] + 2.0 * dpr_g[1],
                dpa_g[2] + 2.0 * dpr_g[2],
                dpa_g[3] + 2.0 * dpr_g[3],
            ],
        )
        rows_g[4][3] += 1.0
        mu_col = (dpa_mu, dpr_mu, 0.0, cgap * dbar_mu, dpa_mu + 2.0 * dpr_mu)
        jac = [[g[0], g[1], m, g[2], g[3]] for g, m in zip(rows_g, mu_col, strict=True)]
        dsig = [
            [sa_g[0], sa_g[1], 0.0, sa_g[2], sa_g[3]],
            [sr_g[0], sr_g[1], 0.0, sr_g[2], sr_g[3]],
        ]
        return res, sa, sr, (pc, dpa, dpr, dbar, w), jac, dsig

    def finite_difference_jacobian(self, x, trial_a, trial_r, beta_n, lnv_n, strain_scale,
                                   base):  # fmt: skip
        """Forward-difference ∂R/∂x and ∂σ/∂x around ``base`` = (res, σ_a, σ_r) at x, with
        steps 1e-7 max(|x_j|, typical_j) (the Jacobian used before issue 12); (None, None)
        where a perturbed point is inadmissible."""
        res, sa, sr = base
        typical = (strain_scale, strain_scale, strain_scale, 1e-2, 1e-2)
        jac = [[0.0] * 5 for _ in range(5)]
        dsig = [[0.0] * 5 for _ in range(2)]
        for j in range(5):
            h = _FD * max(abs(x[j]), typical[j])
            xp = list(x)
            xp[j] += h
            rp, sap, srp, _ = self.evaluate(xp, trial_a, trial_r, beta_n, lnv_n)
            if rp is None:
                return None, None
            for i in range(5):
                jac[i][j] = (rp[i] - res[i]) / h
            dsig[0][j] = (sap - sa) / h
            dsig[1][j] = (srp - sr) / h
        return jac, dsig


@lru_cache(maxsize=64)
def model_for(params: Parameters, options: ModelOptions) -> TriaxialModel:
    """Cached :class:`TriaxialModel` for a parameter set and options."""
    return TriaxialModel(params, options)


def elastic_tangent(model: TriaxialModel, ea: float, er: float, beta: float, lnv: float):
    """2×2 elastic tangent [dσ_a, dσ_r]/[dε_a, dε_r] (radial strain applied to both radial
    directions), exact (kPa)."""
    _, _, sa_g, sr_g, _ = model.stress_gradient(ea, er, beta, lnv)
    return np.array([[sa_g[0], sa_g[1]], [sr_g[0], sr_g[1]]])


def finite_difference_elastic_tangent(model: TriaxialModel, ea, er, beta, lnv):
    """Central-difference version of :func:`elastic_tangent` (the one used before issue 12)."""
    tangent = np.empty((2, 2))
    h = _FD * max(abs(ea), abs(er), 1e-12)
    for j, (da, dr) in enumerate(((1.0, 0.0), (0.0, 1.0))):
        sp = model.stress(ea + h * da, er + h * dr, beta, lnv)
        sm = model.stress(ea - h * da, er - h * dr, beta, lnv)
        tangent[0, j] = (sp[0] - sm[0]) / (2 * h)
        tangent[1, j] = (sp[1] - sm[1]) / (2 * h)
    return tangent


def is_axisymmetric(state, control) -> bool:
    """Whether state and control stay diag(a, r, r) (so the fast path applies)."""
    sc = control.stress_controlled
    if any(sc[3:]) or any(control.strain_increment[3:]) or sc[1] != sc[2]:
        return False
    if sc[1] and control.stress_target[1] != control.stress_target[2]:
        return False
    if not sc[1] and control.strain_increment[1] != control.strain_increment[2]:
        return False
    for vec in (state.stress, state.elastic_strain, state.fabric):
        v0, v1, v2, v3, v4, v5 = vec.tolist()
        tol = 1e-13 * max(abs(v0), abs(v1), 1e-300)
        if abs(v1 - v2) > tol or max(abs(v3), abs(v4), abs(v5)) > tol:
            return False
    return True
