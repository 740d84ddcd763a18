"""The flexmech command: runs, writes plain files, and rejects bad input with one line and exit code 2."""

import json
import subprocess
import sys

import numpy as np
import pytest

from flexmech_py.cli import main
from flexmech_py.run.results import read_timeseries


def test_run_writes_files(cases_dir, tmp_path, capsys):
    out = tmp_path / "r"
    rc = main(["run", str(cases_dir / "fourbar_hac.toml"), "--model", "classic", "--set", "solver.t_end=0.02",
               "--elements-per-link", "4", "--dt", "2e-5", "--out", str(out)])
    assert rc == 0
    cols, units = read_timeseries(out / "timeseries.csv")
    assert list(cols)[:5] == ["t", "crank_angle", "crank_speed", "strain_coupler_mid", "strain_follower_mid"]
    assert units["t"] == "s" and units["crank_speed"] == "rad/s"
    assert cols["t"][-1] == pytest.approx(0.02)
    summ = json.loads((out / "summary.json").read_text())
    assert summ["model"] == "classic" and summ["steps"] == 1000 and summ["dofs"]["elements"] == 12
    assert summ["input"]["links"][0]["elements"] == 4
    assert summ["outputs"]["crank_speed"]["final"] == pytest.approx(cols["crank_speed"][-1], rel=1e-8)
    assert "strain_coupler_mid" in capsys.readouterr().out


@pytest.mark.parametrize("args, needle", [
    (["run", "nope.toml"], "does not exist"),
    (["run", "{case}", "--set", "links.crank.area=-1"], "links[0].area"),
    (["run", "{case}", "--set", "solver.dt=1"], "solver.dt"),
    (["run", "{case}", "--set", "links.crank.length=1.0"], "cannot assemble"),
    (["run", "{case}", "--set", 'outputs.bad = {kind = "strain", link = "rod"}'], "outputs.bad.link"),
])
def test_bad_input_one_line_exit_2(cases_dir, tmp_path, capsys, args, needle):
    out = tmp_path / "never"
    args = [a.replace("{case}", str(cases_dir / "fourbar_hac.toml")) for a in args] + ["--out", str(out)]
    rc = main(args)
    err = capsys.readouterr().err
    assert rc == 2
    assert needle in err
    assert err.count("\n") == 1 and err.startswith("flexmech: error: ")
    assert not out.exists()  # nothing half-written


def test_unwritable_output_folder(cases_dir, tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    rc = main(["run", str(cases_dir / "fourbar_hac.toml"), "--set", "solver.t_end=0.001", "--out", str(blocker / "sub")])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("flexmech: error: ") and "--out" in err and err.count("\n") == 1


def test_argparse_rejects_nonpositive_dt(cases_dir, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["run", str(cases_dir / "fourbar_hac.toml"), "--dt", "0"])
    assert exc.value.code == 2
    assert "--dt" in capsys.readouterr().err


def test_console_script_installed(cases_dir, tmp_path):
    """The installed `flexmech` entry point runs end to end (subprocess, as a user would)."""
    exe = [sys.executable, "-m", "flexmech_py"]
    p = subprocess.run(exe + ["run", str(cases_dir / "manipulator_bricout.toml"), "--set", "solver.t_end=0.01",
                              "--no-plots", "--out", str(tmp_path / "m")], capture_output=True, text=True, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    cols, _ = read_timeseries(tmp_path / "m" / "timeseries.csv")
    assert np.all(np.isfinite(cols["tip_y"]))
