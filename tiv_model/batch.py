"""Many material points integrated at once (numpy, general Mandel equations).

:class:`BatchState` holds the state of B points as arrays; :func:`strain_increment` applies a
strain increment ``(B, 6)`` (or one ``(6,)`` for all) by the same backward Euler as
:func:`tiv_model.integrate.strain_increment`: elastic trial for every point, then one batched
Newton with line search (exact Jacobian of :class:`tiv_model.local_problem.LocalProblem`,
``numpy.linalg.solve`` over the batch) for the points outside the yield surface. Points whose
Newton does not converge are integrated alone by :func:`tiv_model.integrate.advance` (with its
halving), so the batch gives the single-point answer everywhere (tested).

Strain control only (what a finite-element or a homogenisation code asks of the model).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .dissipation import YieldEvaluation, dissipation_rate, preconsolidation_pressure
from .energy import CONVEXITY_LIMIT, convexity_measure
from .errors import ConvergenceError, NonConvexEnergyError, SpecificVolumeBelowOneError
from .integrate import Control, advance
from .local_problem import LNV, MU, B, E, LocalProblem
from .params import DEFAULT_OPTIONS, DEFAULT_SETTINGS, TABLE1, ModelOptions, Parameters
from .state import State
from .tensors import trace

_ALPHAS = 0.5 ** np.arange(1, 10)


@dataclass(frozen=True)
class BatchState:
    """States of B points: Mandel arrays ``(B, 6)`` (strain, elastic_strain, stress, fabric)
    and ``(B,)`` arrays (specific_volume, preconsolidation_pressure, plastic_multiplier,
    dissipated_energy, plastic); units as in :class:`tiv_model.state.State`."""

    strain: np.ndarray
    elastic_strain: np.ndarray
    stress: np.ndarray
    specific_volume: np.ndarray
    fabric: np.ndarray
    preconsolidation_pressure: np.ndarray
    plastic_multiplier: np.ndarray
    dissipated_energy: np.ndarray
    plastic: np.ndarray

    @classmethod
    def from_states(cls, states: list[State]) -> BatchState:
        return cls(**{
            name: np.array([getattr(s, name) for s in states])
            for name in cls.__dataclass_fields__
        })  # fmt: skip

    def __len__(self) -> int:
        return self.stress.shape[0]

    def state(self, i: int) -> State:
        """Point ``i`` as a :class:`State`."""
        return State(**{name: getattr(self, name)[i] for name in self.__dataclass_fields__})

    def states(self) -> list[State]:
        return [self.state(i) for i in range(len(self))]


def _solve_batch(jac: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Steps ``(n, 14)`` and a mask of the points whose Jacobian could be solved."""
    try:
        steps = np.linalg.solve(jac, rhs[:, :, None])[:, :, 0]
        return steps, np.all(np.isfinite(steps), axis=1)
    except np.linalg.LinAlgError:
        steps = np.zeros_like(rhs)
        ok = np.zeros(len(rhs), dtype=bool)
        for i in range(len(rhs)):
            try:
                steps[i] = np.linalg.solve(jac[i], rhs[i])
                ok[i] = True
            except np.linalg.LinAlgError:
                pass
        return steps, ok & np.all(np.isfinite(steps), axis=1)


def _newton(problem: LocalProblem, x: np.ndarray, settings):
    """Batched Newton with backtracking; returns (x, res, stress, Δε^p, converged mask)."""
    with np.errstate(all="ignore"):
        res, sig, dep = problem.evaluate(x)
    norm = problem.norm(res)
    done = norm < settings.tolerance
    failed = ~np.isfinite(norm)
    for _ in range(settings.max_iterations):
        idx = np.flatnonzero(~done & ~failed)
        if idx.size == 0:
            break
        with np.errstate(all="ignore"):
            jac = problem.evaluate_jacobian(x[idx], rows=idx)[3]
        step, solved = _solve_batch(jac, -res[idx])
        failed[idx[~solved]] = True
        idx, step = idx[solved], step[solved]
        # full step for all, then shorter ones for the points it did not improve
        accepted = np.zeros(idx.size, dtype=bool)
        pending = np.arange(idx.size)
        for alpha in np.concatenate([[1.0], _ALPHAS]):
            if pending.size == 0:
                break
            rows = idx[pending]
            trial = x[rows] + alpha * step[pending]
            with np.errstate(all="ignore"):
                res_t, sig_t, dep_t = problem.evaluate(trial, rows=rows)
            norm_t = problem.norm(res_t, rows=rows)
            good = np.isfinite(norm_t) & (norm_t < (1.0 - 1e-4 * alpha) * norm[rows])
            take = rows[good]
            x[take], res[take], sig[take], dep[take], norm[take] = (
                trial[good],
                res_t[good],
                sig_t[good],
                dep_t[good],
                norm_t[good],
            )
            accepted[pending[good]] = True
            pending = pending[~good]
        stalled = idx[~accepted]
        # stagnation at round-off level is accepted as in the single-point solver
        done[stalled[norm[stalled] < 1e3 * settings.tolerance]] = True
        failed[stalled[norm[stalled] >= 1e3 * settings.tolerance]] = True
        done |= norm < settings.tolerance
    return x, res, sig, dep, done & ~failed


def strain_increment(
    batch: BatchState,
    strain_increment_m,
    params: Parameters = TABLE1,
    options: ModelOptions = DEFAULT_OPTIONS,
    settings=DEFAULT_SETTINGS,
) -> BatchState:
    """Integrate one strain increment at every point (module docstring); raises the typed
    errors of :func:`tiv_model.integrate.advance`, naming the point."""
    n = len(batch)
    deps = np.broadcast_to(np.asarray(strain_increment_m, dtype=float), (n, 6))
    trial = batch.elastic_strain + deps
    v_n = batch.specific_volume
    with np.errstate(all="ignore"):
        ye = YieldEvaluation(trial, v_n, batch.fabric, params, options)
    pc = ye.preconsolidation
    p_trial = trace(ye.stress) / 3.0
    plastic = ~(ye.value <= 1e-12 * pc * pc)
    bad_trial = ~(np.all(np.isfinite(ye.stress), axis=1) & (p_trial >= settings.minimum_pressure))
    out = {
        "strain": batch.strain + deps,
        "elastic_strain": trial.copy(),
        "stress": ye.stress.copy(),
        "specific_volume": v_n.copy(),
        "fabric": batch.fabric.copy(),
        "preconsolidation_pressure": pc.copy(),
        "plastic_multiplier": batch.plastic_multiplier.copy(),
        "dissipated_energy": batch.dissipated_energy.copy(),
        "plastic": np.zeros(n, dtype=bool),
    }
    alone: list[int] = np.flatnonzero(bad_trial).tolist()
    idx = np.flatnonzero(plastic & ~bad_trial)
    if idx.size:
        scale = np.maximum.reduce([np.abs(trial[idx]).max(axis=1), np.abs(deps[idx]).max(axis=1),
                                   np.full(idx.size, 1e-14)])  # fmt: skip
        problem = LocalProblem(trial[idx], batch.fabric[idx], np.log(v_n[idx]), params, options,
                               scale)  # fmt: skip
        x = np.concatenate(
            [trial[idx], np.zeros((idx.size, 1)), batch.fabric[idx], np.log(v_n[idx])[:, None]],
            axis=1,
        )
        x, _, sig, dep, ok = _newton(problem, x, settings)
        ok &= x[:, MU] >= -1e3 * settings.tolerance * scale
        alone.extend(idx[~ok].tolist())
        good, x, sig, dep = idx[ok], x[ok], sig[ok], dep[ok]
        v = np.exp(x[:, LNV])
        pc_new = preconsolidation_pressure(v, params)
        out["elastic_strain"][good] = x[:, E]
        out["stress"][good] = sig
        out["specific_volume"][good] = v
        out["fabric"][good] = x[:, B]
        out["preconsolidation_pressure"][good] = pc_new
        out["plastic_multiplier"][good] += x[:, MU] / pc_new
        out["dissipated_energy"][good] += dissipation_rate(dep, x[:, B], pc_new, params)
        out["plastic"][good] = True
    for i in sorted(alone):  # the single-point solver, with its halving and its errors
        try:
            new = advance(batch.state(i), Control.strain(deps[i]), params, options, settings)
        except ConvergenceError as exc:
            raise ConvergenceError(f"point {i}: {exc}", exc.state) from exc
        for name in out:
            out[name][i] = getattr(new, name)
    result = BatchState(**out)
    _check_batch(result, params)
    return result


def _check_batch(batch: BatchState, params: Parameters) -> None:
    low = np.flatnonzero(batch.specific_volume < 1.0)
    if low.size:
        i = int(low[0])
        raise SpecificVolumeBelowOneError(
            f"point {i}: specific volume v = {batch.specific_volume[i]:.6g} < 1", batch.state(i)
        )
    convex = np.flatnonzero(~(convexity_measure(batch.fabric, params) < CONVEXITY_LIMIT))
    if convex.size:
        i = int(convex[0])
        raise NonConvexEnergyError(f"point {i}: ω β_s² ≥ 3/2", batch.state(i))
    finite = np.all(np.isfinite(batch.stress), axis=1) & np.isfinite(batch.specific_volume)
    if not np.all(finite):
        i = int(np.flatnonzero(~finite)[0])
        raise ConvergenceError(f"point {i}: non-finite state after an increment")


def strain_path(batch: BatchState, increments, params=TABLE1, options=DEFAULT_OPTIONS,
                settings=DEFAULT_SETTINGS) -> list[BatchState]:  # fmt: skip
    """Apply a sequence of strain increments (each ``(B, 6)`` or ``(6,)``); all states."""
    states = [batch]
    for deps in increments:
        states.append(strain_increment(states[-1], deps, params, options, settings))
    return states


__all__ = ["BatchState", "strain_increment", "strain_path"]
