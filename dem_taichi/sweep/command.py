"""Sweeps: many protocol runs over scene keys on Dask, one run directory per member.

::

    python -m dem_taichi.sweep SWEEP.toml --out DIR [--scheduler ADDRESS] [--n-workers N]
        [--tls-ca-file CA.pem --tls-cert CERT.pem [--tls-key KEY.pem]] [--dashboard ADDRESS]
        [--max-members N]
    python -m dem_taichi.sweep summarise DIR [--over scene.seed] [--out FILE.md] [--overwrite]

The sweep file (:mod:`dem_taichi.sweep.spec`) gives a base scene and a grid and/or a list of
members; each member is a whole :func:`dem_taichi.protocol.runner.run_protocol` in
``DIR/members/<name>``. Member names are 1 to 120 characters of ``A-Z a-z 0-9 - _ . = +`` and
neither ``.`` nor ``..`` (checked at load, naming the member), and every member folder is resolved
and checked to be ``DIR/members/<name>`` (no link leading elsewhere) before anything in it is
written or deleted. A sweep has at most 10,000 members (:data:`dem_taichi.sweep.spec.MAX_MEMBERS`;
``--max-members`` raises it): a larger grid is refused with its size before anything is built.

Members run as Dask tasks (``dask.distributed``): by default on a ``LocalCluster`` of one
process per core (÷ the sweep's ``workers``, the processes each member uses for its paths from
A), one thread each, listening on 127.0.0.1 only and serving no HTTP route (Dask's scheduler
otherwise opens port 8787 even without a dashboard); ``--dashboard 127.0.0.1:8787`` opts in to
Dask's dashboard. ``--scheduler`` runs them on an existing cluster instead, whose workers must
have this package installed and see ``DIR`` at the same path. Taichi is initialised in each
worker process by the first member it runs (:mod:`dem_taichi.engine.runtime`); the Nanny *spawns*
the worker processes (never forks), and a process runs one member at a time (a lock, for workers
with several threads).

A Dask scheduler runs whatever task a client submits to it: anyone who can reach its port can
run any code as the workers' user (read and delete their files, start processes). A ``tcp://``
scheduler has neither encryption nor authentication: keep it on 127.0.0.1, behind a firewall or
an SSH tunnel, on a network whose every user you trust. Across a shared network use TLS with
mutual authentication: start the scheduler and workers with ``--tls-ca-file``, ``--tls-cert``,
``--tls-key`` and ``distributed.comm.require-encryption: true`` (``dask scheduler --help``),
then give this command ``--scheduler tls://HOST:PORT --tls-ca-file CA.pem --tls-cert
CLIENT.pem [--tls-key CLIENT.key]``; only clients holding a certificate signed by that CA can
then connect. From Python: ``run_sweep(spec, DIR, scheduler="tls://HOST:PORT",
security=distributed.security.Security(tls_ca_file=..., tls_client_cert=...,
tls_client_key=..., require_encryption=True))``.

What a sweep writes in ``DIR``:

- ``sweep.toml`` (the sweep file as given) and ``sweep.json`` (the members, their keys and
  scene hashes);
- ``members/<name>/``: the member's protocol run (``run.json``, ``history.nc``, ``summary.json``,
  ...), ``member.json`` (status ``running`` | ``done`` | ``failed``, the error and its traceback,
  wall time, worker) and ``progress.log`` (the protocol's progress lines);
- ``index.json`` and ``index.csv``: one row per member (name, status, seconds, error, keys).

A failed member (an exception in its protocol, or its worker process dying) is recorded with
its error and does not stop the others; the exit code is then 1. SIGINT (Ctrl-C) or SIGTERM
stops the sweep: the cluster is closed, the index written, one line says how many members are
done and that the same command resumes the others; the exit code is 128 + the signal (130,
143). (On a ``--scheduler`` cluster the members already running finish on their workers.) A
re-run of the same sweep says it resumes (how many members were done, unfinished, failed),
skips the members that are done (same scene hash) and runs the others again: an unfinished or
failed member that had reached state A resumes from there, with the branches from A it had
finished (:mod:`dem_taichi.protocol.resume`); one stopped before A goes on from its last save
inside the ageing stage, if it has one, or starts again from the gas.
A member done with another scene than the sweep file now gives it is refused unless
``--overwrite``. ``summarise`` refuses existing summary files (or links there) unless
``--overwrite`` and writes each atomically (a link is replaced, never its target); it and
:func:`dem_taichi.sweep.results.open_sweep` read the finished members
(:mod:`dem_taichi.sweep.results`).
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any

from clay_cli import UsageError, first_control_character
from dem_taichi.sweep.client import (  # noqa: F401 - the public names of the sweep
    INDEX_CSV,
    INDEX_JSON,
    SweepOutcome,
    read_index,
    run_sweep,
    write_index,
)
from dem_taichi.sweep.member import (
    MEMBER_RECORD,
    run_member,
)
from dem_taichi.sweep.spec import MAX_MEMBERS, SweepError, SweepSpec, load_sweep

__all__ = ["MEMBER_RECORD", "SweepOutcome", "run_sweep", "run_member", "read_index", "main"]


# -- command line -------------------------------------------------------------------------------
def _no_control_characters(flag: str):
    """An argparse ``type``: the text of ``flag``, refused when it holds a line break or other
    control character (a pasted line break would cut an address or a path in two)."""

    def parse(text: str) -> str:
        bad = first_control_character(text)
        if bad is not None:
            raise argparse.ArgumentTypeError(
                f"{text!r} contains the control character {bad!r} (a line break?)"
            )
        return text

    parse.__name__ = flag
    return parse


def _security(args):
    """The ``distributed.security.Security`` of ``--tls-ca-file/--tls-cert/--tls-key``, or None.

    TLS authenticates both ends: the client checks the scheduler's certificate against the CA,
    and a scheduler started with ``require-encryption`` and the same CA accepts only clients
    with a certificate it signed."""
    given = {
        flag: value
        for flag, value in (
            ("--tls-ca-file", args.tls_ca_file),
            ("--tls-cert", args.tls_cert),
            ("--tls-key", args.tls_key),
        )
        if value
    }
    scheduler = args.scheduler or ""
    if not given:
        if scheduler.startswith("tls://"):
            raise UsageError(
                f"--scheduler {scheduler} is a TLS address: give --tls-ca-file and --tls-cert "
                "(and --tls-key unless the certificate file holds the key)"
            )
        return None
    if not scheduler:
        raise UsageError(
            f"{', '.join(given)} apply to --scheduler only (the local cluster stays on "
            "127.0.0.1): give --scheduler tls://HOST:PORT"
        )
    missing = [flag for flag in ("--tls-ca-file", "--tls-cert") if flag not in given]
    if missing:
        raise UsageError(f"{', '.join(given)} need {' and '.join(missing)} as well")
    for flag, value in given.items():
        if not Path(value).is_file():
            raise UsageError(f"{flag} {value}: no such file")
    if not scheduler.startswith("tls://"):
        raise UsageError(
            f"--scheduler {scheduler} with TLS certificates: the address must start with tls://"
        )
    from distributed.security import Security

    return Security(
        tls_ca_file=args.tls_ca_file,
        tls_client_cert=args.tls_cert,
        tls_client_key=args.tls_key,
        require_encryption=True,
    )


class _Stop:
    """SIGINT/SIGTERM during a sweep: the first raises ``KeyboardInterrupt`` (run_sweep closes
    the cluster and writes the index), later ones are ignored while that clean-up runs."""

    def __init__(self) -> None:
        self.received: int | None = None
        self._previous: dict[int, Callable[[int, FrameType | None], Any] | int | None] = {}

    def _handle(self, signum: int, frame) -> None:
        if self.received is None:
            self.received = signum
            raise KeyboardInterrupt

    def __enter__(self) -> _Stop:
        for signum in (signal.SIGINT, signal.SIGTERM):
            self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)


def _stopped_line(prog: str, spec: SweepSpec, out: Path, signum: int, argv: list[str]) -> str:
    """The one line printed when a sweep is stopped by a signal: what is done, how to resume."""
    rows = []
    with contextlib.suppress(SweepError, OSError):
        rows = read_index(out)["members"]
    done = [r.get("status") for r in rows].count("done")
    total = len(spec.members)
    return (
        f"{prog}: {signal.Signals(signum).name}: stopped; {done} of {total} members done "
        f"(index {out / INDEX_JSON}); the same command resumes the other {total - done}: "
        f"{prog} {' '.join(argv)}"
    )


def _run_command(args, prog: str) -> int:
    spec = load_sweep(args.sweep, max_members=args.max_members)
    security = _security(args)
    with _Stop() as stop:
        try:
            outcome = run_sweep(
                spec,
                args.out,
                scheduler=args.scheduler,
                n_workers=args.n_workers,
                overwrite=args.overwrite,
                verbose=args.verbose,
                say=(lambda _: None) if args.quiet else _say,
                command=f"{prog} " + " ".join(args.argv),
                security=security,
                dashboard=args.dashboard,
            )
        except KeyboardInterrupt:
            if args.debug:
                raise
            signum = stop.received or signal.SIGINT
            print(_stopped_line(prog, spec, Path(args.out), signum, args.argv), file=sys.stderr)
            return 128 + signum
    return 1 if outcome.failed else 0


def _say(line: str) -> None:
    """A progress line on stdout, flushed (a sweep's log is often a pipe or a file)."""
    print(line, flush=True)


def _summarise_command(args) -> int:
    from dem_taichi.sweep.results import summarise_sweep

    files = summarise_sweep(
        args.dir,
        over=tuple(args.over or ["scene.seed"]),
        out=args.out,
        extra_runs=args.add,
        overwrite=args.overwrite,
    )
    if not args.quiet:
        print(Path(files["table"]).read_text())
    for kind, path in files.items():
        print(f"{kind}: {path}")
    return 0


def _parser(prog: str) -> argparse.ArgumentParser:
    from clay_cli import ArgumentParser, add_common_flags, int_in_range

    parser = ArgumentParser(
        prog=prog,
        description="Protocol runs over scene keys on Dask, and their replica statistics.",
    )
    add_common_flags(parser)
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a sweep (the default: `SWEEP.toml --out DIR`)")
    run.add_argument("sweep", help="sweep TOML file ([sweep] scene, [sweep.grid], ...)")
    run.add_argument(
        "--out", required=True, type=_no_control_characters("--out"),
        help="sweep directory (members/<name>, index)",
    )  # fmt: skip
    run.add_argument(
        "--scheduler", type=_no_control_characters("--scheduler"),
        help="address of a running Dask scheduler (else a local one on 127.0.0.1). Anyone who "
        "can reach a scheduler's port can run any code as its workers' user: keep it on "
        "127.0.0.1 or a trusted network, or use tls:// with --tls-ca-file/--tls-cert",
    )  # fmt: skip
    for flag, what in (
        ("--tls-ca-file", "CA certificate (PEM) that signed the scheduler's and the client's"),
        ("--tls-cert", "this client's TLS certificate (PEM) for a tls:// --scheduler"),
        ("--tls-key", "the key of --tls-cert (PEM), unless that file holds it"),
    ):
        run.add_argument(flag, type=_no_control_characters(flag), default=None, help=what)
    run.add_argument(
        "--dashboard", type=_no_control_characters("--dashboard"), default=None,
        metavar="ADDRESS",
        help="serve Dask's dashboard of the local cluster at ADDRESS, e.g. 127.0.0.1:8787 "
        "(':8787' listens on every interface: anyone on the network sees the cluster; "
        "default: no dashboard, no HTTP route at all)",
    )  # fmt: skip
    run.add_argument(
        "--max-members", type=int_in_range(1), default=MAX_MEMBERS,
        help=f"the most members the sweep file may make (default {MAX_MEMBERS:,}): a larger "
        "grid is refused with its size before anything is built",
    )  # fmt: skip
    run.add_argument(
        "--n-workers", type=int_in_range(1), default=None,
        help="worker processes of the local cluster (default: cores / the sweep's workers)",
    )  # fmt: skip
    run.add_argument(
        "--overwrite", action="store_true",
        help="run again the members done with another scene than the sweep file gives them",
    )  # fmt: skip
    run.add_argument("--verbose", action="store_true", help="every member's protocol lines")
    add_common_flags(run, sub=True)
    for name in ("summarise", "summarize"):
        summary = sub.add_parser(name, help="replica statistics of a sweep's finished members")
        summary.add_argument("dir", help="sweep directory")
        summary.add_argument(
            "--over", action="append", default=None,
            help="the replica key(s): members that differ only in them are pooled "
            "(default scene.seed; repeat for several)",
        )  # fmt: skip
        summary.add_argument(
            "--out", default=None, type=_no_control_characters("--out"),
            help="markdown file (default DIR/replica_summary.md); the figure (.png), statistics "
            "(.json) and dataset (_members.nc) take its stem",
        )  # fmt: skip
        summary.add_argument(
            "--overwrite", action="store_true",
            help="replace the summary's files if they exist (else refused)",
        )  # fmt: skip
        summary.add_argument(
            "--add", nargs="+", default=[], metavar="RUN_DIR",
            help="finished protocol runs of the same scene made outside the sweep, pooled as "
            "more replicas (default: none)",
        )  # fmt: skip
        add_common_flags(summary, sub=True)
    return parser


def _main(argv: list[str], prog: str) -> int:
    first = next((i for i, a in enumerate(argv) if not a.startswith("-")), None)
    if first is not None and argv[first] not in ("run", "summarise", "summarize"):
        argv = [*argv[:first], "run", *argv[first:]]  # `SWEEP.toml --out DIR` is `run ...`
    args = _parser(prog).parse_args(argv)
    args.argv = argv
    if args.command == "run":
        return _run_command(args, prog)
    return _summarise_command(args)


def main(argv: list[str] | None = None, prog: str = "python -m dem_taichi.sweep") -> int:
    """``python -m dem_taichi.sweep [run] SWEEP.toml --out DIR [--scheduler ADDRESS]
    [--tls-ca-file F --tls-cert F [--tls-key F]] [--n-workers N] [--dashboard ADDRESS]
    [--max-members N] [--overwrite] [--verbose]`` | ``summarise DIR [--over KEY] [--out FILE]
    [--overwrite]``
    (both with ``--quiet``, ``--debug``); returns the exit code: 0 every member done, 1 a
    member failed, 2 bad input (an invalid sweep file: one line naming the key and what is
    allowed; the traceback with ``--debug``; :mod:`clay_cli`), 128 + N stopped
    by signal N (130 SIGINT, 143 SIGTERM; a re-run resumes)."""
    from clay_cli import run_command

    return run_command(prog, lambda args: _main(args, prog), argv, user_errors=(SweepError,))


if __name__ == "__main__":
    sys.exit(main())
