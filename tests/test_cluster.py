"""Batches on a real Dask cluster (flexmech_py/run/cluster.py): a ``distributed.LocalCluster`` of 2
worker processes started here.  The same table as the local pool, bit for bit; a worker killed
during a batch loses no result; a scheduler that does not answer is one line and exit 2.

Reduced size: the seed four-bar at constant speed over a few ms per point (a few tenths of a
second per point where a batch must still be running when a worker is killed).
"""

from __future__ import annotations

import csv
import os
import signal
import socket
import threading
import time

import pytest

from flexmech_py import load_case, validate_case
from flexmech_py.cli import main
from flexmech_py.run.cluster import DaskExecutor
from flexmech_py.studies.compare import compare_models
from flexmech_py.studies.sampling import sample_study
from flexmech_py.run.parallel import run_tasks
from flexmech_py.studies.sweep import VARYING_COLUMNS, sweep, sweep_point

from conftest import CASES, interrupt_after_first_result

if os.environ.get("CI") == "true":   # CI installs distributed (.ci/setup.sh): never skip there
    import distributed
else:
    distributed = pytest.importorskip("distributed", reason="the optional package 'distributed' is not installed "
                                                            "(pip install 'flexmech[cluster]'; .ci/setup.sh installs it)")

SEED = CASES / "fourbar_constant_speed.toml"
SHORT = ["solver.t_end=0.005"]


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as lc:
        with distributed.Client(lc.scheduler_address) as client:
            client.run(lambda: __import__("flexmech_py.studies.sweep"))   # workers import flexmech once, here
            yield lc, client


def _rows(path):
    with open(path) as f:
        return list(csv.DictReader(line for line in f if not line.startswith("#")))


def _stable(rows):
    return [{k: v for k, v in r.items() if k not in VARYING_COLUMNS} for r in rows]


def test_cluster_sweep_is_the_local_pool_table_bit_for_bit(cluster, tmp_path):
    lc, client = cluster
    params = ["drive.speed=100:140:3", "mesh.elements_per_link=2,4"]
    local = sweep(SEED, params, overrides=SHORT, jobs=2, out_dir=tmp_path / "local", progress=False)
    dask = sweep(SEED, params, overrides=SHORT, out_dir=tmp_path / "dask", progress=False,
                 scheduler=lc.scheduler_address)
    a, b = _rows(tmp_path / "local" / "sweep.csv"), _rows(tmp_path / "dask" / "sweep.csv")
    assert len(a) == 6 and all(r["status"] == "ok" for r in a)
    assert _stable(a) == _stable(b)        # every number as written, to the last digit
    for x, y in zip(dask["batch"].results, local["batch"].results):   # as returned: only the timings differ
        assert {k: v for k, v in x.items() if k not in VARYING_COLUMNS} == \
               {k: v for k, v in y.items() if k not in VARYING_COLUMNS}
    # the Dask rows name the cluster's worker processes; the local ones this machine's pool
    pids = {str(p) for p in client.run(os.getpid).values()}
    assert {r["worker"].rsplit(":", 1)[1] for r in b} <= pids
    assert not {r["worker"].rsplit(":", 1)[1] for r in a} & pids
    assert dask["batch"].retries == 0 and "Dask" in dask["batch"].executor and dask["batch"].jobs == 2
    # the cache written by the client serves a rerun on the other executor
    again = sweep(SEED, params, overrides=SHORT, jobs=1, out_dir=tmp_path / "dask", progress=False)
    assert again["batch"].cached == 6 and _stable(_rows(tmp_path / "dask" / "sweep.csv")) == _stable(a)
    with DaskExecutor(lc.scheduler_address) as ex:   # one connection for several batches, left open by each
        for k in range(2):
            sw = sweep(SEED, params[:1], overrides=SHORT, out_dir=tmp_path / f"ex{k}", progress=False, scheduler=ex)
            assert sw["batch"].computed == 3 and sw["batch"].jobs == 2


def test_cluster_samples_and_model_comparison_match_the_local_pool(cluster, tmp_path):
    lc, _ = cluster
    spec = ["links.coupler.area=normal:0.406e-4:0.01e-4", "point_masses.1.mass=uniform:0.03:0.045"]
    kw = dict(n=4, seed=7, overrides=SHORT, progress=False, plots=False)
    sample_study(SEED, spec, jobs=1, out_dir=tmp_path / "l", **kw)
    sample_study(SEED, spec, out_dir=tmp_path / "d", scheduler=lc.scheduler_address, **kw)
    assert _stable(_rows(tmp_path / "l" / "samples.csv")) == _stable(_rows(tmp_path / "d" / "samples.csv"))
    assert (tmp_path / "l" / "statistics.csv").read_text() == (tmp_path / "d" / "statistics.csv").read_text()
    case = load_case(CASES / "manipulator_bricout.toml", overrides=["solver.t_end=0.01"])
    kw = dict(columns=["tip_dy_elastic"])
    ml, _, _ = compare_models(case, ["classic"], out_dir=tmp_path / "cl", jobs=1, **kw)
    md, runs, _ = compare_models(case, ["classic"], out_dir=tmp_path / "cd", scheduler=lc.scheduler_address, **kw)
    assert ml["classic"].keys() == md["classic"].keys() and runs["nonlinear"].timing["kernel_s"] > 0
    for c in ml["classic"]:
        assert ml["classic"][c]["max_error"] == md["classic"][c]["max_error"]


def test_cluster_task_errors_are_results_and_bugs_stop_the_batch(cluster):
    lc, _ = cluster
    bad = run_tasks(validate_case, [{"links": 1}, {"mechanism": 2}], scheduler=lc.scheduler_address, progress=False)
    assert bad.failed == [0, 1] and all(r["error_type"] == "CaseError" for r in bad.results)
    with pytest.raises(KeyError):     # not a FlexmechError: a bug, raised in the client with its type
        run_tasks(sweep_point, [{}], scheduler=lc.scheduler_address, progress=False)


def test_a_task_that_kills_its_workers_is_given_up_on_the_cluster(cluster):
    lc, client = cluster
    # os._exit(0) ends the worker process that runs it; Dask gives up after allowed-failures (3) + 1 deaths
    b = run_tasks(os._exit, [0], scheduler=lc.scheduler_address, progress=False)
    assert b.failed == [0] and b.results[0]["error_type"] == "WorkerLost" and b.retries == 3
    assert "died 4 times" in b.results[0]["error"]
    client.wait_for_workers(2, timeout=60)


def test_environment_variable_selects_the_cluster_unless_jobs_is_given(cluster, tmp_path, capsys, monkeypatch):
    lc, _ = cluster
    monkeypatch.setenv("FLEXMECH_SCHEDULER", lc.scheduler_address)
    argv = ["sweep", str(SEED), "--param", "drive.speed=100,110", "--set", SHORT[0]]
    assert main(argv + ["--out", str(tmp_path / "a")]) == 0
    assert f"on the Dask scheduler {lc.scheduler_address} (2 workers)" in capsys.readouterr().out
    assert main(argv + ["--jobs", "1", "--out", str(tmp_path / "b")]) == 0
    assert "on this process" in capsys.readouterr().out


def test_a_worker_killed_during_the_batch_loses_no_result(cluster, tmp_path):
    lc, client = cluster
    victim = next(iter(client.run(os.getpid).values()))
    out = tmp_path / "k"
    killed = []

    def kill_after_the_first_result():
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not killed:
            if list((out / "cache").glob("*.json")):
                os.kill(victim, signal.SIGKILL)
                killed.append(time.monotonic())
            time.sleep(0.005)

    # 8 points of ~0.2 s on 2 workers: both are busy when the first result arrives
    params = ["drive.speed=80:120:8"]
    ov = ["solver.t_end=0.1", "mesh.elements_per_link=4"]
    th = threading.Thread(target=kill_after_the_first_result)
    th.start()
    sw = sweep(SEED, params, overrides=ov, out_dir=out, progress=False, scheduler=lc.scheduler_address)
    th.join()
    b = sw["batch"]
    assert killed, "the batch ended before a result arrived"
    assert b.retries >= 1 and not b.failed and len(b.results) == 8 and b.computed == 8
    # every result is the one the local pool gives
    ref = sweep(SEED, params, overrides=ov, jobs=2, out_dir=tmp_path / "ref", progress=False)
    assert _stable(_rows(out / "sweep.csv")) == _stable(_rows(tmp_path / "ref" / "sweep.csv"))
    client.wait_for_workers(2, timeout=60)   # the nanny restarts the killed worker


def test_ctrl_c_on_the_cluster_keeps_the_finished_results(cluster, tmp_path):
    lc, client = cluster
    argv = ["sweep", str(SEED), "--param", "drive.speed=80:120:12", "--set", "solver.t_end=0.1",
            "--scheduler", lc.scheduler_address]
    rc, kept = interrupt_after_first_result(argv, tmp_path / "sw", tmp_path)
    assert rc == 130 and 1 <= kept < 12
    sw = sweep(SEED, ["drive.speed=80:120:12"], overrides=["solver.t_end=0.1"], out_dir=tmp_path / "sw",
               progress=False, scheduler=lc.scheduler_address)
    assert sw["batch"].cached == kept and sw["batch"].computed == 12 - kept and not sw["failures"]


def test_a_scheduler_that_does_not_answer_is_one_line_exit_2(tmp_path, capsys):
    with socket.socket() as s:   # a free port on this machine with nothing listening
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "never"
    t0 = time.monotonic()
    rc = main(["sweep", str(SEED), "--param", "drive.speed=100,110", "--set", SHORT[0],
               "--scheduler", f"tcp://127.0.0.1:{port}", "--out", str(out)])
    took = time.monotonic() - t0
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and err.startswith("flexmech: error: --scheduler tcp://127.0.0.1:")
    assert "no Dask scheduler answers" in err and took < 10 and not out.exists()
