"""flexmech compare: metrics, alignment by time and crank angle, the reference format, the CLI."""

import json

import numpy as np
import pytest

from flexmech_py.cli import main
from flexmech_py.studies.compare import compare_columns, read_reference


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory, cases_dir_module):
    out = tmp_path_factory.mktemp("run")
    assert main(["run", str(cases_dir_module / "fourbar_hac.toml"), "--set", "solver.t_end=0.12", "--no-plots",
                 "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def cases_dir_module():
    from conftest import CASES
    return CASES


def _write_ref(path, header, units, rows, source="test data"):
    lines = ([f"# source: {source}"] if source else []) + ([f"# units: {units}"] if units else []) + [header]
    lines += [",".join(f"{x:.12g}" for x in r) for r in rows]
    path.write_text("\n".join(lines) + "\n")


def test_metrics_on_known_curves():
    x = np.linspace(0, 1, 201)
    res = {"t": x, "y": np.sin(2 * np.pi * x) * 1.1}
    ref = {"t": x[::2], "y": np.sin(2 * np.pi * x[::2])}
    m = compare_columns(res, ref)["y"]
    assert m["max_error"] == pytest.approx(0.1, rel=1e-3)
    assert m["peak_error"] == pytest.approx(0.1, rel=1e-3)
    assert m["correlation"] == pytest.approx(1.0, abs=1e-12)
    assert m["peak_shift"] == pytest.approx(0.0, abs=1e-12)
    shifted = {"t": x, "y": np.sin(2 * np.pi * (x - 0.05))}
    assert compare_columns(shifted, ref)["y"]["peak_shift"] == pytest.approx(0.05, abs=0.011)


def test_self_comparison_by_time_and_by_crank_angle_in_degrees(run_dir, tmp_path):
    from flexmech_py.run.results import read_timeseries
    cols, _ = read_timeseries(run_dir / "timeseries.csv")
    ref = tmp_path / "ref.csv"
    _write_ref(ref, "crank_angle,strain_coupler_mid", "deg,1",
               [(np.degrees(a), e) for a, e in zip(cols["crank_angle"][1::3], cols["strain_coupler_mid"][1::3])])
    rc = main(["compare", str(run_dir), "--reference", str(ref), "--x", "crank_angle", "--out", str(tmp_path / "c")])
    assert rc == 0
    m = json.loads((tmp_path / "c" / "compare.json").read_text())["columns"]["strain_coupler_mid"]
    assert m["max_error"] < 1e-6 and m["correlation"] > 0.999999
    from flexmech_py.figures.plots import have_matplotlib
    if have_matplotlib():
        assert (tmp_path / "c" / "compare_strain_coupler_mid.png").exists()


@pytest.mark.parametrize("content, needle", [
    ("t,strain_coupler_mid\n0,0\n0.1,1e-3\n", "# source:"),
    ("# source: x\nt,nothing\n0,0\n0.1,1\n", "no column in common"),
    ("# source: x\nt,strain_coupler_mid\n5,0\n6,1\n", "do not overlap"),
    ("# source: x\nt,strain_coupler_mid\n0,zero\n0.1,1e-3\n", "line 3, column 'strain_coupler_mid': 'zero' is not a number"),
    ("# source: x\nt,strain_coupler_mid\n0,0\n0.05,nan\n0.1,1e-3\n", "line 4, column 'strain_coupler_mid': nan is not a finite"),
    ("# source: x\nt,strain_coupler_mid\n0,0\n0.05,inf\n0.1,1e-3\n", "inf is not a finite"),
    ("# source: x\nt,strain_coupler_mid\n0,0\n0.05\n0.1,1e-3\n", "line 4: 1 value, but the header names 2 columns"),
    ("# source: x\nt,strain_coupler_mid\n0,0,7\n0.1,1e-3\n", "line 3: 3 values"),
    ("# source: x\n# units: s, furlong\nt,strain_coupler_mid\n0,0\n0.1,1e-3\n", "unknown unit 'furlong'"),
    ("# source: x\n# units: s, m\nt,strain_coupler_mid\n0,0\n0.1,1e-3\n", "is in m in the reference but in 1"),
    ("# source: x\n# units: deg, 1\nt,strain_coupler_mid\n0,0\n0.1,1e-3\n", "is in deg (an angle) in the reference but in s"),
    (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xfe", "is not a text CSV file"),
    (b"# source: x\nt,strain_coupler_mid\n0,0\n0.1,\xe9\n", "is not a text CSV file (byte 0xe9"),
])
def test_bad_reference_one_line_exit_2(run_dir, tmp_path, capsys, content, needle):
    ref = tmp_path / "bad.csv"
    ref.write_bytes(content) if isinstance(content, bytes) else ref.write_text(content)
    out = tmp_path / "c"
    rc = main(["compare", str(run_dir), "--reference", str(ref), "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and needle in err and err.count("\n") == 1 and err.startswith("flexmech: error: "), err
    assert not out.exists()   # nothing written


def test_compare_models_against_nonlinear(cases_dir, tmp_path, capsys):
    rc = main(["compare", "--models", str(cases_dir / "manipulator_bricout.toml"), "--set", "solver.t_end=0.02",
               "--model-list", "classic,coupled", "--out", str(tmp_path / "m")])
    assert rc == 0
    js = {m: json.loads((tmp_path / "m" / m / "compare.json").read_text()) for m in ("classic", "coupled")}
    assert js["coupled"]["reference_model"] == "nonlinear"
    # the coupled model is far closer to the nonlinear one than the superposition model on this case
    assert (js["coupled"]["columns"]["tip_dy_elastic"]["max_error"]
            < 0.1 * js["classic"]["columns"]["tip_dy_elastic"]["max_error"])
    assert "coupled against nonlinear" in capsys.readouterr().out


def test_reference_in_degrees_is_converted_for_any_angle_column():
    t = np.linspace(0, 1, 11)
    res, res_units = {"t": t, "joint_angle": 0.5 * t}, {"t": "s", "joint_angle": "rad"}
    ref = {"t": t, "joint_angle": np.degrees(0.5 * t)}
    m = compare_columns(res, ref, ref_units={"t": "s", "joint_angle": "deg"}, res_units=res_units)["joint_angle"]
    assert m["max_error"] < 1e-12 and m["peak_ref"] == pytest.approx(0.5)


def test_read_reference_units_and_source(tmp_path):
    p = tmp_path / "r.csv"
    _write_ref(p, "t,y", "s,m", [(0, 1), (1, 2)], source="Somebody et al. 1999, Fig. 2")
    cols, units, source = read_reference(p)
    assert units == {"t": "s", "y": "m"} and source.startswith("Somebody") and cols["y"][1] == 2
