"""The parallel runner: order, caching (resume), error capture, worker processes, a worker killed
in the local pool, and the optional Dask dependency (never imported without --scheduler)."""

import json
import multiprocessing
import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from flexmech_py.case import validate_case
from flexmech_py.cli import main
from flexmech_py.run.parallel import MAX_WORKER_DEATHS, default_jobs, run_tasks, task_key
from flexmech_py.studies.sweep import sweep

from conftest import CASES, interrupt_after_first_result

SEED = CASES / "fourbar_constant_speed.toml"


def _square(task):
    _square.calls += 1
    return {"x": task["x"], "y": task["x"] ** 2}


_square.calls = 0


def test_results_in_task_order_and_cached_on_resume(tmp_path):
    tasks = [{"x": x} for x in (3, 1, 2)]
    _square.calls = 0
    b = run_tasks(_square, tasks, jobs=1, cache_dir=tmp_path, progress=False)
    assert [r["y"] for r in b.results] == [9, 1, 4]
    assert (b.computed, b.cached, _square.calls) == (3, 0, 3)
    # an interrupted batch: one stored result removed, one task added; only those two run again
    (tmp_path / f"{task_key(_square, tasks[1])}.json").unlink()
    b2 = run_tasks(_square, tasks + [{"x": 5}], jobs=1, cache_dir=tmp_path, progress=False)
    assert [r["y"] for r in b2.results] == [9, 1, 4, 25]
    assert (b2.computed, b2.cached, _square.calls) == (2, 2, 5)
    stored = json.loads((tmp_path / f"{task_key(_square, {'x': 5})}.json").read_text())
    assert stored["task"] == {"x": 5} and stored["result"]["y"] == 25


def test_torn_cache_file_is_recomputed(tmp_path):
    (tmp_path / f"{task_key(_square, {'x': 4})}.json").write_text("{not json")
    b = run_tasks(_square, [{"x": 4}], jobs=1, cache_dir=tmp_path, progress=False)
    assert b.results[0]["y"] == 16 and b.computed == 1


def test_worker_processes_give_the_same_results_and_capture_user_errors():
    # dict() copies its task; validate_case raises CaseError on a broken case: a result, not a crash
    tasks = [{"x": i} for i in range(5)]
    b = run_tasks(dict, tasks, jobs=2, progress=False)
    assert b.results == tasks and b.jobs == 2 and b.retries == 0 and b.executor == "2 local processes"
    # each task names the worker process that ran it: two spawned processes, not this one
    workers = set(b.task_worker)
    assert len(workers) <= 2 and f":{os.getpid()}" not in "".join(workers) and all(t >= 0 for t in b.task_s)
    bad = run_tasks(validate_case, [{"links": 1}, {"nonsense": 2}], jobs=2, progress=False)
    assert bad.failed == [0, 1]
    assert all(r["error_type"] == "CaseError" and r["error"] for r in bad.results)


def test_bugs_are_not_swallowed_and_local_functions_are_refused():
    def local(task):
        return task
    with pytest.raises(TypeError, match="module-level"):
        run_tasks(local, [{}], jobs=1)
    with pytest.raises(ZeroDivisionError):
        run_tasks(_divide, [{"x": 0}], jobs=1, progress=False)
    assert default_jobs() >= 1


def _divide(task):
    return {"y": 1 / task["x"]}


def test_a_local_worker_killed_during_the_batch_loses_no_result(tmp_path):
    out = tmp_path / "k"
    before = set(multiprocessing.active_children())
    killed = []

    def kill_after_the_first_result():
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not killed:
            pool = set(multiprocessing.active_children()) - before
            if pool and list((out / "cache").glob("*.json")):
                os.kill(next(iter(pool)).pid, signal.SIGKILL)
                killed.append(True)
            time.sleep(0.005)

    params, ov = ["drive.speed=80:120:8"], ["solver.t_end=0.1", "mesh.elements_per_link=4"]
    th = threading.Thread(target=kill_after_the_first_result)
    th.start()
    sw = sweep(SEED, params, overrides=ov, jobs=2, out_dir=out, progress=False)
    th.join()
    b = sw["batch"]
    assert killed, "the batch ended before a result arrived"
    assert b.retries >= 1 and not b.failed and b.computed == 8
    # the results are those of an undisturbed run (cached rows are reused: remove the cache)
    ref = sweep(SEED, params, overrides=ov, jobs=1, out_dir=tmp_path / "ref", progress=False)
    for a, c in zip(b.results, ref["batch"].results):
        assert a["strain_coupler_mid_maxabs"] == c["strain_coupler_mid_maxabs"] and a["steps"] == c["steps"]


def test_scheduler_without_distributed_names_the_extra(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)    # `import distributed` now fails
    rc = main(["sweep", str(SEED), "--param", "drive.speed=100,110", "--set", "solver.t_end=0.005",
               "--scheduler", "local:2", "--out", str(tmp_path / "never")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "pip install 'flexmech[cluster]'" in err
    assert not (tmp_path / "never").exists()


def test_no_command_without_scheduler_imports_dask(tmp_path):
    code = ("import importlib, pkgutil, sys, flexmech_py; from flexmech_py.cli import main; "
            "[importlib.import_module('flexmech_py.' + m.name) "
            " for m in pkgutil.iter_modules(flexmech_py.__path__) if m.name != '__main__']; "
            f"rc = main(['sweep', {str(SEED)!r}, '--param', 'drive.speed=100,110', '--set', 'solver.t_end=0.005', "
            f"'--jobs', '2', '--out', {str(tmp_path / 'sw')!r}]); "
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')); "
            "print(rc, bad); sys.exit(rc or len(bad))")
    env = {k: v for k, v in os.environ.items() if k != "FLEXMECH_SCHEDULER"}
    p = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, env=env, timeout=120)
    assert p.returncode == 0, p.stdout + p.stderr
    assert p.stdout.strip().endswith("0 []")


def test_ctrl_c_keeps_the_finished_results(tmp_path):
    argv = ["sweep", str(SEED), "--param", "drive.speed=80:120:12", "--set", "solver.t_end=0.1", "--jobs", "2"]
    rc, kept = interrupt_after_first_result(argv, tmp_path / "sw", tmp_path)
    assert rc == 130 and 1 <= kept < 12
    assert main(argv + ["--out", str(tmp_path / "sw")]) == 0      # the rerun computes only the rest
    assert json.loads((tmp_path / "sw" / "sweep.json").read_text())["cached"] == kept


def test_a_task_that_kills_its_worker_every_time_is_given_up():
    # os._exit(0) ends the worker process that runs it: each pool dies, the tasks are retried
    # MAX_WORKER_DEATHS - 1 times and then become WorkerLost error entries; the batch completes
    b = run_tasks(os._exit, [0, 0], jobs=2, progress=False)
    assert b.failed == [0, 1] and all(r["error_type"] == "WorkerLost" for r in b.results)
    assert b.retries == 2 * (MAX_WORKER_DEATHS - 1) and "died 3 times" in b.results[0]["error"]
