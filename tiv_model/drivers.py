"""Element tests (drivers) returning ``xarray.Dataset``s along dimension ``step``.

Paths (triaxial, index 0 axial/vertical, 1 and 2 radial; compression positive, kPa):
- :func:`isotropic`: σ_a = σ_r = p increasing (stress control);
- :func:`k0`: ε_r = 0, σ_a increasing (axial stress control, radial strain control);
- :func:`constant_p_unloading`: p constant, q decreasing to a target (stress control);
- :func:`radial`: constant stress ratio η = q/p, p increasing (stress control);
- :func:`drained_triaxial`: axial strain increments at constant radial stress (mixed control);
- :func:`elastic_probe`: constrained moduli E_oed,v = D_aaaa, E_oed,h = D_rrrr, bulk and shear
  moduli of the **elastic** stiffness D at a state, without changing the state.
Default initial state: isotropic fabric, normally consolidated at p0 = 5 kPa.

Each step stores the state at the end of an increment; step 0 is the initial state. With
``on_error="stop"`` a path that cannot continue (typed error) returns what was done, with the
error message in the dataset attribute ``termination``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

import numpy as np
import xarray as xr

from . import __version__
from .dissipation import bounding_fabric
from .energy import EnergyEvaluation, constraint_pressure, stiffness
from .errors import ParameterError, TivModelError
from .integrate import Control, advance, initial_state
from .params import DEFAULT_OPTIONS, DEFAULT_SETTINGS, TABLE1, ModelOptions, Parameters
from .state import IncrementGuess, State
from .tensors import IDENTITY_MANDEL, axial_minus_radial, deviatoric_invariant

#: name -> (units, long_name) of every variable written along ``step``.
VARIABLES: dict[str, tuple[str, str]] = {
    "axial_stress": ("kPa", "axial (vertical) effective stress sigma_a"),
    "radial_stress": ("kPa", "radial (horizontal) effective stress sigma_r"),
    "mean_stress": ("kPa", "mean effective stress p = (sigma_a + 2 sigma_r)/3"),
    "deviatoric_stress": ("kPa", "deviatoric stress q = sigma_a - sigma_r"),
    "stress_ratio": ("1", "stress ratio eta = q/p"),
    "specific_volume": ("1", "specific volume v (model internal variable, sets p_c)"),
    "kinematic_specific_volume": ("1", "specific volume including elastic strain v exp(-tr eps_e)"),
    "fabric": ("1", "fabric invariant beta, signed like q (beta_a - beta_r)"),
    "bounding_fabric": ("1", "bounding fabric beta_b, signed like q"),
    "preconsolidation_pressure": ("kPa", "preconsolidation pressure p_c = p_r (v/N)^(-1/lambda*)"),
    "constraint_force": ("kPa", "volumetric constraint force Lambda_K = -X phi"),
    "axial_strain": ("1", "axial logarithmic strain"),
    "radial_strain": ("1", "radial logarithmic strain"),
    "volumetric_strain": ("1", "volumetric logarithmic strain eps_v"),
    "deviatoric_strain": ("1", "triaxial deviatoric strain eps_s = 2/3 (eps_a - eps_r)"),
    "e_oed_v": ("kPa", "vertical constrained elastic modulus E_oed,v = D_aaaa"),
    "e_oed_h": ("kPa", "horizontal constrained elastic modulus E_oed,h = D_rrrr"),
    "stiffness_ratio": ("1", "elastic stiffness anisotropy E_oed,h / E_oed,v"),
    "bulk_modulus": ("kPa", "elastic bulk modulus dp/deps_v under an isotropic strain probe"),
    "shear_modulus": ("kPa", "elastic shear modulus dq/(3 deps_s) under an isochoric probe"),
    "plastic_multiplier": ("kPa-1", "accumulated plastic multiplier sum of delta lambda"),
    "dissipated_energy": ("kPa", "accumulated dissipation per unit volume"),
    "plastic": ("1", "1 if the increment ending at this step was plastic"),
}


@dataclass(frozen=True)
class ElasticModuli:
    """Elastic moduli at a state (kPa); ``stiffness`` is the Mandel 6×6 matrix D."""

    e_oed_v: float
    e_oed_h: float
    bulk_modulus: float
    shear_modulus: float
    stiffness: np.ndarray

    @property
    def stiffness_ratio(self) -> float:
        """E_oed,h / E_oed,v."""
        return self.e_oed_h / self.e_oed_v


_SHEAR_PROBE = np.array([1.0, -0.5, -0.5, 0.0, 0.0, 0.0])


def elastic_probe(
    state: State, params: Parameters = TABLE1, options: ModelOptions = DEFAULT_OPTIONS
) -> ElasticModuli:
    """Elastic moduli of the free energy at ``state`` (the state is not changed).

    E_oed,v = D_aaaa, E_oed,h = D_rrrr (constrained moduli, docs/science/tiv-model.md §2.1);
    bulk = I:D:I / 9 (isotropic strain probe); shear = Δq / (3 Δε_s) for the isochoric strain
    probe Δε = Δε_s diag(1, −1/2, −1/2). On the isotropic axis these are K and G exactly.
    """
    d = stiffness(state.elastic_strain, state.specific_volume, state.fabric, params, options)
    dsig = d @ _SHEAR_PROBE
    return ElasticModuli(
        e_oed_v=float(d[0, 0]),
        e_oed_h=float(d[1, 1]),
        bulk_modulus=float(IDENTITY_MANDEL @ d @ IDENTITY_MANDEL) / 9.0,
        shear_modulus=float(dsig[0] - dsig[1]) / 3.0,
        stiffness=d,
    )


def record(state: State, params: Parameters, options: ModelOptions) -> dict[str, float]:
    """All dataset variables of one state."""
    return {name: float(values[0]) for name, values in records([state], params, options).items()}


def records(
    states: list[State], params: Parameters, options: ModelOptions
) -> dict[str, np.ndarray]:
    """All dataset variables of many states, evaluated batched (one numpy call per quantity).

    The elastic moduli are those of :func:`elastic_probe`, the bounding fabric that of
    :func:`tiv_model.dissipation.bounding_fabric` and Λ_K that of
    :func:`tiv_model.integrate.constraint_force`, each on the stacked states.
    """
    n = len(states)
    if n == 0:
        return {name: np.zeros(0) for name in VARIABLES}
    stress = np.array([s.stress for s in states])
    strain = np.array([s.strain for s in states])
    eps_e = np.array([s.elastic_strain for s in states])
    fabric = np.array([s.fabric for s in states])
    v = np.array([s.specific_volume for s in states])
    d = stiffness(eps_e, v, fabric, params, options)
    dsig = d @ _SHEAR_PROBE
    bound = bounding_fabric(stress, params, options)
    bound_scalar = np.copysign(deviatoric_invariant(bound), axial_minus_radial(bound))
    if options.constraint_forces:
        energy = EnergyEvaluation(eps_e, v, fabric, params, options).energy
        shift = constraint_pressure(energy, params)
    else:
        shift = np.zeros(n)
    mean = (stress[:, 0] + stress[:, 1] + stress[:, 2]) / 3.0
    q = stress[:, 0] - stress[:, 1]
    e_v, e_h = d[:, 0, 0], d[:, 1, 1]
    return {
        "axial_stress": stress[:, 0],
        "radial_stress": stress[:, 1],
        "mean_stress": mean,
        "deviatoric_stress": q,
        "stress_ratio": q / mean,
        "specific_volume": v,
        "kinematic_specific_volume": v * np.exp(-(eps_e[:, 0] + eps_e[:, 1] + eps_e[:, 2])),
        "fabric": fabric[:, 0] - fabric[:, 1],
        "bounding_fabric": bound_scalar,
        "preconsolidation_pressure": np.array([s.preconsolidation_pressure for s in states]),
        "constraint_force": shift,
        "axial_strain": strain[:, 0],
        "radial_strain": strain[:, 1],
        "volumetric_strain": strain[:, 0] + strain[:, 1] + strain[:, 2],
        "deviatoric_strain": 2.0 / 3.0 * (strain[:, 0] - strain[:, 1]),
        "e_oed_v": e_v,
        "e_oed_h": e_h,
        "stiffness_ratio": e_h / e_v,
        "bulk_modulus": np.einsum("i,nij,j->n", IDENTITY_MANDEL, d, IDENTITY_MANDEL) / 9.0,
        "shear_modulus": (dsig[:, 0] - dsig[:, 1]) / 3.0,
        "plastic_multiplier": np.array([s.plastic_multiplier for s in states]),
        "dissipated_energy": np.array([s.dissipated_energy for s in states]),
        "plastic": np.array([float(s.plastic) for s in states]),
    }


def to_dataset(
    states: list[State],
    params: Parameters,
    options: ModelOptions,
    title: str,
    path: str,
    termination: str | None = None,
) -> xr.Dataset:
    """A CF-1.11 dataset of a list of states along ``step``."""
    columns = records(states, params, options)
    data_vars = {}
    for name, (units, long_name) in VARIABLES.items():
        variable_attrs = {"units": units, "long_name": long_name}
        if name.endswith("_stress") or name in ("constraint_force", "preconsolidation_pressure"):
            variable_attrs["sign_convention"] = "compression_positive"
        data_vars[name] = ("step", columns[name], variable_attrs)
    attrs: dict[str, Any] = {
        "Conventions": "CF-1.11",
        "title": title,
        "source": f"tiv_model {__version__} (hyperplastic anisotropic clay model)",
        "history": f"{datetime.now(UTC).strftime('%Y-%m-%dT%H:%M:%SZ')} created by tiv_model",
        "path": path,
        "axes": "index 0 axial (vertical), 1 and 2 radial (horizontal)",
        "termination": termination or "completed",
    }
    for key, value in params.as_symbols().items():
        attrs[f"parameter_{key}"] = value
    for key, value in options.describe().items():
        attrs[f"option_{key}"] = value
    ds = xr.Dataset(data_vars, coords={"step": ("step", np.arange(len(states)))}, attrs=attrs)
    ds["step"].attrs.update({"long_name": "increment number (0 = initial state)", "units": "1"})
    return ds


def run_path(
    state: State,
    controls: Iterable[Control],
    params: Parameters = TABLE1,
    options: ModelOptions = DEFAULT_OPTIONS,
    settings=DEFAULT_SETTINGS,
    on_error: str = "raise",
    progress: Callable[[int, State], None] | None = None,
    guesses: Sequence[IncrementGuess | None] | None = None,
) -> tuple[list[State], str | None]:
    """Apply a sequence of controls; returns the states (initial included) and a termination
    message (None when complete). Each increment's Newton starts from the previous increment's
    changes (:class:`tiv_model.state.IncrementGuess`), scaled to the new stress step, or from
    ``guesses[i]`` where given (e.g. the increments of a run with nearby parameters: a
    calibration's finite differences start next to the solution). Starting values change the
    iterations, never the converged states.
    """
    if on_error not in ("raise", "stop"):
        raise ParameterError(f"on_error = {on_error!r}: use 'raise' or 'stop'")
    states = [state]
    previous: State | None = None
    previous_stress_step: list[float] | None = None
    for i, control in enumerate(controls):
        current = states[-1]
        stress = current.stress.tolist()
        stress_step = [t - s for t, s in zip(control.stress_target, stress, strict=True)]
        guess = None
        if previous is not None and previous_stress_step is not None:
            mask = control.stress_controlled
            pairs = zip(previous_stress_step, mask, strict=True)
            den = math.sqrt(sum(d * d for d, m in pairs if m))
            if den > 0.0:
                num = math.sqrt(sum(d * d for d, m in zip(stress_step, mask, strict=True) if m))
                guess = IncrementGuess.between(previous, current, num / den)
        if guesses is not None and i < len(guesses) and guesses[i] is not None:
            guess = guesses[i]
        try:
            new = advance(current, control, params, options, settings, guess=guess)
        except TivModelError as exc:
            if on_error == "raise":
                raise
            return states, f"{type(exc).__name__}: {exc}"
        previous = current
        previous_stress_step = [a - b for a, b in zip(new.stress.tolist(), stress, strict=True)]
        states.append(new)
        if progress is not None:
            progress(i + 1, new)
    return states, None


def _check_increments(increments: int) -> int:
    if isinstance(increments, bool) or not isinstance(increments, int) or increments < 1:
        raise ParameterError(f"increments = {increments!r} must be an integer ≥ 1")
    return increments


def _check_positive(name: str, value: float) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ParameterError(f"{name} = {value!r} must be a finite number > 0 (kPa)")
    return float(value)


def _start(state, p0, params, options) -> State:
    if state is not None:
        return state
    return initial_state(_check_positive("p0", p0), params, options)


def isotropic(
    p_max: float = 300.0,
    p0: float = 5.0,
    increments: int = 100,
    params: Parameters = TABLE1,
    options: ModelOptions = DEFAULT_OPTIONS,
    state: State | None = None,
    on_error: str = "raise",
    settings=DEFAULT_SETTINGS,
) -> xr.Dataset:
    """Isotropic compression from p0 (or ``state``) to p_max, geometric stress increments."""
    start = _start(state, p0, params, options)
    p_max = _check_positive("p_max", p_max)
    targets = np.geomspace(start.mean_stress, p_max, _check_increments(increments) + 1)[1:]
    controls = [Control.triaxial(axial_stress=p, radial_stress=p) for p in targets]
    states, term = run_path(start, controls, params, options, settings, on_error)
    return to_dataset(states, params, options, "TIV isotropic compression", "isotropic", term)


def k0(
    sigma_v_max: float = 300.0,
    p0: float = 5.0,
    increments: int = 100,
    params: Parameters = TABLE1,
    options: ModelOptions = DEFAULT_OPTIONS,
    state: State | None = None,
    on_error: str = "raise",
    settings=DEFAULT_SETTINGS,
) -> xr.Dataset:
    """Oedometric (K0) loading: ε_r = 0, σ_a from its start value to σ_v,max (geometric)."""
    start = _start(state, p0, params, options)
    sigma_v_max = _check_positive("sigma_v_max", sigma_v_max)
    targets = np.geomspace(float(start.stress[0]), sigma_v_max, _check_increments(increments) + 1)
    controls = [Control.triaxial(axial_stress=s, radial_strain_increment=0.0) for s in targets[1:]]
    states, term = run_path(start, controls, params, options, settings, on_error)
    return to_dataset(states, params, options, "TIV oedometric (K0) loading", "k0", term)


def constant_p_unloading(
    state: State,
    q_final: float = 0.0,
    increments: int = 50,
    params: Parameters = TABLE1,
    options: ModelOptions = DEFAULT_OPTIONS,
    on_error: str = "raise",
    settings=DEFAULT_SETTINGS,
) -> xr.Dataset:
    """Unloading at constant p from ``state`` until q = q_final (linear in q)."""
    p = state.mean_stress
    q0 = float(state.stress[0] - state.stress[1])
    qs = np.linspace(q0, float(q_final), _check_increments(increments) + 1)[1:]
    controls = [
        Control.triaxial(axial_stress=p + 2.0 * q / 3.0, radial_stress=p - q / 3.0) for q in qs
    ]
    states, term = run_path(state, controls, params, options, settings, on_error)
    return to_dataset(
        states, params, options, "TIV constant-p unloading", "constant_p_unloading", term
    )


def radial(
    eta: float,
    p_max: float = 200.0,
    p0: float = 5.0,
    increments: int = 100,
    approach_increments: int = 10,
    params: Parameters = TABLE1,
    options: ModelOptions = DEFAULT_OPTIONS,
    state: State | None = None,
    on_error: str = "raise",
    settings=DEFAULT_SETTINGS,
) -> xr.Dataset:
    """Radial path at constant η = q/p, stress-controlled.

    From the start state (p, q) the stress first moves at constant p onto the ray q = η p in
    ``approach_increments`` increments, then p grows geometrically to p_max along the ray in
    ``increments`` increments (targets (p, η p)).
    """
    if not (isinstance(eta, (int, float)) and math.isfinite(eta) and -1.5 < eta < 3.0):
        raise ParameterError(f"eta = {eta!r} must be a finite stress ratio in (-1.5, 3)")
    start = _start(state, p0, params, options)
    p_max = _check_positive("p_max", p_max)
    p_start = start.mean_stress
    q_start = float(start.stress[0] - start.stress[1])
    qs = np.linspace(q_start, eta * p_start, _check_increments(approach_increments) + 1)[1:]
    ps = np.geomspace(p_start, p_max, _check_increments(increments) + 1)[1:]
    controls = [
        Control.triaxial(axial_stress=p_start + 2 * q / 3, radial_stress=p_start - q / 3)
        for q in qs
    ] + [
        Control.triaxial(axial_stress=p * (1 + 2 * eta / 3), radial_stress=p * (1 - eta / 3))
        for p in ps
    ]
    states, term = run_path(start, controls, params, options, settings, on_error)
    return to_dataset(states, params, options, f"TIV radial path eta = {eta:g}", "radial", term)


def drained_triaxial(
    axial_strain: float = 0.2,
    p0: float = 5.0,
    increments: int = 100,
    params: Parameters = TABLE1,
    options: ModelOptions = DEFAULT_OPTIONS,
    state: State | None = None,
    on_error: str = "raise",
    settings=DEFAULT_SETTINGS,
) -> xr.Dataset:
    """Strain-controlled drained triaxial compression (σ_r constant, ε_a increasing)."""
    start = _start(state, p0, params, options)
    n = _check_increments(increments)
    radial_stress = float(start.stress[1])
    controls = [
        Control.triaxial(axial_strain_increment=axial_strain / n, radial_stress=radial_stress)
    ] * n
    states, term = run_path(start, controls, params, options, settings, on_error)
    return to_dataset(
        states, params, options, "TIV drained triaxial compression", "drained_triaxial", term
    )


def concatenate(datasets: list[xr.Dataset], names: list[str]) -> xr.Dataset:
    """Join path datasets along ``step`` (dropping each later path's repeated first step) and add
    an integer variable ``stage`` with its names in the attribute ``flag_meanings``."""
    parts = []
    for i, ds in enumerate(datasets):
        part = ds if i == 0 else ds.isel(step=slice(1, None))
        part = part.assign(stage=("step", np.full(part.sizes["step"], i, dtype=np.int32)))
        parts.append(part)
    out = xr.concat(parts, dim="step", combine_attrs="drop_conflicts")
    out = out.assign_coords(step=np.arange(out.sizes["step"]))
    out["step"].attrs.update(datasets[0]["step"].attrs)  # assign_coords drops them (CF 3.1)
    out["stage"].attrs.update(
        {
            "long_name": "loading stage",
            "flag_values": np.arange(len(names), dtype=np.int32),
            "flag_meanings": " ".join(names),
        }
    )
    out.attrs["path"] = "+".join(names)
    terms = [ds.attrs.get("termination", "completed") for ds in datasets]
    out.attrs["termination"] = next((t for t in terms if t != "completed"), "completed")
    return out


def k0_then_unload(
    sigma_v_max: float = 250.0,
    p0: float = 5.0,
    increments: int = 100,
    q_final: float = 0.0,
    unload_increments: int = 50,
    params: Parameters = TABLE1,
    options: ModelOptions = DEFAULT_OPTIONS,
    on_error: str = "raise",
    settings=DEFAULT_SETTINGS,
) -> xr.Dataset:
    """The study's path A→C→B: K0 loading to σ_v,max, then constant-p unloading to q_final.

    One dataset with the integer variable ``stage`` (0 = k0, 1 = constant_p_unloading).
    """
    start = _start(None, p0, params, options)
    sigma_v_max = _check_positive("sigma_v_max", sigma_v_max)
    targets = np.geomspace(float(start.stress[0]), sigma_v_max, _check_increments(increments) + 1)
    controls = [Control.triaxial(axial_stress=s, radial_strain_increment=0.0) for s in targets[1:]]
    states, term = run_path(start, controls, params, options, settings, on_error)
    loading = to_dataset(states, params, options, "TIV oedometric (K0) loading", "k0", term)
    if term is not None:
        return concatenate([loading], ["k0"])
    unloading = constant_p_unloading(
        states[-1], q_final, unload_increments, params, options, on_error, settings
    )
    out = concatenate([loading, unloading], ["k0", "constant_p_unloading"])
    out.attrs["title"] = "TIV K0 loading then constant-p unloading"
    return out
