"""Predictions of the calibrated TIV model along the DEM's paths, labelled fitted / out of sample.

Two kinds of prediction (each a dataset along ``point``, the DEM's points of the path):

* **path runs** (:func:`predict_paths`): the model run along the DEM paths from its own state A
  (:mod:`bridge.runs`): isotropic through the DEM's p; K0 through the DEM's σ_a with ε_r = 0
  (``k0_mode="element"``, default) or following the DEM's (σ_a, σ_r) history
  (``k0_mode="stress"``); unloading from the model's C, the end of that K0 run (of the same
  mode), along the DEM's (p, q) path scaled onto it; each radial path (``radial_1``…) from the
  model's A along the DEM's stresses. Variables: stresses, η, v, β, E_oed,v, E_oed,h, E_h/E_v
  (model states).
* **elastic law at the measured probe states** (:func:`predict_probes`): the model's elastic
  stiffness at the DEM's measured (σ, v, β) of every probe: E_oed,v, E_oed,h, C_xxyy,
  E_h/E_v. Along K0 this is the back-prediction of the stiffness anisotropy from the measured
  fabric.

Every variable has the attribute ``role``: ``"input"`` where the driver prescribes it (the
stresses of stress-controlled runs, σ_a along K0), ``"fitted"`` when the same (path, variable)
entered a residual of the calibration (:attr:`bridge.calibration.CalibrationResult.fitted_`), else
``"out_of_sample"``; E_h/E_v is fitted only where both moduli were. Where the DEM has the same
variable, the attribute ``error_rms`` gives the RMS difference model − DEM (relative, i.e. of
ln, for v and moduli; absolute for β and η), and ``dem_<name>`` holds the DEM values.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import xarray as xr

from tiv_model.errors import TivModelError
from tiv_model.params import DEFAULT_OPTIONS, ModelOptions, Parameters

from .moduli import moduli_at_states
from .runs import (
    RUN_VARIABLES,
    isotropic_run,
    k0_run,
    start_state,
    stress_path_run,
    unloading_run,
)
from .series import SERIES_VARIABLES

K0_MODES = ("element", "stress")
_RELATIVE = {"specific_volume", "e_oed_v", "e_oed_h", "e_cross", "stiffness_ratio"}
_UNITS = {
    "stiffness_ratio": ("1", "stiffness anisotropy E_oed,h / E_oed,v"),
    "preconsolidation_pressure": ("kPa", "preconsolidation pressure p_c"),
    "plastic": ("1", "1 if the increment ending here was plastic"),
}


class PredictionError(RuntimeError):
    """A prediction run failed; the message names the path and the model's reason."""


def _role(fitted: set, path: str, name: str) -> str:
    if name == "stiffness_ratio":
        both = (path, "e_oed_v") in fitted and (path, "e_oed_h") in fitted
        return "fitted" if both else "out_of_sample"
    return "fitted" if (path, name) in fitted else "out_of_sample"


#: Stress variables prescribed by each driver (role "input": the model follows the DEM there).
_STRESSES = ("axial_stress", "radial_stress", "mean_stress", "deviatoric_stress", "stress_ratio")
_INPUTS = {
    "isotropic": _STRESSES,
    "k0:element": ("axial_stress",),
    "k0:stress": _STRESSES,
    "unloading": _STRESSES,
}


def _dataset(values, dem: xr.Dataset, path: str, fitted: set, attrs: dict, inputs=()) -> xr.Dataset:
    data: dict[str, tuple[str, Any, dict[str, Any]]] = {}
    for name, array in values.items():
        units, long_name = SERIES_VARIABLES.get(name) or _UNITS[name]
        var_attrs: dict[str, str | float] = {
            "units": units,
            "long_name": "TIV " + long_name,
            "role": "input" if name in inputs else _role(fitted, path, name),
        }
        dem_values = _dem_values(dem, name)
        if dem_values is not None:
            model = np.asarray(array, dtype=float)
            with np.errstate(all="ignore"):
                diff = np.log(model / dem_values) if name in _RELATIVE else model - dem_values
            good = np.isfinite(diff)
            var_attrs["error_rms"] = (
                float(np.sqrt(np.mean(diff[good] ** 2))) if good.any() else np.nan
            )
            var_attrs["error_measure"] = (
                "rms of ln(model/DEM)" if name in _RELATIVE else "rms of model - DEM"
            )
            data[f"dem_{name}"] = (
                "point",
                dem_values,
                {"units": units, "long_name": "DEM " + long_name},
            )
        data[name] = ("point", np.asarray(array, dtype=float), var_attrs)
    ds = xr.Dataset(data, coords={"point": np.arange(dem.sizes["point"])})
    ds.attrs.update(
        {
            k: v
            for k, v in dem.attrs.items()
            if k.startswith("convention") or k in ("stress_scale_kpa", "fabric_scale")
        }
    )
    ds.attrs.update(attrs)
    ds.attrs["path"] = path
    return ds


def _dem_values(dem: xr.Dataset, name: str):
    if name in dem:
        return np.asarray(dem[name].values, dtype=float)
    if name == "stiffness_ratio" and "e_oed_v" in dem and "e_oed_h" in dem:
        return np.asarray(dem["e_oed_h"].values / dem["e_oed_v"].values, dtype=float)
    return None


def _params_and_fitted(calibrated) -> tuple[Parameters, set]:
    if isinstance(calibrated, Parameters):
        return calibrated, set()
    return calibrated.params_, set(calibrated.fitted_)


def predict_paths(
    calibrated,
    series: Mapping[str, xr.Dataset],
    options: ModelOptions = DEFAULT_OPTIONS,
    k0_mode: str = "element",
    max_increments: int = 40,
    initial_fabric: str = "zero",
    failures: dict[str, str] | None = None,
) -> dict[str, xr.Dataset]:
    """Model runs along each DEM path in ``series`` (see the module docstring).

    ``failures``: None (default), a model run that fails raises :class:`PredictionError`; a dict,
    the path is left out of the result and the reason stored there under the path's name (the
    unloading path, which starts at the model's C, then too), so that one path the calibrated
    model cannot follow does not lose the others.

    ``initial_fabric``: the model's β at A, ``"zero"`` or ``"measured"`` (the DEM's β at the
    first point of the path; see :func:`bridge.runs.start_state`).

    ``calibrated``: a :class:`bridge.calibration.CalibrationResult` (roles from what it fitted)
    or plain :class:`tiv_model.params.Parameters` (everything out of sample).
    """
    if k0_mode not in K0_MODES:
        raise PredictionError(f"k0_mode = {k0_mode!r}: use one of {K0_MODES}")
    if initial_fabric not in ("zero", "measured"):
        raise PredictionError(f"initial_fabric = {initial_fabric!r}: use 'zero' or 'measured'")
    params, fitted = _params_and_fitted(calibrated)

    def beta_a(ds: xr.Dataset) -> float:
        return float(ds["fabric"].values[0]) if initial_fabric == "measured" else 0.0

    out: dict[str, xr.Dataset] = {}
    state_c = None

    def failed(path: str, reason: str, cause: Exception | None = None) -> None:
        """Raise (no ``failures`` dict) or record why ``path`` has no model run."""
        if failures is None:
            raise PredictionError(f"path {path}: {reason}") from cause
        failures[path] = reason

    for path in ("isotropic", "k0", "unloading"):
        if path not in series:
            continue
        dem = series[path]
        if path == "unloading" and state_c is None and "k0" in (failures or {}):
            failed(path, "not run: it starts at the model's C, and the k0 path failed")
            continue
        try:
            if path == "isotropic":
                run = isotropic_run(
                    dem["mean_stress"].values, params, options, max_increments, beta_a(dem)
                )
                driver = "isotropic stress control through the DEM's p"
            elif path == "k0":
                if k0_mode == "element":
                    run, state_c = k0_run(
                        dem["axial_stress"].values,
                        float(dem["mean_stress"][0]),
                        params,
                        options,
                        max_increments,
                        return_state=True,
                        start_fabric=beta_a(dem),
                    )
                    driver = "K0 (radial strain 0) through the DEM's axial stress"
                else:
                    run, state_c = stress_path_run(
                        dem["axial_stress"].values,
                        dem["radial_stress"].values,
                        params,
                        options,
                        None,
                        max_increments,
                        beta_a(dem),
                        return_state=True,
                    )
                    driver = "stress control along the DEM's (sigma_a, sigma_r) history"
            else:
                if state_c is None:  # the K0 run of this k0_mode gives C (paths run in order)
                    raise PredictionError(
                        "the unloading prediction starts at the model's C: "
                        "it needs the 'k0' path series"
                    )
                run = unloading_run(
                    dem["mean_stress"].values,
                    dem["deviatoric_stress"].values,
                    state_c,
                    params,
                    options,
                    max_increments,
                )
                driver = "stress control from the model's C along the DEM's (p, q) scaled onto it"
        except TivModelError as exc:
            failed(path, f"the model run failed: {exc}", exc)
            continue
        values = {k: run[k] for k in RUN_VARIABLES}
        inputs = _INPUTS[f"k0:{k0_mode}" if path == "k0" else path]
        attrs = {
            "kind": "model run",
            "driver": driver,
            "k0_mode": k0_mode,
            "initial_fabric": initial_fabric,
        }
        out[path] = _dataset(values, dem, path, fitted, attrs, inputs)
    for path, dem in series.items():  # radial paths: from A along the DEM's stresses
        if not path.startswith("radial_"):
            continue
        sa, sr = dem["axial_stress"].values.copy(), dem["radial_stress"].values.copy()
        p_a = float(dem["mean_stress"].values[0])
        sa[0] = sr[0] = p_a
        try:
            start = start_state(p_a, params, options, beta_a(dem))
            run = stress_path_run(sa, sr, params, options, start, max_increments)
        except TivModelError as exc:
            failed(path, f"the model run failed: {exc}", exc)
            continue
        attrs = {
            "kind": "model run",
            "driver": "stress control from the model's A along the DEM's radial path",
            "initial_fabric": initial_fabric,
        }
        values = {k: run[k] for k in RUN_VARIABLES}
        out[path] = _dataset(values, dem, path, fitted, attrs, _STRESSES)
    return out


def predict_probes(
    calibrated,
    probes: Mapping[str, xr.Dataset],
    options: ModelOptions = DEFAULT_OPTIONS,
) -> dict[str, xr.Dataset]:
    """The model's elastic moduli at the DEM's measured probe states, per path."""
    params, fitted = _params_and_fitted(calibrated)
    out = {}
    for path, dem in probes.items():
        try:
            mod = moduli_at_states(
                dem["axial_stress"].values,
                dem["radial_stress"].values,
                dem["specific_volume"].values,
                dem["fabric"].values,
                params,
                options,
            )
        except TivModelError as exc:
            raise PredictionError(f"probes of path {path}: {exc}") from exc
        values = {k: mod[k] for k in ("e_oed_v", "e_oed_h", "e_cross", "stiffness_ratio")}
        values.update({k: dem[k].values for k in ("mean_stress", "fabric")})
        ds = _dataset(
            values, dem, path, fitted, {"kind": "elastic law at the measured probe states"}
        )
        for k in ("mean_stress", "fabric"):  # these are the DEM's own inputs here
            ds[k].attrs["role"] = "input"
            ds = ds.drop_vars(f"dem_{k}")
        for name, (ratio, long_name) in anisotropy_parts(dem, params, options).items():
            ds[name] = (
                "point",
                ratio,
                {"units": "1", "long_name": long_name, "role": "diagnostic"},
            )
        out[path] = ds
    return out


def anisotropy_parts(
    dem: xr.Dataset, params: Parameters, options: ModelOptions = DEFAULT_OPTIONS
) -> dict[str, tuple[np.ndarray, str]]:
    """The model's E_oed,h/E_oed,v at the DEM's probe states split into its two sources: at the
    measured stress with the fabric set to 0 (``stiffness_ratio_stress_only``: the anisotropy the
    pressure-dependent elasticity draws from the stress alone) and at the measured fabric under
    the isotropic stress p (``stiffness_ratio_fabric_only``). NaN where the elastic law cannot be
    inverted at such a state. A diagnostic of the out-of-sample K0 stiffness ratio: where the
    model misses it, which part does."""
    sa, sr = dem["axial_stress"].values, dem["radial_stress"].values
    v, beta = dem["specific_volume"].values, dem["fabric"].values
    p = (sa + 2.0 * sr) / 3.0
    cases = {
        "stiffness_ratio_stress_only": (
            sa,
            sr,
            0.0,
            "TIV E_oed,h/E_oed,v at the DEM stress, fabric 0",
        ),
        "stiffness_ratio_fabric_only": (
            p,
            p,
            beta,
            "TIV E_oed,h/E_oed,v at the DEM fabric, stress p",
        ),
    }
    return {
        name: (stiffness_ratio_or_nan(axial, radial, v, fabric, params, options), long_name)
        for name, (axial, radial, fabric, long_name) in cases.items()
    }


def stiffness_ratio_or_nan(
    axial_stress, radial_stress, specific_volume, fabric, params: Parameters, options: ModelOptions
) -> np.ndarray:
    """The model's E_oed,h/E_oed,v at the given states (:func:`bridge.moduli.moduli_at_states`),
    all NaN where the elastic law cannot be inverted or the energy is not convex there."""
    try:
        ratio = moduli_at_states(
            axial_stress, radial_stress, specific_volume, fabric, params, options
        )["stiffness_ratio"]
    except TivModelError:
        ratio = np.full(np.shape(np.atleast_1d(axial_stress)), np.nan)
    return np.asarray(ratio, dtype=float)


def summary(predictions: Mapping[str, xr.Dataset]) -> list[dict[str, object]]:
    """Rows (path, variable, role, error_rms, error_measure, kind) of every compared variable
    that the model predicts (prescribed inputs left out)."""
    rows = []
    for path, ds in predictions.items():
        for name, var in ds.data_vars.items():
            if "error_rms" in var.attrs and var.attrs.get("role") != "input":
                rows.append(
                    {
                        "path": path,
                        "variable": str(name),
                        "role": var.attrs["role"],
                        "error_rms": float(var.attrs["error_rms"]),
                        "error_measure": var.attrs["error_measure"],
                        "kind": ds.attrs.get("kind", ""),
                    }
                )
    return rows
