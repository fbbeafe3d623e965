"""Moved to :mod:`bridge.calibration.identifiability` (kept here for one release).

Importing this module gives the same objects as :mod:`bridge.calibration.identifiability` and a
:class:`DeprecationWarning`. To be removed in the release after the next one.
"""

import warnings

from .calibration import identifiability as _new
from .calibration.identifiability import *  # noqa: F403

__all__ = list(_new.__all__)

warnings.warn(
    "bridge.identifiability moved to bridge.calibration.identifiability "
    "(import the same names from there); "
    "the old path goes in the release after the next one",
    DeprecationWarning,
    stacklevel=2,
)
