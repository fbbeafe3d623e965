"""Replica bands: the replicas' mean and the 95 % interval of that mean, record by record.

For the replicas of one protocol (run folders as :func:`bridge.replicas.replica_runs` accepts
them: each with ``relaxed_states.nc`` and ``probes.nc``, or a sweep folder) :func:`replica_bands`
aligns the records exactly as :func:`bridge.replicas.replica_mean` does
(:func:`bridge.replicas.aligned_replicas`: state A, then each later stage's records in order;
probes likewise), converts every run to the model's quantities with *its own* stress scale
(:class:`bridge.series.Convention`, units checked by :func:`bridge.units.checked`), and gives per
aligned record the mean over the replicas and the half-width of the interval of the mean,

    h = t_{(1+c)/2, n−1} · s / √n        (Student t, n − 1 degrees of freedom, c = 0.95),

s the replicas' sample SD (ddof 1), n the number of replicas with a finite value there (NaN
half-width where n < 2). Ratios (E_h/E_v, E_v/p) are taken in each run, then averaged.

Symbols and units: p = (σ_a + 2σ_r)/3 and q = σ_a − σ_r (kPa, the model's invariants of the
convention, ``"triaxial"``: σ_a = S σ_yy, σ_r = S σ_xx), η = q/p (1), v specific volume (1),
β = −F (β_yy − β_xx) the model's fabric (1), E_oed,v = C_yyyy and E_oed,h = C_xxxx (kPa),
S the stress scale (kPa per DEM stress unit), F the fabric scale.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import xarray as xr
from scipy import stats

from .pipeline_options import PipelineOptions, stress_scale_of
from .replicas import PROBES, RELAXED, aligned_replicas, history_stage, nan_mean, replica_runs
from .series import PATHS, RADIAL_STAGE, Convention, check_layout
from .units import checked

__all__ = [
    "replica_bands",
    "mean_and_half_width",
    "record_labels",
    "summary_labels",
    "path_members",
    "CONFIDENCE",
]

#: Confidence of the interval of the mean (the ``_ci95`` variables).
CONFIDENCE = 0.95

#: name -> (units, long name) of the state variables (dimension ``state``); the probes' have the
#: prefix ``probe_`` (dimension ``probe``), with the moduli of :data:`PROBE_ONLY` besides.
STATE_VARIABLES: dict[str, tuple[str, str]] = {
    "axial_stress": ("kPa", "model axial stress sigma_a"),
    "radial_stress": ("kPa", "model radial stress sigma_r"),
    "mean_stress": ("kPa", "model mean stress p = (sigma_a + 2 sigma_r)/3"),
    "deviatoric_stress": ("kPa", "model deviatoric stress q = sigma_a - sigma_r"),
    "stress_ratio": ("1", "stress ratio eta = q/p"),
    "specific_volume": ("1", "specific volume v"),
    "fabric": ("1", "model fabric beta = -F (beta_yy - beta_xx)"),
    "fabric_deviator": ("1", "DEM rod-orientation fabric deviator beta_yy - beta_xx"),
}
PROBE_ONLY: dict[str, tuple[str, str]] = {
    "e_oed_v": ("kPa", "vertical constrained modulus E_oed,v = C_yyyy"),
    "e_oed_h": ("kPa", "horizontal constrained modulus E_oed,h = C_xxxx"),
    "stiffness_ratio": ("1", "E_oed,h / E_oed,v of each run, averaged"),
    "e_oed_v_over_p": ("1", "E_oed,v / p of each run, averaged"),
}

#: The label of the last record of each stage block (the DEM protocol's state labels).
END_LABELS = {"isotropic_to_A": "A", "A_to_B": "B", "A_to_C": "C", "C_to_B": "B'"}


def mean_and_half_width(values, confidence: float = CONFIDENCE):
    """(mean, half-width, n) over axis 0 (the replicas) of the finite values of ``values``:
    h = t_{(1+c)/2, n−1} s/√n with s the sample SD (ddof 1); NaN mean where n = 0, NaN
    half-width where n < 2."""
    x = np.asarray(values, dtype=float)
    finite = np.isfinite(x)
    n = finite.sum(axis=0)
    mean = nan_mean(x)
    squares = np.where(finite, x - mean, 0.0) ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        sd = np.sqrt(squares.sum(axis=0) / (n - 1))
        t = stats.t.ppf(0.5 + confidence / 2.0, np.maximum(n - 1, 1))
        half = np.where(n > 1, t * sd / np.sqrt(n), np.nan)
    return mean, half, n


def record_labels(stages, mean_stress, steps=None, known=None) -> np.ndarray:
    """State labels of aligned records.

    With ``known`` ({(stage, step): label}, :func:`summary_labels`) and the records' ``steps``,
    the records the run itself labelled carry those labels and the others ``""``: the only rule
    that is right when a path goes on past its labelled state (an isotropic path continued past
    B by ``isotropic_end_stress``, whose last record is not B). Without them, the rule for runs
    without a summary: the last record of each stage block is A, B, C or B'
    (:data:`END_LABELS`); the radial records, split where p falls (every radial path starts
    from A and loads), end at R1_end, R2_end…; others ``""``."""
    stages = np.asarray(stages).astype(str)
    labels = np.full(stages.size, "", dtype=object)
    if known and steps is not None:
        for k, (stage, step) in enumerate(zip(stages, np.asarray(steps), strict=True)):
            labels[k] = known.get((stage, int(step)), "")
        return labels.astype(str)
    radial = 0
    for k in range(stages.size):
        last = k + 1 == stages.size or stages[k + 1] != stages[k]
        if stages[k] == RADIAL_STAGE:
            if last or mean_stress[k + 1] < mean_stress[k]:
                radial += 1
                labels[k] = f"R{radial}_end"
        elif last and stages[k] in END_LABELS:
            labels[k] = END_LABELS[stages[k]]
    return labels.astype(str)


def summary_labels(folder: Path) -> dict[tuple[str, int], str] | None:
    """{(stage, step): label} of the labelled states (A, B, C, B', R<k>_end) that a protocol
    run's ``summary.json`` lists; None when the folder has no summary or it names no stage and
    step (plain JSON, no code runs)."""
    try:
        states = json.loads((Path(folder) / "summary.json").read_text()).get("states", {})
    except (OSError, ValueError, AttributeError):
        return None
    known = {
        (str(m["stage"]), int(m["step"])): str(label)
        for label, m in states.items()
        if isinstance(m, dict) and "stage" in m and "step" in m
    }
    return known or None


def path_members(stages, labels, mean_stress) -> dict[str, np.ndarray]:
    """Indices of each path's records, its start first, like :mod:`bridge.series`: isotropic
    and K0 from A, unloading from C, ``radial_k`` from A (the radial records split where p
    falls); a path without records is left out, one without its start (a state not probed)
    begins at its first record."""
    stages = np.asarray(stages).astype(str)
    labels = np.asarray(labels).astype(str)
    a, c = np.flatnonzero(labels == "A")[-1:], np.flatnonzero(labels == "C")[-1:]
    out = {}
    for path, (stage, _) in PATHS.items():
        members = np.flatnonzero(stages == stage)
        start = c if path == "unloading" else a
        if members.size:
            out[path] = np.concatenate([start, members])
    radial = np.flatnonzero(stages == RADIAL_STAGE)
    if radial.size:
        falls = np.flatnonzero(np.diff(np.asarray(mean_stress)[radial]) < 0) + 1
        for k, part in enumerate(np.split(radial, falls), start=1):
            out[f"radial_{k}"] = np.concatenate([a, part])
    return out


def _model_values(ds: xr.Dataset, convention: Convention, what: str, moduli=()) -> dict:
    """The model's quantities (:data:`STATE_VARIABLES`, and with ``moduli`` the
    :data:`PROBE_ONLY` ones) of one run's aligned records, in kPa by its ``convention``."""
    names = ("stress_xx", "stress_yy", "specific_volume", "fabric_deviator", *moduli)
    check_layout(ds, names, what)
    ds = checked(ds, names, convention.stress_scale_kpa, what)
    sa, sr = convention.model_stress(ds["stress_yy"].values, ds["stress_xx"].values)
    p, q = (sa + 2.0 * sr) / 3.0, sa - sr
    dev = np.asarray(ds["fabric_deviator"].values, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = {
            "axial_stress": sa,
            "radial_stress": sr,
            "mean_stress": p,
            "deviatoric_stress": q,
            "stress_ratio": np.where(p > 0, q / p, np.nan),
            "specific_volume": np.asarray(ds["specific_volume"].values, dtype=float),
            "fabric": convention.model_fabric(dev),
            "fabric_deviator": dev,
        }
        if moduli:
            e_v = convention.model_modulus(ds[moduli[0]].values)
            e_h = convention.model_modulus(ds[moduli[1]].values)
            out |= {"e_oed_v": e_v, "e_oed_h": e_h}
            out |= {"stiffness_ratio": e_h / e_v, "e_oed_v_over_p": e_v / p}
    return out


def _band_variables(per_run: list[dict], table: dict, dim: str, prefix: str) -> dict:
    """``prefix + name`` (the mean) and ``prefix + name + "_ci95"`` (the half-width of the 95 %
    interval of the mean) along ``dim`` of every variable of ``table`` over the runs' values
    ``per_run``."""
    data = {}
    for name, (units, long_name) in table.items():
        mean, half, _ = mean_and_half_width([run[name] for run in per_run], CONFIDENCE)
        about = f"the 95 % interval of the replica mean of {long_name}"
        data[prefix + name] = (
            dim,
            mean,
            {"units": units, "long_name": "replica mean of " + long_name},
        )
        data[f"{prefix}{name}_ci95"] = (
            dim,
            half,
            {"units": units, "long_name": f"half-width of {about} (Student t, n - 1 dof)"},
        )
    return data


def replica_bands(
    runs,
    stress_scale_kpa: float | None = None,
    convention: str = "triaxial",
    fabric_scale: float = 1.0,
    probe_method: str = "linear",
) -> xr.Dataset:
    """The replicas' mean ± half-width of the 95 % interval of the mean, per aligned record.

    ``runs``: run folders or sweep folders (:func:`bridge.replicas.replica_runs`: at least two
    runs, else :class:`bridge.series.SeriesError`; misaligned stages are refused naming the run
    and the stage). ``stress_scale_kpa``: None reads each run's own (its ``relaxed_states.nc``
    attribute, as the calibration does: :func:`bridge.pipeline.stress_scale_of`);
    ``convention``, ``fabric_scale``: see :class:`bridge.series.Convention`; ``probe_method``:
    ``"linear"`` or ``"dynamic"`` moduli. The records' state labels are those the first run's
    ``summary.json`` gives (the same record in every aligned replica; :func:`record_labels`).

    Returns a dataset with dimension ``state`` (the relaxed path states: ``stage``,
    ``state_label``, and each of :data:`STATE_VARIABLES` as its mean and ``<name>_ci95``, the
    half-width) and, when every run has probes, ``probe`` (``probe_stage``, ``probe_state_label``,
    ``probe_<name>`` and ``probe_<name>_ci95`` of the same and of :data:`PROBE_ONLY`), ``n`` (the
    number of replicas) and the attributes ``replica_runs``, ``stress_scales_kpa`` and the
    convention's.
    """
    folders = replica_runs(runs)
    relaxed, probes = aligned_replicas(folders)
    options = PipelineOptions(stress_scale_kpa=stress_scale_kpa, probe_method=probe_method)
    conventions = []
    for k, (folder, ds) in enumerate(zip(folders, relaxed, strict=True)):
        scale, _ = stress_scale_of(options, ds, folder / RELAXED, probes[k] if probes else None)
        conventions.append(Convention(scale, convention, fabric_scale))
    states = [
        _model_values(ds, conv, f"replica file {f / RELAXED}")
        for ds, conv, f in zip(relaxed, conventions, folders, strict=True)
    ]
    data = _band_variables(states, STATE_VARIABLES, "state", "")
    stages = [history_stage(relaxed[0], i) for i in range(relaxed[0].sizes["time"])]
    data["stage"] = ("state", np.array(stages, dtype=object), {"long_name": "DEM stage"})
    _, mean_p, _ = data["mean_stress"]
    known = summary_labels(folders[0]) if "step" in relaxed[0] else None
    steps = relaxed[0]["step"].values if known else None
    labels = record_labels(stages, mean_p, steps, known)
    data["state_label"] = ("state", labels.astype(object), {"long_name": "state label"})
    if probes is not None:
        moduli = (f"e_oed_v_{probe_method}", f"e_oed_h_{probe_method}")
        values = [
            _model_values(ds, conv, f"replica file {f / PROBES}", moduli)
            for ds, conv, f in zip(probes, conventions, folders, strict=True)
        ]
        table = STATE_VARIABLES | PROBE_ONLY
        data |= _band_variables(values, table, "probe", "probe_")
        for name, source in (("probe_stage", "path"), ("probe_state_label", "state_label")):
            text = np.asarray(probes[0][source].values).astype(str).astype(object)
            data[name] = ("probe", text, {"long_name": f"DEM probe {source}"})
    data["n"] = ((), len(folders), {"long_name": "number of replicas"})
    ds = xr.Dataset(data)
    ds.attrs.update(conventions[0].attrs())
    ds.attrs.update(
        title=f"mean and 95 % interval of the mean over {len(folders)} replicas",
        replica_runs=", ".join(str(f) for f in folders),
        stress_scales_kpa=", ".join(f"{c.stress_scale_kpa:g}" for c in conventions),
        probe_method=probe_method,
        confidence=CONFIDENCE,
        alignment="record by record, as bridge.replicas.replica_mean",
    )
    del ds.attrs["stress_scale_kpa"]  # each run's own: stress_scales_kpa
    return ds
