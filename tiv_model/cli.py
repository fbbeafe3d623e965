"""Command line: run the TIV element tests without writing Python; results in netCDF.

Examples::

    python -m tiv_model isotropic --p-max 300 --out iso.nc
    python -m tiv_model k0 --sigma-v-max 300 --out k0.nc
    python -m tiv_model unload --sigma-v-max 250 --out unload.nc   # K0, then constant-p to q = 0
    python -m tiv_model radial --eta 0.5 --p-max 200 --out radial.nc
    python -m tiv_model probe --p 100                              # elastic moduli, NC state

Common options: ``--p0`` (kPa, start of the path, normally consolidated, isotropic fabric),
``--anisotropy A|B``, ``--no-constraint-forces``, ``--bound-law exponential|tanh``,
``--increments``, ``--param SYMBOL=VALUE`` (override Table 1, repeatable).
Exit codes: 0 done; 1 the path stopped early on a model error (the file holds what was done);
2 bad input.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from . import __version__, drivers
from .errors import ParameterError, TivModelError
from .integrate import initial_state
from .params import BOUND_LAWS, SYMBOLS, TABLE1, ModelOptions, Parameters


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tiv-model",
        description="Hyperplastic anisotropic clay model (TIV): element tests to netCDF.",
    )
    parser.add_argument("--version", action="version", version=f"tiv_model {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    def common(p: argparse.ArgumentParser, out: bool = True) -> None:
        p.add_argument("--p0", type=float, default=5.0, help="initial mean stress, kPa (5)")
        p.add_argument("--anisotropy", choices=["A", "B"], default="A")
        p.add_argument("--no-constraint-forces", action="store_true")
        p.add_argument("--bound-law", choices=sorted(BOUND_LAWS), default="exponential")
        p.add_argument(
            "--param",
            action="append",
            default=[],
            metavar="SYMBOL=VALUE",
            help=f"override a Table 1 parameter; symbols: {', '.join(SYMBOLS.values())}",
        )
        if out:
            p.add_argument("--increments", type=int, default=100)
            p.add_argument("--out", type=Path, required=True, help="netCDF file to write")
            p.add_argument("--quiet", action="store_true")

    p = sub.add_parser("isotropic", help="isotropic compression to --p-max")
    p.add_argument("--p-max", type=float, required=True, help="final mean stress, kPa")
    common(p)
    p = sub.add_parser("k0", help="oedometric loading to --sigma-v-max")
    p.add_argument("--sigma-v-max", type=float, required=True, help="final axial stress, kPa")
    common(p)
    p = sub.add_parser("unload", help="K0 loading to --sigma-v-max, then constant-p unloading")
    p.add_argument("--sigma-v-max", type=float, required=True, help="axial stress of the K0 end")
    p.add_argument("--q-final", type=float, default=0.0, help="final q of the unloading, kPa")
    p.add_argument("--unload-increments", type=int, default=50)
    common(p)
    p = sub.add_parser("radial", help="radial path at constant stress ratio --eta")
    p.add_argument("--eta", type=float, required=True, help="stress ratio q/p")
    p.add_argument("--p-max", type=float, required=True, help="final mean stress, kPa")
    common(p)
    p = sub.add_parser("probe", help="print the elastic moduli of a normally consolidated state")
    p.add_argument("--p", type=float, required=True, help="mean stress, kPa")
    common(p, out=False)
    return parser


def _parameters(overrides: list[str]) -> Parameters:
    changes = {}
    for item in overrides:
        key, sep, value = item.partition("=")
        if not sep:
            raise ParameterError(f"--param {item!r}: expected SYMBOL=VALUE")
        try:
            changes[key.strip()] = float(value)
        except ValueError:
            raise ParameterError(f"--param {item!r}: value {value!r} is not a number") from None
    return TABLE1.replace(**changes) if changes else TABLE1


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        params = _parameters(args.param)
        options = ModelOptions(
            anisotropy=args.anisotropy,
            constraint_forces=not args.no_constraint_forces,
            bound_law=BOUND_LAWS[args.bound_law],
        )
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
    except ParameterError as exc:
        parser.exit(2, f"tiv-model: error: {exc}\n")
    except TivModelError as exc:
        # e.g. the initial state itself is impossible (v < 1 at p0)
        parser.exit(2, f"tiv-model: error: {type(exc).__name__}: {exc}\n")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    ds.to_netcdf(args.out)
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
        print(f"tiv-model: path stopped early: {term}", file=sys.stderr)
        return 1
    return 0


__all__ = ["main"]
