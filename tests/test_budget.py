"""The error budget of every run and ``model = "auto"`` (flexmech_py/checks/budget.py, auto_model.py; docs/theory.md
section 21, docs/validation.md "Error budget"), at reduced size: the estimates track the true errors, the
worst column is never a negligible one, the warning names the part that dominates and the setting that cuts
it, auto escalates on a fast mechanism and stays cheap on a slow one, and streaming stays bounded.
Full-size validation: python -m flexmech_py.studies.budget_study."""

from pathlib import Path

import numpy as np
import pytest

import flexmech_py as fm
from flexmech_py.checks import budget, mesh_error, scales
from flexmech_py.checks.budget_text import quote, significant_digits
from flexmech_py.cli import main
from flexmech_py.checks.probes import Probe
from flexmech_py.run.simulate import Prepared
from flexmech_py.checks.step_doubling import error_estimate

CASES = Path(__file__).resolve().parents[1] / "cases"


def _sixbar(*ov):
    return fm.load_case(CASES / "watt_sixbar.toml", overrides=list(ov))


def _rel(a, b, col):
    """max |a - b| / max |b| of one column (the frames of b, a at the same times)."""
    y = np.interp(b.t, a.t, a.columns[col])
    return float(np.max(np.abs(y - b.columns[col])) / np.max(np.abs(b.columns[col])))


# ----------------------------------------------------------------------------- settings
def test_error_estimate_parts_switch_the_budget_on_and_off():
    case = _sixbar("solver.t_end=0.01", "mesh.elements_per_link=4")
    only_time = Prepared(case).run("hac", estimate="time")
    b = only_time.extra["error_budget"]
    assert b["parts"] == ["time"] and not b["probes"]["made"]
    assert all(c["mesh"] is None and c["model"] is None for c in b["columns"].values())
    no_time = Prepared(case).run("hac", estimate="mesh+model")
    assert no_time.extra["error_estimate"] == {"method": "none"}
    cols = no_time.extra["error_budget"]["columns"]
    assert cols["strain_coupler_mid"]["mesh"] > 0 and cols["strain_coupler_mid"]["model"] > 0
    none = Prepared(_sixbar("solver.t_end=0.01", "solver.error_estimate='none'")).run("hac")
    assert "error_budget" not in none.extra
    assert fm.load_case(CASES / "watt_sixbar.toml", ["solver.error_estimate='time+mesh'"])["solver"][
        "error_estimate"] == "time+mesh"


@pytest.mark.parametrize("setting, field", [("solver.error_estimate='space'", "solver.error_estimate"),
                                            ("solver.tolerance=2", "solver.tolerance"),
                                            ("solver.model='exact'", "solver.model")])
def test_bad_budget_settings_get_one_line_and_exit_2(tmp_path, capsys, setting, field):
    out = tmp_path / "out"
    assert main(["run", str(CASES / "watt_sixbar.toml"), "--set", setting, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and field in err[0]
    assert not out.exists()


def test_defaults_of_a_case_that_names_no_model_or_mesh():
    case = _sixbar()
    assert case["solver"]["model"] == "auto" and case["solver"]["tolerance"] == budget.TOLERANCE
    assert case["mesh"]["elements_per_link"] == 8 and case["solver"]["error_estimate"] == "all"
    assert fm.load_case(CASES / "fourbar_hac.toml")["solver"]["model"] == "hac"      # the seed cases keep theirs


# ----------------------------------------------------------------------------- negligible columns
def test_negligible_columns_against_their_scale():
    case = fm.load_case(CASES / "slider_crank.toml")
    units = {"y": "m", "x": "m", "a": "rad", "f": "N", "g": "N", "z": "N"}
    peaks = {"y": 1e-17, "x": 0.3, "a": 1e-14, "f": 1e-12, "g": 500.0, "z": 0.0}
    tiny = scales.negligible(case, units, peaks)
    assert set(tiny) == {"y", "a", "f", "z"}
    assert "mechanism's size" in tiny["y"] and "zero" in tiny["z"]
    assert scales.negligible(case, {"f": "N"}, {"f": 1e-12}) == {}   # alone in its unit: not negligible


def test_a_zero_column_is_never_the_worst_column():
    """The y of the slider-crank's pin, which moves on the x axis (~1e-17 m): step doubling once named it
    the worst column at 67-344 % on every slider-crank run."""
    case = fm.load_case(CASES / "slider_crank.toml", [
        "solver.t_end=0.01", 'outputs.pin_y={kind="position", at="rod.end", component="y"}'])
    prep = Prepared(case)
    res = prep.run("classic")
    b = res.extra["error_budget"]
    assert "negligible" in b["columns"]["pin_y"] and b["worst_column"] != "pin_y"
    assert not any("pin_y" in w for w in res.extra.get("warnings", []))
    # step doubling on its own rigid-motion samples (a run held in memory): round-off over round-off
    est = error_estimate(prep, res)
    assert est["columns"]["pin_y"]["relative"] > 0.5
    assert "negligible" in est["columns"]["pin_y"] and est["worst_column"] != "pin_y"


# ----------------------------------------------------------------------------- the estimates
@pytest.fixture(scope="module")
def fast():
    """The six-bar spun up to 120 rad/s, first 0.05 s, 4 elements per link (reduced)."""
    return _sixbar("drives.0.final_speed=120", "solver.t_end=0.05", "solver.dt=2e-5", "mesh.elements_per_link=4")


@pytest.fixture(scope="module")
def exact16(fast):
    return Prepared(fast, elements_per_link=16).run("nonlinear", estimate=False)


def test_mesh_estimate_tracks_the_true_mesh_error(fast):
    col = "strain_coupler_mid"
    run = Prepared(fast).run("nonlinear", estimate="time+mesh")
    fine = Prepared(fast, elements_per_link=32).run("nonlinear", estimate=False)
    est, true = run.extra["error_budget"]["columns"][col]["mesh"], _rel(run, fine, col)
    assert true > 0.01
    assert 0.5 < est / true < 2.0, (est, true)


@pytest.mark.parametrize("model", ["hac", "classic"])
def test_model_estimate_tracks_the_true_model_error(fast, exact16, model):
    col = "strain_coupler_mid"
    run = Prepared(fast).run(model, estimate="model")
    same_mesh = Prepared(fast, elements_per_link=16).run(model, estimate=False)
    est, true = run.extra["error_budget"]["columns"][col]["model"], _rel(same_mesh, exact16, col)
    assert true > 0.05
    assert 0.5 < est / true < 2.0, (est, true)
    assert run.extra["error_budget"]["columns"]["crank_angle"]["model"] < 1e-9   # the drive law in every model


def test_the_exact_model_has_no_model_error(fast):
    b = Prepared(fast).run("nonlinear", estimate="model").extra["error_budget"]
    assert all(c["model"] == 0.0 for c in b["columns"].values())
    assert not b["probes"]["runs"]


def test_warning_names_the_dominant_part_and_its_setting(fast):
    res = Prepared(fast).run("hac")
    w = res.extra["error_budget"]["warning"]
    assert w["dominant"] == "model" and "--model nonlinear" in w["remedy"] and "--model auto" in w["remedy"]
    assert any(m.startswith("error budget: ") for m in res.extra["warnings"])
    slow = _sixbar("drives.0.final_speed=20", "solver.t_end=0.05", "solver.dt=2e-5", "mesh.elements_per_link=2")
    w = Prepared(slow).run("nonlinear").extra["error_budget"]["warning"]
    assert w["dominant"] == "mesh" and "--elements-per-link" in w["remedy"]
    m = int(w["remedy"].split("--elements-per-link ")[1].split()[0])
    assert m > 2 and m % 2 == 0


def test_a_rigid_drive_torque_asks_for_the_exact_model_not_geometric_stiffness():
    """A superposition model's kinematic drive torque is the rigid-body solution's (theory 18.5): at
    120 rad/s it is 99 % off near t = 0.1 s with or without geometric stiffness, so the warning must not
    offer geometric stiffness as the fix."""
    case = _sixbar("drives.0.final_speed=120", "solver.dt=2e-5", "mesh.elements_per_link=4",
                   "outputs.strain_coupler_mid=", "outputs.strain_cd_mid=", "outputs.strain_rocker_mid=")
    w = Prepared(case).run("classic").extra["error_budget"]["warning"]
    assert w["column"] == "drive_torque" and w["dominant"] == "model"
    assert "rigid-body solution" in w["remedy"] and "--model nonlinear" in w["remedy"]
    assert "geometric_stiffness=" not in w["remedy"]


def test_quiet_when_every_part_is_within_the_tolerance():
    slow = _sixbar("drives.0.final_speed=20", "solver.t_end=0.05", "solver.dt=2e-5")
    res = Prepared(slow).run("nonlinear")
    b = res.extra["error_budget"]
    assert b["worst_total"] < b["tolerance"] and "warning" not in b
    assert not any("error budget" in w for w in res.extra.get("warnings", []))


# ----------------------------------------------------------------------------- auto
def test_auto_escalates_on_a_fast_mechanism(fast):
    res = Prepared(fast).run("auto")
    ch = res.extra["model_choice"]
    assert ch["tried"][0]["model"] == "hac" and ch["tried"][0]["estimate"] > ch["tolerance"]
    assert res.model != "hac" and ch["model"] == res.model
    assert "auto" in res.table() and ch["label"] in res.table()


def test_auto_stays_on_the_cheapest_model_when_it_suffices():
    slow = _sixbar("drives.0.final_speed=10", "solver.t_end=0.05", "solver.dt=2e-5", "mesh.elements_per_link=4")
    res = Prepared(slow).run()                       # the case names no model: auto
    ch = res.extra["model_choice"]
    assert res.model == "hac" and len(ch["tried"]) == 1 and ch["tried"][0]["estimate"] <= ch["tolerance"]
    assert "geometric_stiffness" not in res.extra


def test_auto_reuses_its_probes_in_the_budget(monkeypatch):
    """The probes auto made are replayed by the budget, not made again: the run of the chosen model with
    its budget makes no other probe than the mesh probe."""
    ran = {}
    orig = Probe._next

    def count(self):
        ran[id(self)] = (self.model, self.geometric, self.ratio)
        return orig(self)

    monkeypatch.setattr(Probe, "_next", count)
    slow = _sixbar("drives.0.final_speed=10", "solver.t_end=0.02", "solver.dt=2e-5", "mesh.elements_per_link=4")
    Prepared(slow).run("auto")
    assert sorted(map(repr, ran.values())) == sorted(map(repr, [("hac", "none", 16), ("nonlinear", None, 16),
                                                                 ("hac", "none", 2)]))


# ----------------------------------------------------------------------------- streaming and the probe grids
def test_a_streamed_budget_equals_the_one_in_memory_and_stays_bounded(tmp_path, monkeypatch):
    case = _sixbar("solver.t_end=0.04", "solver.dt=2e-5", "mesh.elements_per_link=4")
    held = Prepared(case).run("hac").extra["error_budget"]
    longest = []
    orig = budget.ErrorBudget._match

    def watch(self, finished):
        orig(self, finished)
        longest.append(max(b.frames for b in self.matcher.buffers.values()))

    monkeypatch.setattr(budget.ErrorBudget, "_match", watch)
    streamed = Prepared(case, chunk_steps=100).stream(tmp_path / "s", "hac").extra["error_budget"]
    for col, c in held["columns"].items():
        for part in ("time", "mesh", "model"):
            if c[part] is None:
                assert streamed["columns"][col][part] is None
            else:
                assert streamed["columns"][col][part] == pytest.approx(c[part], rel=1e-6, abs=1e-15), (col, part)
    assert max(longest[:-1]) <= 2 * 100 // 10 + 10      # about a chunk of frames, not the run's 200


def test_probe_mesh_halves_or_doubles_keeping_output_points_on_nodes():
    case = _sixbar("solver.t_end=0.01")
    grids, _ = budget.probe_plan(Prepared(case))
    assert grids.ratio == 2 and {ln["elements"] for ln in grids.mesh.case["links"] if not ln.get("rigid")} == {4}
    two = Prepared(_sixbar("solver.t_end=0.01", "mesh.elements_per_link=2"))
    grids, _ = budget.probe_plan(two)
    assert grids.ratio == 2 and grids.mesh.case["links"][1]["elements"] == 1
    assert grids.model.case["links"][1]["elements"] == 2          # the model probe keeps the run's mesh
    mid = Prepared(_sixbar("solver.t_end=0.01", "mesh.elements_per_link=2",
                           'outputs.p={kind="position", at="coupler.mid", component="y"}'))
    grids, _ = budget.probe_plan(mid)
    assert grids.ratio == 0.5 and grids.mesh.case["links"][1]["elements"] == 4    # coupler.mid must stay a node
    quarter = _sixbar("solver.t_end=0.01", "mesh.elements_per_link=4",
                      'outputs.q={kind="strain", link="coupler", at=0.25}')
    grids, _ = budget.probe_plan(Prepared(quarter))
    assert grids.ratio == 2                    # strains may sit anywhere: 0.25 inside an element is fine
    assert mesh_error.spatial_error(0.3, 2.0) == pytest.approx(0.1)
    assert mesh_error.spatial_error(0.3, 0.5) == pytest.approx(0.4)


def test_probes_take_the_rigid_motion_of_the_run():
    """A probe fed by the run's rigid motion (a torque-driven mechanism: a forward-dynamics integration)
    gives the frames it gives with its own rigid-motion source."""
    case = fm.load_case(CASES / "fourbar_hac.toml", ["solver.t_end=0.02"])
    prep = Prepared(case)
    grids, _ = budget.probe_plan(prep)
    own = Probe(grids.model, "hac", "none", grids.model_step, "hac")
    own.run_to_end()
    grids2, _ = budget.probe_plan(prep)
    fed = Probe(grids2.model, "hac", "none", grids2.model_step, "hac")
    prep.share_motion(grids2.model, grids2.model_step)
    for block in prep.blocks("hac"):
        fed.advance_to(int(block.steps[-1]))
    prep.end_shared_motion()
    fed.run_to_end()
    for col, y in own.buffer.cols.items():
        np.testing.assert_allclose(fed.buffer.cols[col], y, rtol=1e-9, atol=1e-12 * np.max(np.abs(y)))


# ----------------------------------------------------------------------------- significant figures
@pytest.mark.parametrize("value, err, text", [(1.684, 0.16, "1.7"), (0.8512, 0.16, "0.9"), (1.684, 0.001, "1.684"),
                                              (123.4, 0.5, "120"), (51.0, 0.3, "50"), (0.01234, None, "0.01234")])
def test_quoted_digits_follow_the_error(value, err, text):
    assert quote(value, err) == text
    assert significant_digits(1.0, 1e-9) == 4


def test_a_model_error_checked_over_only_the_start_of_the_run_is_a_warning():
    """The Bricout PD arm's model-error probe (the coupled model at the probe's coarser step) stops within
    the first millisecond: the run warns that its model error is checked only up to there (a lower bound)
    and names the exact model to compare with; a run whose probes reach its end (the seed four-bar) does
    not."""
    res = Prepared(fm.load_case("manipulator_bricout_pd", ["solver.t_end=0.02"])).run("coupled")
    b = res.extra["error_budget"]
    stopped = [r["stopped_at_s"] for r in b["probes"]["runs"] if r["role"] in ("model", "reference")
               and r["stopped_at_s"] is not None]
    assert stopped and min(stopped) < 0.018
    assert "checked only over [0," in b["model_unchecked"] and "--model nonlinear" in b["model_unchecked"]
    quiet = Prepared(fm.load_case(CASES / "fourbar_hac.toml", ["solver.t_end=0.01"])).run("hac")
    assert "model_unchecked" not in quiet.extra["error_budget"]
