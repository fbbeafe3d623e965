"""The sweep's client: plan the members, start or join a Dask cluster, run them, write the index.

Split from :mod:`dem_taichi.sweep.command` (the command line and the public names, whose docstring
describes sweeps); the members themselves run in :mod:`dem_taichi.sweep.member`.
"""

from __future__ import annotations

import contextlib
import csv
import os
import signal
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dem_taichi.sweep.member import (
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
from dem_taichi.sweep.spec import Member, SweepError, SweepSpec

INDEX_JSON = "index.json"
INDEX_CSV = "index.csv"

__all__ = ["INDEX_JSON", "INDEX_CSV", "SweepOutcome", "run_sweep", "read_index", "write_index"]


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
    (:func:`~dem_taichi.sweep.member.checked_member_dir`)."""
    to_run, done, why = [], [], {}
    stale = []
    for m in spec.members:
        folder = checked_member_dir(out, m.name)
        record = read_json(folder / MEMBER_RECORD)
        status = None if record is None else record.get("status")
        if record is not None and status == "done" and (folder / "summary.json").exists():
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
        elif record is not None and status == "failed":
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
    from dem_taichi.protocol.resume import stage_a_file

    if can_resume(folder, member.scene_sha256):
        if not stage_a_file(folder).exists():
            return "resumes from its last save inside the ageing stage (state A not reached)"
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
    # the run record's name (kept from the flat layout: older runs resume)
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
