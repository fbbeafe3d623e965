"""What the pipeline of :mod:`bridge.pipeline` is asked to do: :class:`PipelineOptions`, the
mapping form of them (:func:`pipeline_options`), and the stress scale a run's options and files
give (:func:`stress_scale_of`). :mod:`bridge.pipeline` re-exports the three.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path

import xarray as xr

from tiv_model.params import BOUND_LAWS, ModelOptions

from .calibration import STAGES, CalibrationOptions
from .series import HISTORY_REQUIRED, PROBES_REQUIRED, SeriesError
from .units import in_dem_units

__all__ = ["PipelineOptions", "pipeline_options", "stress_scale_of"]


@dataclass(frozen=True)
class PipelineOptions:
    """Everything the pipeline needs besides the files (see :mod:`bridge.pipeline`).

    stress_scale_kpa: kPa per DEM stress unit; None: the history's ``stress_scale_kpa``.
    convention, fabric_scale: see :class:`bridge.series.Convention`.
    probe_method: ``"linear"`` or ``"dynamic"`` probe moduli.
    calibration: :class:`bridge.calibration.CalibrationOptions` (model options inside).
    stages: calibration stages to run.
    k0_mode: ``"element"`` (K0 driver) or ``"stress"`` (DEM stress history) for predictions.
    max_increments: most model increments per predicted path.
    figures: write the figures.
    identifiability: profile likelihoods of the fitted parameters
        (:mod:`bridge.calibration.identifiability`) in ``calibration.json``
        (``"identifiability"``), the text report and ``report.md``.
    """

    stress_scale_kpa: float | None = None
    convention: str = "triaxial"
    fabric_scale: float = 1.0
    probe_method: str = "linear"
    prefer_relaxed_states: bool = True
    calibration: CalibrationOptions = field(default_factory=CalibrationOptions)
    stages: tuple[str, ...] = STAGES
    k0_mode: str = "element"
    max_increments: int = 40
    figures: bool = True
    identifiability: bool = True


def pipeline_options(options) -> PipelineOptions:
    """:class:`PipelineOptions` from None, itself, or a mapping of its fields (a nested mapping
    under ``"calibration"`` becomes :class:`CalibrationOptions`, one under ``"model_options"``
    in it :class:`tiv_model.params.ModelOptions`, with ``bound_law`` given by name)."""
    if options is None:
        return PipelineOptions()
    if isinstance(options, PipelineOptions):
        return options
    if not isinstance(options, Mapping):
        raise TypeError(f"options must be PipelineOptions or a mapping, got {type(options)}")
    known = {f.name for f in fields(PipelineOptions)}
    unknown = sorted(set(options) - known)
    if unknown:
        raise TypeError(f"unknown pipeline option(s) {unknown}; allowed: {sorted(known)}")
    values = dict(options)
    calibration = values.get("calibration")
    if isinstance(calibration, Mapping):
        calibration = dict(calibration)
        model = calibration.get("model_options")
        if isinstance(model, Mapping):
            model = dict(model)
            if isinstance(model.get("bound_law"), str):
                model["bound_law"] = BOUND_LAWS[model["bound_law"]]
            calibration["model_options"] = ModelOptions(**model)
        if "fixed" in calibration:
            calibration["fixed"] = tuple(calibration["fixed"])
        values["calibration"] = CalibrationOptions(**calibration)
    return PipelineOptions(**values)


def stress_scale_of(
    options: PipelineOptions, history: xr.Dataset, path: Path, probes: xr.Dataset | None = None
) -> tuple[float, str]:
    """The stress scale S (kPa per DEM stress unit) of one run, and how it was found.

    In order: ``options.stress_scale_kpa`` when given; else the attribute ``stress_scale_kpa``
    of ``history`` (the file ``path``, named in the note and the error); else 1.0 when every
    stress and modulus read (the history's and, with ``probes``, the probes' moduli of
    ``options.probe_method``) has a pressure unit (:mod:`bridge.units`); else
    :class:`bridge.series.SeriesError` naming what is in DEM units. Returns (S, a note for the
    report, e.g. ``"from the attribute stress_scale_kpa of relaxed_states.nc"``).
    """
    if options.stress_scale_kpa is not None:
        return float(options.stress_scale_kpa), "given as an option"
    value = history.attrs.get("stress_scale_kpa")
    method = options.probe_method
    dem = []  # what needs the scale: stresses and moduli in DEM units
    if names := in_dem_units(history, HISTORY_REQUIRED):
        dem.append(f"history {', '.join(names)}")
    if probes is not None:
        moduli = (f"e_oed_v_{method}", f"e_oed_h_{method}", "stiffness_tensor_linear")
        if names := in_dem_units(probes, PROBES_REQUIRED + moduli):
            dem.append(f"probes {', '.join(names)}")
    stresses = all(name in history.variables for name in ("stress_xx", "stress_yy"))
    if value is None and stresses and not dem:
        return 1.0, "not needed: every stress and modulus read has a pressure unit"
    if value is None:
        raise SeriesError(
            f"no stress scale: {path} has no global attribute 'stress_scale_kpa' and these "
            f"are not in a pressure unit: {'; '.join(dem)}; give PipelineOptions("
            "stress_scale_kpa=...) (--stress-scale), kPa per DEM stress unit"
        )
    return float(value), f"from the attribute stress_scale_kpa of {path.name}"
