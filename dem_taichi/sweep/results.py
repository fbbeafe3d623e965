"""A sweep's finished members as one dataset along ``member``, and their replica statistics.

No Taichi, no Dask: reads the run directories a sweep (:mod:`dem_taichi.sweep.command`) wrote. The
findings of each member come from :mod:`dem_taichi.analysis.findings` (the computations of
``benchmarks/validation_summary.py``): the labelled states' measures and linear-response moduli
(``state_findings``) and the path findings (``run_findings``: λ*, K0, the moduli's p-exponent,
...). Replica statistics are mean ± 95 % interval of the mean (Student t, n − 1 degrees of
freedom, :func:`dem_taichi.analysis.findings.mean_interval`) over the members that differ only in
the replica key(s) (``scene.seed`` by default); members that differ in any other key of the sweep
form separate groups.

Symbols: v specific volume, β_yy − β_xx rod fabric deviator, E_oed,h/E_oed,v the ratio of the
constrained moduli (linear response), K0 = σ_xx/σ_yy at C, λ* = −d ln v/d ln p along A→B,
n the exponent of E_oed,v ∝ p^n along A→B.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import xarray as xr

from dem_taichi.analysis.findings import STATE_MEASURES, mean_interval, run_findings, state_findings
from dem_taichi.io import open_history
from dem_taichi.io.schema import HISTORY_VARIABLES, PROBE_VARIABLES
from dem_taichi.sweep.member import checked_member_dir

__all__ = [
    "open_sweep",
    "open_relaxed_states",
    "replica_statistics",
    "summary_table",
    "summarise_sweep",
    "summary_files",
]

#: Per-member findings of :func:`dem_taichi.analysis.findings.run_findings`: dataset name, key, long
# name.
RUN_SCALARS = (
    ("lambda_star", "lambda_star", "compressibility index lambda* = -d ln v / d ln p on A-B"),
    ("lambda_star_r2", "r2", "R^2 of the ln v - ln p fit over A and A-B"),
    ("k0_at_C", "k0_C", "K0 = sigma_xx / sigma_yy at C"),
    ("modulus_exponent", "modulus_exponent", "n of E_oed,v proportional to p^n on A-B"),
    ("e_oed_v_over_p_at_B", "ev_over_p_B", "E_oed,v / p at B"),
    ("isotropic_fabric_max", "iso_fabric_max", "max |beta_yy - beta_xx| over A and A-B"),
    ("mean_stress_at_A", "p_A", "mean stress p at the fluid-solid transition A"),
    ("max_inertial_number", "max_i", "largest inertial number on the paths from A"),
    ("fabric_noise", "noise", "fabric sampling noise sqrt(0.5/N)"),
    ("wall_seconds", "seconds", "wall time of the member's protocol run"),
    # the mapped stress window (dem_taichi.analysis.mapped_window, issue 19)
    ("stress_scale_kpa_measured", "stress_scale_kpa_measured",
     "kPa per DEM stress unit: 100 / p* where E_oed,v / p = 125 on A-B"),
    ("stress_scale_kpa_used", "stress_scale_kpa_used",
     "kPa per DEM stress unit mapping p (measured, else the scene's)"),
    ("lambda_window", "lambda_window", "lambda* = -d ln v / d ln p, 1 <= p <= 200 kPa on A-B"),
    ("lambda_window_se", "lambda_window_se", "standard error of lambda_window"),
    ("n_window_points", "n_window_points", "states of A and A-B in 1 <= p <= 200 kPa"),
    ("exponent_window_v", "exponent_window_v", "n of E_oed,v proportional to p^n, 1-200 kPa"),
    ("exponent_window_h", "exponent_window_h", "n of E_oed,h proportional to p^n, 1-200 kPa"),
    ("N_disc", "N_disc", "v at 100 kPa on A-B (disc-union rod area)"),
    ("N_rectangle", "N_rectangle", "v at 100 kPa on A-B (rod as rectangle L x d)"),
    ("densification_sensitivity_v", "densification_sensitivity_v",
     "ln(E_oed,v B' / B) / ln(v B' / B)"),
    ("densification_sensitivity_h", "densification_sensitivity_h",
     "ln(E_oed,h B' / B) / ln(v B' / B)"),
)  # fmt: skip
_STATE_ORDER = ("A", "B", "C", "B'")
_PROBE_ATTRS = {"e_oed_v": "e_oed_v_linear", "e_oed_h": "e_oed_h_linear"}


def _state_key(label: str) -> tuple:
    return (
        (_STATE_ORDER.index(label), label) if label in _STATE_ORDER else (len(_STATE_ORDER), label)
    )


def _coordinate(values: list) -> np.ndarray:
    """One array for a key's values over the members (numbers, booleans or strings)."""
    present = [v for v in values if v is not None]
    if not present:
        return np.full(len(values), math.nan)
    if all(isinstance(v, bool) for v in present) and len(present) == len(values):
        return np.array(values, dtype=bool)
    if present and all(isinstance(v, int | float) and not isinstance(v, bool) for v in present):
        if len(present) == len(values) and all(isinstance(v, int) for v in present):
            return np.array(values, dtype=np.int64)
        return np.array([math.nan if v is None else float(v) for v in values])
    return np.array(["" if v is None else str(v) for v in values], dtype=object)


def parameter_name(key: str) -> str:
    """The dataset name of a sweep key: ``"scene.seed"`` → ``scene_seed``."""
    return key.replace(".", "_")


def _finished_members(out: Path) -> tuple[dict, list[dict], list[str]]:
    """The sweep record, its finished members and the names of the others; each member's
    folder checked to lie in ``out/members`` (a ``sweep.json`` naming ``..`` is refused)."""
    sweep = json.loads((out / "sweep.json").read_text())
    finished: list[dict] = []
    other: list[dict] = []
    for m in sweep["members"]:
        folder = checked_member_dir(out, m["name"])
        try:
            record = json.loads((folder / "member.json").read_text())
        except (OSError, ValueError):
            record = {}
        ok = record.get("status") == "done" and record.get("scene_sha256") == m["scene_sha256"]
        (finished if ok and (folder / "summary.json").exists() else other).append(m)
    return sweep, finished, [m["name"] for m in other]


def _extra_member(folder: Path, keys) -> dict:
    """A finished protocol run outside the sweep as a member: its folder name, and the swept
    keys it can state (``scene.seed`` from its history's attributes; the others None)."""
    if not (folder / "summary.json").exists():
        raise FileNotFoundError(f"{folder / 'summary.json'} does not exist: not a finished run")
    seed = None
    with xr.open_dataset(folder / "relaxed_states.nc") as relaxed:
        if "seed" in relaxed.attrs:
            seed = int(relaxed.attrs["seed"])
    return {"name": folder.name, "parameters": {k: seed if k == "scene.seed" else None
                                                for k in keys}}  # fmt: skip


def open_sweep(out_dir: str | Path, extra_runs=()) -> xr.Dataset:
    """The finished members of the sweep in ``out_dir`` as one dataset along ``member``.

    Dimensions ``member`` (the finished members, in the sweep's order) and ``state`` (every
    labelled state any member reached: A, B, C, B', R<k>_end). Variables along (member, state):
    the measures of :data:`dem_taichi.analysis.findings.STATE_MEASURES` and the linear-response
    moduli ``e_oed_v``, ``e_oed_h``, ``e_ratio`` (NaN where a member lacks the state or its probe);
    along ``member``: the path findings of :data:`RUN_SCALARS`. Every key the sweep varies is a
    coordinate along ``member`` (``scene.seed`` → ``scene_seed``, attribute ``sweep_key``).
    Attributes: the sweep's name and scene, and the members not finished (failed, pending).
    ``extra_runs``: folders of finished protocol runs of the same scene made outside the sweep
    (earlier replicas), added after the sweep's members (attribute ``extra_runs``).
    """
    out = Path(out_dir)
    if not (out / "sweep.json").exists():
        raise FileNotFoundError(f"{out / 'sweep.json'} does not exist: not a sweep directory")
    sweep, members, not_finished = _finished_members(out)
    swept = list(dict.fromkeys(k for m in sweep["members"] for k in m["parameters"]))
    extras = [Path(f) for f in extra_runs]
    folders = [out / "members" / m["name"] for m in members] + extras
    members = members + [_extra_member(f, swept) for f in extras]
    names = [m["name"] for m in members]
    if len(set(names)) != len(names):
        raise ValueError(f"member names must be distinct (extra runs included): {names}")
    per_state = [state_findings(f) for f in folders]
    per_run = [run_findings(f) for f in folders]
    labels = sorted({label for s in per_state for label in s}, key=_state_key)
    history = {v.name: v for v in HISTORY_VARIABLES}
    probes = {v.name: v for v in PROBE_VARIABLES}
    data: dict[str, xr.DataArray] = {}
    for key in (*STATE_MEASURES, "e_oed_v", "e_oed_h", "e_ratio"):
        values = np.array(
            [[s.get(label, {}).get(key, math.nan) for label in labels] for s in per_state],
            dtype=float,
        ).reshape(len(names), len(labels))
        if key in history:
            attrs = history[key].attrs()
            attrs.pop("flag_values", None)
        elif key in _PROBE_ATTRS:
            attrs = probes[_PROBE_ATTRS[key]].attrs()
        else:
            attrs = {"units": "1", "long_name": "E_oed,h / E_oed,v (linear response)"}
        data[key] = xr.DataArray(values, dims=("member", "state"), attrs=attrs)
    for name, key, long_name in RUN_SCALARS:
        values = np.array([float(r.get(key, math.nan)) for r in per_run], dtype=float)
        data[name] = xr.DataArray(
            values, dims=("member",), attrs={"units": "1", "long_name": long_name}
        )
    coords: dict[str, tuple] = {
        "member": ("member", np.array(names, dtype=object)),
        "state": ("state", np.array(labels, dtype=object)),
    }
    keys: dict[str, None] = {}
    for m in sweep["members"]:
        keys.update(dict.fromkeys(m["parameters"]))
    for key in keys:
        values = _coordinate([m["parameters"].get(key) for m in members])
        coords[parameter_name(key)] = ("member", values, {"sweep_key": key})
    ds = xr.Dataset(data, coords=coords)
    ds.attrs = {
        "title": f"DEM protocol sweep {sweep['sweep']}: findings of the finished members",
        "sweep": sweep["sweep"],
        "scene": sweep["scene"],
        "sweep_keys": ", ".join(keys),
        "members_not_finished": ", ".join(not_finished),
        "extra_runs": ", ".join(str(f) for f in extras),
        "source": "dem_taichi.sweep.results.open_sweep",
    }
    return ds


def open_relaxed_states(out_dir: str | Path) -> xr.Dataset:
    """Every relaxed path state of the finished members (``relaxed_states.nc``, the history
    schema) as one dataset along ``member`` × ``record``: record k is the k-th relaxed state of
    a member's run (gas → A increments, then the paths in the order run), padded with NaN to
    the longest run; ``stage_label`` says which path each record belongs to. The swept keys
    are coordinates along ``member``, as in :func:`open_sweep`."""
    out = Path(out_dir)
    if not (out / "sweep.json").exists():
        raise FileNotFoundError(f"{out / 'sweep.json'} does not exist: not a sweep directory")
    sweep, members, not_finished = _finished_members(out)
    if not members:
        raise ValueError(f"sweep in {out}: no finished member")
    parts = []
    for m in members:
        ds = open_history(out / "members" / m["name"] / "relaxed_states.nc")
        ds = ds.drop_indexes("time").rename_dims(time="record")
        parts.append(ds.assign_coords(record=np.arange(ds.sizes["record"])))
    combined = xr.concat(
        parts,
        dim="member",
        data_vars="all",
        coords="all",
        join="outer",
        compat="equals",
        combine_attrs="drop_conflicts",
    )
    combined = combined.assign_coords(member=[m["name"] for m in members])
    keys: dict[str, None] = {}
    for m in sweep["members"]:
        keys.update(dict.fromkeys(m["parameters"]))
    for key in keys:
        values = _coordinate([m["parameters"].get(key) for m in members])
        combined = combined.assign_coords({parameter_name(key): ("member", values)})
        combined[parameter_name(key)].attrs["sweep_key"] = key
    combined.attrs.update(
        sweep=sweep["sweep"],
        members_not_finished=", ".join(not_finished),
        title=f"DEM protocol sweep {sweep['sweep']}: relaxed path states of the finished members",
    )
    return combined


def _findings_rows(ds: xr.Dataset) -> list[tuple[str, np.ndarray]]:
    """(label, values over the members) of every finding the summary tabulates."""
    rows = []
    for key, name in (
        ("specific_volume", "v"),
        ("fabric_deviator", "fabric β_yy−β_xx"),
        ("e_ratio", "E_h/E_v"),
    ):
        for label in ds["state"].values:
            rows.append((f"{name} at {label}", ds[key].sel(state=label).values))
    for name, label in (
        ("k0_at_C", "K0 = σ_xx/σ_yy at C"),
        ("lambda_star", "λ* (A→B)"),
        ("modulus_exponent", "n: E_v ∝ p^n (A→B)"),
        ("e_oed_v_over_p_at_B", "E_v/p at B"),
        ("stress_scale_kpa_measured", "kPa per DEM unit (E_v/p = 125)"),
        ("lambda_window", "λ* (1–200 kPa)"),
        ("exponent_window_v", "n: E_v ∝ p^n (1–200 kPa)"),
        ("exponent_window_h", "n: E_h ∝ p^n (1–200 kPa)"),
        ("N_disc", "N: v at 100 kPa (disc union)"),
        ("N_rectangle", "N: v at 100 kPa (rectangle L×d)"),
        ("densification_sensitivity_v", "ln(E_v B′/B)/ln(v B′/B)"),
        ("densification_sensitivity_h", "ln(E_h B′/B)/ln(v B′/B)"),
        ("mean_stress_at_A", "p at A"),
        ("isotropic_fabric_max", "max abs fabric on A→B"),
        ("max_inertial_number", "max I on the paths"),
        ("wall_seconds", "wall time (s)"),
    ):
        rows.append((label, ds[name].values))
    return rows


def _groups(ds: xr.Dataset, over: tuple[str, ...]) -> list[tuple[str, np.ndarray]]:
    """(label, member mask) of the groups of members that differ only in the ``over`` keys."""
    keys = [
        k
        for k in ds.attrs.get("sweep_keys", "").split(", ")
        if k and k not in over and len({str(v) for v in ds[parameter_name(k)].values}) > 1
    ]  # the keys that vary among the finished members, the replica keys left out
    if not keys or ds.sizes["member"] == 0:
        return [("all members", np.ones(ds.sizes["member"], dtype=bool))]
    combos = [
        tuple(str(ds[parameter_name(k)].values[i]) for k in keys) for i in range(ds.sizes["member"])
    ]
    groups = []
    for combo in dict.fromkeys(combos):
        label = ", ".join(f"{k} = {v}" for k, v in zip(keys, combo, strict=True))
        groups.append((label, np.array([c == combo for c in combos])))
    return groups


def replica_statistics(ds: xr.Dataset, over: tuple[str, ...] = ("scene.seed",)) -> dict:
    """Per group of replicas (members differing only in ``over``), per finding: ``mean``,
    ``half`` (95 % half-width, Student t), ``n`` (finite values), ``min``, ``max``."""
    result: dict[str, dict] = {}
    for group, mask in _groups(ds, over):
        entry = {}
        for label, values in _findings_rows(ds):
            x = np.asarray(values, dtype=float)[mask]
            mean, half, n = mean_interval(x)
            finite = x[np.isfinite(x)]
            entry[label] = {
                "mean": mean,
                "half": half,
                "n": n,
                "min": float(finite.min()) if finite.size else math.nan,
                "max": float(finite.max()) if finite.size else math.nan,
            }
        result[group] = {"members": [str(m) for m in ds["member"].values[mask]], "findings": entry}
    return result


def _number(x: float) -> str:
    return "–" if not np.isfinite(x) else f"{x:.4g}"


def summary_table(ds: xr.Dataset, stats: dict) -> str:
    """Markdown: per group, every finding as mean ± 95 % interval (n) and its range."""
    lines = [
        f"# Sweep {ds.attrs.get('sweep', '')}: the study's findings over replicas",
        "",
        "Mean ± 95 % interval of the mean (Student t, n − 1 degrees of freedom) over the",
        "finished members of each group (n: members with a value); moduli from the linear",
        f"response. Scene `{ds.attrs.get('scene', '')}`.",
    ]
    if ds.attrs.get("members_not_finished"):
        lines.append(f"Not finished (left out): {ds.attrs['members_not_finished']}.")
    if ds.attrs.get("extra_runs"):
        lines.append(f"Runs from outside the sweep, pooled as replicas: {ds.attrs['extra_runs']}.")
    for group, entry in stats.items():
        lines += [
            "",
            f"## {group}: {len(entry['members'])} members ({', '.join(entry['members'])})",
            "",
            "| finding | mean ± 95 % | n | min … max |",
            "|---|---|---|---|",
        ]
        for label, s in entry["findings"].items():
            pm = _number(s["mean"]) + (f" ± {s['half']:.2g}" if np.isfinite(s["half"]) else "")
            lines.append(
                f"| {label} | {pm} | {s['n']} | {_number(s['min'])} … {_number(s['max'])} |"
            )
    return "\n".join(lines) + "\n"


def summary_figure(ds: xr.Dataset, stats: dict, path: str | Path, over=("scene.seed",)) -> Path:
    """Error bars (mean ± 95 %) per state of v, fabric and E_h/E_v, and of K0, λ*, n; each
    member a small grey dot beside them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = [str(s) for s in ds["state"].values]
    fig, axes = plt.subplots(1, 4, figsize=(15, 3.8))
    panels = (
        ("specific_volume", "v", "specific volume v"),
        ("fabric_deviator", "fabric β_yy−β_xx", "fabric β_yy − β_xx"),
        ("e_ratio", "E_h/E_v", "E_oed,h / E_oed,v"),
    )
    groups = _groups(ds, over)
    width = 0.6 / max(len(groups), 1)
    dot = 0.25 * width  # the members beside their group's error bar
    for ax, (key, name, ylabel) in zip(axes, panels, strict=False):
        x = np.arange(len(labels))
        for g, (group, mask) in enumerate(groups):
            shift = (g - (len(groups) - 1) / 2) * width
            values = ds[key].values[mask]
            ax.plot(
                np.repeat(x[None, :] + shift + dot, values.shape[0], 0),
                values,
                ".",
                color="0.5",
                ms=4,
            )
            found = stats[group]["findings"]
            mean = [found[f"{name} at {s}"]["mean"] for s in labels]
            half = [found[f"{name} at {s}"]["half"] for s in labels]
            ax.errorbar(x + shift, mean, yerr=np.nan_to_num(half), fmt="o", capsize=3, ms=4,
                        label=group)  # fmt: skip
        ax.set_xticks(np.arange(len(labels)), labels, rotation=45 if len(labels) > 5 else 0)
        ax.set_ylabel(ylabel)
        if key == "e_ratio":
            ax.axhline(1.0, color="k", lw=0.6)
    ax = axes[3]
    scalars = ("K0 = σ_xx/σ_yy at C", "λ* (A→B)", "n: E_v ∝ p^n (A→B)")
    columns = ("k0_at_C", "lambda_star", "modulus_exponent")
    x = np.arange(len(scalars))
    for g, (group, mask) in enumerate(groups):
        shift = (g - (len(groups) - 1) / 2) * width
        for i, column in enumerate(columns):
            values = ds[column].values[mask]
            ax.plot(np.full(values.shape, x[i] + shift + dot), values, ".", color="0.5", ms=4)
        found = stats[group]["findings"]
        ax.errorbar(x + shift, [found[s]["mean"] for s in scalars],
                    yerr=np.nan_to_num([found[s]["half"] for s in scalars]), fmt="s",
                    capsize=3, ms=4, label=group)  # fmt: skip
    ax.set_xticks(x, ["K0 at C", "λ*", "n"])
    ax.set_ylabel("value")
    if len(groups) > 1:
        axes[0].legend(fontsize=7)
    n = ds.sizes["member"]
    fig.suptitle(f"sweep {ds.attrs.get('sweep', '')}: mean ± 95 % over {n} members", fontsize=10)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _finite(value):
    """NaN → None, for strict JSON."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def summary_files(out_dir: str | Path, out: str | Path | None = None) -> dict[str, Path]:
    """The files :func:`summarise_sweep` writes: the table (``out``, default
    ``out_dir/replica_summary.md``), and beside it the figure (``.png``), the statistics
    (``.json``) and the combined dataset (``<stem>_members.nc``)."""
    table = Path(out) if out is not None else Path(out_dir) / "replica_summary.md"
    return {
        "table": table,
        "figure": table.with_suffix(".png"),
        "statistics": table.with_suffix(".json"),
        "dataset": table.with_name(table.stem + "_members.nc"),
    }


def _check_summary_files(files: dict[str, Path], overwrite: bool) -> None:
    """Refuse (ValueError, one line) a table path that names its companions, a folder among
    the files, and existing files (links too) unless ``overwrite``."""
    table = files["table"]
    if len(set(files.values())) < len(files):
        raise ValueError(
            f"--out {table}: the summary also writes {files['figure'].name}, "
            f"{files['statistics'].name} and {files['dataset'].name} beside it: give a markdown "
            "file (FILE.md)"
        )
    for path in files.values():
        if path.is_dir() and not path.is_symlink():
            raise ValueError(f"{path} is a folder; the summary writes a file there: choose --out")
    existing = [p for p in files.values() if p.exists() or p.is_symlink()]
    if existing and not overwrite:
        names = ", ".join(str(p) for p in existing)
        raise ValueError(
            f"{names} exist(s); add --overwrite to replace the summary's files (a link is "
            "replaced, never its target), or choose another --out"
        )


def summarise_sweep(
    out_dir: str | Path,
    over: tuple[str, ...] = ("scene.seed",),
    out: str | Path | None = None,
    extra_runs=(),
    overwrite: bool = False,
) -> dict[str, str]:
    """Write the replica table (markdown), figure (PNG), statistics (JSON) and the combined
    dataset (netCDF) of the sweep in ``out_dir``; returns their paths. ``out``: the table's
    path (default ``out_dir/replica_summary.md``; the other files take its stem,
    :func:`summary_files`). An existing file among them (or a link there) is refused
    (ValueError) unless ``overwrite``; each file is written atomically
    (:func:`clay_cli.replace_file`: a link is replaced, never written through)."""
    from clay_cli import replace_file

    folder = Path(out_dir)
    files = summary_files(folder, out)
    _check_summary_files(files, overwrite)
    ds = open_sweep(folder, extra_runs)
    if ds.sizes["member"] == 0:
        raise ValueError(f"sweep in {folder}: no finished member to summarise")
    stats = replica_statistics(ds, over)
    replace_file(files["table"], lambda t: t.write_text(summary_table(ds, stats)))
    replace_file(files["figure"], lambda t: summary_figure(ds, stats, t, over))
    text = json.dumps(_finite(stats), indent=2)
    replace_file(files["statistics"], lambda t: t.write_text(text))
    replace_file(files["dataset"], lambda t: ds.to_netcdf(t))
    return {kind: str(path) for kind, path in files.items()}
