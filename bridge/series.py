"""DEM results → series of the TIV model, with stated and switchable 2D → 3D conventions.

The DEM is 2D (x horizontal, y vertical, stresses in DEM units, force/length); the TIV model is
written for 3D tensors in kPa (docs/science/tiv-model.md §3). This module, with its convention
(:mod:`bridge.convention`), is the only place that maps one onto the other, both ways (the
inverse builds DEM-schema datasets from model runs, used by the tests and by synthetic studies).

Conventions: :class:`Convention` (:mod:`bridge.convention`, re-exported here) maps the
stresses, the fabric and the moduli both ways, in one of two stated 2D → 3D conventions
(``"triaxial"``, the default, or ``"plane"``), with a stated stress scale S and fabric
scale F.

Paths (DEM stage labels of ``dem_taichi.io.schema.STAGE_CODES``):

* ``isotropic``: state A (last ``isotropic_to_A`` record) then the ``A_to_B`` records;
* ``k0``: state A then the ``A_to_C`` records (the last one is C);
* ``unloading``: state C then the ``C_to_B`` records;
* ``radial_1``, ``radial_2``…: state A then the records of each radial path (stage ``radial``;
  the paths are told apart where the mean stress falls back), :func:`radial_series`.

Units: every variable read from a file passes :func:`bridge.units.checked` first: its
``units`` attribute is parsed with pint; stresses and moduli in DEM units (``units = "1"`` with
``dem_units = "force/length"``) are taken times S, those in a pressure unit (Pa, kPa, MPa, GPa…)
converted to kPa; specific volume and fabric must be dimensionless; a missing, unknown or
incompatible unit is refused naming the variable (:class:`bridge.units.UnitsError`).

Symbols: σ stress (kPa in the model, DEM units in the files), p mean stress, q deviatoric
stress, η = q/p, v specific volume (1; the DEM's A/A_solid is identified with the model's
internal variable v, as in the study), β fabric (1), S stress scale (kPa per DEM stress unit),
F fabric scale (1), E_oed constrained moduli (kPa).
"""

from __future__ import annotations

import numpy as np
import xarray as xr

# the convention and the error live in bridge.convention; re-exported here, where they were
from .convention import CONVENTIONS as CONVENTIONS
from .convention import Convention as Convention
from .convention import SeriesError as SeriesError
from .units import checked

#: Model path name -> (DEM stage of the records, DEM stage whose last record starts the path).
PATHS: dict[str, tuple[str, str]] = {
    "isotropic": ("A_to_B", "isotropic_to_A"),
    "k0": ("A_to_C", "isotropic_to_A"),
    "unloading": ("C_to_B", "A_to_C"),
}

#: Variables of the history that the series need.
HISTORY_REQUIRED = ("stage", "stress_xx", "stress_yy", "specific_volume", "fabric_deviator")
#: Variables of the probes dataset that the series need (plus the moduli of the chosen method).
PROBES_REQUIRED = ("path", "stress_xx", "stress_yy", "specific_volume", "fabric_deviator")
PROBE_METHODS = ("linear", "dynamic")

#: name -> (units, long_name) of the variables of a model series.
SERIES_VARIABLES: dict[str, tuple[str, str]] = {
    "axial_stress": ("kPa", "model axial stress sigma_a"),
    "radial_stress": ("kPa", "model radial stress sigma_r"),
    "mean_stress": ("kPa", "model mean stress p = (sigma_a + 2 sigma_r)/3"),
    "deviatoric_stress": ("kPa", "model deviatoric stress q = sigma_a - sigma_r"),
    "stress_ratio": ("1", "stress ratio eta = q/p"),
    "specific_volume": ("1", "specific volume v (DEM A/A_solid)"),
    "fabric": ("1", "model fabric beta = -fabric_scale (beta_yy - beta_xx), signed like q"),
    "dem_stress_xx": ("1", "DEM horizontal stress sigma_xx (DEM units, force/length)"),
    "dem_stress_yy": ("1", "DEM vertical stress sigma_yy (DEM units, force/length)"),
    "dem_fabric_deviator": ("1", "DEM rod-orientation fabric deviator beta_yy - beta_xx"),
    "e_oed_v": ("kPa", "vertical constrained modulus E_oed,v = C_yyyy (model D_aaaa)"),
    "e_oed_h": ("kPa", "horizontal constrained modulus E_oed,h = C_xxxx (model D_rrrr)"),
    "e_cross": ("kPa", "cross stiffness C_xxyy (model D_ra)"),
}


# ---------------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------------
def _require(ds: xr.Dataset, names, what: str) -> None:
    missing = [n for n in names if n not in ds.variables]
    if missing:
        raise SeriesError(
            f"{what} lacks variable(s) {missing} needed by the bridge; it has "
            f"{sorted(str(v) for v in ds.variables)}"
        )


#: Variables read as labels (codes or text), not as numbers.
LABEL_VARIABLES = ("stage", "path", "state_label")


def check_layout(ds: xr.Dataset, names, what: str, matrices=()) -> str:
    """The one record dimension of ``ds`` that the variables ``names`` share; :class:`SeriesError`
    naming the variable and what is needed otherwise.

    The bridge reads each of ``names`` as one value per record: present, 1-D along the same
    non-empty dimension, and numeric (:data:`LABEL_VARIABLES` may also be text). Each of
    ``matrices`` that is present must be (records, i, j) with i, j ≥ 2 (a 2D stiffness).
    ``what`` names the file (e.g. "history h.nc") in the messages.
    """
    _require(ds, names, what)
    dims = {name: ds[name].dims for name in names}
    first = names[0]
    for name, var_dims in dims.items():
        if len(var_dims) != 1:
            raise SeriesError(
                f"{what} variable {name!r} has dimensions {var_dims}: the bridge needs one value "
                f"per record, 1-D like {first!r} {dims[first]}"
            )
    dim = dims[first][0]
    other = {name: d for name, d in dims.items() if d != (dim,)}
    if other:
        name, var_dims = next(iter(other.items()))
        raise SeriesError(
            f"{what} variable {name!r} is along {var_dims}, {first!r} along ({dim!r},): the "
            "variables the bridge reads must share one record dimension"
        )
    if ds.sizes[dim] == 0:
        raise SeriesError(f"{what} has no records (dimension {dim!r} is empty)")
    for name in names:
        kind = ds[name].dtype.kind
        if kind not in "iuf" and not (name in LABEL_VARIABLES and kind in "OUS"):
            raise SeriesError(
                f"{what} variable {name!r} has type {ds[name].dtype}: the bridge needs numbers"
            )
    for name in matrices:
        if name in ds.variables:
            shape = ds[name].shape
            if ds[name].dims[:1] != (dim,) or len(shape) != 3 or min(shape[1:]) < 2:
                raise SeriesError(
                    f"{what} variable {name!r} has dimensions {ds[name].dims} {shape}: the "
                    f"bridge needs ({dim!r}, i, j) with i, j >= 2 (a 2D stiffness per record)"
                )
    return dim


def _stage_labels(history: xr.Dataset) -> np.ndarray:
    if "stage_label" in history.coords or "stage_label" in history.variables:
        return np.asarray(history["stage_label"].values, dtype=object).astype(str)
    stage = history["stage"]
    if "flag_values" in stage.attrs and "flag_meanings" in stage.attrs:
        values = np.atleast_1d(stage.attrs["flag_values"]).astype(int)
        meanings = str(stage.attrs["flag_meanings"]).split()
        lookup = dict(zip(values.tolist(), meanings, strict=True))
        return np.array([lookup.get(int(c), "") for c in stage.values], dtype=object).astype(str)
    if stage.dtype.kind in "OUS":
        return np.asarray(stage.values).astype(str)
    raise SeriesError("history variable 'stage' has no flag_values/flag_meanings to decode it")


def path_indices(history: xr.Dataset, path: str) -> np.ndarray:
    """Record indices (along the history's dimension) of a path, its start state first."""
    if path not in PATHS:
        raise SeriesError(f"unknown path {path!r}; allowed: {sorted(PATHS)}")
    check_layout(history, ("stage",), "history")
    labels = _stage_labels(history)
    stage, start_stage = PATHS[path]
    records = np.flatnonzero(labels == stage)
    present = sorted(set(labels.tolist()) - {""})
    if records.size == 0:
        raise SeriesError(
            f"path {path!r}: no history records with stage {stage!r}; stages present: {present}"
        )
    before = np.flatnonzero((labels == start_stage) & (np.arange(labels.size) < records[0]))
    if before.size == 0:
        raise SeriesError(
            f"path {path!r}: no {start_stage!r} record before the first {stage!r} record, so its "
            f"start state is unknown; stages present: {present}"
        )
    return np.concatenate([[before[-1]], records])


def _series_dataset(values: dict[str, np.ndarray], convention: Convention, attrs) -> xr.Dataset:
    data = {}
    for name, array in values.items():
        units, long_name = SERIES_VARIABLES[name]
        data[name] = (
            "point",
            np.asarray(array, dtype=float),
            {"units": units, "long_name": long_name},
        )
    ds = xr.Dataset(data, coords={"point": np.arange(len(next(iter(values.values()))))})
    ds.attrs.update(convention.attrs())
    ds.attrs.update(attrs)
    return ds


def _state_values(sv, sh, v, dev, convention: Convention) -> dict[str, np.ndarray]:
    sa, sr = convention.model_stress(sv, sh)
    p = (sa + 2.0 * sr) / 3.0
    q = sa - sr
    with np.errstate(divide="ignore", invalid="ignore"):
        eta = np.where(p > 0, q / np.where(p > 0, p, 1.0), np.nan)
    return {
        "axial_stress": sa,
        "radial_stress": sr,
        "mean_stress": p,
        "deviatoric_stress": q,
        "stress_ratio": eta,
        "specific_volume": np.asarray(v, dtype=float),
        "fabric": convention.model_fabric(dev),
        "dem_stress_xx": np.asarray(sh, dtype=float),
        "dem_stress_yy": np.asarray(sv, dtype=float),
        "dem_fabric_deviator": np.asarray(dev, dtype=float),
    }


# ---------------------------------------------------------------------------------------------
# DEM → model
# ---------------------------------------------------------------------------------------------
def path_series(history: xr.Dataset, path: str, convention: Convention) -> xr.Dataset:
    """Model series (along ``point``) of one path of a DEM history (see the module docstring).

    ``history`` has the history schema (``relaxed_states.nc`` holds only relaxed path states,
    the full ``history.nc`` also the loading records in between).
    """
    dim = check_layout(history, HISTORY_REQUIRED, "history")
    history = checked(history, HISTORY_REQUIRED, convention.stress_scale_kpa, "history")
    idx = path_indices(history, path)

    def take(name):
        return np.asarray(history[name].isel({dim: idx}).values, dtype=float)

    values = _state_values(
        take("stress_yy"),
        take("stress_xx"),
        take("specific_volume"),
        take("fabric_deviator"),
        convention,
    )
    bad = ~np.isfinite(values["mean_stress"]) | ~(values["mean_stress"] > 0)
    if np.any(bad):
        raise SeriesError(
            f"path {path!r}: records {idx[bad].tolist()} have a non-positive or missing mean "
            "stress; the model needs p > 0"
        )
    attrs = {"path": path, "dem_stage": PATHS[path][0], "record_index": idx.astype(np.int64)}
    return _series_dataset(values, convention, attrs)


def history_series(
    history: xr.Dataset, convention: Convention, paths=tuple(PATHS)
) -> dict[str, xr.Dataset]:
    """:func:`path_series` of each path in ``paths``; a missing path fails naming it."""
    return {path: path_series(history, path, convention) for path in paths}


#: DEM stage of the radial paths (all of them: they are told apart by their mean stress).
RADIAL_STAGE = "radial"


def radial_indices(history: xr.Dataset) -> list[np.ndarray]:
    """Record indices of each radial path, state A first: the ``radial`` records split where
    the mean stress falls (every radial path starts from A and loads in p)."""
    check_layout(history, ("stage", "stress_xx", "stress_yy"), "history")
    labels = _stage_labels(history)
    records = np.flatnonzero(labels == RADIAL_STAGE)
    if records.size == 0:
        return []
    before = np.flatnonzero((labels == "isotropic_to_A") & (np.arange(labels.size) < records[0]))
    if before.size == 0:
        raise SeriesError("radial paths: no isotropic_to_A record before them (state A)")
    p = 0.5 * (history["stress_xx"].values + history["stress_yy"].values)[records]
    starts = np.concatenate([[0], np.flatnonzero(np.diff(p) < 0) + 1, [records.size]])
    return [np.concatenate([[before[-1]], records[a:b]]) for a, b in zip(starts[:-1], starts[1:],
                                                                          strict=True)]  # fmt: skip


def radial_series(history: xr.Dataset, convention: Convention) -> dict[str, xr.Dataset]:
    """Model series of every radial path of a DEM history, named ``radial_1``, ``radial_2``…
    in the order of the records, with their DEM and model stress ratios (of the last state)
    in the attributes ``dem_stress_ratio`` and ``stress_ratio``; {} when there are none."""
    dim = check_layout(history, HISTORY_REQUIRED, "history")
    history = checked(history, HISTORY_REQUIRED, convention.stress_scale_kpa, "history")
    out = {}
    for k, idx in enumerate(radial_indices(history), start=1):

        def take(name, idx=idx):
            return np.asarray(history[name].isel({dim: idx}).values, dtype=float)

        values = _state_values(take("stress_yy"), take("stress_xx"), take("specific_volume"),
                               take("fabric_deviator"), convention)  # fmt: skip
        sv, sh = values["dem_stress_yy"][-1], values["dem_stress_xx"][-1]
        attrs = {
            "path": f"radial_{k}",
            "dem_stage": RADIAL_STAGE,
            "record_index": idx.astype(np.int64),
            "dem_stress_ratio": float(2.0 * (sv - sh) / (sv + sh)),
            "stress_ratio": float(values["stress_ratio"][-1]),
        }
        out[f"radial_{k}"] = _series_dataset(values, convention, attrs)
    return out


def probe_series(
    probes: xr.Dataset, path: str, convention: Convention, method: str = "linear"
) -> xr.Dataset:
    """Probe states and moduli (kPa) of one path, its start state (A or C) first.

    ``method``: ``"linear"`` (linear-response probes, default; gives the cross term C_xxyy from
    ``stiffness_tensor_linear`` when present) or ``"dynamic"`` (dynamic probes; no cross term).
    Probes whose moduli are missing (NaN) are left out.
    """
    if method not in PROBE_METHODS:
        raise SeriesError(f"probe method {method!r} is not allowed; use one of {PROBE_METHODS}")
    if path not in PATHS:
        raise SeriesError(f"unknown path {path!r}; allowed: {sorted(PATHS)}")
    moduli = (f"e_oed_v_{method}", f"e_oed_h_{method}")
    names = PROBES_REQUIRED + moduli + (("state_label",) if "state_label" in probes else ())
    dim = check_layout(probes, names, "probes dataset", matrices=("stiffness_tensor_linear",))
    read = PROBES_REQUIRED + moduli + ("stiffness_tensor_linear",)
    probes = checked(probes, read, convention.stress_scale_kpa, "probes")
    labels = np.asarray(probes["path"].values, dtype=object).astype(str)
    state_labels = (
        np.asarray(probes["state_label"].values, dtype=object).astype(str)
        if "state_label" in probes.variables
        else np.full(labels.shape, "")
    )
    stage, start_stage = PATHS[path]
    on_path = np.flatnonzero(labels == stage)
    if path == "unloading":  # C is probed as the last state of A_to_C
        start = np.flatnonzero(state_labels == "C")
    else:
        start = np.flatnonzero((state_labels == "A") | (labels == start_stage))
    idx = np.concatenate([start[-1:], on_path]) if start.size else on_path
    present = sorted(set(labels.tolist()))
    if on_path.size == 0:
        raise SeriesError(
            f"path {path!r}: no probes with path {stage!r}; probe paths present: {present}"
        )

    def take(name):
        return np.asarray(probes[name].isel({dim: idx}).values, dtype=float)

    values = _state_values(
        take("stress_yy"),
        take("stress_xx"),
        take("specific_volume"),
        take("fabric_deviator"),
        convention,
    )
    values["e_oed_v"] = convention.model_modulus(take(moduli[0]))
    values["e_oed_h"] = convention.model_modulus(take(moduli[1]))
    if method == "linear" and "stiffness_tensor_linear" in probes.variables:
        tensor = np.asarray(probes["stiffness_tensor_linear"].isel({dim: idx}).values, dtype=float)
        values["e_cross"] = convention.model_modulus(0.5 * (tensor[:, 0, 1] + tensor[:, 1, 0]))
    keep = np.isfinite(values["e_oed_v"]) & np.isfinite(values["e_oed_h"])
    keep &= np.isfinite(values["mean_stress"]) & (values["mean_stress"] > 0)
    if not np.any(keep):
        raise SeriesError(f"path {path!r}: no probe with finite {moduli} and p > 0")
    values = {k: v[keep] for k, v in values.items()}
    labels_kept = state_labels[idx][keep]
    attrs = {
        "path": path,
        "dem_stage": stage,
        "probe_method": method,
        "probe_index": idx[keep].astype(np.int64),
        "state_labels": " ".join(lab if lab else "-" for lab in labels_kept),
    }
    return _series_dataset(values, convention, attrs)


def all_probe_series(
    probes: xr.Dataset, convention: Convention, method: str = "linear", paths=tuple(PATHS)
) -> dict[str, xr.Dataset]:
    """:func:`probe_series` of each path in ``paths`` that has probes (others are left out)."""
    out = {}
    for path in paths:
        try:
            out[path] = probe_series(probes, path, convention, method)
        except SeriesError as exc:
            if "no probes with path" not in str(exc):
                raise
    if not out:
        raise SeriesError(f"the probes dataset has no probes on any of the paths {list(paths)}")
    return out


# ---------------------------------------------------------------------------------------------
# model → DEM (inverse, for synthetic data and round trips)
# ---------------------------------------------------------------------------------------------
def dem_state_values(axial, radial, specific_volume, fabric, convention: Convention) -> dict:
    """History-schema values (DEM units) of model states (kPa, model β): stresses, p and q in
    the DEM's 2D definitions, v, fabric components with tr β = 1."""
    sv, sh = convention.dem_stress(axial, radial)
    dev = convention.dem_fabric(fabric)
    return {
        "stress_xx": sh,
        "stress_yy": sv,
        "stress_xy": np.zeros_like(sv),
        "mean_stress": 0.5 * (sv + sh),
        "deviatoric_stress": sv - sh,
        "specific_volume": np.asarray(specific_volume, dtype=float),
        "void_ratio": np.asarray(specific_volume, dtype=float) - 1.0,
        "fabric_xx": 0.5 * (1.0 - dev),
        "fabric_yy": 0.5 * (1.0 + dev),
        "fabric_xy": np.zeros_like(dev),
        "fabric_deviator": dev,
    }


def history_from_model(
    paths: dict[str, xr.Dataset], convention: Convention, attrs: dict | None = None
) -> xr.Dataset:
    """A DEM-schema history (dimension ``time``) of model path datasets (tiv_model drivers).

    ``paths`` maps ``"isotropic"``, ``"k0"``, ``"unloading"`` (and ``"radial_1"``,
    ``"radial_2"``…, each starting at A) to driver datasets; the first step of the isotropic
    (else the K0) run is written as the A record (stage ``isotropic_to_A``), each path's later
    steps with its DEM stage. The unloading run must start at the last K0 state (C).
    """
    from dem_taichi.io.schema import HISTORY, stage_code

    order: list[str] = [p for p in ("isotropic", "k0", "unloading") if p in paths]
    radial = sorted((p for p in paths if p.startswith("radial_")), key=lambda p: int(p[7:]))
    if not order:
        raise SeriesError(f"no known path among {sorted(paths)}; use {sorted(PATHS)}")
    first = paths["isotropic"] if "isotropic" in paths else paths["k0"]
    parts = [(first.isel(step=[0]), "isotropic_to_A")]
    for name in order:
        parts.append((paths[name].isel(step=slice(1, None)), PATHS[name][0]))
    for name in radial:  # from A, like the DEM's radial paths
        parts.append((paths[name].isel(step=slice(1, None)), RADIAL_STAGE))
    columns: dict[str, list[np.ndarray]] = {}
    stages: list[np.ndarray] = []
    for ds, stage in parts:
        values = dem_state_values(
            ds["axial_stress"].values,
            ds["radial_stress"].values,
            ds["specific_volume"].values,
            ds["fabric"].values,
            convention,
        )
        for key, val in values.items():
            columns.setdefault(key, []).append(np.atleast_1d(val))
        stages.append(np.full(ds.sizes["step"], stage_code(stage), dtype=np.int32))
    n = sum(len(s) for s in stages)
    data = {}
    for key, chunks in columns.items():
        data[key] = ("time", np.concatenate(chunks), HISTORY[key].attrs())
    data["stage"] = ("time", np.concatenate(stages), HISTORY["stage"].attrs())
    data["step"] = ("time", np.arange(n, dtype=np.int64), HISTORY["step"].attrs())
    time = ("time", np.arange(n, dtype=float), HISTORY["time"].attrs())
    ds = xr.Dataset(data, coords={"time": time})
    ds["time"].encoding["_FillValue"] = None  # a coordinate has no fill value (CF 2.5.1)
    ds.attrs["Conventions"] = "CF-1.11"
    ds.attrs["title"] = "DEM-schema history made from TIV model paths (bridge.series)"
    ds.attrs.update(attrs or {})
    ds.attrs["stress_scale_kpa"] = convention.stress_scale_kpa
    return ds


def probes_from_model(
    states: list[tuple[str, str, float, float, float, float, np.ndarray]],
    convention: Convention,
    attrs: dict | None = None,
) -> xr.Dataset:
    """A DEM-schema probes dataset of model states.

    ``states``: (state_label, DEM path stage, σ_a, σ_r (kPa), v, β_model, D) with D the model's
    Mandel 6×6 elastic stiffness (kPa); E_oed,v = D_aa, E_oed,h = D_rr, the 2D tensor
    [[D_rr, D_ra, 0], [D_ar, D_aa, 0], [0, 0, D_mandel,ar-shear/2]] (Voigt xx, yy, xy) for both
    methods. Uses the DEM writer's :func:`dem_taichi.io.make_dataset`.
    """
    from dem_taichi.io import make_dataset

    n = len(states)
    if n == 0:
        raise SeriesError("no probe states given")
    sa = np.array([s[2] for s in states])
    sr = np.array([s[3] for s in states])
    values = dem_state_values(sa, sr, [s[4] for s in states], [s[5] for s in states], convention)
    d = np.array([np.asarray(s[6], dtype=float) for s in states])
    tensor = np.zeros((n, 3, 3))
    tensor[:, 0, 0] = d[:, 1, 1]
    tensor[:, 1, 1] = d[:, 0, 0]
    tensor[:, 0, 1] = d[:, 1, 0]
    tensor[:, 1, 0] = d[:, 0, 1]
    tensor[:, 2, 2] = 0.5 * d[:, 5, 5]
    tensor = convention.dem_modulus(tensor)
    out = {
        "state_label": np.array([s[0] for s in states], dtype=object),
        "path": np.array([s[1] for s in states], dtype=object),
        "step": np.arange(n, dtype=np.int64),
        "stress_xx": values["stress_xx"],
        "stress_yy": values["stress_yy"],
        "mean_stress": values["mean_stress"],
        "deviatoric_stress": values["deviatoric_stress"],
        "specific_volume": values["specific_volume"],
        "fabric_deviator": values["fabric_deviator"],
        "stiffness_tensor_linear": tensor,
    }
    for method in PROBE_METHODS:
        out[f"e_oed_v_{method}"] = tensor[:, 1, 1]
        out[f"e_oed_h_{method}"] = tensor[:, 0, 0]
    merged = dict(attrs or {})
    merged["stress_scale_kpa"] = convention.stress_scale_kpa
    return make_dataset(out, attrs=merged)
