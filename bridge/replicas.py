"""Calibration on replicas: the replica-mean series, and the replica spread in the parameters.

Replicas are protocol runs of the same scene that differ only in the seed (a sweep over
``scene.seed``, :mod:`dem_taichi.sweep.command`). A small sample scatters from seed to seed (300
rods: E_h/E_v at C from 0.48 to 1.09), so one run's parameters carry that sampling error unseen.
:func:`calibrate_replicas` therefore

1. averages the replicas' relaxed path states and probes record by record
   (:func:`replica_mean`): state A (the last ``isotropic_to_A`` record), then every record of
   each later stage in order, which the stress-controlled paths place at the same increment of
   each run (the same ``path_increments`` and targets from each run's own A; a different count
   of records in a stage is refused). The mean of (p, v, fabric, moduli) at increment k stands
   for the mean curve there (p_A differs by a few per cent between seeds);
2. calibrates on the mean (:func:`bridge.pipeline.calibrate_from_results`): the point estimate;
3. calibrates every replica on its own (same options): the parameters' seed-to-seed spread;
4. carries the spread into the uncertainty of the estimate: for each parameter θ, the mean
   fit's standard error s_fit (from the residuals), the replicas' SD s_rep, the 95 % interval of
   the replica mean t_{0.975, n−1} s_rep / √n, and the combined standard uncertainty
   u = sqrt(s_fit² + s_rep² / n) (the two are independent: noise about the mean curve and the
   sampling of the mean curve itself).

Outputs in ``out_dir``: ``mean/`` (the mean files ``relaxed_states.nc`` and ``probes.nc`` and
their calibration, report and figures), ``replica_<name>/`` (each replica's calibration),
``replicas.json`` and ``replicas.md`` (the parameter table). Command line:
``python -m bridge calibrate --replicas RUN_DIR [RUN_DIR ...] --out DIR`` (or a sweep folder,
whose finished ``members/*`` are the replicas), with every option of ``calibrate``; in Python
:func:`bridge.pipeline.calibrate_on_replicas`.
"""

from __future__ import annotations

import json
import math
from itertools import zip_longest
from pathlib import Path

import numpy as np
import xarray as xr
from scipy import stats

from .series import HISTORY_REQUIRED, PROBES_REQUIRED, SeriesError, check_layout

__all__ = [
    "replica_runs",
    "replica_mean",
    "aligned_replicas",
    "aligned_records",
    "history_stage",
    "probe_stage",
    "nan_mean",
    "calibrate_replicas",
    "parameter_spread",
]

RELAXED = "relaxed_states.nc"
PROBES = "probes.nc"


def replica_runs(folders) -> list[Path]:
    """The replica run folders: each given folder that holds ``relaxed_states.nc``, or the
    finished members of a sweep folder (``members/*`` with ``summary.json``). At least two."""
    runs: list[Path] = []
    for folder in map(Path, folders):
        if (folder / RELAXED).exists():
            runs.append(folder)
        elif (folder / "members").is_dir():
            runs += sorted(
                d for d in (folder / "members").iterdir() if (d / "summary.json").exists()
            )
        else:
            raise SeriesError(
                f"{folder}: neither a protocol run (no {RELAXED}) nor a sweep (no members/)"
            )
    if len(runs) < 2:
        raise SeriesError(f"replicas need at least two runs; found {len(runs)} in {list(folders)}")
    names = [r.name for r in runs]
    if len(set(names)) != len(names):
        raise SeriesError(f"replica runs must have distinct folder names: {names}")
    return runs


def _stage_blocks(ds: xr.Dataset, dim: str, key) -> list[tuple[object, np.ndarray]]:
    """(stage key, record indices) in order of appearance; of state A's stage only the last."""
    keys = [key(ds, i) for i in range(ds.sizes[dim])]
    blocks: list[tuple[object, list[int]]] = []
    for i, k in enumerate(keys):
        if blocks and blocks[-1][0] == k:
            blocks[-1][1].append(i)
        else:
            blocks.append((k, [i]))
    return [(k, np.array(idx[-1:] if k == "isotropic_to_A" else idx)) for k, idx in blocks]


def nan_mean(values: np.ndarray) -> np.ndarray:
    """Mean over axis 0 of the finite values; NaN where none is (a variable a run lacks)."""
    finite = np.isfinite(values)
    count = finite.sum(axis=0)
    total = np.where(finite, values, 0.0).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def _first_difference(ours: list[tuple[object, int]], theirs: list[tuple[object, int]]) -> str:
    """Where two stage layouts, lists of (stage, record count), first differ, in words."""
    for a, b in zip_longest(ours, theirs):
        if a == b:
            continue
        if a is None:
            return f"stage {b[0]!r} ({b[1]} records), which the first has not"
        if b is None:
            return f"stage {a[0]!r}, which it lacks (the first has {a[1]} records)"
        if a[0] == b[0]:
            return f"stage {a[0]!r}: {b[1]} records against {a[1]}"
        return f"stage {b[0]!r} ({b[1]} records) where the first has {a[0]!r} ({a[1]})"
    return "no stage"


def aligned_records(
    datasets: list[xr.Dataset], dim: str, key, names: list[str], what: str = "records"
) -> list[xr.Dataset]:
    """Each replica's records in the aligned order: state A (the last record of the stage
    ``isotropic_to_A``), then every record of each later stage in order of appearance;
    ``key(ds, i)`` is the stage of record i. The same stages with the same record counts in
    every replica, else :class:`SeriesError` (one line) naming the replica (``names``) and the
    first stage that differs from the first replica's; ``what`` names the files."""
    layouts = [_stage_blocks(ds, dim, key) for ds in datasets]
    first = [(k, len(i)) for k, i in layouts[0]]
    for name, layout in zip(names[1:], layouts[1:], strict=True):
        other = [(k, len(i)) for k, i in layout]
        if other != first:
            raise SeriesError(
                f"replica {name!r} has other stages or record counts than {names[0]!r} in its "
                f"{what}, at {_first_difference(first, other)}: replicas must be runs of one "
                "protocol"
            )
    return [
        ds.isel({dim: np.concatenate([i for _, i in layout])})
        for ds, layout in zip(datasets, layouts, strict=True)
    ]


def _mean_dataset(picked: list[xr.Dataset], dim: str, names: list[str]) -> xr.Dataset:
    """The record-by-record mean of aligned replicas (:func:`aligned_records`)."""
    numeric = [v for v in picked[0].data_vars if np.issubdtype(picked[0][v].dtype, np.number)]
    mean = picked[0].copy(deep=True)
    stack = {v: np.stack([p[v].values for p in picked]) for v in numeric}
    for v in numeric:
        if v in ("stage", "step"):
            continue
        mean[v].values = nan_mean(stack[v])
    if dim in mean.coords and np.issubdtype(mean[dim].dtype, np.number):
        mean = mean.assign_coords({dim: np.mean([p[dim].values for p in picked], axis=0)})
    mean.attrs.update(
        title=f"mean of {len(picked)} replicas: " + str(picked[0].attrs.get("title", "")),
        replicas=len(picked),
        replica_runs=", ".join(names),
        replica_mean="record-by-record mean over replicas (bridge.replicas.replica_mean)",
    )
    return mean


def _checked_replica(path: Path, names: tuple[str, ...], record_dim: str) -> xr.Dataset:
    """A replica's dataset, checked before the means read it: the variables ``names`` present,
    numeric, 1-D along the record dimension ``record_dim``; :class:`SeriesError` naming the file
    otherwise (a wrongly shaped file was a KeyError deep in the means)."""
    try:
        ds = xr.load_dataset(path)
    except (OSError, ValueError) as error:
        raise SeriesError(
            f"replica file {path} is not a readable netCDF dataset ({error}); give the folders "
            "of protocol runs"
        ) from error
    what = f"replica file {path}"
    dim = check_layout(ds, names, what)
    if dim != record_dim:
        raise SeriesError(
            f"{what}: its variables are along {dim!r}, not {record_dim!r} as a protocol run "
            "writes them; give the folders of protocol runs"
        )
    return ds


def history_stage(ds: xr.Dataset, i: int) -> str:
    """The stage label of record ``i`` of a relaxed-states dataset (its alignment key)."""
    from dem_taichi.io.schema import STAGE_LABELS

    return STAGE_LABELS.get(int(ds["stage"].values[i]), "?")


def probe_stage(ds: xr.Dataset, i: int) -> str:
    """The alignment key of probe ``i``: ``"A"`` for state A's probe, else its path (stage)."""
    label = str(ds["state_label"].values[i])
    return label if label == "A" else str(ds["path"].values[i])


def aligned_replicas(runs: list[Path]) -> tuple[list[xr.Dataset], list[xr.Dataset] | None]:
    """Each replica's ``relaxed_states.nc`` and ``probes.nc`` (None when a run has no probes),
    checked (:func:`check_layout`) and cut to the aligned records (:func:`aligned_records`)."""
    names = [r.name for r in runs]
    relaxed = [_checked_replica(r / RELAXED, HISTORY_REQUIRED, "time") for r in runs]
    history = aligned_records(relaxed, "time", history_stage, names, RELAXED)
    if not all((r / PROBES).exists() for r in runs):
        return history, None
    wanted = PROBES_REQUIRED + ("state_label",)
    probes = [_checked_replica(r / PROBES, wanted, "probe") for r in runs]
    return history, aligned_records(probes, "probe", probe_stage, names, PROBES)


def replica_mean(runs: list[Path]) -> tuple[xr.Dataset, xr.Dataset | None]:
    """The record-by-record means of the replicas' ``relaxed_states.nc`` and ``probes.nc``
    (None when a run has no probes), aligned by :func:`aligned_replicas`."""
    names = [r.name for r in runs]
    history, probes = aligned_replicas(runs)
    mean = _mean_dataset(history, "time", names)
    return mean, None if probes is None else _mean_dataset(probes, "probe", names)


def parameter_spread(mean_fit: dict, replica_fits: dict[str, dict], confidence=0.95) -> dict:
    """Per parameter: the estimate on the mean, s_fit, the replicas' values, mean, SD, the
    half-width of the ``confidence`` interval of their mean and u = sqrt(s_fit² + SD²/n)."""
    out = {}
    for symbol, value in mean_fit["parameters"].items():
        values = [fit["parameters"][symbol] for fit in replica_fits.values()]
        x = np.asarray(values, dtype=float)
        n = x.size
        sd = float(x.std(ddof=1)) if n > 1 else math.nan
        se_fit = mean_fit["standard_errors"].get(symbol)
        se_fit = math.nan if se_fit is None else float(se_fit)
        half = float(stats.t.ppf(0.5 + confidence / 2, n - 1) * sd / math.sqrt(n))
        combined = math.sqrt((se_fit if math.isfinite(se_fit) else 0.0) ** 2 + sd**2 / n)
        fitted = symbol in mean_fit["standard_errors"]  # the fitted ones have an error entry
        out[symbol] = {
            "estimate": float(value),
            "fit_standard_error": se_fit,
            "replica_values": dict(zip(replica_fits, map(float, values), strict=True)),
            "replica_mean": float(x.mean()),
            "replica_sd": sd,
            "replica_interval_95": half,
            "combined_uncertainty": combined,
            "fitted": fitted,
        }
    return out


def _markdown(spread: dict, runs: list[Path], mean_dir: Path) -> str:
    lines = [
        f"# Calibration on {len(runs)} replicas",
        "",
        "Replicas: " + ", ".join(str(r) for r in runs) + ".",
        f"Estimate: calibration on the record-by-record mean ({mean_dir}); s_fit its standard "
        "error; the replicas' own calibrations give the SD and the 95 % interval of their mean "
        "(Student t); u = sqrt(s_fit² + SD²/n) the combined standard uncertainty "
        "(bridge.replicas).",
        "",
        "| symbol | estimate (mean series) | s_fit | replica mean ± 95 % | replica SD | u | "
        "replicas |",
        "|---|---|---|---|---|---|---|",
    ]
    for symbol, row in spread.items():
        if not row["fitted"]:
            continue
        vals = ", ".join(f"{v:.4g}" for v in row["replica_values"].values())
        lines.append(
            f"| {symbol} | {row['estimate']:.4g} | {row['fit_standard_error']:.2g} | "
            f"{row['replica_mean']:.4g} ± {row['replica_interval_95']:.2g} | "
            f"{row['replica_sd']:.2g} | {row['combined_uncertainty']:.2g} | {vals} |"
        )
    held = [s for s, r in spread.items() if not r["fitted"]]
    if held:
        lines += ["", "Not fitted (held): " + ", ".join(held) + "."]
    return "\n".join(lines) + "\n"


def calibrate_replicas(folders, out_dir, calibrate, options, replica_options, say=print) -> dict:
    """Calibrate on the mean of the replicas and on each replica (see the module docstring).

    ``calibrate(history, probes, out_dir, options)`` is the calibration of one data set
    (:func:`bridge.pipeline.calibrate_from_results`, passed in by
    :func:`bridge.pipeline.calibrate_on_replicas`, which is the entry to use); ``options`` are
    the mean's, ``replica_options`` the replicas' (without figures and profile likelihoods).
    Returns the dict written to ``replicas.json``: ``runs``, ``mean`` (the mean calibration's
    outcome), ``replicas`` (each one's parameters and standard errors) and ``parameters``
    (:func:`parameter_spread`).
    """
    runs = replica_runs(folders)
    out = Path(out_dir)
    mean_dir = out / "mean"
    mean_dir.mkdir(parents=True, exist_ok=True)
    history, probes = replica_mean(runs)
    history.to_netcdf(mean_dir / RELAXED)
    probes_path = None
    if probes is not None:
        probes.to_netcdf(mean_dir / PROBES)
        probes_path = mean_dir / PROBES
    say(f"calibrating on the mean of {len(runs)} replicas ...")
    mean_fit = calibrate(mean_dir / RELAXED, probes_path, mean_dir, options)
    replica_fits = {}
    for run in runs:
        say(f"calibrating replica {run.name} ...")
        fit = calibrate(
            run / RELAXED,
            run / PROBES if probes_path and (run / PROBES).exists() else None,
            out / f"replica_{run.name}",
            replica_options,
        )
        replica_fits[run.name] = {k: fit[k] for k in ("parameters", "standard_errors", "fitted")}
    spread = parameter_spread(mean_fit, replica_fits)
    result = {
        "runs": [str(r) for r in runs],
        "mean": {k: mean_fit[k] for k in ("parameters", "standard_errors", "fitted", "files")},
        "replicas": replica_fits,
        "parameters": spread,
    }
    (out / "replicas.json").write_text(json.dumps(result, indent=2, default=str))
    (out / "replicas.md").write_text(_markdown(spread, runs, mean_dir))
    return result
