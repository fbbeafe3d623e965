"""Worker processes that die with their parent.

Why: the protocol's branches run in spawned worker processes
(:func:`dem_taichi.protocol.branches.run_branches_in_processes`). When the parent is killed with a
signal it cannot handle (``kill -9``, the out-of-memory killer), a worker would otherwise go
on for hours, holding the parent's output pipes and a CPU, and writing into the run folder.

:func:`die_with_parent` is the workers' initializer (``ProcessPoolExecutor(initializer=...)``):

- on Linux, ``prctl(PR_SET_PDEATHSIG, SIGTERM)`` (through ctypes): the kernel sends the worker
  SIGTERM when its parent dies;
- everywhere, a daemon thread that polls ``os.getppid()`` every ``poll_seconds`` and ends the
  process (``os._exit``) once the parent is no longer the one that started it (an orphan is
  re-parented), for systems without prctl and for a parent that died before prctl was set.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import sys
import threading
import time

__all__ = ["die_with_parent", "set_parent_death_signal", "EXIT_PARENT_GONE"]

PR_SET_PDEATHSIG = 1  # linux/prctl.h
#: Exit code of a worker ended by the watchdog: 128 + SIGTERM, as if the signal had killed it.
EXIT_PARENT_GONE = 128 + int(signal.SIGTERM)


def set_parent_death_signal(signum: int = signal.SIGTERM) -> bool:
    """Ask the Linux kernel to send ``signum`` to this process when its parent dies; returns
    whether it was set (False off Linux or where prctl is unavailable)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, int(signum), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watch_parent(parent_pid: int, poll_seconds: float) -> None:
    while os.getppid() == parent_pid:
        time.sleep(poll_seconds)
    os._exit(EXIT_PARENT_GONE)  # the parent is gone: nobody will read what this process makes


def die_with_parent(parent_pid: int, poll_seconds: float = 0.5) -> None:
    """Make this (worker) process end when ``parent_pid``, the process that started it, dies:
    the kernel's parent-death signal where there is one, and a watchdog thread everywhere."""
    set_parent_death_signal(signal.SIGTERM)
    if os.getppid() != parent_pid:  # died before the death signal was set
        os._exit(EXIT_PARENT_GONE)
    watchdog = threading.Thread(
        target=_watch_parent, args=(parent_pid, poll_seconds), name="parent-watchdog", daemon=True
    )
    watchdog.start()
