"""The study's findings read from a finished protocol run, and their replica statistics.

numpy/scipy/xarray only (no Taichi): reads ``summary.json``, ``relaxed_states.nc`` and
``probes.nc`` of a run directory (:func:`dem_taichi.protocol.runner.run_protocol`) into arrays
(:func:`path_arrays`, :func:`probe_arrays`) and assembles the findings from them
(:func:`findings_from_arrays`, :func:`states_from_arrays`), the same way for a run held in memory
(``benchmarks/paired_paths.py``). Used by the benchmarks' summaries (runs side by side) and by
the sweeps (:mod:`dem_taichi.sweep.results`: mean ± 95 % interval over replicas).

Findings (docs/science/dem-model.md §1, the study): fabric isotropic along A→B within the sampling
noise sqrt(0.5/N) and E_oed,h ≈ E_oed,v there; along K0 the rods lie down (β_yy − β_xx falls) and
E_oed,h/E_oed,v > 1, growing; ln v linear in ln p beyond A (slope −λ*); K0 = σ_xx/σ_yy at C;
the moduli ∝ p^n along A→B (the study: n ≈ 0.8) and E_v/p at B (≈ 125). Moduli are the
linear-response ones. A run without some path or without probes gives NaN for what it lacks.
On the mapped stress window (:func:`mapped_window_findings`,
:mod:`dem_taichi.analysis.mapped_window`): the stress scale measured where E_v/p = 125 (the study's
100 kPa), λ* and the moduli exponents over 1–200 kPa, N (v at 100 kPa) under the disc-union and the
rectangle rod areas, and the densification sensitivity ln(E_B′/E_B)/ln(v_B′/v_B).

Symbols: p = (σ_xx + σ_yy)/2, q = σ_yy − σ_xx (DEM units), v specific volume, β_yy − β_xx rod
fabric deviator, E_oed,v = ∂σ_yy/∂ε_yy and E_oed,h = ∂σ_xx/∂ε_xx (constrained moduli), λ*.
"""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from dem_taichi.analysis.arrays import (
    PathArrays,
    ProbeArrays,
    compressibility_slope,
    fabric_isotropy,
    modulus_over_p_at,
    power_law_exponent,
    stiffness_ratio,
    stress_ratio_at,
)
from dem_taichi.analysis.mapped_window import (
    STUDY_REFERENCE_KPA,
    STUDY_WINDOW_KPA,
    densification_sensitivity,
    local_compressibility,
    moduli_exponent,
    specific_volume_at,
    specific_volume_rectangle,
    stress_scale_from_stiffness,
    windowed_compressibility,
)
from dem_taichi.io import open_history, open_probes
from dem_taichi.io.schema import STAGE_LABELS

__all__ = [
    "STATE_MEASURES",
    "path_arrays",
    "probe_arrays",
    "run_findings",
    "headline_findings",
    "findings_from_arrays",
    "state_findings",
    "states_from_arrays",
    "mean_interval",
    "mapped_window_findings",
    "stress_scale_interval",
]

#: Measures of a labelled state taken from ``summary.json`` (history names).
STATE_MEASURES = (
    "mean_stress",
    "deviatoric_stress",
    "stress_xx",
    "stress_yy",
    "specific_volume",
    "fabric_deviator",
    "mechanical_coordination_number",
)

_NAN = float("nan")


def _probes(folder: Path):
    path = folder / "probes.nc"
    return open_probes(path) if path.exists() else None


def path_arrays(summary: dict, relaxed) -> PathArrays:
    """The relaxed states of a run folder as :class:`~dem_taichi.analysis.arrays.PathArrays`: the
    labelled states of ``summary.json`` and the records of ``relaxed_states.nc`` (``relaxed``,
    its dataset), stage codes read back to their names ("" for a code the schema lacks)."""
    stage = np.array([STAGE_LABELS.get(int(c), "") for c in relaxed["stage"].values], dtype=str)
    measures = {
        name: np.asarray(relaxed[name].values, dtype=float)
        for name in relaxed.data_vars
        if name != "stage" and relaxed[name].dims == ("time",)
    }
    return PathArrays(summary.get("states", {}), stage, measures)


def probe_arrays(probes) -> ProbeArrays:
    """The probes of a run folder (``probes.nc``, its dataset, or None) as
    :class:`~dem_taichi.analysis.arrays.ProbeArrays`."""
    if probes is None or not probes.sizes.get("probe", 0):
        return ProbeArrays.empty()
    n = probes.sizes["probe"]

    def values(name: str) -> np.ndarray:  # NaN for a modulus the file does not hold
        return np.asarray(probes[name].values, dtype=float) if name in probes else np.full(n, _NAN)

    return ProbeArrays(
        label=probes["state_label"].values.astype(str),
        path=probes["path"].values.astype(str),
        mean_stress=values("mean_stress"),
        e_oed_v=values("e_oed_v_linear"),
        e_oed_h=values("e_oed_h_linear"),
        e_oed_v_dynamic=values("e_oed_v_dynamic"),
        e_oed_h_dynamic=values("e_oed_h_dynamic"),
    )


def run_findings(folder: str | Path) -> dict:
    """The findings of one run directory as a flat dict (one row of the validation summary).

    Keys: ``run`` (the folder's name), ``max_i`` (largest inertial number on the paths from A),
    the findings over the run's arrays (:func:`findings_from_arrays`: ``n_rods``, ``noise``,
    ``iso_fabric_max``, ``iso_fabric_within_noise``, ``iso_ratio``, ``k0_fabric``, ``k0_p``,
    ``k0_ratio``, ``lambda_star``, ``r2``, ``p_A``, ``v_A``, ``v_B``, ``v_C``, ``fabric_A``,
    ``fabric_C``, ``k0_C``, ``modulus_exponent``, ``ev_over_p_B`` and those on the mapped stress
    window), ``seconds``, ``workers``, ``max_overlap`` (the largest contact overlap δ/d at the
    labelled states, :func:`dem_taichi.analysis.overlaps.run_max_overlap`: from their
    configurations, or their state checkpoints for bonded rods; NaN without either);
    ``anisotropy_C`` when the folder holds
    ``anisotropy.json``. The files give the arrays (:func:`path_arrays`, :func:`probe_arrays`),
    the scene's stress scale and the rod shape; what is computed from them is
    :func:`findings_from_arrays`, which a run in memory calls too
    (``benchmarks/paired_paths.py``).
    """
    folder = Path(folder)
    summary = json.loads((folder / "summary.json").read_text())
    relaxed = open_history(folder / "relaxed_states.nc")
    loading = [
        st["max_inertial_number"]
        for name, st in summary["stages"].items()
        if name != "isotropic_to_A"
    ]
    row = {"run": folder.name, "max_i": max(loading) if loading else _NAN}
    row |= findings_from_arrays(
        path_arrays(summary, relaxed),
        probe_arrays(_probes(folder)),
        int(summary["n_rods"]),
        _scene_scale(summary, relaxed.attrs),
        _rod_shape(relaxed.attrs),
    )
    row |= {"seconds": summary["total_seconds"], "workers": summary.get("workers", 1)}
    from dem_taichi.analysis.overlaps import run_max_overlap  # scipy's tree, loaded on use

    row["max_overlap"] = run_max_overlap(folder)
    aniso = folder / "anisotropy.json"
    if aniso.exists():
        rows = {r["state"]: r for r in json.loads(aniso.read_text())}
        row["anisotropy_C"] = rows.get("C")
    return row


def headline_findings(folder: str | Path, found: Mapping[str, Any] | None = None) -> dict:
    """The study's headline findings of one finished run directory, as plain numbers.

    :func:`run_findings`' numeric values, plus the linear-response anisotropy at the labelled
    states and its paired changes within the run: ``ratio_B``, ``ratio_C``, ``ratio_Bp``
    (E_oed,h/E_oed,v of the probes at B, C and B′), ``ratio_C_minus_B`` and
    ``ratio_Bp_minus_B`` (against the same run's B), and ``minutes`` (wall time). Read at the
    labels, so an isotropic path continued past B (``isotropic_end_stress``) leaves them as
    they were. NaN for what the run lacks. What the benchmark summaries over replicas and
    ``make demo`` report. ``found``: the folder's :func:`run_findings`, when the caller has
    read them already.
    """
    folder = Path(folder)
    f = run_findings(folder) if found is None else found
    row = {k: v for k, v in f.items() if isinstance(v, int | float)}
    states = state_findings(folder)

    def ratio(label: str) -> float:
        return states.get(label, {}).get("e_ratio", _NAN)

    row["ratio_B"], row["ratio_C"], row["ratio_Bp"] = ratio("B"), ratio("C"), ratio("B'")
    row["ratio_C_minus_B"] = row["ratio_C"] - row["ratio_B"]
    row["ratio_Bp_minus_B"] = row["ratio_Bp"] - row["ratio_B"]
    row["minutes"] = float(f["seconds"]) / 60.0
    return row


def findings_from_arrays(
    path: PathArrays,
    probes: ProbeArrays,
    n_rods: int,
    stress_scale_kpa: float = 1.0,
    rod_shape: tuple[int, float, float] | None = None,
) -> dict:
    """The study's findings over a run's arrays, as a flat dict: what :func:`run_findings`
    computes once it has read a run folder, for a run read from its files or held in memory
    (:func:`dem_taichi.protocol.report.path_arrays` and ``probe_arrays`` of a
    :class:`~dem_taichi.protocol.records.ProtocolResult`).

    ``path``/``probes``: the relaxed states and the probes; ``n_rods`` (the fabric's sampling
    noise); ``stress_scale_kpa``: the scene's ``[protocol] stress_scale_kpa``, used on the
    mapped window when the probes do not measure a scale; ``rod_shape``: (n_spheres, spacing,
    diameter) of the rods, for ``N_rectangle`` (NaN without it). Keys: ``n_rods``, ``noise``
    (sqrt(0.5/N)), ``iso_fabric_max`` (max |β_yy − β_xx| on A and A→B),
    ``iso_fabric_within_noise`` (every one within 2 noises), ``iso_ratio`` / ``k0_ratio``
    (E_h/E_v of the probes along A→B / along K0 by rising p), ``k0_fabric``, ``k0_p``,
    ``lambda_star`` and ``r2`` (ln v – ln p fit over A and A→B), ``p_A``, ``v_A``, ``v_B``,
    ``v_C``, ``fabric_A``, ``fabric_C``, ``k0_C`` (σ_xx/σ_yy at C), ``modulus_exponent`` (n of
    E_v ∝ p^n on A and A→B), ``ev_over_p_B``, and the findings on the mapped stress window
    (:func:`mapped_window_findings`). NaN (or an empty list) for what a run lacks. Each finding
    is computed by the functions of :mod:`dem_taichi.analysis.arrays` that the run's report
    uses too.
    """
    iso_p = path.from_a("A_to_B", "mean_stress")
    iso_v = path.from_a("A_to_B", "specific_volume")
    fit = compressibility_slope(iso_p, iso_v)
    fabric = fabric_isotropy(path.from_a("A_to_B", "fabric_deviator"), n_rods)
    ratio = stiffness_ratio(probes.e_oed_h, probes.e_oed_v)
    on_iso = probes.isotropic()
    k0 = probes.along_k0()
    row = {
        "n_rods": n_rods,
        "noise": fabric.noise,
        "iso_fabric_max": fabric.max_abs,
        "iso_fabric_within_noise": fabric.within_noise,
        "iso_ratio": [float(x) for x in ratio[on_iso]],
        "k0_fabric": [float(x) for x in path.on("A_to_C", "fabric_deviator")],
        "k0_p": [float(x) for x in probes.mean_stress[k0]],
        "k0_ratio": [float(x) for x in ratio[k0]],
        "lambda_star": fit["lambda_star"],
        "r2": fit["r2"],
        "p_A": path.at("A", "mean_stress"),
        "v_A": path.at("A", "specific_volume"),
        "v_B": path.at("B", "specific_volume"),
        "v_C": path.at("C", "specific_volume"),
        "fabric_A": path.at("A", "fabric_deviator"),
        "fabric_C": path.at("C", "fabric_deviator"),
        "k0_C": stress_ratio_at(path, "C"),
        # moduli ∝ p^n along A→B (the study: n ≈ 0.8)
        "modulus_exponent": power_law_exponent(probes.mean_stress[on_iso], probes.e_oed_v[on_iso]),
        "ev_over_p_B": modulus_over_p_at(probes, "B"),
    }
    window = _window_findings(path.states, stress_scale_kpa, rod_shape, probes, iso_p, iso_v)
    return row | window


def _scene_scale(summary: dict, attrs) -> float:
    """The scene's ``[protocol] stress_scale_kpa`` as a run folder states it (``summary.json``,
    else the relaxed states' attribute; 1 when neither has it)."""
    return float(summary.get("stress_scale_kpa", attrs.get("stress_scale_kpa", 1.0)))


def _rod_shape(attrs) -> tuple[int, float, float] | None:
    """(n_spheres, spacing, diameter) of the rods from the run's effective scene (the history's
    attribute ``scene_toml_effective``); None when the attribute is missing."""
    text = attrs.get("scene_toml_effective")
    if not text:
        return None
    particles = tomllib.loads(str(text))["particles"]
    return int(particles["n_spheres"]), float(particles["spacing"]), float(particles["diameter"])


def mapped_window_findings(summary: dict, attrs, probes: ProbeArrays | None, iso_p, iso_v) -> dict:
    """The findings on the mapped stress window (:mod:`dem_taichi.analysis.mapped_window`, issue
    19).

    ``summary`` (``summary.json``), ``attrs`` (the relaxed states' attributes: the effective
    scene), ``probes`` (the run's :class:`~dem_taichi.analysis.arrays.ProbeArrays`,
    :func:`probe_arrays`; None for none), ``iso_p``/``iso_v`` (p in DEM units and v of
    state A and the relaxed states of A→B, in path order). Keys:

    - ``stress_scale_kpa_measured``: 100/p* kPa per DEM unit, p* the DEM stress at which
      E_oed,v/p = 125 on the probes of A→B (state A included), interpolated, never
      extrapolated; NaN (``stress_scale_reason`` says why) when no pair brackets 125;
      ``p_star`` = p*;
    - ``stress_scale_kpa_used`` and ``stress_scale_source``: the measured scale ("measured")
      when it exists, else the scene's ``[protocol] stress_scale_kpa`` ("scene");
    - ``lambda_window``, ``lambda_window_se``, ``n_window_points``: λ* = −d ln v/d ln p over the
      states of A and A→B with 1 ≤ p ≤ 200 kPa (least squares, standard error, points);
    - ``exponent_window_v``/``exponent_window_h``: n of E_oed,v/E_oed,h ∝ p^n over the probes of
      A and A→B in that window; ``n_exponent_points``;
    - ``N_disc``/``N_rectangle``: v at 100 kPa along A→B (ln v – ln p interpolation; NaN unless
      bracketed) with v as the DEM counts it (disc-union rod area) and with the rod as its
      rectangle L × d;
    - ``densification_sensitivity_v``/``_h``: ln(E_B′/E_B)/ln(v_B′/v_B) of E_oed,v/E_oed,h;
    - ``local_lambda_p_kpa``, ``local_lambda``: the local −d ln v/d ln p between consecutive
      states of A and A→B at their mid-points √(p_k p_k+1) in kPa (lists).
    """
    probes = probes if probes is not None else ProbeArrays.empty()
    scale, shape = _scene_scale(summary, attrs), _rod_shape(attrs)
    return _window_findings(summary.get("states", {}), scale, shape, probes, iso_p, iso_v)


def _window_findings(
    states: Mapping[str, Mapping[str, Any]],
    scene_scale: float,
    shape: tuple[int, float, float] | None,
    probes: ProbeArrays,
    iso_p,
    iso_v,
) -> dict:
    """:func:`mapped_window_findings` from the labelled states' measures, the scene's stress
    scale (kPa per DEM unit) and the rod shape (n_spheres, spacing, diameter; None: unknown)."""
    on_iso = probes.isotropic()
    p, e_v, e_h = probes.mean_stress[on_iso], probes.e_oed_v[on_iso], probes.e_oed_h[on_iso]
    measured = stress_scale_from_stiffness(p, e_v)
    found = bool(np.isfinite(measured.kpa_per_unit))
    scale = measured.kpa_per_unit if found else scene_scale
    iso_p_kpa = np.asarray(iso_p, dtype=float) * scale
    window = windowed_compressibility(iso_p_kpa, iso_v, STUDY_WINDOW_KPA)
    exp_v = moduli_exponent(p * scale, e_v, STUDY_WINDOW_KPA)
    exp_h = moduli_exponent(p * scale, e_h, STUDY_WINDOW_KPA)
    n_disc = specific_volume_at(iso_p_kpa, iso_v, STUDY_REFERENCE_KPA)
    n_rect = specific_volume_rectangle(n_disc, *shape) if shape is not None else _NAN
    ev_b, eh_b = probes.moduli_at("B")
    ev_bp, eh_bp = probes.moduli_at("B'")
    v_b, v_bp = (
        float(states[label]["specific_volume"]) if label in states else _NAN
        for label in ("B", "B'")
    )
    p_mid, local = local_compressibility(iso_p_kpa, iso_v)
    return {
        "stress_scale_kpa_measured": measured.kpa_per_unit,
        "p_star": measured.p_star,
        "stress_scale_reason": measured.reason,
        "stress_scale_kpa_used": scale,
        "stress_scale_source": "measured" if found else "scene",
        "lambda_window": window.slope,
        "lambda_window_se": window.se,
        "n_window_points": window.n,
        "exponent_window_v": exp_v.slope,
        "exponent_window_h": exp_h.slope,
        "n_exponent_points": exp_v.n,
        "N_disc": n_disc,
        "N_rectangle": n_rect,
        "densification_sensitivity_v": densification_sensitivity(ev_b, ev_bp, v_b, v_bp),
        "densification_sensitivity_h": densification_sensitivity(eh_b, eh_bp, v_b, v_bp),
        "local_lambda_p_kpa": [float(x) for x in p_mid],
        "local_lambda": [float(x) for x in local],
    }


def state_findings(folder: str | Path) -> dict[str, dict[str, float]]:
    """Per labelled state of a run (A, B, C, B', R<k>_end, in the order reached): the measures
    of :data:`STATE_MEASURES` and the linear-response moduli ``e_oed_v``, ``e_oed_h`` and their
    ratio ``e_ratio`` = E_oed,h/E_oed,v (NaN where the state was not probed)."""
    folder = Path(folder)
    summary = json.loads((folder / "summary.json").read_text())
    return states_from_arrays(summary["states"], probe_arrays(_probes(folder)))


def states_from_arrays(
    states: Mapping[str, Mapping[str, Any]], probes: ProbeArrays
) -> dict[str, dict[str, float]]:
    """:func:`state_findings` from the labelled states' measures (label → history name →
    value, in the order reached) and the run's probes, for a run read from its files or held
    in memory."""
    out: dict[str, dict[str, float]] = {}
    for label, measures in states.items():
        entry = {k: float(measures.get(k, _NAN)) for k in STATE_MEASURES}
        e_v, e_h = probes.moduli_at(label)
        entry.update(e_oed_v=e_v, e_oed_h=e_h, e_ratio=float(stiffness_ratio(e_h, e_v)))
        out[label] = entry
    return out


def mean_interval(values, confidence: float = 0.95) -> tuple[float, float, int]:
    """Mean, half-width of the ``confidence`` interval of the mean (Student t, n − 1 degrees of
    freedom: t · s/√n) and count of the finite values; half-width NaN below two values."""
    x = np.asarray([v for v in np.ravel(values) if np.isfinite(v)], dtype=float)
    if x.size == 0:
        return _NAN, _NAN, 0
    if x.size == 1:
        return float(x[0]), _NAN, 1
    t = stats.t.ppf(0.5 + confidence / 2.0, x.size - 1)
    return float(x.mean()), float(t * x.std(ddof=1) / math.sqrt(x.size)), int(x.size)


def stress_scale_interval(scales, confidence: float = 0.95) -> tuple[float, float, float, int]:
    """Replica statistics of measured stress scales (kPa per DEM unit), in log space.

    The scale is a ratio of units, so the interval is taken on ln(scale): the mean m and the
    Student-t half-width h of ln(scale) (:func:`mean_interval`) give the geometric mean exp(m)
    and the interval (exp(m − h), exp(m + h)), asymmetric about it. Returns (geometric mean,
    low, high, number of finite positive values); low/high NaN below two values.
    """
    x = np.asarray(scales, dtype=float).ravel()
    x = x[np.isfinite(x) & (x > 0)]
    mean, half, n = mean_interval(np.log(x), confidence)
    if n == 0:
        return _NAN, _NAN, _NAN, 0
    return math.exp(mean), math.exp(mean - half), math.exp(mean + half), n
