"""What a worker process does with one task, the same for every executor (the local pool of
:mod:`flexmech_py.run.parallel` and the Dask executor of :mod:`flexmech_py.run.cluster`): run it, time it,
say where it ran, and turn a user-caused failure into a result."""

from __future__ import annotations

import os
import socket
import time

from ..base.errors import FlexmechError
from ..base.notices import silenced

__all__ = ["call_task", "default_jobs", "worker_lost", "worker_name"]


def default_jobs() -> int:
    """The cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def worker_name() -> str:
    """The process running a task, as ``host:pid`` (the same form for every executor)."""
    return f"{socket.gethostname()}:{os.getpid()}"


def call_task(func, task):
    """Run one task in a worker: (result, seconds, worker).  A FlexmechError (bad input, a solver that
    stopped) is a result ``{"error": message, "error_type": name}``, not a crash."""
    t0 = time.perf_counter()
    try:
        with silenced():           # a batch reports its runs' warnings from their results
            res = func(task)
    except FlexmechError as exc:
        res = {"error": str(exc), "error_type": type(exc).__name__}
    return res, time.perf_counter() - t0, worker_name()


def worker_lost(deaths: int) -> dict:
    """The error result of a task whose worker died ``deaths`` times while running it."""
    return {"error": f"its worker process died {deaths} times while running it (out of memory, or a crash in "
                     "the compiled kernels?); rerun the command to try it again", "error_type": "WorkerLost"}
