"""Worker processes of a dataset run (:mod:`agents.dataset`) that die with the run.

A run holds its dataset's lock (``OUT/.lock``, :func:`topo.fileio.exclusive_lock`) and farms
episodes out to worker processes. Killed (even ``kill -9``), it must leave no worker behind
writing into a folder nobody holds, or idling forever. So each pool worker

* asks Linux to kill it when its parent, the run, dies (``prctl(PR_SET_PDEATHSIG, SIGKILL)``;
  the pool starts workers with ``spawn``, so that their parent is the run itself: a fork
  server's children keep the server alive);
* runs a watchdog thread that ends it once its parent process or the run is gone (every
  system, and the moment before the ``prctl``);
* checks before each write that the run still holds the lock (:func:`check_owner`).

Workers run with one BLAS/OpenMP thread (:data:`WORKER_ENV`): one episode per CPU. This module
imports nothing heavy, so that a worker is watched from its first moment.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

WORKER_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
"""Environment of worker processes (either backend): one BLAS/OpenMP thread per episode."""

WATCH_S = 0.5
"""How often a worker's watchdog looks for its parent and its run (seconds)."""

_PR_SET_PDEATHSIG = 1  # linux/prctl.h

Owner = tuple[int, str, str]
"""A run as its workers know it: ``(pid, host, lock file path)``."""

_OWNER: Owner | None = None
"""In a worker: the run whose lock it writes under (``None`` in the run's own process, which
holds the lock itself)."""


class RunGone(RuntimeError):
    """A worker found that the run that started it no longer holds the dataset's lock."""


@contextlib.contextmanager
def worker_env() -> Iterator[None]:
    """Set :data:`WORKER_ENV` while worker processes start (they inherit it), then restore."""
    saved = {k: os.environ.get(k) for k in WORKER_ENV}
    os.environ.update(WORKER_ENV)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def alive(pid: int) -> bool:
    """Whether process ``pid`` runs on this host (a zombie, dead but not yet reaped, does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True  # no /proc: os.kill is all there is


def owner(lock: str | Path) -> Owner:
    """This process as the owner of the lock file ``lock`` (what its workers check)."""
    return (os.getpid(), socket.gethostname(), str(lock))


def set_owner(run: Owner | None) -> None:
    """Record in this worker the run it writes for (:func:`check_owner`)."""
    global _OWNER
    _OWNER = run


def check_owner() -> None:
    """In a worker: raise :class:`RunGone` unless the run that started it still holds its
    lock, so that nothing is written without it (no-op in the run's own process)."""
    if _OWNER is None:
        return
    pid, host, path = _OWNER
    lock = Path(path)
    try:
        holder = json.loads(lock.read_text() or "{}")
    except (OSError, ValueError):
        holder = {}
    if (not isinstance(holder, dict) or (holder.get("pid"), holder.get("host")) != (pid, host)
            or (host == socket.gethostname() and not alive(pid))):
        raise RunGone(f"the run that started this worker (pid {pid} on {host}) no longer holds "
                      f"{lock}: nothing written")


def _watchdog(parent: int, owner: int) -> None:
    while os.getppid() == parent and alive(owner):
        time.sleep(WATCH_S)
    os._exit(1)


def worker_init(run: Owner) -> None:
    """Initializer of a pool worker of ``run`` (:func:`owner`): see the module docstring."""
    set_owner(run)
    parent = os.getppid()
    if sys.platform.startswith("linux"):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL))
    threading.Thread(target=_watchdog, args=(parent, run[0]), daemon=True,
                     name="run-watchdog").start()


def pool_results(fn: Callable[..., Any], calls: Sequence[tuple], workers: int,
                 lock: str | Path) -> Iterator[Any]:
    """``fn(*call)`` for every call on ``workers`` processes that die with this one and write
    only while it holds ``lock``, yielded as they complete. ``fn`` must be importable
    (top-level). On a failure no further call starts (the running ones end) and the error is
    raised."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    with worker_env(), ProcessPoolExecutor(
            max_workers=workers, mp_context=mp.get_context("spawn"), initializer=worker_init,
            initargs=(owner(lock),)) as pool:
        futures = [pool.submit(fn, *call) for call in calls]
        try:
            for fut in as_completed(futures):
                yield fut.result()
        finally:
            for fut in futures:
                fut.cancel()
