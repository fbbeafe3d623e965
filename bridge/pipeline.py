"""DEM results → calibration → predictions → figures → report, in one call or one command.

``calibrate_from_results(history_path, probes_path, out_dir, options)`` is what the demo runs;
``python -m bridge.pipeline --history H.nc --probes P.nc --out DIR`` does the same from a shell
(``--synthetic`` makes DEM-like results with the TIV model itself, Table 1 perturbed, and
calibrates on them: a check that needs no DEM run).

History file: the series need relaxed path states. The protocol writes them to
``relaxed_states.nc`` beside ``history.nc`` (which also holds every loading record); when
``history_path`` is a ``history.nc`` with a ``relaxed_states.nc`` beside it, the latter is used
(``PipelineOptions.prefer_relaxed_states``, stated in the report).

Stress scale: ``PipelineOptions.stress_scale_kpa``; when None it is read from the history's
global attribute ``stress_scale_kpa`` (written by the DEM protocol), and the report says so; a
file without it and no option fails, unless every stress and modulus read has a pressure unit
(then no scale is needed: :mod:`bridge.units`).

Outputs in ``out_dir``: ``calibration.json`` (parameters, standard errors, stages, fit quality,
what was fitted), ``calibration.txt`` (text report), ``prediction_<path>.nc`` (model runs) and
``prediction_probes_<path>.nc`` (elastic law at the measured probe states), the figures
``bridge_*.png``, ``report.md`` and ``calibration_files.json``, the list of every file the
calibration wrote (:mod:`bridge.outputs`): an earlier calibration's files that are not written
again (a ``prediction_radial_2.nc`` when there is one radial path now) are deleted, and nothing
else. The command line refuses an ``--out`` holding an earlier calibration unless
``--overwrite``, a DEM run folder as ``--out``, and a symbolic link where it writes (one line,
exit code 2); a full disk is exit code 4 (:mod:`clay_cli`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path

import xarray as xr

from clay_cli import (
    ArgumentParser,
    UsageError,
    add_common_flags,
    int_in_range,
    positive_float,
    run_command,
)
from tiv_model.params import BOUND_LAWS, SYMBOLS, TABLE1, ModelOptions

from .calibration import (
    STAGES,
    CalibrationError,
    CalibrationOptions,
    ModelFailureError,
    calibrate,
)
from .calibration.identifiability import identifiability
from .command_options import add_k0_mode_option, add_model_options
from .figures import PANELS, write_figures
from .outputs import (
    MANIFEST,
    Outputs,
    check_out,
    files_now,
    read_manifest,
    refuse_links,
    write_netcdf,
)
from .pipeline_options import PipelineOptions, pipeline_options, stress_scale_of
from .pipeline_result import PipelineResult
from .predict import predict_paths, predict_probes, summary
from .replicas import calibrate_replicas
from .report import report_markdown, write_report
from .series import (
    PATHS,
    Convention,
    SeriesError,
    all_probe_series,
    history_series,
    radial_series,
)

PROG = "python -m bridge.pipeline"


def _open(path: Path, kind: str) -> xr.Dataset:
    from dem_taichi.io import open_history, open_probes

    return open_history(path) if kind == "history" else open_probes(path)


def _relative_inside(path, out: Path) -> str | None:
    """``path`` relative to ``out`` (``/``-separated) when it lies inside it, else None."""
    if path is None:
        return None
    try:
        return Path(path).resolve().relative_to(out.resolve()).as_posix()
    except ValueError:
        return None


def calibrate_from_results(
    history_path,
    probes_path,
    out_dir,
    options: PipelineOptions | Mapping | None = None,
    outputs: Outputs | None = None,
) -> PipelineResult:
    """Calibrate on DEM results, predict, draw and report (see the module docstring).

    ``options``: :class:`PipelineOptions`, a mapping of its fields (:func:`pipeline_options`)
    or None (defaults). ``probes_path`` may be None: then the elastic stage is skipped (k, g, n,
    r, ω stay at their starting values, as the report says). Returns a
    :class:`~bridge.pipeline_result.PipelineResult`: ``parameters``, ``standard_errors``,
    ``fitted``, ``out_of_sample``, ``predictions`` (rows of :func:`bridge.predict.summary`),
    ``files`` (paths), ``report``, ``seconds``, the ``calibration`` and ``identifiability``
    objects; ``to_dict()`` is the JSON-able dict of 0.1.0, whose keys the result also reads as
    a mapping (``outcome["parameters"]``).

    ``outputs``: the :class:`bridge.outputs.Outputs` of a command that lists and replaces the
    folder's files itself (the command line); None: this call lists what it writes in
    ``calibration_files.json`` and deletes the earlier calibration's files it did not write
    again (never its input files). A symbolic link where it writes is refused.
    """
    t0 = time.perf_counter()
    options = pipeline_options(options)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    refuse_links(out)
    own = outputs is None
    earlier = set(read_manifest(out) or []) if own else set()
    outputs = Outputs(out) if outputs is None else outputs
    history_file = Path(history_path)
    used_history = history_file
    sibling = history_file.with_name("relaxed_states.nc")
    if options.prefer_relaxed_states and history_file.name == "history.nc" and sibling.exists():
        used_history = sibling
    history = _open(used_history, "history")
    probes_data = None if probes_path is None else _open(Path(probes_path), "probes")
    scale, scale_note = stress_scale_of(options, history, used_history, probes_data)
    convention = Convention(scale, options.convention, options.fabric_scale)
    available, reasons = [], {}
    for path in PATHS:
        try:
            history_series(history, convention, (path,))
            available.append(path)
        except SeriesError as error:
            reasons[path] = str(error)
    if not available:  # say why no path could be read instead of "given: []"
        by_reason: dict[str, list[str]] = {}
        for path, reason in reasons.items():
            by_reason.setdefault(reason, []).append(path)
        raise SeriesError(
            f"no loading path could be read from {used_history}: "
            + "; ".join(f"{', '.join(paths)}: {reason}" for reason, paths in by_reason.items())
        )
    series = history_series(history, convention, tuple(available))
    series.update(radial_series(history, convention))  # radial_1, radial_2… (none: {})
    stages = tuple(options.stages)
    probes: dict[str, xr.Dataset] = {}
    if probes_data is not None:
        probes = all_probe_series(probes_data, convention, options.probe_method)
    elif "elastic" in stages:
        stages = tuple(s for s in stages if s != "elastic")
    # the fabric stage (model runs along K0 and the radial paths) can fail where the model
    # reaches a limit point at every parameter set the fit tries; the cheap stages need it not,
    # so they are kept, and the fabric parameters keep their starting values (a set-up error of
    # the stage, e.g. an empty search range, is a CalibrationError and still raises). Fitted
    # after the cheap stages (the default), calibrate keeps them itself; coupled to them
    # (omega_stage = "fabric"), they are fitted again without it.
    try:
        result = calibrate(series, probes, options.calibration, stages, keep_cheap_stages=True)
    except ModelFailureError as error:
        if error.stage != "fabric":
            raise
        stages = tuple(s for s in stages if s != "fabric")
        result = calibrate(series, probes, options.calibration, stages)
        result.not_fitted["fabric"] = str(error)
    stage_failures = dict(result.not_fitted)
    stages = tuple(s for s in stages if s not in stage_failures)
    seconds_calibration = time.perf_counter() - t0
    ide = identifiability(result, series, probes) if options.identifiability else None
    model_options = options.calibration.model_options
    failures: dict[str, str] = {}  # a path the calibrated model cannot follow loses no other
    runs = predict_paths(
        result,
        series,
        model_options,
        options.k0_mode,
        options.max_increments,
        options.calibration.initial_fabric,
        failures,
    )
    model_probes = predict_probes(result, probes, model_options) if probes else {}
    files: dict[str, str] = {}
    for path, ds in runs.items():
        target = write_netcdf(ds, outputs.path(f"prediction_{path}.nc"))
        files[f"prediction_{path}"] = str(target)
    for path, ds in model_probes.items():
        target = write_netcdf(ds, outputs.path(f"prediction_probes_{path}.nc"))
        files[f"prediction_probes_{path}"] = str(target)
    figures = {}
    if options.figures:
        for name in (*PANELS, "overview"):
            outputs.path(f"bridge_{name}.png")
        figures = write_figures(series, probes, runs, model_probes, out)
        files.update({f"figure_{k}": str(v) for k, v in figures.items()})
    description = {
        "history": f"{used_history}"
        + (" (relaxed states beside the given history)" if used_history != history_file else ""),
        "probes": f"{probes_path} ({options.probe_method} moduli)" if probes_path else "none",
        "paths": ", ".join(f"{p} ({series[p].sizes['point']} points)" for p in series),
        "probe paths": ", ".join(f"{p} ({ds.sizes['point']})" for p, ds in probes.items()) or "—",
        "stress scale": f"{scale:g} kPa per DEM stress unit ({scale_note})",
        "convention": f"{convention.attrs()['convention_stress']} [{convention.name}]",
        "fabric": f"{convention.attrs()['convention_fabric']}, F = {convention.fabric_scale:g}",
        "moduli": convention.attrs()["convention_moduli"],
        "stages": ", ".join(stages),
        "model fabric at A": options.calibration.initial_fabric,
    }
    if stage_failures:
        description["stages not fitted"] = "; ".join(
            f"{s}: {r} (its parameters keep their starting values)"
            for s, r in stage_failures.items()
        )
    if failures:
        description["predictions not run"] = "; ".join(f"{p}: {r}" for p, r in failures.items())
    text = report_markdown(result, runs, model_probes, probes, description, figures, out, ide)
    files["report"] = str(write_report(outputs.path("report.md"), text))
    extra = "" if ide is None else "\n[[What the data determine]]\n" + ide.statement() + "\n"
    outputs.path("calibration.txt").write_text(result.report() + "\n" + extra)
    files["calibration_text"] = str(out / "calibration.txt")
    rows = summary(runs) + summary({f"{p} (probes)": ds for p, ds in model_probes.items()})
    seconds = time.perf_counter() - t0
    data = {k: str(v) for k, v in description.items()}
    calibration = result.to_dict() | {"data": data, "predictions": rows}
    if ide is not None:
        calibration["identifiability"] = ide.to_dict()
    outputs.path("calibration.json").write_text(json.dumps(calibration, indent=2, default=str))
    files["calibration"] = str(out / "calibration.json")
    if own:
        inputs = {
            inside
            for p in (used_history, probes_path)
            if (inside := _relative_inside(p, out)) is not None
        }
        outputs.remove_earlier(keep=inputs)
        files["manifest"] = str(outputs.save(keep=inputs & earlier))
    return PipelineResult(
        parameters=result.params_.as_symbols(),
        standard_errors={
            k: (v if math.isfinite(v) else None) for k, v in result.standard_errors_.items()
        },
        fitted=tuple((path, series) for path, series in result.fitted_),
        out_of_sample=tuple(
            sorted({f"{r['path']}:{r['variable']}" for r in rows if r["role"] == "out_of_sample"})
        ),
        predictions=tuple(rows),
        data=data,
        files={key: Path(value) for key, value in files.items()},
        seconds=seconds,
        seconds_calibration=seconds_calibration,
        calibration=result,
        identifiability=ide,
    )


def calibrate_on_replicas(folders, out_dir, options=None, say=print) -> dict:
    """Calibrate on replica runs (:mod:`bridge.replicas`): on their record-by-record mean with
    ``options`` (as for :func:`calibrate_from_results`), then on each replica alone (without
    figures and profile likelihoods); returns what ``out_dir/replicas.json`` holds."""
    opts = pipeline_options(options)
    quick = replace(opts, figures=False, identifiability=False)
    return calibrate_replicas(folders, out_dir, calibrate_from_results, opts, quick, say)


def synthetic_inputs(
    out_dir,
    increments: int = 8,
    seed: int = 0,
    noise: float = 0.0,
    outputs: Outputs | None = None,
):
    """Write synthetic DEM-like ``relaxed_states.nc`` and ``probes.nc`` (Table 1 perturbed:
    g 40, k 70, n 0.2, r 0.5, N 1.35, λ* 0.22, M 1.0, c 1.5, s 10, z 6, ω 20) into
    ``out_dir`` (listed in ``outputs`` when given); returns (history path, probes path, the
    true Parameters)."""
    from .synthetic import synthetic_results

    truth = TABLE1.replace(
        g=40.0,
        k=70.0,
        n=0.2,
        r=0.5,
        N=1.35,
        lambda_star=0.22,
        M=1.0,
        c=1.5,
        s=10.0,
        z=6.0,
        omega=20.0,
    )
    noise_map = {"stress": noise, "specific_volume": noise, "fabric": noise, "moduli": noise}
    syn = synthetic_results(
        truth,
        convention=Convention(1.0),
        increments=increments,
        noise=noise_map if noise > 0 else None,
        seed=seed,
    )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    outputs = Outputs(out) if outputs is None else outputs
    history = outputs.path("synthetic_relaxed_states.nc")
    probes = outputs.path("synthetic_probes.nc")
    write_netcdf(syn.history, history)
    write_netcdf(syn.probes, probes)
    return history, probes, truth


def _parser(prog: str = PROG) -> argparse.ArgumentParser:
    from bridge import __version__

    parser = ArgumentParser(
        prog=prog,
        description="Calibrate the TIV model on DEM results, predict, draw and report.",
    )
    parser.add_argument("--version", action="version", version=f"bridge {__version__}")
    parser.add_argument("--history", help="DEM history or relaxed_states.nc")
    parser.add_argument(
        "--replicas",
        nargs="+",
        metavar="RUN_DIR",
        help="calibrate on the mean of replica protocol runs (folders, or a sweep folder whose "
        "finished members are the replicas) and on each one: the spread in the parameters "
        "(bridge.replicas); instead of --history/--probes",
    )
    parser.add_argument("--probes", help="DEM probes.nc (optional: no elastic stage without it)")
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the earlier calibration in --out: delete the files its "
        "calibration_files.json lists, nothing else (default: such an --out is refused)",
    )
    parser.add_argument(
        "--synthetic",
        action="store_true",
        help="calibrate on synthetic DEM-like results made by the TIV model",
    )
    parser.add_argument(
        "--noise",
        type=_non_negative,
        default=0.0,
        help="noise SD of --synthetic data: relative, absolute for the fabric (default 0)",
    )
    add_model_options(
        parser,
        {
            "--stress-scale": "kPa per DEM stress unit (default: the history's attribute)",
            "--convention": "2D → 3D stress convention (bridge.series.Convention; default "
            "triaxial)",
            "--fabric-scale": "F of the convention: β_model = −F (β_yy − β_xx) (default 1)",
            "--probe-method": "which DEM moduli the elastic stage fits (default linear: the "
            "linear response)",
            "--anisotropy": "form of the anisotropic strain ε̃ in the free energy (ModelOptions, "
            "docs/science/tiv-model.md §2; default A)",
            "--no-constraint-forces": "set the constraint forces Λ_K to 0 (ModelOptions; "
            "default: the exact theory, with them)",
        },
    )
    parser.add_argument(
        "--bound-law",
        default="exponential",
        choices=tuple(BOUND_LAWS),
        help="law f(η) of the bounding fabric β_b = f(η) s/p (ModelOptions; default exponential)",
    )
    parser.add_argument(
        "--reference-pressure",
        type=positive_float,
        default=100.0,
        help="p_r of the elastic law in kPa (default 100)",
    )
    parser.add_argument("--fix", nargs="*", default=[], help="symbols held at Table 1 values")
    parser.add_argument("--fix-M", action="store_true", help="do not fit M (Table 1 value)")
    parser.add_argument(
        "--omega-stage",
        default="elastic",
        choices=("elastic", "fabric"),
        help="the calibration stage that fits ω (default elastic)",
    )
    parser.add_argument(
        "--initial-fabric",
        default="zero",
        choices=("zero", "measured"),
        help="model fabric at A: isotropic (zero) or the DEM's",
    )
    parser.add_argument(
        "--fabric-series",
        nargs="+",
        default=["fabric", "stress_ratio"],
        help="series the fabric stage fits (default: fabric stress_ratio)",
    )
    parser.add_argument(
        "--passes",
        type=int_in_range(1, 1000),
        default=12,
        help="most cycles of coupled stages (default 12)",
    )
    parser.add_argument(
        "--max-k0-increments",
        type=int_in_range(1, 10_000),
        default=12,
        help="most model increments per K0 fit run (12)",
    )
    add_k0_mode_option(
        parser,
        "K0 predictions by the K0 element test or driven by the DEM's stresses (default element)",
    )
    parser.add_argument("--no-figures", action="store_true", help="no figures (default: drawn)")
    parser.add_argument(
        "--no-identifiability", action="store_true", help="skip the profile likelihoods"
    )
    parser.add_argument(
        "--stages",
        nargs="+",
        default=list(STAGES),
        choices=STAGES,
        help=f"calibration stages to run (default: all, {' '.join(STAGES)})",
    )
    add_common_flags(parser)
    return parser


def _non_negative(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0.0 <= value < math.inf:
        raise argparse.ArgumentTypeError(f"{text} is not allowed: give a finite number >= 0")
    return value


def _check_files(args: argparse.Namespace) -> None:
    """The input files exist and are files; --out is not a file; --fix names known symbols."""
    for option, name in (("--history", args.history), ("--probes", args.probes)):
        if name is None:
            continue
        path = Path(name)
        if not path.exists():
            raise UsageError(f"{option} {path}: no such file; give a DEM history or probes file")
        if not path.is_file():
            raise UsageError(f"{option} {path} is a folder: give the netCDF file inside it")
    if Path(args.out).exists() and not Path(args.out).is_dir():
        raise UsageError(f"--out {args.out} is a file: give a folder for the results")
    unknown = sorted(set(args.fix) - set(SYMBOLS.values()))
    if unknown:
        raise UsageError(
            f"--fix {' '.join(unknown)}: unknown symbol(s); allowed: {', '.join(SYMBOLS.values())}"
        )


def _run(argv: list[str], prog: str = PROG) -> int:
    parser = _parser(prog)
    args = parser.parse_args(argv)
    out = check_out(args.out, args.overwrite)
    outputs = Outputs(out)
    if args.overwrite:
        outputs.remove_earlier()
    before = files_now(out)
    try:
        return _calibrate(parser, args, outputs)
    finally:
        if out.is_dir():  # what was written, also by a run that failed half-way
            outputs.add_written_since(before)
            if outputs.written or (out / MANIFEST).exists():
                outputs.save()


def _calibrate(parser: argparse.ArgumentParser, args: argparse.Namespace, outputs) -> int:
    """The command's work once ``--out`` is checked; every file written is in ``outputs``."""
    stress_scale = args.stress_scale
    if args.replicas and (args.history or args.probes or args.synthetic):
        raise UsageError(
            "--replicas reads each run's relaxed_states.nc and probes.nc: leave out --history, "
            "--probes and --synthetic"
        )
    if args.replicas:
        _check_files(args)
    elif args.synthetic:
        if args.history or args.probes:
            raise UsageError("--synthetic makes its own inputs: leave out --history and --probes")
        _check_files(args)
        history, probes, truth = synthetic_inputs(args.out, noise=args.noise, outputs=outputs)
    else:
        if not args.history:
            parser.error("--history is required (or --synthetic, or --replicas)")
        _check_files(args)
        history, probes, truth = args.history, args.probes, None
    model_options = ModelOptions(
        anisotropy=args.anisotropy,
        constraint_forces=not args.no_constraint_forces,
        bound_law=BOUND_LAWS[args.bound_law],
    )
    calibration = CalibrationOptions(
        reference_pressure=args.reference_pressure,
        model_options=model_options,
        fixed=tuple(args.fix),
        fit_critical_stress_ratio=not args.fix_M,
        omega_stage=args.omega_stage,
        initial_fabric=args.initial_fabric,
        fabric_series=tuple(args.fabric_series),
        passes=args.passes,
        max_k0_increments=args.max_k0_increments,
    )
    options = PipelineOptions(
        stress_scale_kpa=stress_scale,
        convention=args.convention,
        fabric_scale=args.fabric_scale,
        probe_method=args.probe_method,
        calibration=calibration,
        k0_mode=args.k0_mode,
        figures=not args.no_figures,
        stages=tuple(args.stages),
        identifiability=not args.no_identifiability,
    )
    if args.replicas:
        calibrate_on_replicas(args.replicas, args.out, options, say=_quiet_say(args.quiet))
        if not args.quiet:
            print((Path(args.out) / "replicas.md").read_text())
        return 0
    outcome = calibrate_from_results(history, probes, args.out, options, outputs=outputs)
    if args.quiet:
        return 0
    print(outcome.files["calibration_text"].read_text())
    if truth is not None:
        print("synthetic truth vs calibrated:")
        for sym, value in truth.as_symbols().items():
            print(f"    {sym:<12} {value:<10.5g} {outcome.parameters[sym]:.6g}")
    print(f"report: {outcome.report} ({outcome.seconds:.1f} s)")
    return 0


def _quiet_say(quiet: bool):
    return (lambda *_: None) if quiet else print


def main(argv: list[str] | None = None, prog: str = PROG) -> int:
    """``python -m bridge.pipeline`` (also ``python -m bridge calibrate``); returns the exit code
    (one error handler, :mod:`clay_cli`: bad input, an ``--out`` holding an
    earlier calibration without ``--overwrite`` included, is one line with exit code 2; a
    calibration that cannot run, :class:`CalibrationError`, exit code 1; a full disk
    (ENOSPC/EDQUOT), exit code 4; ``--debug`` shows the traceback)."""
    return run_command(prog, lambda args: _run(args, prog), argv, failures={CalibrationError: 1})


if __name__ == "__main__":
    sys.exit(main())
