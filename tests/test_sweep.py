"""``flexmech sweep`` (flexmech_py/studies/sweep.py): grid, summary table, resumability, reproducibility.

Reduced size: the seed four-bar at constant speed over 0.01 s (1000 steps) per point.
"""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from flexmech_py import load_case
from flexmech_py.cli import main
from flexmech_py.base.errors import CaseError
from flexmech_py.run.simulate import simulate
from flexmech_py.studies.sweep import VARYING_COLUMNS, grid_points, parse_param, sweep

from conftest import CASES

SEED = CASES / "fourbar_constant_speed.toml"
SHORT = ["solver.t_end=0.01"]


def _read(path):
    with open(path) as f:
        return list(csv.DictReader(line for line in f if not line.startswith("#")))


def test_parse_param_forms():
    assert parse_param("drive.speed=100:140:3") == ("drive.speed", [100, 120, 140], "100:140:3")
    k, v, _ = parse_param("solver.dt=1e-5:2e-5:2")
    assert v == [1e-5, 2e-5] and all(isinstance(x, float) for x in v)
    assert parse_param("mesh.elements_per_link=2,4")[1] == [2, 4]
    assert parse_param("joints.follower_pivot=pin,clamp")[1] == ["pin", "clamp"]
    assert parse_param("drive.speed=100.5:100.5:1")[1] == [100.5]
    for bad in ("drive.speed", "drive.speed=1:2", "drive.speed=a:b:3", "drive.speed=1:2:0", "solver.rayleigh=[1,2]"):
        with pytest.raises(CaseError):
            parse_param(bad)
    pts = grid_points([parse_param("a=1,2"), parse_param("b=x,y,z")])
    assert pts[:4] == [{"a": 1, "b": "x"}, {"a": 1, "b": "y"}, {"a": 1, "b": "z"}, {"a": 2, "b": "x"}]
    with pytest.raises(CaseError, match="twice"):
        grid_points([parse_param("a=1,2"), parse_param("a=3")])


def test_sweep_table_resume_and_reproducibility(tmp_path):
    out = tmp_path / "sw"
    params = ["drive.speed=100:140:2", "mesh.elements_per_link=2,4"]
    sw = sweep(SEED, params, overrides=SHORT, jobs=2, out_dir=out, progress=False)
    b = sw["batch"]
    assert b.jobs == 2 and b.computed == 4 and not b.failed
    rows = _read(out / "sweep.csv")
    # grid order, first parameter slowest, whatever order the workers finished in
    assert [(float(r["drive.speed"]), int(r["mesh.elements_per_link"])) for r in rows] == \
           [(100, 2), (100, 4), (140, 2), (140, 4)]
    assert all(r["status"] == "ok" for r in rows)
    # every row is the case run directly with those overrides
    res = simulate(load_case(SEED, overrides=SHORT + ["drive.speed=140", "mesh.elements_per_link=4"]))
    r = rows[3]
    y = res["strain_coupler_mid"]
    assert float(r["strain_coupler_mid_maxabs"]) == pytest.approx(np.max(np.abs(y)), rel=1e-9)
    assert float(r["strain_coupler_mid_rms"]) == pytest.approx(np.sqrt(np.mean(y * y)), rel=1e-9)
    assert float(r["strain_coupler_mid_final"]) == pytest.approx(y[-1], rel=1e-9, abs=1e-15)
    assert float(r["coupler_compression_over_euler"]) == pytest.approx(
        res.extra["validity"]["coupler"]["max_compression_over_euler"], rel=1e-9)
    assert float(r["kernel_s"]) > 0
    # the faster crank loads the coupler more
    assert float(rows[2]["strain_coupler_mid_maxabs"]) > float(rows[0]["strain_coupler_mid_maxabs"])
    grid = json.loads((out / "sweep.json").read_text())
    assert [p["values"] for p in grid["params"]] == [[100, 140], [2, 4]] and grid["points"] == 4

    # interrupted: the table and one finished run lost; the rerun recomputes that one only
    cached = sorted((out / "cache").glob("*.json"))
    assert len(cached) == 4
    (out / "sweep.csv").unlink()
    cached[1].unlink()
    sw2 = sweep(SEED, params, overrides=SHORT, jobs=1, out_dir=out, progress=False)
    assert sw2["batch"].computed == 1 and sw2["batch"].cached == 3
    rows2 = _read(out / "sweep.csv")
    for a, c in zip(rows, rows2):   # identical numbers; only measured times and the worker differ
        assert {k: v for k, v in a.items() if k not in VARYING_COLUMNS} == \
               {k: v for k, v in c.items() if k not in VARYING_COLUMNS}
    # per-run time and worker (host:pid) of every row, computed or cached
    assert all(float(r["task_s"]) > 0 and ":" in r["worker"] for r in rows2)


def test_sweep_failed_points_are_rows_and_exit_3(tmp_path, capsys):
    # 3 elements per link put no node at the coupler's midpoint the outputs ask for: that point fails
    out = tmp_path / "bad"
    assert main(["sweep", str(SEED), "--param", "mesh.elements_per_link=2,3,3", "--set", "solver.t_end=0.005",
                 "--jobs", "1", "--out", str(out)]) == 3
    rows = _read(out / "sweep.csv")
    assert [r["status"] for r in rows] == ["ok", "error", "error"]
    assert "not at a mesh node" in rows[1]["error"] and rows[1]["strain_coupler_mid_maxabs"] == ""
    io = capsys.readouterr()
    assert "2 failed" in io.out
    # each distinct reason once, with its count
    err = [line for line in io.err.splitlines() if not line.startswith("runs: ")]   # not the progress bar
    assert err[0] == "flexmech: error: 2 of 3 runs failed (the others are kept):"
    assert len(err) == 2 and err[1].startswith("  2 x ") and "not at a mesh node" in err[1]


@pytest.mark.parametrize("argv, needle", [
    (["--param", "drive.sped=100,120"], "the first grid point (drive.sped=100): drive.sped: unknown key"),
    (["--param", "drive.speed=fast,slow"], "the first grid point (drive.speed=\"fast\")"),
    (["--param", "drive.speed=1,2", "--set", "solver.dt=-1"], "solver.dt"),     # a broken base case
    (["--param", "drive.speed=1,2", "--sample", "links.coupler.length=normal:0.28:0.001"], "one of the two"),
    (["--param", "drive.speed=1,2", "--scheduler", "nowhere"], "--scheduler: 'nowhere' must be"),
    (["--param", "drive.speed=1,2", "--scheduler", "local:2", "--jobs", "2"], "--jobs"),
])
def test_sweep_bad_input_one_line_exit_2_nothing_written(tmp_path, capsys, argv, needle):
    out = tmp_path / "never"
    assert main(["sweep", str(SEED), *argv, "--set", "solver.t_end=0.005", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("flexmech: error: ") and needle in err, err
    assert not out.exists()
