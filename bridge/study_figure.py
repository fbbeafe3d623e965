"""The study's Figure 2 over replicas: our DEM mean ± 95 % against the study's own TIV curves.

* :func:`bridge.replica_bands.replica_bands` (re-exported here): per aligned record of the
  replicas, the mean and the half-width of the 95 % interval of the mean (Student t);
* :func:`study_curves`: the TIV model with the study's published parameters
  (:data:`tiv_model.params.TABLE1`) driven along the replica mean's stress paths (kPa) from the
  study's own state at our p_A — what the study's model says on our paths, not a fit;
* :func:`write_study_figure`: Figure 2 a–d as in the study (a: compressibility v–ln p, b: fabric
  β–p, c: E_oed,v and E_oed,h against p, d: E_h/E_v against p) with our means as markers with
  95 % error bars, the study's curves as lines, one colour per path as in
  :mod:`bridge.figures`; beside it ``figure2_replicas.md``, the table of both at the labelled
  states A, B, C, B′ and the radial ends, and ``figure2_replicas.nc``, the replica bands
  themselves (every aligned record and probe: mean and 95 % half-width, with units), which
  scripts read instead of the table (:func:`bridge.study_figure_panels.state_means`).

Command line: ``python -m bridge figure2 --replicas RUN_DIR [RUN_DIR ...] --out DIR`` (a sweep
folder's finished members are its replicas, as for ``calibrate --replicas``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from clay_cli import (
    ArgumentParser,
    UsageError,
    add_common_flags,
    int_in_range,
    replace_file,
    run_command,
)
from tiv_model.errors import TivModelError
from tiv_model.params import DEFAULT_OPTIONS, TABLE1, ModelOptions, Parameters

from .command_options import add_k0_mode_option, add_model_options
from .outputs import write_netcdf
from .predict import K0_MODES, PredictionError
from .replica_bands import path_members, replica_bands
from .runs import RUN_VARIABLES, isotropic_run, k0_run, stress_path_run, unloading_run
from .series import SERIES_VARIABLES, SeriesError
from .study_figure_panels import STUDY, figure2, figure2_markdown

__all__ = ["replica_bands", "study_curves", "figure2", "figure2_markdown", "write_study_figure"]

PROG = "python -m bridge figure2"
FIGURE = "figure2_replicas.png"
TABLE = "figure2_replicas.md"
BANDS = "figure2_replicas.nc"
_UNITS = SERIES_VARIABLES | {
    "stiffness_ratio": ("1", "E_oed,h / E_oed,v"),
    "preconsolidation_pressure": ("kPa", "preconsolidation pressure"),
    "plastic": ("1", "1 if the increment was plastic"),
}


def refined(values, substeps: int) -> np.ndarray:
    """``values`` with every interval split into ``substeps`` equal steps (the end points kept)."""
    values = np.asarray(values, dtype=float)
    steps = np.linspace(0.0, values.size - 1.0, (values.size - 1) * substeps + 1)
    return np.interp(steps, np.arange(values.size), values)


def mean_paths(bands: xr.Dataset, substeps: int = 1) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per path (:func:`bridge.replica_bands.path_members`), the replica mean's (σ_a, σ_r) in kPa
    along it, its start first, each interval split into ``substeps``."""
    members = path_members(
        bands["stage"].values, bands["state_label"].values, bands["mean_stress"].values
    )
    sa, sr = bands["axial_stress"].values, bands["radial_stress"].values
    return {
        path: (refined(sa[i], substeps), refined(sr[i], substeps)) for path, i in members.items()
    }


def model_label(parameters: Parameters) -> str:
    """The legend's name of the model's curves: the study's when ``parameters`` are Table 1."""
    return STUDY if parameters == TABLE1 else "TIV, parameters given (not Table 1)"


def _dataset(run: dict, path: str, driver: str, params: Parameters) -> xr.Dataset:
    data = {
        k: (
            "point",
            np.asarray(run[k], dtype=float),
            {"units": _UNITS[k][0], "long_name": "TIV " + _UNITS[k][1]},
        )
        for k in RUN_VARIABLES
    }
    symbols = ", ".join(f"{k} = {v:g}" for k, v in params.as_symbols().items())
    attrs = {"path": path, "driver": driver, "model": model_label(params), "parameters": symbols}
    return xr.Dataset(data, attrs=attrs)


def _curves(paths, params, options, k0_mode) -> dict[str, xr.Dataset]:
    out: dict[str, xr.Dataset] = {}
    if "isotropic" in paths:
        sa, sr = paths["isotropic"]
        p = (sa + 2.0 * sr) / 3.0
        out["isotropic"] = _dataset(
            isotropic_run(p, params, options, p.size - 1),
            "isotropic",
            "isotropic stress control through our p",
            params,
        )
    if "k0" in paths and k0_mode == "stress":  # A→C→B′ in one run: B′ starts at its own C
        (sa, sr), n = paths["k0"], paths["k0"][0].size
        if "unloading" in paths:
            sa = np.concatenate([sa, paths["unloading"][0][1:]])
            sr = np.concatenate([sr, paths["unloading"][1][1:]])
        run = stress_path_run(sa, sr, params, options, None, sa.size - 1)
        what = "stress control along our (sigma_a, sigma_r)"
        out["k0"] = _dataset({k: v[:n] for k, v in run.items()}, "k0", what, params)
        if "unloading" in paths:
            unloading = {k: v[n - 1 :] for k, v in run.items()}
            out["unloading"] = _dataset(unloading, "unloading", what, params)
    elif "k0" in paths:
        sa, sr = paths["k0"]
        run, state_c = k0_run(
            sa, (sa[0] + 2.0 * sr[0]) / 3.0, params, options, sa.size - 1, return_state=True
        )
        out["k0"] = _dataset(run, "k0", "K0 (radial strain 0) through our sigma_a", params)
        if "unloading" in paths:
            sa, sr = paths["unloading"]
            run = unloading_run(
                (sa + 2.0 * sr) / 3.0, sa - sr, state_c, params, options, sa.size - 1
            )
            what = "from the model's C along our (p, q) scaled onto it"
            out["unloading"] = _dataset(run, "unloading", what, params)
    for path in (p for p in paths if p.startswith("radial_")):
        sa, sr = paths[path]
        run = stress_path_run(sa, sr, params, options, None, sa.size - 1)
        out[path] = _dataset(run, path, "stress control along our (sigma_a, sigma_r)", params)
    return out


def study_curves(
    bands: xr.Dataset,
    parameters: Parameters = TABLE1,
    options: ModelOptions = DEFAULT_OPTIONS,
    k0_mode: str = "element",
    substeps: int = 4,
) -> dict[str, xr.Dataset]:
    """The study's TIV model (``parameters``, default Table 1) along the replica mean's paths.

    Start: at our p_A (the replica mean's p of state A, kPa) the model's own normally
    consolidated isotropic state (:func:`bridge.runs.start_state` →
    :func:`tiv_model.integrate.initial_state`): isotropic fabric, p_c on the yield surface at
    p_A, and v = N (p_c/p_r)^(−λ*) from Table 1's N = 1.3 and λ* = 0.25 — the study's own v,
    not ours (Table 1 has no κ*: the elastic law is k, g, n, r; v < 1 above p_c ≈ 286 kPa,
    which the model refuses). Paths, each interval of our mean split into ``substeps``:

    * isotropic A→B: σ_a = σ_r = our p (:func:`bridge.runs.isotropic_run`);
    * ``k0_mode="element"`` (default): K0 with ε_r = 0 through our σ_a (its K0 ratio is the
      model's), then unloading from its C along our (p, q) scaled onto it
      (:func:`bridge.runs.unloading_run`); ``"stress"``: K0 A→C and unloading C→B′ follow our
      mean (σ_a, σ_r) in one run (:func:`bridge.runs.stress_path_run`), so B′ starts at the
      model's own C. The default is the element test because our K0 paths can start above the
      model's M: on the 8-disc loose clay at 1520 rods (2026-12-02) the stress mode fails near A
      (η ≈ 1.04 at p ≈ 1.8 kPa, Table 1's M = 1.1 with its fabric).
    * each radial path ``radial_k``: from A along our mean (σ_a, σ_r).

    Returns path → dataset along ``point`` (our points, refined) of
    :data:`bridge.runs.RUN_VARIABLES` (kPa, 1). A model failure is a
    :class:`bridge.predict.PredictionError` naming the reason.
    """
    if k0_mode not in K0_MODES:
        raise ValueError(f"k0_mode = {k0_mode!r}: use one of {K0_MODES}")
    paths = mean_paths(bands, substeps)
    if not paths:
        raise SeriesError(
            "the replicas have no loading path after state A (stages: "
            f"{sorted(set(bands['stage'].values.astype(str)))}): nothing to drive the model along"
        )
    try:
        return _curves(paths, parameters, options, k0_mode)
    except TivModelError as error:
        sa, sr = next(iter(paths.values()))
        hint = (
            "; our K0 stresses may exceed what the model carries (stress ratio near M): try "
            "k0_mode element (--k0-mode element)"
            if k0_mode == "stress"
            else ""
        )
        raise PredictionError(
            f"the study's model cannot run along our paths from p_A = "
            f"{(sa[0] + 2.0 * sr[0]) / 3.0:.4g} kPa: {error}{hint}"
        ) from error


def write_study_figure(
    runs,
    out_dir,
    parameters: Parameters = TABLE1,
    options: ModelOptions = DEFAULT_OPTIONS,
    k0_mode: str = "element",
    substeps: int = 4,
    **band_options,
) -> Path:
    """Write ``figure2_replicas.png``, ``figure2_replicas.md`` and ``figure2_replicas.nc`` (the
    bands) into ``out_dir`` (made if needed; each file replaced atomically, never written
    through a link); returns the figure's path. ``band_options`` (``stress_scale_kpa``,
    ``convention``, ``fabric_scale``, ``probe_method``) go to :func:`replica_bands`, the rest
    to :func:`study_curves`."""
    bands = replica_bands(runs, **band_options)
    curves = study_curves(bands, parameters, options, k0_mode, substeps)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    label = model_label(parameters)
    fig = figure2(bands, curves, label)
    try:
        path = replace_file(out / FIGURE, lambda tmp: fig.savefig(tmp, dpi=130))
    finally:
        plt.close(fig)
    text = figure2_markdown(bands, curves, k0_mode, label)
    replace_file(out / TABLE, lambda tmp: tmp.write_text(text, encoding="utf-8"))
    write_netcdf(bands, out / BANDS)
    return path


def _parser(prog: str = PROG) -> argparse.ArgumentParser:
    parser = ArgumentParser(
        prog=prog,
        description="The study's Figure 2 over replicas: DEM mean "
        "± 95 % against the TIV model with Table 1 (bridge.study_figure).",
    )
    parser.add_argument(
        "--replicas",
        nargs="+",
        required=True,
        metavar="RUN_DIR",
        help="protocol run folders of one scene, or a sweep folder whose finished "
        "members are the replicas (at least two runs)",
    )
    parser.add_argument("--out", required=True, help="output folder (made if needed)")
    add_model_options(
        parser,
        {
            "--stress-scale": "kPa per DEM stress unit for every run (default: each run's own "
            "attribute stress_scale_kpa)",
            "--convention": "2D → 3D stress convention (default triaxial)",
            "--fabric-scale": "F of β_model = −F (β_yy − β_xx) (default 1)",
            "--probe-method": "which DEM moduli (default linear)",
            "--anisotropy": "the model's form of the anisotropic strain (default A)",
            "--no-constraint-forces": "the model without constraint forces (default: with them)",
        },
    )
    add_k0_mode_option(
        parser,
        "the model's K0 and unloading: K0 with radial strain 0 through our sigma_a "
        "(default element) or along our stresses (stress)",
    )
    parser.add_argument(
        "--substeps",
        type=int_in_range(1, 100),
        default=4,
        help="model increments per interval of our records (default 4)",
    )
    add_common_flags(parser)
    return parser


def _run(argv: list[str], prog: str = PROG) -> int:
    args = _parser(prog).parse_args(argv)
    out = Path(args.out)
    if not args.out.strip() or ((out.exists() or out.is_symlink()) and not out.is_dir()):
        raise UsageError(f"--out {args.out!r}: give a folder for the figure and its table")
    options = ModelOptions(
        anisotropy=args.anisotropy, constraint_forces=not args.no_constraint_forces
    )
    path = write_study_figure(
        args.replicas,
        out,
        TABLE1,
        options,
        args.k0_mode,
        args.substeps,
        stress_scale_kpa=args.stress_scale,
        convention=args.convention,
        fabric_scale=args.fabric_scale,
        probe_method=args.probe_method,
    )
    if not args.quiet:
        print((out / TABLE).read_text(encoding="utf-8"))
        print(f"figure: {path}")
    return 0


def main(argv: list[str] | None = None, prog: str = PROG) -> int:
    """``python -m bridge figure2``; returns the exit code (:mod:`clay_cli`: bad input, e.g.
    fewer than two replicas or misaligned ones, is one line with exit code 2; a model that
    cannot run along the paths, :class:`bridge.predict.PredictionError`, one line, exit 1;
    ``--debug`` shows the traceback)."""
    return run_command(prog, lambda args: _run(args, prog), argv, failures={PredictionError: 1})


if __name__ == "__main__":
    sys.exit(main())
