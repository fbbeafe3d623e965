"""What one calibration on DEM results gives back: :class:`PipelineResult`.

:func:`bridge.pipeline.calibrate_from_results` returns it. Its fields are typed (the calibrated
parameters by symbol, their standard errors, what was fitted, the predictions, the files
written as paths, the timings, and the :class:`~bridge.calibration.CalibrationResult` and
:class:`~bridge.calibration.identifiability.Identifiability` objects themselves);
:meth:`PipelineResult.to_dict` is the JSON-able dict that ``calibrate_from_results`` returned
up to 0.1.0, with the same keys and values. For the callers written against that dict the
result is also a read-only mapping of those keys (``outcome["parameters"]``,
``outcome.get("seconds_identifiability")``): one entry point, one result, the old reading kept.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .calibration import CalibrationResult
from .calibration.identifiability import Identifiability

__all__ = ["PipelineResult"]


@dataclass(frozen=True, eq=False)
class PipelineResult(Mapping[str, Any]):
    """One calibration on DEM results, its predictions and the files it wrote.

    parameters: the calibrated TIV parameters by symbol (``"lambda*"``, ``"k"``, …; units of
        :data:`bridge.calibration.UNITS`), fitted or held.
    standard_errors: the fitted parameters' standard errors (same units); None where infinite
        (the data do not fix the parameter).
    fitted: (path, series) pairs that entered a residual, e.g. ``("k0", "fabric")``.
    out_of_sample: ``"path:variable"`` of every prediction no residual saw.
    predictions: rows of :func:`bridge.predict.summary` (model against DEM per path and
        variable).
    data: what was read and how (history, probes, paths, stress scale, conventions, stages).
    files: every file written, by role (``"report"``, ``"calibration"``, ``"calibration_text"``,
        ``"prediction_<path>"``, ``"figure_<name>"``, ``"manifest"`` when it wrote one).
    seconds: wall time of the whole call (s); seconds_calibration: of the fit alone (s).
    calibration: the :class:`~bridge.calibration.CalibrationResult` (stage fits, covariances,
        :meth:`~bridge.calibration.CalibrationResult.report`).
    identifiability: the profile likelihoods, when asked for
        (``PipelineOptions.identifiability``), else None.
    """

    parameters: Mapping[str, float]
    standard_errors: Mapping[str, float | None]
    fitted: tuple[tuple[str, str], ...]
    out_of_sample: tuple[str, ...]
    predictions: tuple[Mapping[str, Any], ...]
    data: Mapping[str, str]
    files: Mapping[str, Path]
    seconds: float
    seconds_calibration: float
    calibration: CalibrationResult
    identifiability: Identifiability | None = None

    @property
    def report(self) -> Path:
        """The markdown report, ``report.md``."""
        return self.files["report"]

    @property
    def seconds_identifiability(self) -> float | None:
        """Wall time of the profile likelihoods (s), None when they were not computed."""
        return None if self.identifiability is None else self.identifiability.seconds

    def to_dict(self) -> dict[str, Any]:
        """The JSON-able dict of 0.1.0's ``calibrate_from_results``: ``parameters``,
        ``standard_errors``, ``fitted`` (lists), ``out_of_sample``, ``predictions``, ``data``,
        ``files`` (strings), ``seconds``, ``seconds_calibration``, and with the profile
        likelihoods ``identifiability`` (their dict) and ``seconds_identifiability``."""
        out: dict[str, Any] = {
            "parameters": dict(self.parameters),
            "standard_errors": dict(self.standard_errors),
            "fitted": [list(pair) for pair in self.fitted],
            "out_of_sample": list(self.out_of_sample),
            "predictions": [dict(row) for row in self.predictions],
            "data": dict(self.data),
            "files": {key: str(path) for key, path in self.files.items()},
            "seconds": self.seconds,
            "seconds_calibration": self.seconds_calibration,
        }
        if self.identifiability is not None:
            out["identifiability"] = self.identifiability.to_dict()
            out["seconds_identifiability"] = self.identifiability.seconds
        return out

    # the read-only mapping of to_dict()'s keys, for callers of the former dict
    def __getitem__(self, key: str) -> Any:
        return self.to_dict()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.to_dict())

    def __len__(self) -> int:
        return len(self.to_dict())
