"""Moved to :mod:`bridge.calibration.options` (kept here for one release).

Importing this module gives the same objects as :mod:`bridge.calibration.options` and a
:class:`DeprecationWarning`. To be removed in the release after the next one.
"""

import warnings

from .calibration import options as _new
from .calibration.options import *  # noqa: F403

__all__ = list(_new.__all__)

warnings.warn(
    "bridge.calibration_options moved to bridge.calibration.options "
    "(import the same names from there); "
    "the old path goes in the release after the next one",
    DeprecationWarning,
    stacklevel=2,
)
