"""A run's warnings reach Python users as Python warnings of flexmech's classes (issue 24,
flexmech_py.base.notices): one per message of ``res.extra["warnings"]``, of its kind's class, attributed to
the caller's line, filterable; the command line prints each once in its own format."""

import warnings
from pathlib import Path

import pytest

import flexmech_py as fm
from flexmech_py.cli import main
from flexmech_py.run.simulate import Prepared

WATT = Path(__file__).parent / "data" / "watt_sixbar_spinup.toml"
PAST_VALIDITY = ["solver.t_end=0.1", "solver.error_estimate=none"]   # the coupler bends past 2 % at 0.055 s


def _issued(fn):
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        res = fn()
    return res, [w for w in got if issubclass(w.category, fm.FlexmechWarning)]


def test_simulate_issues_the_validity_warnings_as_python_warnings():
    case = fm.load_case("fourbar_hac", overrides=PAST_VALIDITY)
    res, got = _issued(lambda: fm.simulate(case))
    assert res.extra["warnings"] and [str(w.message) for w in got] == res.extra["warnings"]
    assert all(w.category is fm.ValidityWarning for w in got)
    assert all(Path(w.filename).resolve() == Path(__file__).resolve() for w in got)    # the caller's line
    assert issubclass(fm.ValidityWarning, UserWarning) and issubclass(fm.AccuracyWarning, fm.FlexmechWarning)


def test_warnings_are_filtered_by_their_class():
    case = fm.load_case("fourbar_hac", overrides=PAST_VALIDITY)
    with warnings.catch_warnings():
        warnings.simplefilter("error", fm.ValidityWarning)
        with pytest.raises(fm.ValidityWarning, match="coupler"):
            Prepared(case).run()
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        warnings.filterwarnings("ignore", category=fm.FlexmechWarning)
        fm.simulate(case)
    assert not got


def test_each_kind_has_its_class(tmp_path):
    """The step-doubling estimate's warning is an AccuracyWarning, the mechanism's own (a degree of
    freedom with no drive and no gravity) a MechanismWarning; a run without warnings issues none."""
    sc = fm.load_case("slider_crank", overrides=["solver.t_end=0.01"])
    res, got = _issued(lambda: Prepared(sc).stream(tmp_path / "sc"))
    assert got and {w.category for w in got} == {fm.AccuracyWarning}
    assert res.extra["warning_kinds"] == {m: "accuracy" for m in res.extra["warnings"]}
    free = fm.load_case(WATT, overrides=["drives=", "outputs.drive_torque=", "joints.crank_pivot.elastic=clamp",
                                         "solver.t_end=0.001", "solver.error_estimate=none"])
    _, got = _issued(lambda: fm.simulate(free))
    assert [w.category for w in got] == [fm.MechanismWarning] and "no drive and no gravity" in str(got[0].message)
    # the seed four-bar warns even over 0.02 s (its error budget: hac's follower strain ~83 % off the
    # nonlinear model); the six-bar spun up slowly is within the tolerance under model = "auto"
    slow = fm.load_case("watt_sixbar", overrides=["drives.0.final_speed=20", "solver.t_end=0.02"])
    res, got = _issued(lambda: fm.simulate(slow))
    assert res.extra["error_budget"]["worst_total"] < res.extra["error_budget"]["tolerance"]
    assert not got


def test_the_command_line_prints_each_warning_once(cases_dir, tmp_path, capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("error")                     # a Python warning escaping the CLI would fail it
        rc = main(["run", str(cases_dir / "fourbar_hac.toml"), "--set", "solver.t_end=0.1", "--set",
                   "solver.error_estimate=none", "--out", str(tmp_path / "r"), "--quiet", "--no-plots"])
    err = capsys.readouterr().err
    lines = [x for x in err.splitlines() if x.startswith("flexmech: warning: ")]
    assert rc == 0 and len(lines) == len(set(lines)) >= 2
    assert "Warning" not in err                          # no Python-format warning lines beside them
