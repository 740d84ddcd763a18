"""Guards in every run (flexmech_py/checks/guards.py, docs/stability.md): failures stop with a diagnosis and
keep their partial results, validity limits warn, and the step-doubling error estimate is honest.

Run as a script to print the estimate-vs-actual table of docs/stability.md:
    python tests/test_guards.py
"""

import json
from pathlib import Path

import numpy as np
import pytest

import flexmech_py as fm
from flexmech_py.cli import main
from flexmech_py.base.errors import SolverError
from flexmech_py.studies.gap import validity_time
from flexmech_py.checks.guards import frames_before
from flexmech_py.run.results import read_timeseries
from flexmech_py.run.simulate import Prepared
from flexmech_py.checks.step_doubling import FRAMES_FULL

CASES = Path(__file__).resolve().parents[1] / "cases"


def _seed(*ov):
    return fm.load_case(CASES / "fourbar_hac.toml", overrides=list(ov))


# ----------------------------------------------------------------------------- failures
@pytest.fixture(scope="module")
def buckled():
    """The seed four-bar, classic model with geometric stiffness from the current axial forces:
    its follower is compressed far beyond the Euler load; the run stops when the buckled links'
    displacement passes the divergence limit (code 6) or the axial-force iteration fails (code 5),
    whichever comes first."""
    case = _seed("solver.t_end=0.16", "solver.geometric_stiffness=current")
    with pytest.raises(SolverError) as info:
        fm.simulate(case, model="classic")
    return case, info.value


def test_failure_keeps_finite_partial_frames_before_the_failed_step(buckled):
    case, exc = buckled
    res = exc.partial
    oe = case["solver"]["output_every"]
    assert exc.code in (5, 6) and exc.step >= 1
    assert res.t.size == frames_before(exc.step, oe)
    assert res.t[-1] < exc.time <= res.t[-1] + oe * res.dt + 1e-12   # the last kept frame precedes the failure
    assert exc.time == pytest.approx(exc.step * res.dt)
    for name, y in res.columns.items():
        assert y.shape == res.t.shape and np.all(np.isfinite(y)), name
    # the partial frames equal those of a complete run that stops just before the failure
    ok = fm.simulate(_seed(f"solver.t_end={res.t[-1]:.10g}", "solver.geometric_stiffness=current",
                           "solver.error_estimate='none'"), model="classic")
    assert ok.t.size == res.t.size
    np.testing.assert_allclose(ok.columns["strain_follower_mid"], res.columns["strain_follower_mid"], rtol=1e-9, atol=1e-15)


def test_failure_message_names_time_quantity_and_validity_cause(buckled):
    _, exc = buckled
    msg = str(exc)
    assert f"t = {exc.time:.6g} s" in msg
    assert ("geometric-stiffness" if exc.code == 5 else "divergence_limit") in msg
    assert "largest elastic displacement" in msg and "% of the link length" in msg
    f = exc.failure
    # the failure persists at dt/2 (not the step) and the follower was past its Euler load before it
    assert f["evidence"]["half_step"]["failed_at_s"] == pytest.approx(exc.time, rel=0.05)
    assert f["cause"] == "outside_validity" and "Euler load" in msg and "--model nonlinear" in msg
    v = exc.partial.extra["validity"]["follower"]
    assert v["compression_exceeds_at_s"] < exc.time and v["max_compression_over_euler"] > 1


def test_failure_from_a_too_large_step_is_blamed_on_the_step():
    """The nonlinear model's Newton iterations fail at dt = 5e-3 s (at t = 0.065 s; they failed at
    4e-4 s before the new start of the iteration, docs/theory.md 12.2, and at 2e-3 s before the
    shallow-arch strain, 12.4) and pass at dt/2; the message gives the last residual norm, and the
    diagnosis blames the step."""
    case = _seed("solver.t_end=0.08", "solver.output_every=1", "solver.dt=5e-3",
                 "solver.integrator='newmark'")     # (generalized-alpha, the nonlinear model's default, passes)
    with pytest.raises(SolverError) as info:
        fm.simulate(case, model="nonlinear")
    f = info.value.failure
    assert info.value.code == 5 and f["cause"] == "step_too_large"
    assert f["evidence"]["half_step"]["failed_at_s"] is None or f["evidence"]["half_step"]["failed_at_s"] > 1.1 * info.value.time
    assert f["evidence"]["dt_over_shortest_period"] > 1
    assert "reduce solver.dt" in str(info.value) and "Newton" in str(info.value)
    assert "last iteration: residual norm" in str(info.value)


def test_cli_writes_marked_partial_results_and_exits_3(tmp_path, capsys):
    rc = main(["run", str(CASES / "fourbar_hac.toml"), "--model", "classic", "--set", "solver.t_end=0.16",
               "--set", "solver.geometric_stiffness=current", "--set", "solver.error_estimate='none'",
               "--out", str(tmp_path)])
    cap = capsys.readouterr()
    assert rc == 3
    errors = [ln for ln in cap.err.splitlines() if ln.startswith("flexmech: error: ")]
    assert len(errors) == 1 and "classic run stopped at t = " in errors[0] and "Likely cause:" in errors[0]
    assert "PARTIAL" in cap.out and "wrote partial results" in cap.out
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["status"] == "failed" and s["failure"]["cause"] == "outside_validity"
    assert s["failed_at_s"] > s["t_end"] and s["frames"] == frames_before(s["failure"]["step"], 10)
    lines = (tmp_path / "timeseries.csv").read_text().splitlines()
    assert lines[0].startswith("# partial: the run stopped at t = ") and lines[1].startswith("# flexmech ")
    cols, _ = read_timeseries(tmp_path / "timeseries.csv")
    assert cols["t"].size == s["frames"] and cols["t"][-1] == pytest.approx(s["t_end"])
    assert not list(tmp_path.glob("*.png"))


def test_kernel_status_6_has_a_message():
    from flexmech_py.base import kernels

    with pytest.raises(SolverError, match="divergence_limit") as info:
        kernels.check_status(6, "Newmark integration", time=0.1, step=5, data={"u": None})
    assert info.value.code == 6 and info.value.step == 5 and info.value.data is not None
    with pytest.raises(SolverError) as info:   # a bad-input status keeps no partial data
        kernels.check_status(4, "Newmark integration", time=0.0, step=0, data={"u": None})
    assert info.value.data is None


# ----------------------------------------------------------------------------- validity
@pytest.fixture(scope="module")
def seed_run():
    return fm.simulate(_seed("solver.t_end=0.12", "solver.error_estimate='none'"))


def test_validity_times_agree_with_the_gap_study(seed_run):
    res = seed_run
    t_defl, t_comp = validity_time(res)
    val, ov = res.extra["validity"], res.extra["validity_overall"]
    assert min(v["deflection_exceeds_at_s"] or np.inf for v in val.values()) == pytest.approx(t_defl)
    assert min(v["compression_exceeds_at_s"] or np.inf for v in val.values()) == pytest.approx(t_comp)
    assert ov["valid_until_s"] == pytest.approx(min(t_defl, t_comp))
    assert ov["max_compression_over_euler"] == max(v["max_compression_over_euler"] for v in val.values())


def test_largest_strain_bounds_the_midspan_strain_outputs(seed_run):
    """max_strain is over every node and includes the axial strain: at least the |midspan| strain."""
    for link in ("coupler", "follower"):
        v = seed_run.extra["validity"][link]
        mid = np.max(np.abs(seed_run.columns[f"strain_{link}_mid"]))
        assert mid <= v["max_strain"] <= mid + 0.1   # strains of order 1e-2 here


def test_seed_fourbar_warns_plainly(seed_run):
    w = seed_run.extra["warnings"]
    head = w[0]
    assert head.startswith("the hac model's results after t = ") and "outside its validity" in head
    assert "crank speed" in head and "--model nonlinear" in head and "geometric_stiffness" in head
    assert any("coupler: compressive axial force exceeds its Euler load" in x for x in w)
    s = seed_run.summary()
    assert s["warnings"] == w and s["status"] == "completed" and "failure" not in s


def test_yield_strain_warns_only_when_passed():
    case = _seed("solver.t_end=0.03", "solver.error_estimate='none'", "links.coupler.yield_strain=1e-4",
                 "links.follower.yield_strain=1.0")
    res = fm.simulate(case)
    v = res.extra["validity"]
    assert v["coupler"]["max_strain"] > 1e-4 and v["coupler"]["strain_exceeds_yield_at_s"] is not None
    assert v["follower"]["strain_exceeds_yield_at_s"] is None and v["crank"]["yield_strain"] is None
    assert any(x.startswith("coupler: strain exceeds its yield strain") for x in res.extra["warnings"])
    assert not any(x.startswith("follower: strain") for x in res.extra["warnings"])


def test_yield_strain_must_be_positive():
    with pytest.raises(fm.CaseError, match=r"links\[1\].yield_strain"):
        _seed("links.coupler.yield_strain=-1")


def test_console_prints_validity_table_and_warnings(tmp_path, capsys):
    rc = main(["run", str(CASES / "fourbar_hac.toml"), "--set", "solver.t_end=0.12", "--no-plots", "--out", str(tmp_path)])
    cap = capsys.readouterr()
    assert rc == 0
    assert "validity (limits: deflection 2 % of L" in cap.out and "\noverall " in cap.out
    assert "time-step error estimate" in cap.out
    assert "flexmech: warning: the hac model's results after t = " in cap.err


# ----------------------------------------------------------------------------- error estimate
HONESTY_RUNS = [("fourbar_hac", "hac", 0.05, 1e-5, 10), ("fourbar_hac", "hac", 0.05, 4e-5, 5),
                ("manipulator_bricout", "coupled", 0.05, 2e-5, 2)]


def estimate_vs_actual(name, model, t_end, dt, oe):
    """{column: (estimated, actual)} largest errors of a run at dt against a reference at dt/8."""
    case = fm.load_case(CASES / f"{name}.toml", overrides=[f"solver.t_end={t_end}"])
    res = Prepared(case, dt=dt, out_every=oe).run(model)
    ref = Prepared(case, dt=dt / 8, out_every=8 * oe).run(model, estimate=False)
    assert np.allclose(ref.t, res.t)
    out = {}
    for col, e in res.extra["error_estimate"]["columns"].items():
        actual = float(np.max(np.abs(res.columns[col] - ref.columns[col])))
        if actual > 1e-12 * np.max(np.abs(ref.columns[col])):   # skip the rigid columns (exact in both)
            out[col] = (e["max_abs"], actual)
    return res, out


@pytest.mark.parametrize("name, model, t_end, dt, oe", HONESTY_RUNS)
def test_error_estimate_is_honest(name, model, t_end, dt, oe):
    res, pairs = estimate_vs_actual(name, model, t_end, dt, oe)
    est = res.extra["error_estimate"]
    assert est["method"] == "time" and est["coarse_dt"] == pytest.approx(2 * res.dt)
    coarse = res.t.size if oe % 2 == 0 else (res.t.size - 1) // 2 + 1      # the frames of the run at 2 dt
    if coarse > FRAMES_FULL:                                                  # compared at every second one
        coarse = (coarse - 1) // 2 + 1
    assert est["frames_compared"] == coarse
    assert pairs
    for col, (e, a) in pairs.items():
        assert 1 / 3 < e / a < 3, (col, e, a)
    w = est["worst_column"]
    assert est["worst_relative"] == max(c["relative"] for c in est["columns"].values())
    assert est["columns"][w]["relative"] == pytest.approx(est["columns"][w]["max_abs"] / np.max(np.abs(res.columns[w])))


def test_error_estimate_none_is_honoured():
    res = fm.simulate(_seed("solver.t_end=0.01", "solver.error_estimate='none'"))
    assert res.summary()["error_estimate"] == {"method": "none"}
    with pytest.raises(fm.CaseError, match="solver.error_estimate"):
        _seed("solver.error_estimate='space'")


if __name__ == "__main__":   # the table of docs/stability.md
    for run in HONESTY_RUNS + [("manipulator_bricout", "hac", 0.05, 1e-4, 2), ("fourbar_hac", "nonlinear", 0.02, 5e-6, 4)]:
        _, pairs = estimate_vs_actual(*run)
        ratios = {c: e / a for c, (e, a) in pairs.items()}
        print(f"| {run[0]}, {run[1]}, t_end {run[2]} s, dt {run[3]:g} s, output_every {run[4]} | "
              f"{min(ratios.values()):.2f}–{max(ratios.values()):.2f} | "
              + ", ".join(f"{c} {r:.2f}" for c, r in ratios.items()))


def test_nonlinear_drive_torque_stays_smooth_with_average_acceleration():
    """The nonlinear spin-up beam (kinematic drive = a rotation constraint) with average acceleration.
    Before the shared node angles (docs/theory.md 12.1) the drive row acted on the chord angle plus
    the element's end rotation, its curvature was missing from the iteration matrix, and the drive
    torque's period-2 dt oscillation grew until Newton failed (the guards blamed the integrator).
    Now the drive row is linear in the node angle: Newmark runs through, its drive torque equals
    generalized-alpha's to 1e-4 of its peak, with at most 2 Newton iterations per step."""
    runs = {}
    for integ in ("newmark", "generalized-alpha"):
        runs[integ] = fm.simulate(fm.load_case(
            CASES / "extreme" / "spinup_beam.toml",
            overrides=["solver.dt=2e-3", "solver.t_end=4.0", "solver.model='nonlinear'", f"solver.integrator='{integ}'",
                       "solver.error_estimate='none'"]))
    tn, tg = (runs[k].columns["drive_torque"] for k in ("newmark", "generalized-alpha"))
    peak = np.abs(tn).max()
    assert runs["newmark"].t[-1] == pytest.approx(4.0)
    assert np.abs(tn - tg).max() < 1e-4 * peak
    assert np.abs(np.diff(tn, 2)).max() < 1e-3 * peak          # no period-2 dt oscillation
    assert runs["newmark"].extra["coupled"]["newton"]["max_per_step"] <= 2


# ----------------------------------------------------------------------------- error-estimate warning
def _spun_cantilever(dt, final_speed=6.0, t_end=0.8):
    """A slender cantilever spun up smoothly over 0.4 s (every excited mode resolved: order 2 in dt)."""
    from conftest import beam_case

    drive = {"type": "kinematic", "law": "spinup", "final_speed": final_speed, "spinup_time": 0.4}
    return beam_case(n_el=2, drive=drive, t_end=t_end, dt=dt, second_moment=2e-10,
                     outputs={"tip_v": {"kind": "displacement", "at": "beam.end", "component": "transverse"}})


def test_error_estimate_warns_past_the_threshold_with_the_step_that_meets_it():
    from flexmech_py.checks.step_doubling import ERROR_WARN

    res = fm.simulate(_spun_cantilever(0.016), model="classic")
    est = res.extra["error_estimate"]
    assert est["worst_relative"] > 1.5 * ERROR_WARN            # measured 9.2 %
    w = est["warning"]
    assert abs(w["observed_order"] - 2) < 0.3 and w["suggested_dt"] < res.dt
    assert [x for x in res.extra["warnings"] if x.startswith("error estimate:")] == [w["message"]]
    assert f"--dt {w['suggested_dt']:.2g}" in w["message"] and "above the 5 % threshold" in w["message"]
    # the promised step meets the threshold, and not by a wide margin (the dt^2 extrapolation is sharp)
    again = fm.simulate(_spun_cantilever(w["suggested_dt"]), model="classic").extra["error_estimate"]
    assert 0.6 * ERROR_WARN < again["worst_relative"] <= ERROR_WARN and "warning" not in again
    assert not any(x.startswith("error estimate:") for x in fm.simulate(_spun_cantilever(0.008), model="classic")
                   .extra["warnings"])


def test_error_estimate_outside_the_asymptotic_range_promises_no_step():
    # 2 s at 3 rad/s: the free vibration left by the spin-up accumulates a phase error; at dt = 0.016 s the
    # differences between dt, 2 dt and 4 dt grow only linearly (observed order about 1), so no step is promised
    res = fm.simulate(_spun_cantilever(0.016, final_speed=3.0, t_end=2.0), model="classic")
    w = res.extra["error_estimate"]["warning"]
    assert w["suggested_dt"] is None and abs(w["observed_order"] - 2) > 0.3
    assert "not in the asymptotic range" in w["message"] and "no step can be promised" in w["message"]


def test_observed_order_from_the_kept_frames_equals_the_run_made_again(monkeypatch):
    """The 2 dt run's frames on the 4 dt grid are kept while it runs beside the dt run, so the observed
    order needs only the run at 4 dt: the same order and message as when the 2 dt run is made again
    (KEEP_FRAMES_MAX = 0 forces that)."""
    from flexmech_py.checks import step_doubling

    seen = []
    original = step_doubling.StepComparison.kept_block
    monkeypatch.setattr(step_doubling.StepComparison, "kept_block", lambda self: seen.append(original(self)) or seen[-1])
    kept = fm.simulate(_spun_cantilever(0.016), model="classic").extra["error_estimate"]["warning"]
    assert seen and seen[0] is not None and seen[0].steps.size > 2
    monkeypatch.setattr(step_doubling, "KEEP_FRAMES_MAX", 0)
    again = fm.simulate(_spun_cantilever(0.016), model="classic").extra["error_estimate"]["warning"]
    assert seen[-1] is None
    assert kept["observed_order"] == again["observed_order"] and kept["message"] == again["message"]
