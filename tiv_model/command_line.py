"""Moved: the command-line conventions are :mod:`clay_cli` now (kept here for one release).

Up to 0.1.0 the shared error handler, exit codes and common flags lived in this module. They
moved to a package of their own, :mod:`clay_cli` (module :mod:`clay_cli.conventions`), so that
``dem_taichi`` need not import ``tiv_model`` for them. Importing this module gives the same
objects (``tiv_model.command_line.run_command is clay_cli.run_command``) and a
:class:`DeprecationWarning`; patching a name here does not reach :mod:`clay_cli.conventions`.
To be removed in the release after the next one.
"""

import warnings

from clay_cli import conventions as _conventions
from clay_cli.conventions import *  # noqa: F403
from clay_cli.conventions import FULL_DISK_BYTES

__all__ = [*_conventions.__all__, "FULL_DISK_BYTES"]

warnings.warn(
    "tiv_model.command_line moved to clay_cli (import the same names from clay_cli); "
    "the old path goes in the release after the next one",
    DeprecationWarning,
    stacklevel=2,
)
