"""The one parallel runner behind every multi-run command (sweep, stability, accuracy, compare --models).

``run_tasks(func, tasks)`` calls ``func(task)`` for every task on an *executor*, shows a
progress bar on stderr and returns the results in task order. Each task is a
JSON-serialisable dict; ``func`` a module-level function returning a JSON-serialisable
dict. With ``cache_dir`` every finished result is stored as one JSON file named by a
hash of (function, task); a later call with the same cache directory reuses it, so an
interrupted batch resumes where it stopped and a finished one costs nothing.

Executors (one interface: ``workers``, ``description``, ``run(func, todo, finish)``, a
context manager):

* :class:`LocalPool` -- the embedded default: worker processes on this machine (``jobs``,
  default every core; ``jobs = 1`` runs in this process). Nothing to start.
* :class:`flexmech_py.run.cluster.DaskExecutor` -- an existing Dask cluster
  (``scheduler="tcp://HOST:PORT"``) or a Dask ``LocalCluster`` started for the batch
  (``scheduler="local:N"``); needs the optional ``distributed`` (``pip install
  'flexmech[cluster]'``), imported only then.

Whatever the executor, every result travels back to this process, which writes the
cache and the tables: results are identical whichever executor ran them, and the cache
works when the workers run on other machines. Each result comes with its run time and
the worker that ran it (``host:pid``).

A task that fails with a :class:`~flexmech_py.base.errors.FlexmechError` (bad input, solver
failure) is a result, not a crash: its entry is ``{"error": message, "error_type": name}``
(cached like any result: the same inputs fail the same way). Any other exception is a
bug and stops the batch. A worker process that dies (killed, out of memory) loses no
result: the tasks it held run again elsewhere (``Batch.retries`` counts them); a task
whose workers died ``MAX_WORKER_DEATHS`` times becomes an error result of type
``WorkerLost`` (not cached). Ctrl-C (or SIGTERM, SIGHUP) stops the batch and its workers at once;
what finished stays cached.  The local workers end with the process that started them, even when
it is killed outright (:func:`~flexmech_py.base.signals.die_with_parent`).
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import hashlib
import json
import multiprocessing
import os
import sys
import time
from collections import Counter, deque
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path

from ..base.errors import CaseError
from ..base.signals import die_with_parent
from .worker import call_task, default_jobs, worker_lost, worker_name  # noqa: F401 (re-exported)
from ..base.fileio import atomic_write, json_default
from .cluster import DaskExecutor

__all__ = ["run_tasks", "Batch", "LocalPool", "open_executor", "using_executor", "default_jobs", "task_key",
           "MAX_WORKER_DEATHS"]

# worker processes run one task each at a time: keep BLAS/OpenMP single-threaded in them
_SINGLE_THREAD_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}

#: a task in flight when its worker died this many times is given up (an error result)
MAX_WORKER_DEATHS = 3


@dataclass
class Batch:
    """Results of :func:`run_tasks` in task order, with what it cost."""

    results: list
    computed: int = 0          # tasks run in this call
    cached: int = 0            # tasks taken from the cache
    wall_s: float = 0.0        # wall time of this call [s]
    jobs: int = 1              # worker processes used
    task_s: list = field(default_factory=list)   # per-task run time [s] (cached: the time stored with it)
    task_worker: list = field(default_factory=list)   # per task: the worker that ran it, "host:pid"
    retries: int = 0           # tasks run again because their worker died
    executor: str = ""         # where the tasks ran, e.g. "2 local processes"

    @property
    def failed(self) -> list:
        """Indices of the tasks whose result is an error entry."""
        return [i for i, r in enumerate(self.results) if isinstance(r, dict) and "error" in r]


def task_key(func, task: dict) -> str:
    """Cache key of one task: a hash of the function's qualified name and the task's canonical JSON."""
    text = json.dumps({"func": f"{func.__module__}.{func.__qualname__}", "task": task}, sort_keys=True,
                      separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


class _Progress:
    """A one-line progress bar on stderr (a line per 10 % when stderr is not a terminal)."""

    def __init__(self, total: int, label: str, enabled: bool):
        self.total, self.label, self.enabled = total, label, enabled and total > 0
        self.tty = sys.stderr.isatty()
        self.t0 = time.perf_counter()
        self.last_decile = -1

    def update(self, done: int, cached: int) -> None:
        if not self.enabled:
            return
        el = time.perf_counter() - self.t0
        frac = done / self.total
        run_done = done - cached
        left = (el / run_done * (self.total - done)) if run_done > 0 else float("nan")
        text = (f"{self.label}: {done}/{self.total}" + (f" ({cached} cached)" if cached else "")
                + f"  {_clock(el)} elapsed" + (f", ~{_clock(left)} left" if left == left and done < self.total else ""))
        if self.tty:
            width = 30
            bar = "#" * int(round(width * frac)) + "." * (width - int(round(width * frac)))
            sys.stderr.write(f"\r[{bar}] {text}\033[K")
            if done == self.total:
                sys.stderr.write("\n")
            sys.stderr.flush()
        else:
            decile = int(10 * frac)
            if decile != self.last_decile:
                self.last_decile = decile
                print(text, file=sys.stderr, flush=True)


def _clock(s: float) -> str:
    s = int(round(s))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


# ----------------------------------------------------------------------------- executors
class LocalPool:
    """The embedded default executor: ``jobs`` worker processes on this machine (default: every
    core); ``jobs = 1`` runs the tasks in this process (no worker start-up)."""

    def __init__(self, jobs: int | None = None):
        self.jobs = default_jobs() if jobs is None else int(jobs)
        if self.jobs < 1:
            raise ValueError(f"jobs must be >= 1, got {jobs}")

    @property
    def workers(self) -> int:
        return self.jobs

    @property
    def description(self) -> str:
        return "this process" if self.jobs == 1 else f"{self.jobs} local processes"

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        return None

    def run(self, func, todo: list, finish) -> tuple[int, int]:
        """Run ``todo`` [(index, task)], calling ``finish(index, result, seconds, worker)`` for each
        as it ends; returns (retries, worker processes used)."""
        nproc = min(self.jobs, max(1, len(todo)))
        if nproc == 1:
            for i, task in todo:
                finish(i, *call_task(func, task))
            return 0, 1
        with _single_threaded_workers():
            queue, deaths, retries, idle_breaks = deque(todo), Counter(), 0, 0
            while queue:
                before = len(queue)
                for i, task in reversed(_pool_pass(func, queue, finish, nproc)):   # a worker died
                    deaths[i] += 1
                    if deaths[i] >= MAX_WORKER_DEATHS:
                        finish(i, worker_lost(deaths[i]), 0.0, "", store=False)
                    else:
                        queue.appendleft((i, task))
                        retries += 1
                idle_breaks = idle_breaks + 1 if len(queue) == before else 0
                if idle_breaks > MAX_WORKER_DEATHS:
                    raise RuntimeError("the local worker processes keep dying before they run a task")
        return retries, nproc


@contextlib.contextmanager
def _single_threaded_workers():
    saved = {k: os.environ.get(k) for k in _SINGLE_THREAD_ENV}
    os.environ.update(_SINGLE_THREAD_ENV)   # inherited by the spawned workers
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _pool_pass(func, queue: deque, finish, nproc: int) -> list:
    """Run tasks from ``queue`` on a fresh process pool until it is empty or a worker dies; returns
    the tasks in flight when a worker died ([] when all finished).  At most one task per worker
    plus one waits in the pool, so few are run again after a death."""
    lost = []
    before = set(multiprocessing.active_children())
    with cf.ProcessPoolExecutor(max_workers=nproc, mp_context=multiprocessing.get_context("spawn"),
                                initializer=die_with_parent, initargs=(os.getpid(),)) as pool:
        flying, broken = {}, False
        try:
            while (queue or flying) and not (lost or broken):
                while queue and len(flying) <= nproc and not broken:
                    i, task = queue.popleft()
                    try:
                        flying[pool.submit(call_task, func, task)] = (i, task)
                    except BrokenProcessPool:   # a worker died while the pool was idle
                        queue.appendleft((i, task))
                        broken = True
                done, _ = cf.wait(flying, return_when=cf.FIRST_COMPLETED) if flying else ((), ())
                for fut in done:
                    if isinstance(fut.exception(), BrokenProcessPool):
                        lost.append(flying.pop(fut))
                    else:
                        finish(flying.pop(fut)[0], *fut.result())   # a bug in a task raises here
            for fut, (i, task) in flying.items():   # the pool is broken: keep what had finished
                if fut.done() and fut.exception() is None:
                    finish(i, *fut.result())
                else:
                    lost.append((i, task))
        except BaseException:   # Ctrl-C, SIGTERM, a bug: stop the workers now, not after their tasks
            pool.shutdown(wait=False, cancel_futures=True)
            for proc in set(multiprocessing.active_children()) - before:
                proc.terminate()
            raise
    return lost


def open_executor(scheduler=None, jobs: int | None = None):
    """The executor for ``scheduler``: None -- the local pool of ``jobs`` processes;
    ``"tcp://HOST:PORT"`` -- connect to that Dask scheduler; ``"local:N"`` -- start a Dask
    LocalCluster of N worker processes; an executor object -- itself.  Dask executors connect
    here (an address that does not answer fails now, before anything is written)."""
    if scheduler is None:
        return LocalPool(jobs)
    if hasattr(scheduler, "run"):
        return scheduler
    if jobs is not None:
        raise CaseError("--jobs", "sizes the local process pool; with --scheduler the cluster's workers run "
                                  "the tasks: give one of the two")

    return DaskExecutor(str(scheduler))


@contextlib.contextmanager
def using_executor(scheduler=None, jobs: int | None = None):
    """``with using_executor(scheduler, jobs) as ex``: the executor of :func:`open_executor`, closed on
    exit if it was opened here (an executor object passed in is used and left open)."""
    executor = open_executor(scheduler, jobs)
    if executor is scheduler:
        yield executor
    else:
        with executor:
            yield executor


# ----------------------------------------------------------------------------- the batch
def _from_cache(func, tasks: list, cache: Path | None):
    """(paths, {index: stored entry}) of the tasks already in the cache."""
    paths, stored = [None] * len(tasks), {}
    if cache is None:
        return paths, stored
    cache.mkdir(parents=True, exist_ok=True)
    for i, task in enumerate(tasks):
        paths[i] = cache / f"{task_key(func, task)}.json"
        if paths[i].exists():
            try:
                entry = json.loads(paths[i].read_text())
                stored[i] = (entry["result"], entry.get("seconds", 0.0), entry.get("worker", ""))
            except (ValueError, KeyError):   # a torn or foreign file: recompute it
                pass
    return paths, stored


def run_tasks(func, tasks: list, *, jobs: int | None = None, cache_dir: str | os.PathLike | None = None,
              progress: bool = True, label: str = "runs", scheduler=None) -> Batch:
    """Run ``func(task)`` for every task and return the results in task order.

    Where: ``scheduler`` None -- over ``jobs`` local processes (default: every core; ``jobs = 1``
    in this process); otherwise see :func:`open_executor` (a Dask scheduler address, ``local:N``,
    or an open executor, which is left open).  With ``cache_dir`` finished results are stored and
    reused (resumable). Ctrl-C stops the workers; what finished stays cached.
    """
    func_name = getattr(func, "__qualname__", "")
    if "<" in func_name:
        raise TypeError(f"run_tasks needs a module-level function (worker processes import it), got {func_name!r}")
    if jobs is not None and int(jobs) < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    t_start = time.perf_counter()
    with using_executor(scheduler, jobs) as executor:   # a Dask scheduler that does not answer fails here
        n = len(tasks)
        paths, stored = _from_cache(func, tasks, Path(cache_dir) if cache_dir is not None else None)
        results, task_s, task_worker = [None] * n, [0.0] * n, [""] * n
        for i, (res, sec, worker) in stored.items():
            results[i], task_s[i], task_worker[i] = res, sec, worker
        todo = [(i, tasks[i]) for i in range(n) if i not in stored]
        bar = _Progress(n, label, progress)
        done = len(stored)
        bar.update(done, len(stored))

        def finish(i, res, sec, worker, store=True):
            nonlocal done
            results[i], task_s[i], task_worker[i] = res, sec, worker
            if paths[i] is not None and store:
                atomic_write(paths[i], json.dumps({"task": tasks[i], "result": res, "seconds": sec, "worker": worker},
                                                   indent=1, default=json_default))
            done += 1
            bar.update(done, len(stored))

        retries, used = executor.run(func, todo, finish) if todo else (0, 0)
    return Batch(results=results, computed=len(todo), cached=len(stored), wall_s=time.perf_counter() - t_start,
                 jobs=max(1, used), task_s=task_s, task_worker=task_worker, retries=retries,
                 executor=executor.description)
