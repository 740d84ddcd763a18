"""Batches on a Dask cluster: the executor behind ``--scheduler`` (docs/cluster.md).

``--scheduler tcp://HOST:PORT`` connects to a running Dask scheduler (``dask scheduler`` on
one machine, ``dask worker tcp://HOST:PORT`` on each machine with flexmech installed);
``--scheduler local:N`` starts a Dask ``LocalCluster`` of N single-threaded worker processes
on this machine for the batch.  The optional package ``distributed`` (``pip install
'flexmech[cluster]'``) is imported here only, and only when a scheduler is asked for.

The tasks are flexmech's module functions, sent by name: every worker must have the same
flexmech version installed (checked when connecting).  Results travel back to this
process, which writes the cache and the tables (:func:`flexmech_py.run.parallel.run_tasks`).
A worker that dies loses no result: the scheduler runs its tasks again on another worker.
The scheduler announces every worker that leaves with the tasks it takes back from it (its
``remove-worker`` event); those of the batch are its retries.  A task whose workers died
``distributed.scheduler.allowed-failures + 1`` times (default 4) becomes a ``WorkerLost`` error
result (not cached).
"""

from __future__ import annotations

import contextlib
import logging
import re
import sys
import uuid
from collections import Counter

from ..base.errors import CaseError, FlexmechError
from .worker import call_task, default_jobs, worker_lost
from ..base.version import __version__

__all__ = ["DaskExecutor", "SchedulerLost", "parse_scheduler", "CONNECT_TIMEOUT_S"]

#: seconds to wait for a scheduler to answer (a wrong address fails this quickly)
CONNECT_TIMEOUT_S = 3.0
#: seconds to wait for a scheduler without workers to get its first one
WORKER_WAIT_S = 10.0
_ADDRESS = re.compile(r"^[a-z][a-z0-9+.-]*://\S+:\d+$")


def parse_scheduler(text: str) -> tuple[str, object]:
    """``("local", N)`` for ``local:N`` (``local``: N = every core), ``("address", text)`` for
    ``tcp://HOST:PORT`` (any Dask protocol, e.g. ``tls://``); CaseError otherwise."""
    text = str(text).strip()
    if text == "local" or text.startswith("local:"):

        n = text.partition(":")[2]
        if n and (not n.isdigit() or int(n) < 1):
            raise CaseError("--scheduler", f"{text!r}: local:N needs a whole number N >= 1 of worker processes")
        return "local", int(n) if n else default_jobs()
    if not _ADDRESS.match(text):
        raise CaseError("--scheduler", f"{text!r} must be a Dask scheduler address tcp://HOST:PORT, or local:N "
                                       "for N worker processes on this machine")
    return "address", text


def _import_distributed():
    try:
        import distributed
    except ImportError:
        raise FlexmechError("--scheduler needs the optional package 'distributed': pip install 'flexmech[cluster]' "
                            "(or leave out --scheduler to use the local process pool)") from None
    return distributed


def _flexmech_version() -> str:
    return __version__


def _quiet_logs() -> dict:
    """Silence Dask's loggers below CRITICAL (its own levels per module included); {name: old level}."""
    names = ["distributed"] + [n for n in logging.root.manager.loggerDict if n.startswith("distributed.")]
    levels = {n: logging.getLogger(n).level for n in names}
    for n in names:
        logging.getLogger(n).setLevel(logging.CRITICAL)
    return levels


class SchedulerLost(FlexmechError):
    """The Dask scheduler went away during a batch (exit code 3: the batch started; every result that
    had arrived is in the cache, so the same command goes on from there)."""

    exit_code = 3

    def __init__(self, address: str, done: int, total: int, why):
        super().__init__(f"--scheduler {address}: the Dask scheduler stopped answering during the batch "
                         f"({type(why).__name__}) after {done} of {total} tasks; the finished ones are cached: start "
                         "the scheduler again (or leave out --scheduler) and run the same command to go on")


class DaskExecutor:
    """Runs :func:`~flexmech_py.run.parallel.run_tasks` batches on a Dask cluster; connects when made."""

    def __init__(self, scheduler: str):
        kind, value = parse_scheduler(scheduler)
        distributed = _import_distributed()
        self._cluster = None
        self._levels = _quiet_logs()   # a scheduler that goes away is one line of ours, not Dask's tracebacks
        if kind == "local":
            self._cluster = distributed.LocalCluster(n_workers=value, threads_per_worker=1, processes=True,
                                                     dashboard_address=None, silence_logs=logging.ERROR)
            address, self.description = self._cluster.scheduler_address, f"a Dask LocalCluster of {value} processes"
        else:
            address, self.description = value, f"the Dask scheduler {value}"
        self.address = address
        try:
            self.client = distributed.Client(address, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            self._close_cluster()
            self._restore_logs()
            raise FlexmechError(f"--scheduler {value}: no Dask scheduler answers there within "
                                f"{CONNECT_TIMEOUT_S:g} s ({type(exc).__name__}); start one with `dask scheduler` "
                                "or check the address") from None
        try:
            self.workers = self._check_workers(address)
        except BaseException:
            self.close()
            raise
        self.description += f" ({self.workers} workers)"

    def _check_workers(self, address: str) -> int:
        """The number of workers, once every one runs this flexmech version; FlexmechError if not."""
        try:
            self.client.wait_for_workers(1, timeout=WORKER_WAIT_S)
        except (TimeoutError, OSError):
            raise FlexmechError(f"--scheduler {address}: the scheduler has no workers after {WORKER_WAIT_S:g} s; "
                                f"start some with `dask worker {address}`") from None
        try:
            found = self.client.run(_flexmech_version)
        except Exception as exc:   # a worker without flexmech cannot even unpickle the function
            raise FlexmechError(f"--scheduler {address}: a worker cannot run flexmech ({type(exc).__name__}: {exc}); "
                                f"install flexmech {__version__} on every worker machine") from None
        wrong = {w: v for w, v in found.items() if v != __version__}
        if wrong:
            w, v = next(iter(wrong.items()))
            raise FlexmechError(f"--scheduler {address}: worker {w} runs flexmech {v}, this machine {__version__}; "
                                "install the same version everywhere (results would differ)")
        threads = {w: n for w, n in self.client.nthreads().items() if n > 1}
        if threads:
            print(f"flexmech: warning: {len(threads)} Dask worker(s) run several threads (e.g. {next(iter(threads))}: "
                  f"{next(iter(threads.values()))}); flexmech's tasks hold the GIL, start workers with "
                  "`dask worker ADDRESS --nthreads 1 --nworkers N`", file=sys.stderr)
        return len(found)

    def run(self, func, todo: list, finish) -> tuple[int, int]:
        """Run ``todo`` [(index, task)], calling ``finish(index, result, seconds, worker)`` as each
        result arrives; returns (retries, workers)."""
        from distributed import as_completed
        from distributed.scheduler import KilledWorker

        prefix = f"flexmech-{getattr(func, '__name__', 'task')}-{uuid.uuid4().hex[:12]}-"
        reruns, given_up = Counter(), 0

        def count(event):   # the scheduler's word on every worker that left: the tasks it takes back
            msg = event[1]
            if isinstance(msg, dict) and msg.get("action") == "remove-worker":
                for key in (*msg.get("processing-tasks", ()), *msg.get("lost-computed-tasks", ())):
                    if isinstance(key, str) and key.startswith(prefix):
                        reruns[key] += 1

        self.client.subscribe_topic("all", count)
        futures = {self.client.submit(call_task, func, task, key=f"{prefix}{i}"): i for i, task in todo}
        try:   # results are fetched in the background as tasks end (with_results), not one round trip each
            for fut, res in as_completed(list(futures), loop=self.client.loop, with_results=True, raise_errors=False):
                i = futures.pop(fut)
                if fut.status == "finished":
                    finish(i, *res)
                elif fut.status == "error" and isinstance(fut.exception(), KilledWorker):
                    given_up += 1
                    finish(i, worker_lost(reruns[fut.key]), 0.0, "", store=False)
                elif fut.status == "error":
                    fut.result()   # a bug in the task: raise it here, with its traceback
                else:              # cancelled or lost: the scheduler went away
                    raise SchedulerLost(self.address, len(todo) - len(futures) - 1, len(todo), res)
                fut.release()
        except BaseException:
            with contextlib.suppress(Exception):
                self.client.cancel(list(futures))
            raise
        finally:
            with contextlib.suppress(Exception):
                self.client.unsubscribe_topic("all")
        return sum(reruns.values()) - given_up, len(self.client.nthreads())

    def _close_cluster(self) -> None:
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    def close(self) -> None:
        with contextlib.suppress(Exception):    # a scheduler that went away cannot be told goodbye
            self.client.close(timeout=CONNECT_TIMEOUT_S)
        self._close_cluster()
        self._restore_logs()

    def _restore_logs(self) -> None:
        for name, level in self._levels.items():
            logging.getLogger(name).setLevel(level)
        self._levels = {}

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
