"""The one parallel runner behind every multi-run command (sweep, stability, accuracy).

``run_tasks(func, tasks)`` calls ``func(task)`` for every task in worker processes,
shows a progress bar on stderr and returns the results in task order. Each task is a
JSON-serialisable dict; ``func`` a module-level function returning a JSON-serialisable
dict. With ``cache_dir`` every finished result is stored as one JSON file named by a
hash of (function, task); a later call with the same cache directory reuses it, so an
interrupted batch resumes where it stopped and a finished one costs nothing.

A task that fails with a :class:`~flexmech_py.errors.FlexmechError` (bad input, solver
failure) is a result, not a crash: its entry is ``{"error": message, "error_type": name}``
(cached like any result: the same inputs fail the same way). Any other exception is a
bug and stops the batch.
"""

from __future__ import annotations

import concurrent.futures as cf
import hashlib
import json
import multiprocessing
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from .errors import FlexmechError
from .results import _atomic_write, _json_default

__all__ = ["run_tasks", "Batch", "default_jobs", "task_key"]

# worker processes run one task each at a time: keep BLAS/OpenMP single-threaded in them
_SINGLE_THREAD_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


@dataclass
class Batch:
    """Results of :func:`run_tasks` in task order, with what it cost."""

    results: list
    computed: int = 0          # tasks run in this call
    cached: int = 0            # tasks taken from the cache
    wall_s: float = 0.0        # wall time of this call [s]
    jobs: int = 1              # worker processes used
    task_s: list = field(default_factory=list)   # per-task run time [s] (cached: the time stored with it)

    @property
    def failed(self) -> list:
        """Indices of the tasks whose result is an error entry."""
        return [i for i, r in enumerate(self.results) if isinstance(r, dict) and "error" in r]


def default_jobs() -> int:
    """The cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def task_key(func, task: dict) -> str:
    """Cache key of one task: a hash of the function's qualified name and the task's canonical JSON."""
    text = json.dumps({"func": f"{func.__module__}.{func.__qualname__}", "task": task}, sort_keys=True,
                      separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def _call(func, task):
    """Run one task in a worker: (result, seconds)."""
    t0 = time.perf_counter()
    try:
        res = func(task)
    except FlexmechError as exc:
        res = {"error": str(exc), "error_type": type(exc).__name__}
    return res, time.perf_counter() - t0


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


def run_tasks(func, tasks: list, *, jobs: int | None = None, cache_dir: str | os.PathLike | None = None,
              progress: bool = True, label: str = "runs") -> Batch:
    """Run ``func(task)`` for every task, in parallel over ``jobs`` processes (default: every core).

    ``jobs = 1`` runs in this process (no worker start-up). Results come back in task
    order whatever order they finish in. With ``cache_dir`` finished results are stored
    and reused (resumable). Ctrl-C stops the workers; what finished stays cached.
    """
    func_name = getattr(func, "__qualname__", "")
    if "<" in func_name:
        raise TypeError(f"run_tasks needs a module-level function (worker processes import it), got {func_name!r}")
    jobs = default_jobs() if jobs is None else int(jobs)
    if jobs < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    t_start = time.perf_counter()
    n = len(tasks)
    results: list = [None] * n
    task_s = [0.0] * n
    cache = Path(cache_dir) if cache_dir is not None else None
    paths = [None] * n
    todo = []
    cached = 0
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
    for i, task in enumerate(tasks):
        if cache is not None:
            paths[i] = cache / f"{task_key(func, task)}.json"
            if paths[i].exists():
                try:
                    stored = json.loads(paths[i].read_text())
                    results[i], task_s[i] = stored["result"], stored.get("seconds", 0.0)
                    cached += 1
                    continue
                except (ValueError, KeyError):   # a torn or foreign file: recompute it
                    pass
        todo.append(i)
    bar = _Progress(n, label, progress)
    done = cached
    bar.update(done, cached)

    def finish(i, res, sec):
        nonlocal done
        results[i], task_s[i] = res, sec
        if paths[i] is not None:
            _atomic_write(paths[i], json.dumps({"task": tasks[i], "result": res, "seconds": sec}, indent=1,
                                                default=_json_default))
        done += 1
        bar.update(done, cached)

    jobs_used = min(jobs, max(1, len(todo)))
    if jobs_used == 1:
        for i in todo:
            finish(i, *_call(func, tasks[i]))
    elif todo:
        saved = {k: os.environ.get(k) for k in _SINGLE_THREAD_ENV}
        os.environ.update(_SINGLE_THREAD_ENV)   # inherited by the spawned workers
        try:
            ctx = multiprocessing.get_context("spawn")
            with cf.ProcessPoolExecutor(max_workers=jobs_used, mp_context=ctx) as pool:
                futures = {pool.submit(_call, func, tasks[i]): i for i in todo}
                try:
                    for fut in cf.as_completed(futures):
                        finish(futures[fut], *fut.result())
                except BaseException:
                    pool.shutdown(wait=False, cancel_futures=True)
                    raise
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
    return Batch(results=results, computed=len(todo), cached=cached, wall_s=time.perf_counter() - t_start,
                 jobs=jobs_used, task_s=task_s)
