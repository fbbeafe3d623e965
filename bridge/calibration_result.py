"""Moved to :mod:`bridge.calibration.result` (kept here for one release).

Importing this module gives the same objects as :mod:`bridge.calibration.result` and a
:class:`DeprecationWarning`. To be removed in the release after the next one.
"""

import warnings

from .calibration import result as _new
from .calibration.result import *  # noqa: F403

__all__ = list(_new.__all__)

warnings.warn(
    "bridge.calibration_result moved to bridge.calibration.result "
    "(import the same names from there); "
    "the old path goes in the release after the next one",
    DeprecationWarning,
    stacklevel=2,
)
