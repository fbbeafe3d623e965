"""Synthetic "DEM-like" results made by the TIV model itself (known parameters).

Runs the study's paths with :mod:`tiv_model.drivers` (isotropic A→B, K0 A→C, constant-p
unloading C→B from the end of the K0 run), probes the model's elastic stiffness at every
``probe_every``-th state, and writes both as DEM-schema datasets through the *inverse* of the
bridge's convention (:func:`bridge.series.history_from_model`,
:func:`bridge.series.probes_from_model`). Calibrating on them must give the parameters back:
that is the exact-recovery check of :mod:`bridge.calibration`.

Optional Gaussian noise (relative for stresses, moduli and v; absolute for the fabric
deviator) mimics DEM scatter; a fixed ``seed`` makes it reproducible.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import xarray as xr

from tiv_model import drivers
from tiv_model.integrate import Control
from tiv_model.params import DEFAULT_OPTIONS, TABLE1, ModelOptions, Parameters

from .series import Convention, history_from_model, probes_from_model


@dataclass(frozen=True)
class SyntheticPaths:
    """Model runs (tiv_model driver datasets) and their DEM-schema counterparts."""

    model: dict[str, xr.Dataset]
    history: xr.Dataset
    probes: xr.Dataset


def model_paths(
    params: Parameters = TABLE1,
    options: ModelOptions = DEFAULT_OPTIONS,
    p0: float = 5.0,
    p_max: float = 100.0,
    increments: int = 10,
    unloading_increments: int = 4,
    sigma_v_max: float | None = None,
    start_fabric: float = 0.0,
    radial_ratios: tuple[float, ...] = (),
) -> dict[str, xr.Dataset]:
    """The three paths of the study run with the model (kPa): isotropic p0 → p_max, K0 from p0
    to σ_v = ``sigma_v_max`` (default 1.3 p_max, i.e. p ≈ p_max at K0 ≈ 0.65), both with
    geometric stress increments, then constant-p unloading from the end of K0 to q = 0; and a
    radial path from A at each model stress ratio η of ``radial_ratios`` (``radial_1``…: one
    increment onto the ray at p_A, then p geometric to p_max).
    ``start_fabric``: the model's β at A (:func:`bridge.runs.start_state`)."""
    from .runs import start_state

    start = start_state(p0, params, options, start_fabric)
    iso = drivers.isotropic(
        p_max, state=start, increments=increments, params=params, options=options
    )
    sigma_v = 1.3 * p_max if sigma_v_max is None else float(sigma_v_max)
    controls = [
        Control.triaxial(axial_stress=s, radial_strain_increment=0.0)
        for s in np.geomspace(float(start.stress[0]), sigma_v, increments + 1)[1:]
    ]
    states, term = drivers.run_path(start, controls, params, options)
    k0 = drivers.to_dataset(states, params, options, "TIV oedometric (K0) loading", "k0", term)
    unloading = drivers.constant_p_unloading(states[-1], 0.0, unloading_increments, params, options)
    out = {"isotropic": iso, "k0": k0, "unloading": unloading}
    for k, eta in enumerate(radial_ratios, start=1):
        out[f"radial_{k}"] = drivers.radial(eta, p_max, state=start, increments=increments,
                                            approach_increments=1, params=params,
                                            options=options)  # fmt: skip
    return out


def _probe_states(paths: dict[str, xr.Dataset], every: int):
    from .series import PATHS

    out = []
    for name in ("isotropic", "k0", "unloading"):
        if name not in paths:
            continue
        ds = paths[name]
        stage = PATHS[name][0]
        steps = list(range(1, ds.sizes["step"], every))
        if ds.sizes["step"] - 1 not in steps:
            steps.append(ds.sizes["step"] - 1)
        if name == "isotropic" or ("isotropic" not in paths and name == "k0"):
            steps = [0] + steps
        for i in steps:
            label = ""
            if i == 0:
                label, stage_i = "A", "isotropic_to_A"
            else:
                stage_i = stage
                if i == ds.sizes["step"] - 1:
                    label = {"isotropic": "B", "k0": "C", "unloading": "B'"}[name]
            out.append((label, stage_i, ds, i))
    return out


def synthetic_results(
    params: Parameters = TABLE1,
    options: ModelOptions = DEFAULT_OPTIONS,
    convention: Convention | None = None,
    p0: float = 5.0,
    p_max: float = 100.0,
    increments: int = 10,
    unloading_increments: int = 4,
    probe_every: int = 1,
    noise: dict[str, float] | None = None,
    seed: int = 0,
    start_fabric: float = 0.0,
    radial_ratios: tuple[float, ...] = (),
) -> SyntheticPaths:
    """DEM-schema history and probes of model runs (see the module docstring).

    ``noise``: standard deviations, keys ``stress`` (relative), ``specific_volume`` (relative),
    ``fabric`` (absolute, on β_yy − β_xx), ``moduli`` (relative); default none
    (:data:`DEM_NOISE` is the DEM's). ``radial_ratios``: see :func:`model_paths` (the probes
    stay on the study's three paths).
    """
    from tiv_model.drivers import elastic_probe  # noqa: F401 - same stiffness as the drivers
    from tiv_model.energy import stiffness
    from tiv_model.tensors import TRIAXIAL_DIRECTION_MANDEL

    convention = convention or Convention(stress_scale_kpa=1.0)
    paths = model_paths(
        params, options, p0, p_max, increments, unloading_increments, None, start_fabric,
        tuple(radial_ratios),
    )  # fmt: skip
    attrs = {"title": "synthetic DEM-like results from tiv_model", "source": "bridge.synthetic"}
    history = history_from_model(paths, convention, attrs)
    states = []
    from .moduli import triaxial_elastic_strain

    for label, stage, ds, i in _probe_states(paths, probe_every):
        sa = float(ds["axial_stress"][i])
        sr = float(ds["radial_stress"][i])
        v = float(ds["specific_volume"][i])
        beta = float(ds["fabric"][i])
        eps = triaxial_elastic_strain(sa, sr, v, beta, params, options)[0]
        d = stiffness(eps, v, beta * TRIAXIAL_DIRECTION_MANDEL, params, options)
        states.append((label, stage, sa, sr, v, beta, d))
    probes = probes_from_model(states, convention, attrs)
    if noise:
        history, probes = add_noise(history, probes, noise, seed)
    return SyntheticPaths(paths, history, probes)


NOISE_KEYS = ("stress", "specific_volume", "fabric", "moduli")

#: The DEM's scatter, as standard deviations in the units of :func:`add_noise` (stress scale 1,
#: fabric scale 1): measured between two replicas of the paper scene (``protocol paper``, its
#: seed 3, and with ``--set scene.seed=4``) at the same relaxed states, σ = RMS(difference)/√2:
#: fabric deviator 0.014–0.017 (isotropic, K0), ln v 0.009–0.013, p 1.3 % (isotropic; the servo
#: holds the targets), linear-response moduli 4–16 % (E_oed; the cross term up to 30 %).
DEM_NOISE: dict[str, float] = {"stress": 0.013, "specific_volume": 0.01, "fabric": 0.015,
                               "moduli": 0.08}  # fmt: skip


def add_noise(history: xr.Dataset, probes: xr.Dataset, noise: dict[str, float], seed: int = 0):
    """Copies of ``history`` and ``probes`` with Gaussian noise (see :func:`synthetic_results`)."""
    unknown = sorted(set(noise) - set(NOISE_KEYS))
    if unknown:
        raise ValueError(f"unknown noise key(s) {unknown}; allowed: {NOISE_KEYS}")
    rng = np.random.default_rng(seed)
    out = []
    for ds in (history, probes):
        ds = ds.copy(deep=True)
        n = ds["stress_xx"].size
        rel_s = noise.get("stress", 0.0)
        for name in ("stress_xx", "stress_yy"):
            ds[name].values = ds[name].values * (1.0 + rel_s * rng.standard_normal(n))
        ds["mean_stress"].values = 0.5 * (ds["stress_xx"].values + ds["stress_yy"].values)
        ds["deviatoric_stress"].values = ds["stress_yy"].values - ds["stress_xx"].values
        ds["specific_volume"].values = ds["specific_volume"].values * (
            1.0 + noise.get("specific_volume", 0.0) * rng.standard_normal(n)
        )
        ds["fabric_deviator"].values = ds["fabric_deviator"].values + noise.get(
            "fabric", 0.0
        ) * rng.standard_normal(n)
        if "stiffness_tensor_linear" in ds:
            factor = 1.0 + noise.get("moduli", 0.0) * rng.standard_normal((n, 3, 3))
            factor = 0.5 * (factor + np.swapaxes(factor, 1, 2))
            tensor = ds["stiffness_tensor_linear"].values * factor
            ds["stiffness_tensor_linear"].values = tensor
            for method in ("linear", "dynamic"):
                ds[f"e_oed_v_{method}"].values = tensor[:, 1, 1]
                ds[f"e_oed_h_{method}"].values = tensor[:, 0, 0]
        out.append(ds)
    return out[0], out[1]
