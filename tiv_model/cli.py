"""Command line: run the TIV element tests without writing Python; results in netCDF.

Examples::

    python -m tiv_model isotropic --p-max 300 --out iso.nc
    python -m tiv_model k0 --sigma-v-max 300 --out k0.nc
    python -m tiv_model unload --sigma-v-max 250 --out unload.nc   # K0, then constant-p to q = 0
    python -m tiv_model radial --eta 0.5 --p-max 200 --out radial.nc
    python -m tiv_model probe --p 100                              # elastic moduli, NC state

Common options: ``--p0`` (kPa, start of the path, normally consolidated, isotropic fabric),
``--anisotropy A|B``, ``--no-constraint-forces``, ``--bound-law exponential|tanh``,
``--increments``, ``--param SYMBOL=VALUE`` (override Table 1, repeatable), ``--quiet``,
``--debug`` (:mod:`clay_cli`).

Checked before anything runs: the paths load, so ``--p-max`` and ``--sigma-v-max`` must exceed
``--p0`` (an unloading path is ``unload``); ``|--eta| < M`` (the critical stress ratio; paths
with η close to M may still stop early, as the fabric turns the yield surface); increments from
1 to :data:`MAX_INCREMENTS` (longer paths: call :mod:`tiv_model.drivers` from Python); the
output file's folder exists or can be made, ``--out`` is not a folder, and ``--out`` does not
exist unless ``--overwrite`` (then the file is replaced atomically: written beside it and
renamed, so a link at ``--out`` is replaced, never written through).

Exit codes: 0 done; 1 the path stopped early on a model error (the file holds what was done);
2 bad input (one line: what is wrong, what is allowed, what to do); 4 disk full (ENOSPC or
EDQUOT, one line; nothing half-written is left at ``--out``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from clay_cli import (
    ArgumentParser,
    UsageError,
    add_common_flags,
    int_in_range,
    positive_float,
    replace_file,
    run_command,
)

from . import __version__, drivers
from .errors import ParameterError, TivModelError
from .integrate import initial_state
from .params import BOUND_LAWS, SYMBOLS, TABLE1, ModelOptions, Parameters

PROG = "tiv-model"
#: Most increments of one path from the command line (~0.8 ms and ~3 kB each: ~1.5 min, 0.3 GB).
MAX_INCREMENTS = 100_000
_INCREMENTS_NOTE = (
    " (each ~0.8 ms and ~3 kB: 100,000 take ~1.5 min and 0.3 GB; for longer paths call "
    "tiv_model.drivers from Python)"
)


def _parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(
        prog=PROG,
        description="Hyperplastic anisotropic clay model (TIV): element tests to netCDF.",
    )
    parser.add_argument("--version", action="version", version=f"tiv_model {__version__}")
    add_common_flags(parser)
    sub = parser.add_subparsers(dest="command", required=True)
    increments = int_in_range(1, MAX_INCREMENTS, _INCREMENTS_NOTE)

    def common(p: argparse.ArgumentParser, out: bool = True) -> None:
        p.add_argument(
            "--p0", type=positive_float, default=5.0, help="initial mean stress, kPa (default 5)"
        )
        p.add_argument(
            "--anisotropy", choices=["A", "B"], default="A", help="form of the fabric map (A)"
        )
        p.add_argument(
            "--no-constraint-forces", action="store_true", help="yield without constraint forces"
        )
        p.add_argument(
            "--bound-law",
            choices=sorted(BOUND_LAWS),
            default="exponential",
            help="bounding-fabric law (exponential)",
        )
        p.add_argument(
            "--param",
            action="append",
            default=[],
            metavar="SYMBOL=VALUE",
            help=f"override a Table 1 parameter; symbols: {', '.join(SYMBOLS.values())}",
        )
        add_common_flags(p, sub=True)
        if out:
            p.add_argument(
                "--increments",
                type=increments,
                default=100,
                help=f"stress increments of the path, 1 to {MAX_INCREMENTS:,} (default 100)",
            )
            p.add_argument("--out", type=Path, required=True, help="netCDF file to write")
            p.add_argument(
                "--overwrite",
                action="store_true",
                help="replace --out if it exists (default: an existing --out is refused)",
            )

    p = sub.add_parser("isotropic", help="isotropic compression to --p-max")
    p.add_argument("--p-max", type=positive_float, required=True, help="final mean stress, kPa")
    common(p)
    p = sub.add_parser("k0", help="oedometric loading to --sigma-v-max")
    p.add_argument(
        "--sigma-v-max", type=positive_float, required=True, help="final axial stress, kPa"
    )
    common(p)
    p = sub.add_parser("unload", help="K0 loading to --sigma-v-max, then constant-p unloading")
    p.add_argument(
        "--sigma-v-max", type=positive_float, required=True, help="axial stress of the K0 end"
    )
    p.add_argument(
        "--q-final", type=float, default=0.0, help="final q of the unloading, kPa (default 0)"
    )
    p.add_argument(
        "--unload-increments",
        type=increments,
        default=50,
        help=f"increments of the unloading, 1 to {MAX_INCREMENTS:,} (default 50)",
    )
    common(p)
    p = sub.add_parser("radial", help="radial path at constant stress ratio --eta")
    p.add_argument("--eta", type=float, required=True, help="stress ratio q/p, |eta| < M")
    p.add_argument("--p-max", type=positive_float, required=True, help="final mean stress, kPa")
    common(p)
    p = sub.add_parser("probe", help="print the elastic moduli of a normally consolidated state")
    p.add_argument("--p", type=positive_float, required=True, help="mean stress, kPa")
    common(p, out=False)
    return parser


def _parameters(overrides: list[str]) -> Parameters:
    changes = {}
    for item in overrides:
        key, sep, value = item.partition("=")
        if not sep:
            raise ParameterError(f"--param {item!r}: expected SYMBOL=VALUE")
        if key.strip() not in SYMBOLS.values():
            raise ParameterError(
                f"--param {item!r}: unknown symbol {key.strip()!r}; allowed: "
                + ", ".join(SYMBOLS.values())
            )
        try:
            changes[key.strip()] = float(value)
        except ValueError:
            raise ParameterError(f"--param {item!r}: value {value!r} is not a number") from None
    return TABLE1.replace(**changes) if changes else TABLE1


def _check_path(args: argparse.Namespace, params: Parameters) -> None:
    """Up-front checks of what would otherwise fail late or be silently reinterpreted."""
    end = {"isotropic": "p_max", "radial": "p_max", "k0": "sigma_v_max", "unload": "sigma_v_max"}
    name = end.get(args.command)
    if name is not None and getattr(args, name) <= args.p0:
        option = "--" + name.replace("_", "-")
        what = (
            "unload first loads K0 from p0 to it"
            if args.command == "unload"
            else f"the {args.command} path loads from p0 (for unloading use the unload command)"
        )
        raise UsageError(
            f"{option} {getattr(args, name):g} must be greater than --p0 {args.p0:g} kPa: {what}"
        )
    if args.command == "radial":
        m = params.critical_stress_ratio
        if not abs(args.eta) < m:
            raise UsageError(
                f"--eta {args.eta:g} is not allowed: a radial path needs |eta| < M = {m:g} (the "
                "critical stress ratio; set M with --param M=VALUE)"
            )
    out = getattr(args, "out", None)
    if out is not None:
        if out.is_dir():
            raise UsageError(f"--out {out} is a folder: give the netCDF file to write")
        if out.parent.exists() and not out.parent.is_dir():
            raise UsageError(f"--out {out}: {out.parent} is a file, not a folder")
        if (out.exists() or out.is_symlink()) and not args.overwrite:
            raise UsageError(
                f"--out {out} exists; add --overwrite to replace it, or choose another name"
            )


def _run(argv: list[str]) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        params = _parameters(args.param)
        options = ModelOptions(
            anisotropy=args.anisotropy,
            constraint_forces=not args.no_constraint_forces,
            bound_law=BOUND_LAWS[args.bound_law],
        )
        _check_path(args, params)
        if args.command == "probe":
            moduli = drivers.elastic_probe(initial_state(args.p, params, options), params, options)
            print(
                f"p = {args.p:g} kPa (normally consolidated, isotropic fabric): "
                f"E_oed,v = {moduli.e_oed_v:.6g} kPa, E_oed,h = {moduli.e_oed_h:.6g} kPa, "
                f"K = {moduli.bulk_modulus:.6g} kPa, G = {moduli.shear_modulus:.6g} kPa"
            )
            return 0
        common = dict(
            p0=args.p0, increments=args.increments, params=params, options=options,
            on_error="stop",
        )  # fmt: skip
        if args.command == "isotropic":
            ds = drivers.isotropic(args.p_max, **common)
        elif args.command == "k0":
            ds = drivers.k0(args.sigma_v_max, **common)
        elif args.command == "radial":
            ds = drivers.radial(args.eta, args.p_max, **common)
        else:
            ds = drivers.k0_then_unload(
                args.sigma_v_max, q_final=args.q_final,
                unload_increments=args.unload_increments, **common,
            )  # fmt: skip
    except ParameterError:
        raise
    except TivModelError as exc:
        # e.g. the initial state itself is impossible (v < 1 at p0)
        raise UsageError(f"{type(exc).__name__}: {exc}") from exc
    args.out.parent.mkdir(parents=True, exist_ok=True)
    replace_file(args.out, ds.to_netcdf)
    term = ds.attrs["termination"]
    if not args.quiet:
        last = ds.isel(step=-1)
        print(
            f"{args.command}: {ds.sizes['step'] - 1} increments written to {args.out}; end state "
            f"p = {float(last.mean_stress):.5g} kPa, q = {float(last.deviatoric_stress):.5g} kPa, "
            f"v = {float(last.specific_volume):.5g}, beta = {float(last.fabric):.4g}, "
            f"E_oed,h/E_oed,v = {float(last.stiffness_ratio):.4g}"
        )
    if term != "completed":
        print(f"{PROG}: path stopped early: {term}", file=sys.stderr)
        return 1
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m tiv_model`` / ``tiv-model``: returns the exit code (module docstring)."""
    return run_command(PROG, _run, argv)


__all__ = ["main"]
