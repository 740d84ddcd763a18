"""The parallel runner: order, caching (resume), error capture, worker processes."""

import json

import pytest

from flexmech_py.case import validate_case
from flexmech_py.parallel import default_jobs, run_tasks, task_key


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
    assert b.results == tasks and b.jobs == 2
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
