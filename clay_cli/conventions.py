"""The conventions of the project's command lines: one error handler, the same flags.

Used by ``python -m tiv_model``, ``python -m dem_taichi`` (``run``, ``protocol``, ``sweep``,
``snapshot``) and ``python -m bridge``. Standard library only, and a package of its own
(:mod:`clay_cli`) that imports nothing of the project, so that all three packages share it
without any of them importing another for it. Up to 0.1.0 it was ``tiv_model.command_line``
(still importable for one release, with a :class:`DeprecationWarning`).

- A user error (a bad option, a bad scene or file, a value out of range: ``ValueError`` and
  ``OSError`` and what an entry point adds) is one line on stderr, ``PROG: error: MESSAGE``,
  saying what is wrong, what is allowed and what to do, with exit code 2. Option errors of
  argparse are one line too (:class:`ArgumentParser`).
- Any other exception is one line ``PROG: internal error: ...`` with exit code 1.
- ``--debug`` (anywhere on the command line) shows the full traceback instead.
- ``--quiet``: no progress bars or summary lines (results asked for are still printed).
- Ctrl-C that the command does not handle itself: ``PROG: interrupted``, exit code 130.

- A full disk or an exceeded quota (``OSError`` ENOSPC or EDQUOT, also as the cause of another
  error) is one line ``PROG: error: disk full: FILE: ...; free space or write elsewhere`` with
  exit code 4: not bad input, the same command can succeed once there is room.

Exit codes: 0 done; 1 stopped early or failed (a model error, an internal error); 2 bad input;
3 a DEM blow-up; 4 disk full (ENOSPC/EDQUOT); 128 + N stopped by signal N (130: SIGINT,
143: SIGTERM).
"""

from __future__ import annotations

import argparse
import errno
import os
import sys
import tempfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import NoReturn

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

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2
EXIT_DISK_FULL = 4
EXIT_INTERRUPTED = 130


class UsageError(ValueError):
    """A bad input found by a command line's own checks (exit code 2)."""


def first_control_character(text: str, allow: str = "") -> str | None:
    """The first control character (code < 32, or DEL) of ``text`` not in ``allow``, or None.

    A pasted line break in a command-line value would cut a path or a label in two (and TOML
    reads what follows a line break in a ``--set`` as further keys)."""
    return next((c for c in text if (ord(c) < 32 or ord(c) == 127) and c not in allow), None)


def refuse_control_characters(argv: list[str], own_check: tuple[str, ...] = ("--set",)) -> None:
    """Refuse (:class:`UsageError`, one line naming the flag) a command-line value holding a
    line break or other control character (tab included), so the run never writes where the
    user did not say. Values of the flags in ``own_check`` are left to their own check (the
    scene loader's for ``--set``, which allows a tab)."""
    for i, arg in enumerate(argv):
        bad = first_control_character(arg)
        if bad is None:
            continue
        flag, _, value = arg.partition("=") if arg.startswith("--") else ("", "", arg)
        if not flag and i > 0 and argv[i - 1].startswith("--"):
            flag = argv[i - 1]
        if flag in own_check:
            continue
        what = f"{flag} {value!r}" if flag else f"argument {value!r}"
        raise UsageError(
            f"{what} contains the control character {bad!r} (a line break?): give each path "
            "and label on one line"
        )


class ArgumentParser(argparse.ArgumentParser):
    """argparse with a one-line error (``PROG: error: MESSAGE (see PROG --help)``), exit 2.

    Sub-command parsers made by ``add_subparsers`` are of the same class.
    """

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def add_common_flags(parser: argparse.ArgumentParser, sub: bool = False) -> None:
    """``--quiet`` and ``--debug``. On sub-command parsers (``sub``) they do not reset a value
    given before the sub-command."""
    default = argparse.SUPPRESS if sub else False
    parser.add_argument(
        "--quiet", action="store_true", default=default, help="no progress bars or summary lines"
    )
    parser.add_argument(
        "--debug",
        action="store_true",
        default=default,
        help="show the full traceback of an error (default: one line)",
    )


def _text(error: BaseException) -> str:
    if isinstance(error, OSError) and error.filename is not None and error.strerror:
        return f"{error.filename}: {error.strerror}"
    text = str(error) or type(error).__name__
    if isinstance(error, KeyError) and len(error.args) == 1:
        text = str(error.args[0])
    return " ".join(line.strip() for line in text.splitlines() if line.strip())


def disk_full_error(error: BaseException) -> OSError | None:
    """The ``OSError`` ENOSPC/EDQUOT behind ``error`` (itself, its cause or context), or None."""
    seen: set[int] = set()
    current: BaseException | None = error
    while current is not None and id(current) not in seen:
        seen.add(id(current))
        if isinstance(current, OSError) and current.errno in (errno.ENOSPC, errno.EDQUOT):
            return current
        current = current.__cause__ or current.__context__
    return None


#: Less space than this available where a write failed: the disk is taken to be full.
FULL_DISK_BYTES = 1 << 20


def disk_full_while_writing(error: BaseException, path: str | os.PathLike[str]) -> OSError | None:
    """An ``OSError`` ENOSPC standing for ``error``, raised while writing ``path``, when the file
    system of ``path`` has less than :data:`FULL_DISK_BYTES` available, else None.

    netCDF4 (HDF5) reports a full disk as ``RuntimeError('NetCDF: HDF error')`` without the
    errno: writers of netCDF files re-raise such an error as this one (``raise full from
    error``) so that the command line gives the disk-full exit code.
    """
    found = disk_full_error(error)
    if found is not None:
        return found
    folder = os.path.dirname(os.path.abspath(os.fspath(path)))
    try:
        info = os.statvfs(folder)
    except OSError:
        return None
    if info.f_bavail * info.f_frsize >= FULL_DISK_BYTES:
        return None
    reason = f"{os.strerror(errno.ENOSPC)} (the writer said: {_text(error)})"
    return OSError(errno.ENOSPC, reason, os.fspath(path))


def replace_file(target: str | os.PathLike[str], write: Callable[[Path], object]) -> Path:
    """Write a command's output file atomically: ``write(temporary)`` fills a new file beside
    ``target`` (made with O_EXCL, so no link can be there), which is then renamed onto
    ``target``. A reader never sees half a file, an error (a full disk) leaves no file behind,
    and a link at ``target`` is replaced, never written through. netCDF4's "HDF error" on a
    full file system is raised as ``OSError`` ENOSPC (:func:`disk_full_while_writing`)."""
    target = Path(target)
    handle, name = tempfile.mkstemp(
        dir=target.parent, prefix=f".{target.stem}.", suffix=f".tmp{target.suffix}"
    )
    os.close(handle)
    temporary = Path(name)
    try:
        try:
            write(temporary)
        except RuntimeError as error:
            full = disk_full_while_writing(error, target)
            if full is None:
                raise
            raise full from error
        mask = os.umask(0)
        os.umask(mask)
        os.chmod(temporary, 0o666 & ~mask)  # mkstemp makes owner-only files
        os.replace(temporary, target)
    finally:
        temporary.unlink(missing_ok=True)
    return target


def error_line(prog: str, error: BaseException, kind: str = "error") -> str:
    """``PROG: KIND: MESSAGE`` on one line (newlines of the message joined)."""
    return f"{prog}: {kind}: {_text(error)}"


def run_command(
    prog: str,
    body: Callable[[list[str]], int | None],
    argv: Sequence[str] | None = None,
    *,
    user_errors: tuple[type[BaseException], ...] = (),
    failures: Mapping[type[BaseException], int] | None = None,
) -> int:
    """Run ``body(argv)`` under the one error handler (module docstring); returns the exit code.

    ``user_errors``: exception types reported as bad input (exit 2) besides ``ValueError``,
    ``OSError`` and :class:`UsageError`; ``failures``: exception type → exit code for errors
    that are not bad input (e.g. a DEM blow-up → 3), reported on one line as ``error``.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in args
    try:
        code = body(args)
        return EXIT_OK if code is None else int(code)
    except SystemExit as stop:  # argparse: --help (0) and option errors (2, already printed)
        if stop.code is None or isinstance(stop.code, int):
            return stop.code or EXIT_OK
        print(f"{prog}: error: {stop.code}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        if debug:
            raise
        print(f"{prog}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as error:  # noqa: BLE001 - the one handler of a command line
        if debug:
            raise
        full = disk_full_error(error)
        if full is not None:
            print(
                f"{prog}: error: disk full: {_text(full)}; free space (or raise the quota) or "
                "write to another folder, then run the command again",
                file=sys.stderr,
            )
            return EXIT_DISK_FULL
        for kind, code in (failures or {}).items():
            if isinstance(error, kind):
                print(error_line(prog, error), file=sys.stderr)
                return code
        if isinstance(error, (ValueError, OSError, UsageError, *user_errors)):
            print(error_line(prog, error), file=sys.stderr)
            return EXIT_USAGE
        print(
            error_line(prog, error, "internal error")
            + f" ({type(error).__name__}; rerun with --debug for the traceback and report it)",
            file=sys.stderr,
        )
        return EXIT_FAILED


def int_in_range(low: int, high: int | None = None, note: str = "") -> Callable[[str], int]:
    """An argparse ``type``: an integer in [low, high]; the message names the allowed range and
    ``note`` (e.g. the cost that sets the limit and how to go past it)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if value < low or (high is not None and value > high):
            allowed = f">= {low}" if high is None else f"from {low} to {high:,}"
            raise argparse.ArgumentTypeError(
                f"{value:,} is out of range: allowed integers {allowed}{note}"
            )
        return value

    parse.__name__ = "integer"
    return parse


def positive_float(text: str) -> float:
    """An argparse ``type``: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (value > 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"{text} is not allowed: give a finite number > 0")
    return value
