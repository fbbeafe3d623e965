"""The command-line options that ``python -m bridge calibrate`` (:mod:`bridge.pipeline`) and
``python -m bridge figure2`` (:mod:`bridge.study_figure`) share: how the DEM results are read
(:class:`bridge.series.Convention`, the probe moduli), the model's
:class:`tiv_model.params.ModelOptions` and the K0 mode of :mod:`bridge.predict`.

Each option is declared once here: its name, type, default and choices. The help texts are the
command's own (each says what the option does in that command), given as a mapping
option → text; every option added must have one.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping

from clay_cli import positive_float

from .predict import K0_MODES

#: the options :func:`add_model_options` adds, in the order they appear in ``--help``
MODEL_OPTIONS = (
    "--stress-scale",
    "--convention",
    "--fabric-scale",
    "--probe-method",
    "--anisotropy",
    "--no-constraint-forces",
)


def _check_help(options: tuple[str, ...], help_texts: Mapping[str, str]) -> None:
    """Every option of ``options`` has a help text, and no text is for another option."""
    missing = [name for name in options if name not in help_texts]
    unknown = sorted(set(help_texts) - set(options))
    if missing or unknown:
        raise ValueError(f"help texts: missing for {missing}, given for unknown {unknown}")


def add_model_options(parser: argparse.ArgumentParser, help_texts: Mapping[str, str]) -> None:
    """Add :data:`MODEL_OPTIONS` to ``parser``, in that order: ``--stress-scale`` (kPa per DEM
    stress unit, default None: the run's attribute), ``--convention`` (triaxial or plane),
    ``--fabric-scale`` (default 1), ``--probe-method`` (linear or dynamic), ``--anisotropy``
    (A or B) and ``--no-constraint-forces``. ``help_texts``: option → the command's help text."""
    _check_help(MODEL_OPTIONS, help_texts)
    parser.add_argument(
        "--stress-scale", type=positive_float, default=None, help=help_texts["--stress-scale"]
    )
    parser.add_argument(
        "--convention",
        default="triaxial",
        choices=("triaxial", "plane"),
        help=help_texts["--convention"],
    )
    parser.add_argument(
        "--fabric-scale", type=positive_float, default=1.0, help=help_texts["--fabric-scale"]
    )
    parser.add_argument(
        "--probe-method",
        default="linear",
        choices=("linear", "dynamic"),
        help=help_texts["--probe-method"],
    )
    parser.add_argument(
        "--anisotropy", default="A", choices=("A", "B"), help=help_texts["--anisotropy"]
    )
    parser.add_argument(
        "--no-constraint-forces", action="store_true", help=help_texts["--no-constraint-forces"]
    )


def add_k0_mode_option(parser: argparse.ArgumentParser, help_text: str) -> None:
    """Add ``--k0-mode`` (:data:`bridge.predict.K0_MODES`, default element) with the command's
    help text."""
    parser.add_argument("--k0-mode", default="element", choices=K0_MODES, help=help_text)
