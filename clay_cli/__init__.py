"""The shared conventions of the project's command lines: one error handler, the same flags.

Standard library only; it imports nothing of ``tiv_model``, ``dem_taichi`` or ``bridge``, and
all three may import it (ARCHITECTURE.md). The names live in :mod:`clay_cli.conventions`
(until 0.1.0 ``tiv_model.command_line``) and are re-exported here: import them from
``clay_cli``::

    from clay_cli import EXIT_USAGE, ArgumentParser, add_common_flags, run_command
"""

from .conventions import (
    EXIT_DISK_FULL,
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USAGE,
    ArgumentParser,
    UsageError,
    add_common_flags,
    disk_full_error,
    disk_full_while_writing,
    error_line,
    first_control_character,
    int_in_range,
    positive_float,
    refuse_control_characters,
    replace_file,
    run_command,
)

__all__ = [
    "EXIT_OK",
    "EXIT_FAILED",
    "EXIT_USAGE",
    "EXIT_DISK_FULL",
    "EXIT_INTERRUPTED",
    "UsageError",
    "first_control_character",
    "refuse_control_characters",
    "ArgumentParser",
    "add_common_flags",
    "error_line",
    "disk_full_error",
    "disk_full_while_writing",
    "replace_file",
    "run_command",
    "int_in_range",
    "positive_float",
]
