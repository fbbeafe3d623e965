"""Sweeps: many protocol runs over scene keys on Dask, one run directory per member.

::

    python -m dem_taichi.sweep SWEEP.toml --out DIR [--scheduler ADDRESS] [--n-workers N]
        [--tls-ca-file CA.pem --tls-cert CERT.pem [--tls-key KEY.pem]] [--dashboard ADDRESS]
        [--max-members N]
    python -m dem_taichi.sweep summarise DIR [--over scene.seed] [--out FILE.md] [--overwrite]

The sweep file (:mod:`dem_taichi.sweep_spec`) gives a base scene and a grid and/or a list of
members; each member is a whole :func:`dem_taichi.protocol.run_protocol` in ``DIR/members/<name>``.
Member names are 1 to 120 characters of ``A-Z a-z 0-9 - _ . = +`` and neither ``.`` nor ``..``
(checked at load, naming the member), and every member folder is resolved and checked to be
``DIR/members/<name>`` (no link leading elsewhere) before anything in it is written or deleted.
A sweep has at most 10,000 members (:data:`dem_taichi.sweep_spec.MAX_MEMBERS`; ``--max-members``
raises it): a larger grid is refused with its size before anything is built.

Members run as Dask tasks (``dask.distributed``): by default on a ``LocalCluster`` of one
process per core (÷ the sweep's ``workers``, the processes each member uses for its paths from
A), one thread each, listening on 127.0.0.1 only and serving no HTTP route (Dask's scheduler
otherwise opens port 8787 even without a dashboard); ``--dashboard 127.0.0.1:8787`` opts in to
Dask's dashboard. ``--scheduler`` runs them on an existing cluster instead, whose workers must
have this package installed and see ``DIR`` at the same path. Taichi is initialised in each
worker process by the first member it runs (:mod:`dem_taichi.runtime`); the Nanny *spawns* the
worker processes (never forks), and a process runs one member at a time (a lock, for workers
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
finished (:mod:`dem_taichi.protocol_resume`); one stopped before A starts again from the gas.
A member done with another scene than the sweep file now gives it is refused unless
``--overwrite``. ``summarise`` refuses existing summary files (or links there) unless
``--overwrite`` and writes each atomically (a link is replaced, never its target); it and
:func:`dem_taichi.sweep_results.open_sweep` read the finished members
(:mod:`dem_taichi.sweep_results`).
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import os
import signal
import sys
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dem_taichi.sweep_member import (
    MEMBER_RECORD,
    TOPIC,
    can_resume,
    checked_member_dir,
    member_dir,
    now,
    read_json,
    run_member,
    write_json,
)
from dem_taichi.sweep_spec import MAX_MEMBERS, Member, SweepError, SweepSpec, load_sweep
from tiv_model.command_line import UsageError, first_control_character

INDEX_JSON = "index.json"
INDEX_CSV = "index.csv"

__all__ = ["MEMBER_RECORD", "SweepOutcome", "run_sweep", "run_member", "read_index", "main"]


# -- on the client ------------------------------------------------------------------------------
@dataclass
class SweepOutcome:
    """What a sweep did: every member's index row, and which ran this time."""

    out_dir: Path
    rows: list[dict]
    ran: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def failed(self) -> list[str]:
        return [r["name"] for r in self.rows if r["status"] == "failed"]

    @property
    def done(self) -> list[str]:
        return [r["name"] for r in self.rows if r["status"] == "done"]


def _index_row(spec: SweepSpec, member: Member, out: Path) -> dict:
    record = read_json(member_dir(out, member.name) / MEMBER_RECORD) or {}
    status = record.get("status", "pending")
    if status == "done" and record.get("scene_sha256") != member.scene_sha256:
        status = "stale"  # done with another scene than the sweep file now gives it
    return {
        "name": member.name,
        "status": status,
        "seconds": record.get("seconds"),
        "error": record.get("error", ""),
        "finished": record.get("finished", ""),
        "worker": record.get("worker", ""),
        "run_dir": str(Path("members") / member.name),
        "scene_sha256": member.scene_sha256,
        "parameters": member.parameters,
    }


def write_index(spec: SweepSpec, out: Path) -> list[dict]:
    """Write ``index.json`` and ``index.csv`` from the members' records; returns the rows."""
    rows = [_index_row(spec, m, out) for m in spec.members]
    write_json(
        out / INDEX_JSON,
        {"sweep": spec.name, "scene": spec.scene, "updated": now(), "members": rows},
    )
    keys = spec.parameter_keys
    fd, tmp = tempfile.mkstemp(dir=out, prefix=f".{INDEX_CSV}.", suffix=".tmp")
    with os.fdopen(fd, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["name", "status", "seconds", "error", *keys, "run_dir"])
        for r in rows:
            seconds = "" if r["seconds"] is None else f"{r['seconds']:.2f}"
            values = [r["parameters"].get(k, "") for k in keys]
            writer.writerow([r["name"], r["status"], seconds, r["error"], *values, r["run_dir"]])
    os.replace(tmp, out / INDEX_CSV)
    return rows


def read_index(out: str | Path) -> dict:
    """``DIR/index.json`` of a sweep: ``{"sweep", "scene", "updated", "members": [rows]}``."""
    path = Path(out) / INDEX_JSON
    data = read_json(path)
    if data is None:
        raise SweepError(f"{path} does not exist or is not readable: not a sweep directory")
    return data


def _plan(spec: SweepSpec, out: Path, overwrite: bool) -> tuple[list[Member], list[str], dict]:
    """Members to run, members done, and why each one to run runs (for the progress lines).
    Every member's folder is resolved and checked to lie in ``out/members`` first
    (:func:`~dem_taichi.sweep_member.checked_member_dir`)."""
    to_run, done, why = [], [], {}
    stale = []
    for m in spec.members:
        folder = checked_member_dir(out, m.name)
        record = read_json(folder / MEMBER_RECORD)
        status = None if record is None else record.get("status")
        if status == "done" and (folder / "summary.json").exists():
            if record.get("scene_sha256") == m.scene_sha256:
                done.append(m.name)
                continue
            if not overwrite:
                stale.append(m.name)
                continue
            why[m.name] = "done with another scene; --overwrite: running it again"
            write_json(folder / MEMBER_RECORD, dict(record, status="stale"))
        elif record is None and folder.exists() and any(folder.iterdir()):
            raise SweepError(
                f"{folder} holds files not written by a sweep: move them or use a new --out"
            )
        elif status == "failed":
            why[m.name] = f"failed before ({record.get('error', '?')}); {_restart(folder, m)}"
        elif status is not None:
            why[m.name] = f"unfinished; {_restart(folder, m)}"
        to_run.append(m)
    if stale:
        raise SweepError(
            f"member(s) {', '.join(stale)} in {out} were run with another scene than the sweep "
            "file now gives them: use a new --out, or --overwrite to run them again"
        )
    return to_run, done, why


def _restart(folder: Path, member: Member) -> str:
    """How a member run before starts again (what :func:`run_member` will do)."""
    if can_resume(folder, member.scene_sha256):
        return "resumes from its saved state A and finished branches"
    return "it had not saved state A: runs again from the gas"


def _first_line(spec: SweepSpec, done: list[str], to_run: list[Member], why: dict) -> str:
    """The sweep's first progress line: a fresh start, or a resume saying what was done."""
    total = len(spec.members)
    if not done and not why:
        return f"sweep {spec.name}: {total} members, {len(to_run)} to run"
    counts = {
        kind: sum(reason.startswith(kind) for reason in why.values())
        for kind in ("unfinished", "failed", "done")
    }
    new = len(to_run) - sum(counts.values())
    return (
        f"sweep {spec.name}: resuming: {len(done)} of {total} members done before (skipped), "
        f"{len(to_run)} to run ({counts['unfinished']} unfinished, {counts['failed']} failed, "
        f"{counts['done']} changed, {new} not started)"
    )


def _local_cluster(n_workers: int, dashboard: str | None):
    """A ``LocalCluster`` of ``n_workers`` spawned processes of one thread, on 127.0.0.1.

    Without ``dashboard`` no HTTP service is offered: Dask's scheduler always opens an HTTP
    server (on port 8787 even with ``dashboard_address=None``, with its JSON, info, proxy and
    metrics routes); here it gets no routes and an ephemeral port on 127.0.0.1, and the
    workers' HTTP servers no routes either. ``dashboard`` (e.g. ``"127.0.0.1:8787"``) opts in to
    Dask's dashboard at that address."""
    import dask
    from distributed import LocalCluster

    settings = {
        "distributed.worker.multiprocessing-method": "spawn",  # never fork Taichi
        "distributed.worker.daemon": False,  # a member may spawn its branch processes
        "distributed.scheduler.allowed-failures": 1,  # a crashing member: one retry
    }
    if dashboard is None:
        settings["distributed.scheduler.http.routes"] = []
        settings["distributed.worker.http.routes"] = []
    with dask.config.set(settings):
        return LocalCluster(
            n_workers=n_workers,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=dashboard,
            scheduler_kwargs={
                "dashboard": dashboard is not None,
                "dashboard_address": dashboard or "127.0.0.1:0",
            },
            silence_logs=40,  # errors only: the sweep prints its own progress
        )


def _cluster(
    scheduler: str | None,
    n_workers: int | None,
    spec: SweepSpec,
    n_tasks: int,
    security=None,
    dashboard: str | None = None,
):
    """The client, the local cluster (None with ``scheduler``) and a line saying where."""
    from distributed import Client

    if scheduler:
        client = Client(scheduler, security=security) if security else Client(scheduler)
        how = "TLS" if security else "unencrypted, unauthenticated"
        return client, None, f"scheduler {scheduler} ({how})"
    if n_workers is None:
        n_workers = max(1, (os.cpu_count() or 1) // spec.workers)
    n_workers = max(1, min(n_workers, n_tasks))
    cluster = _local_cluster(n_workers, dashboard)
    where = f"LocalCluster ({n_workers} process{'es' if n_workers > 1 else ''} × 1 thread)"
    if dashboard is not None:
        where += f", dashboard {cluster.dashboard_link}"
    return Client(cluster), cluster, where


class _DeferredSignals:
    """Holds SIGINT/SIGTERM back while the cluster starts (in the main thread only), then
    :meth:`deliver` hands a signal received meanwhile to the handler it would have gone to."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.received: int | None = None
        self._previous: dict[int, Any] = {}

    def _record(self, signum: int, frame) -> None:
        if self.received is None:
            self.received = signum

    def __enter__(self) -> _DeferredSignals:
        if threading.current_thread() is threading.main_thread():
            self._previous = {s: signal.signal(s, self._record) for s in self.SIGNALS}
        return self

    def __exit__(self, *exc) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)

    def deliver(self) -> None:
        """Call the previous handler of the signal received while held back, if any."""
        if self.received is None:
            return
        handler = self._previous.get(self.received)
        if callable(handler):
            handler(self.received, None)
        elif handler == signal.SIG_DFL:
            if self.received == signal.SIGINT:
                raise KeyboardInterrupt
            os.kill(os.getpid(), self.received)


def run_sweep(
    spec: SweepSpec,
    out_dir: str | Path,
    scheduler: str | None = None,
    n_workers: int | None = None,
    overwrite: bool = False,
    verbose: bool = False,
    say=print,
    command: str = "dem_taichi.sweep.run_sweep",
    security=None,
    dashboard: str | None = None,
) -> SweepOutcome:
    """Run the members of ``spec`` that are not done into ``out_dir`` (see the module
    docstring); returns the outcome with every member's index row. ``say`` prints a progress
    line (``print`` by default); ``verbose`` also forwards each member's protocol lines.
    ``security``: a ``distributed.security.Security`` for ``scheduler`` (TLS; see the module
    docstring); ``dashboard``: an address for the local cluster's Dask dashboard (default none).
    A ``KeyboardInterrupt`` (SIGINT, or SIGTERM turned into one by the command line) closes the
    cluster, writes the index and is raised again: a re-run resumes the unfinished members."""
    from distributed import as_completed

    start = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    to_run, done, why = _plan(spec, out, overwrite)
    (out / "sweep.toml").write_text(spec.source_text)
    write_json(
        out / "sweep.json",
        {
            "sweep": spec.name,
            "scene": spec.scene,
            "arch": spec.arch,
            "precision": spec.precision,
            "workers": spec.workers,
            "members": [
                {"name": m.name, "parameters": m.parameters, "overrides": m.overrides,
                 "scene_sha256": m.scene_sha256}
                for m in spec.members
            ],
        },
    )  # fmt: skip
    write_index(spec, out)
    outcome = SweepOutcome(out, [], ran=[m.name for m in to_run], skipped=done)
    say(_first_line(spec, done, to_run, why))
    for name, reason in why.items():
        say(f"  {name}: {reason}")
    if not to_run:
        outcome.rows = write_index(spec, out)
        return outcome

    def stamp() -> str:
        return f"[{time.perf_counter() - start:7.1f} s]"

    folders = {str(checked_member_dir(out, m.name)) for m in to_run}

    def on_event(event) -> None:
        msg = event[1] if isinstance(event, tuple) else event
        if not isinstance(msg, dict):
            return
        if msg.get("folder", "") not in folders:  # another sweep on the same scheduler
            return
        if msg.get("kind") == "started":
            say(f"{stamp()} {msg['member']}: started ({msg.get('text', '')})")
            with contextlib.suppress(OSError):
                write_index(spec, out)  # the index shows the member running
        elif msg.get("kind") == "line" and verbose:
            say(f"{stamp()}   {msg['member']}: {msg.get('text', '')}")

    deferred = _DeferredSignals()
    with deferred:  # a cluster half started cannot be closed: its signal waits until it is up
        client, cluster, where = _cluster(
            scheduler, n_workers, spec, len(to_run), security=security, dashboard=dashboard
        )
    try:
        deferred.deliver()
        say(f"{stamp()} running on {where}")
        with contextlib.suppress(Exception):
            client.subscribe_topic(TOPIC, on_event)
        futures = {}
        for m in to_run:
            folder = checked_member_dir(out, m.name)
            future = client.submit(
                run_member,
                m.name,
                m.scene_toml,
                str(folder),
                spec.arch,
                spec.precision,
                spec.workers,
                f"{command} (member {m.name})",
                str(out.resolve()),
                key=f"sweep-member-{m.name}-{os.urandom(4).hex()}",
                pure=False,
            )
            futures[future] = m
        finished = 0
        for future in as_completed(futures):
            m = futures[future]
            finished += 1
            try:
                record = future.result()
            except Exception as exc:  # noqa: BLE001 - the worker died or the task was lost
                record = {
                    "name": m.name,
                    "status": "failed",
                    "error": f"{type(exc).__name__}: {exc}".splitlines()[0],
                    "traceback": "".join(traceback.format_exception(exc)),
                    "scene_sha256": m.scene_sha256,
                    "finished": now(),
                }
                write_json(member_dir(out, m.name) / MEMBER_RECORD, record)
            write_index(spec, out)
            count = f"({finished}/{len(to_run)})"
            if record["status"] == "done":
                say(f"{stamp()} {m.name}: done in {record['seconds']:.1f} s {count}")
            elif record["status"] == "skipped":  # its folder's run lock is held by a live run
                say(f"{stamp()} {m.name}: SKIPPED: {record['error']} {count}")
            else:
                say(f"{stamp()} {m.name}: FAILED: {record['error']} {count}")
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
        with contextlib.suppress(OSError):
            write_index(spec, out)  # an interrupted sweep's index shows its running members
    outcome.rows = write_index(spec, out)
    outcome.seconds = time.perf_counter() - start
    failed = outcome.failed
    say(
        f"sweep {spec.name}: {len(outcome.done)} done, {len(failed)} failed"
        f"{' (' + ', '.join(failed) + ')' if failed else ''} in {outcome.seconds:.1f} s; "
        f"index {out / INDEX_JSON}"
    )
    return outcome


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
        self._previous: dict[int, object] = {}

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
    from dem_taichi.sweep_results import summarise_sweep

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
    from tiv_model.command_line import ArgumentParser, add_common_flags, int_in_range

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
    allowed; the traceback with ``--debug``; :mod:`tiv_model.command_line`), 128 + N stopped
    by signal N (130 SIGINT, 143 SIGTERM; a re-run resumes)."""
    from tiv_model.command_line import run_command

    return run_command(prog, lambda args: _main(args, prog), argv, user_errors=(SweepError,))


if __name__ == "__main__":
    sys.exit(main())
