"""The staged calibration of the TIV model on DEM series, and what the data determine.

- :mod:`bridge.calibration.fit` — the staged least squares (compressibility λ*, N; elastic k,
  g, n, r, ω; fabric c, s, z, M): :func:`calibrate`, the stages and their fits;
- :mod:`bridge.calibration.options` — :class:`CalibrationOptions` (stages, bounds, scales,
  fixed parameters), :class:`CalibrationError`;
- :mod:`bridge.calibration.result` — :class:`CalibrationResult` (parameters, standard errors,
  stage fits, fit quality, report);
- :mod:`bridge.calibration.identifiability` — profile likelihoods, parameters at bounds,
  correlations, the spread over replicas (it refits the stages, so it lives here).

Up to 0.1.0 these were the flat modules ``bridge.calibration``, ``bridge.calibration_options``,
``bridge.calibration_result`` and ``bridge.identifiability``; the last three still import for
one release, with a :class:`DeprecationWarning`. The names of the old ``bridge.calibration``
module are this package's names (``from bridge.calibration import calibrate`` is unchanged).
The function :func:`~bridge.calibration.identifiability.identifiability` is not re-exported
here: it shares its name with its module.
"""

from .fit import JointStage, build_stages, calibrate, fit_stage
from .options import (
    DEFAULT_BOUNDS,
    DEFAULT_SCALES,
    ELASTIC_MODULI,
    FABRIC_SERIES,
    INITIAL_FABRIC,
    STAGE_PARAMETERS,
    STAGES,
    UNITS,
    CalibrationError,
    CalibrationOptions,
    ModelFailureError,
)
from .result import CalibrationResult, StageFit, covariance_from_jacobian

__all__ = [
    "DEFAULT_BOUNDS",
    "DEFAULT_SCALES",
    "ELASTIC_MODULI",
    "FABRIC_SERIES",
    "INITIAL_FABRIC",
    "STAGES",
    "STAGE_PARAMETERS",
    "UNITS",
    "CalibrationError",
    "CalibrationOptions",
    "CalibrationResult",
    "JointStage",
    "ModelFailureError",
    "StageFit",
    "build_stages",
    "calibrate",
    "fit_stage",
    "covariance_from_jacobian",
]
