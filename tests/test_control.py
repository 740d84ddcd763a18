"""Feedback controllers in the time loop ([[controllers]], fortran/flexmech_control.f90): the rigid
limit of a PD-controlled link against the closed-loop linear response, the energy balance with the
actuator's work, saturation and anti-windup, zero-order hold and measurement delay, the stepping API,
and the refusals of bad input; the superposition models' collocated loops closed in their rigid-body
integration (fortran/flexmech_mbs_control.f90) against the exact closed loop and the coupled model."""

import copy
import json
import re

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import flexmech_py as fm
from flexmech_py.studies.control_study import (DAMPED, DURATION, J_HUB, TAU, TIP, TRAVEL, bricout, closed_loop, cycloid,
                                               eigen_loop, growth_rate, link_case, run, saturated_pid, settles,
                                               small_move, swing_growth)
from flexmech_py.studies.control_eigen import critical_gain, linearize_loop
from flexmech_py.case import validate_case
from flexmech_py.base.tomlfile import dumps_toml
from flexmech_py.cli import main
from flexmech_py.base.errors import CaseError, SolverError, ValidityWarning
from flexmech_py.run.stepping import Simulation
from flexmech_py.studies.pi_motor import reference, rigid_closed_loop, ripple, run_case


@pytest.mark.parametrize("model", ["coupled", "nonlinear"])
def test_rigid_limit_of_a_pd_link_is_the_closed_loop_second_order_response(model):
    res = run(link_case(stiffness=1e4), model)
    y = closed_loop(res.t, 2.0, 0.3)
    err = np.abs(res.columns["hub_angle"] - y).max()
    assert err < 2e-5 * np.abs(y).max(), err          # measured 2.3e-6 of the peak (coupled, dt 1e-3)
    # the drive torque is the controller's output, the energy the actuator's work
    assert np.allclose(res.columns["torque"], res.columns["control_hub_pid"])
    e = res.columns["energy_kinetic"] + res.columns["energy_potential"]
    assert abs(e[-1] - res.columns["work_inputs"][-1]) < 1e-4 * np.abs(res.columns["work_inputs"]).max()


def test_flexible_link_energy_balance_includes_the_actuator_work():
    res = run(link_case(kp=5.0, kd=0.5, t_end=0.4))
    c = res.columns
    e = c["energy_kinetic"] + c["energy_potential"]
    assert c["energy_potential"].max() > 1e-3 * c["energy_kinetic"].max()     # the link does bend
    assert np.abs(e - c["work_inputs"]).max() < 1e-3 * np.abs(c["work_inputs"]).max()


def test_saturation_holds_the_limit_and_clamping_is_the_specified_anti_windup():
    gains, limit = dict(kp=20.0, ki=40.0, kd=1.5), 0.6
    res = run(link_case(stiffness=1e4, limit=limit, t_end=1.5, **gains))
    u, y = res.columns["control_hub_pid"], res.columns["hub_angle"]
    assert np.abs(u).max() <= limit * (1 + 1e-12)
    assert np.isclose(np.abs(u).max(), limit)                   # the limit is reached
    clamped = saturated_pid(res.t, limit=limit, **gains)
    wound = saturated_pid(res.t, limit=limit, clamp=False, **gains)
    err = np.abs(y - clamped).max()
    assert err < 0.01 * 0.5, err                                # measured: see docs/validation.md
    assert np.abs(wound - clamped).max() > 5 * err              # the clamping is what makes the difference
    assert abs(y[-1] - 0.5) < 0.01                              # and the move ends at its target


def test_zero_order_hold_holds_the_output_between_samples():
    res = run(link_case(sample_time=5e-3, t_end=0.2))
    u = res.columns["control_hub_pid"]
    steps = np.flatnonzero(np.diff(u) != 0) + 1
    assert steps.size > 0 and np.all(steps % 5 == 0)          # changes only at the samples (every 5 steps)


def test_measurement_delay_shifts_the_output_of_a_p_controller():
    """A P controller on a delayed measurement: its output at t is the undelayed law on y(t - d)."""
    d = 0.01
    res = run(link_case(stiffness=1e4, kp=2.0, kd=0.0, delay=d, t_end=0.3))
    t, y, u = res.t, res.columns["hub_angle"], res.columns["control_hub_pid"]
    r, _ = cycloid(t)
    k = round(d / 1e-3)
    assert np.allclose(u[k:], 2.0 * (r[k:] - y[:-k]), atol=1e-9)


def test_collocated_pd_is_stable_at_every_gain_by_the_closed_loop_eigenvalues():
    """The classic result (Cannon & Schmitz 1984), collocated half: hub-angle PD k (e + 0.15 s e') on
    the flexible link has max Re lambda < 0 over k = 0.01 .. 1e4 (docs/theory.md 23.5: the feedback is
    symmetric); the modes it leaves alone are the link's axial ones (one per element; pinned-free bar:
    (2j - 1) c / 4L, 1273 and 3819 Hz exactly, 1275 and 3874 Hz with 8 elements), and the time runs
    settle."""
    loop = eigen_loop(elements=2)
    sigma = [loop.abscissa(k, TAU * k) for k in np.geomspace(0.01, 1e4, 25)]
    assert max(sigma) < 0.0, max(sigma)      # measured -2.5e-4 1/s (at k = 0.01: the rigid mode, kd / 2J)
    c = (7.0e10 / 2700.0) ** 0.5
    fine = eigen_loop(elements=8)
    assert fine.untouched_hz.size == 8 and abs(fine.untouched_re) <= fine.round_off
    assert np.allclose(fine.untouched_hz[:2], [c / 4, 3 * c / 4], rtol=0.02), fine.untouched_hz
    assert np.allclose(loop.p[:, 0], loop.o[0], rtol=1e-6, atol=1e-9 * np.abs(loop.p).max())    # collocated: c = b
    for k in (0.5, 50.0):
        assert settles(k) < 1.0


def test_tip_feedback_without_damping_grows_at_every_gain_as_the_eigenvalues_say():
    """Tip-height PD on the undamped link: the first bending mode (24.9 Hz) grows at every k > 0 with
    Re lambda = k tau |p o| / 2 (first-order perturbation, docs/theory.md 23.5), the critical gain 0;
    a time run at k = 1 grows at the eigenvalues' rate (measured 1.6649 against 1.6658 1/s), and the
    old finite-time measure (late/early error over 1.5 s: 0.35) hides it until a longer run (6 s: 9.0)."""
    loop = eigen_loop(TIP, elements=4)
    crit = critical_gain(loop, TAU, gains=(1e-3, 10.0))
    assert crit["kp"] == 0.0 and abs(crit["f_hz"] - 24.89) < 0.05
    assert abs(crit["slope_at_zero_per_s"] - loop.slope_at_zero(TAU).max()) < 1e-3 * crit["slope_at_zero_per_s"]
    lead = loop.leading(1.0, TAU)
    rate = growth_rate(small_move(1.0, TIP, t_end=2.5), lead["f_hz"])
    assert abs(rate - lead["re_per_s"]) < 0.01 * lead["re_per_s"], (rate, lead)
    assert settles(1.0, TIP) < 1.0 < settles(1.0, TIP, t_end=6.0)


def test_tip_feedback_critical_gain_with_damping_in_eigenvalues_and_time_runs():
    """With Rayleigh damping (beta = 2.5e-4 s: 2 % of critical in the 24.9 Hz mode) tip-height PD has a
    finite critical gain: the eigenvalues give kp = 1.8344 (4 elements; 1.8291 with 2, 1.8348 with 8:
    converging with the mesh), the first-order estimate 2 zeta w / (tau |p o|) agrees to 1 %, and time
    runs at 0.8 and 1.2 times it decay and grow at the eigenvalues' rates (measured -0.612 and +0.608
    against -/+0.611 1/s)."""
    kc = {ne: critical_gain(eigen_loop(TIP, DAMPED, ne), TAU, gains=(0.1, 100.0))["kp"] for ne in (2, 4, 8)}
    assert 1.82 < kc[2] < kc[4] < kc[8] < 1.84, kc
    assert abs(kc[8] - kc[4]) < 0.2 * abs(kc[4] - kc[2])
    loop = eigen_loop(TIP, DAMPED, 4)
    i = int(np.argmax(loop.slope_at_zero(TAU)))
    w = loop.omega[i]
    assert abs(2 * (DAMPED[1] * w / 2) * w / (TAU * abs(loop.p[i, 0] * loop.o[0, i])) / kc[4] - 1) < 0.01
    f_hz = loop.leading(kc[4], TAU * kc[4])["f_hz"]
    for f in (0.8, 1.2):
        eig = loop.leading(f * kc[4], TAU * f * kc[4])["re_per_s"]
        rate = growth_rate(small_move(f * kc[4], TIP, t_end=2.5, rayleigh=DAMPED), f_hz)
        assert np.sign(rate) == np.sign(eig) and abs(rate - eig) < 0.05 * abs(eig), (f, rate, eig)


def test_tip_proportional_feedback_flutters_above_the_eigenvalues_critical_gain():
    """P feedback of the tip's height (tau = 0) on the undamped link is marginal until the rigid mode,
    rising with k, meets the first bending mode: flutter at kp = 411.66 N m/m, 15.79 Hz (411.21 with 2
    elements, 411.69 with 8).  Time runs: 1.5 % below it the swing stays (1.05 x the first eighth's),
    1.5 % above it it grows (4.9 x) into a large-angle oscillation."""
    crit = critical_gain(eigen_loop(TIP, elements=4), 0.0, gains=(100.0, 1000.0))
    assert 411.0 < crit["kp"] < 412.5 and abs(crit["f_hz"] - 15.79) < 0.05, crit
    assert swing_growth(0.985 * crit["kp"]) < 1.3 and swing_growth(1.015 * crit["kp"]) > 3.0


def test_modes_closed_loop_cli_writes_the_loops_eigenvalues(tmp_path, capsys):
    """`flexmech modes CASE --closed-loop` on the tip-feedback link: the 24.9 Hz mode unstable at every
    factor on the gains (undamped), its files; refused with --at and on a case without controllers."""
    case = tmp_path / "tip.toml"
    case.write_text(dumps_toml(small_move(2.0, TIP)))
    assert main(["modes", str(case), "--closed-loop", "--out", str(tmp_path / "out")]) == 0
    summary = json.loads((tmp_path / "out" / "closed_loop.json").read_text())
    assert summary["critical_gain_factor"]["scale"] == 0.0
    assert abs(summary["leading"]["f_hz"] - 24.89) < 0.05 and summary["leading"]["re_per_s"] > 3.0
    assert "UNSTABLE" in capsys.readouterr().out
    assert main(["modes", str(case), "--closed-loop", "--at", "0.1", "--out", str(tmp_path / "o2")]) == 2
    assert main(["modes", str(fm.case_path("fourbar_constant_speed")), "--closed-loop", "--out", str(tmp_path / "o3")]) == 2


def test_closed_loop_eigenvalues_refuse_a_sampled_law_and_superposition_models():
    raw = small_move(1.0, TIP)
    raw["controllers"][0]["sample_time"] = 1e-3
    with pytest.raises(CaseError, match="continuous"):
        linearize_loop(validate_case(raw))
    with pytest.raises(CaseError, match="superposes them on a rigid motion"):
        linearize_loop(validate_case(small_move(1.0)), model="classic")
    with pytest.raises(CaseError, match="no controller named"):
        linearize_loop(validate_case(small_move(1.0)), "elbow")


def test_stiff_collocated_gains_converge_with_the_law_in_the_iteration_matrix():
    """The continuous law's derivatives in the Newton iteration matrix (docs/theory.md 23.2): a hub
    gain whose kd gamma/(beta h) dwarfs the hub node's own inertia (k = 5000, kd = 750 N m s/rad at
    h = 5e-4 s) converges and settles; with the law in the residual only it stopped with a Newton
    failure (the run's late/early error then inf)."""
    assert settles(5000.0) < 1.0


def test_a_start_from_rest_keeps_the_energy_balance_at_the_default_newton_tol():
    """The Bricout PD case's first 60 steps (tiny motion, the iterations stop early when the matrix
    lacks the law's derivatives: 24 % of the work missing before) at the default tolerance 1e-8."""
    raw = fm.load_case(fm.case_path("manipulator_bricout_pd"))
    raw["solver"].update(t_end=6e-4, output_every=1, newton_tol=1e-8)
    c = run(raw).columns
    e = c["energy_kinetic"] + c["energy_potential"]
    assert abs(e[-1] - c["work_inputs"][-1]) < 1e-4 * abs(c["work_inputs"][-1])   # measured 5.7e-7


def test_bundled_bricout_shapers_cut_the_residual_vibration_without_saturating():
    """The bundled Bricout PD cases (docs/validation.md): ZV and ZVD shapers of the closed-loop first
    mode cut the base strain's ringing in the 0.5 s after the move (measured 34 % and 8.5 % of the
    unshaped move's), the base actuator below its 1000 N m limit in all three."""
    r = bricout()
    plain, zv, zvd = (r[n]["residual_strain_amplitude"] for n in
                      ("manipulator_bricout_pd", "manipulator_bricout_pd_zv", "manipulator_bricout_pd_zvd"))
    assert zv < 0.5 * plain and zvd < 0.2 * plain and zvd < 0.5 * zv, (plain, zv, zvd)
    assert all(v["base_torque_peak"] < 1000.0 for v in r.values())
    assert all(abs(v["alpha_final"] - 0.2) < 2e-3 for v in r.values())


def test_stepping_api_reproduces_the_case_file_loop():
    raw = link_case(t_end=0.05)
    batch = run(raw)
    sim = Simulation(fm.validate_case(copy.deepcopy(raw)))
    for _ in range(50):
        sim.advance(1)
    assert np.allclose(sim.joint("hub")[0], batch.columns["hub_angle"][-1], rtol=0, atol=1e-12)
    stepped = sim.result().columns
    for name in ("hub_angle", "torque", "control_hub_pid", "work_inputs"):
        assert np.allclose(stepped[name], batch.columns[name], rtol=0, atol=1e-12), name


@pytest.mark.parametrize("change, field", [
    ({"kp": -1.0}, "controllers[0].kp"),
    ({"kp": 0.0, "kd": 0.0}, "controllers[0].kp"),
    ({"limit": 0.0}, "controllers[0].limit"),
    ({"limits": [1.0, -1.0]}, "controllers[0].limits"),
    ({"sample_time": -1e-3}, "controllers[0].sample_time"),
    ({"delay": float("nan")}, "controllers[0].delay"),
    ({"delay": 10.0}, "controllers[0].delay"),
    ({"measure": "tip"}, "controllers[0].measure"),
    ({"reference": {"law": "rest_to_rest", "travel": 0.5, "duration": 0.0}}, "controllers[0].reference.duration"),
    ({"joint": "nowhere"}, "controllers[0].joint"),
])
def test_bad_controller_fields_are_refused_naming_the_field(change, field):
    with pytest.raises(CaseError) as err:
        fm.validate_case(link_case(**change))
    assert err.value.field == field


def test_a_prescribed_joint_is_refused():
    raw = link_case()
    raw["drives"] = [{"joint": "hub", "law": "constant_speed", "speed": 1.0}]
    with pytest.raises(CaseError, match="force drive") as err:
        fm.validate_case(raw)
    assert err.value.field == "controllers[0].joint"


def test_a_sample_time_off_the_step_grid_is_resampled_with_a_warning():
    with pytest.warns(ValidityWarning, match="sample_time"):
        case = fm.validate_case(link_case(sample_time=2.5e-3))
    assert case["controllers"][0]["sample_time"] == pytest.approx(2e-3)


def test_no_model_named_runs_a_controlled_case_under_the_nonlinear_model():
    raw = link_case()
    del raw["solver"]["model"]
    assert fm.validate_case(raw)["solver"]["model"] == "nonlinear"


def test_an_unstable_loop_stops_through_the_failure_diagnosis_naming_the_controller():
    """A PD loop sampled far too slowly (kd Ts / J = 3.6: the sampled loop's poles leave the unit
    circle) grows until the divergence guard stops the run; the diagnosis names the controller."""
    with pytest.raises(SolverError, match="feedback controller 'hub_pid': its output grew") as err:
        run(link_case(kp=50.0, kd=20.0, sample_time=0.02, t_end=1.0))
    assert err.value.partial.failure["cause"] == "unstable_control_loop"


def test_a_stable_loop_has_no_controller_suspect():
    from flexmech_py.mechanism.control import loop_suspect
    res = run(link_case(t_end=0.3))
    assert loop_suspect(res.case, res.columns) is None


def test_inverse_dynamics_feedforward_is_the_rigid_torque_and_cancels_the_tracking_error():
    """feedforward = "inverse_dynamics": on a link turning about its hub the rigid-body torque along the
    cycloidal reference is J_hub r''(t) (no gravity, no own load); with it the rigid limit tracks the
    reference to the integration error (measured 1.7e-5 rad against 0.32 rad by PD alone)."""
    raw = link_case(stiffness=1e4)
    raw["controllers"][0]["feedforward"] = "inverse_dynamics"
    case = validate_case(copy.deepcopy(raw))
    ff = case["controllers"][0]["feedforward"]
    t, tau = np.asarray(ff["t"]), np.asarray(ff["value"])
    s = np.clip(t / DURATION, 0.0, 1.0)
    want = J_HUB * TRAVEL * 2 * np.pi * np.sin(2 * np.pi * s) / DURATION ** 2 * (t <= DURATION)
    assert np.abs(tau - want).max() < 1e-6 * np.abs(want).max()
    res, plain = run(case, "coupled"), run(link_case(stiffness=1e4), "coupled")
    y = cycloid(res.t)[0]
    err = np.abs(res.columns["hub_angle"] - y).max()
    assert err < 1e-4 * TRAVEL and np.abs(plain.columns["hub_angle"] - y).max() > 0.1 * TRAVEL


@pytest.mark.parametrize("change, field", [
    (lambda c: c["controllers"][0].update(measure={"point": "arm.end", "direction": [0, 1]},
                                          reference={"law": "rest_to_rest", "travel": 0.05, "duration": 0.3}),
     "controllers[0].feedforward"),
    (lambda c: c["drives"][0].update(sin=[0.1]), "controllers[0].feedforward"),
])
def test_an_inverse_dynamics_feedforward_that_cannot_be_computed_is_refused(change, field):
    raw = link_case()
    raw["controllers"][0]["feedforward"] = "inverse_dynamics"
    change(raw)
    with pytest.raises(CaseError) as exc:
        validate_case(raw)
    assert exc.value.field == field


def test_inverse_dynamics_needs_every_free_joint_followed():
    with pytest.raises(CaseError, match="free degree"):
        fm.load_case("manipulator_bricout_pd", ["controllers.0.feedforward=inverse_dynamics"])


def test_pi_fourbar_rigid_limit_follows_the_rigid_closed_loop_ode():
    """The bundled PI four-bar with every link's E x 1e4 (the spin-up and a quarter cycle, 8 elements per
    link, nonlinear model) against the rigid linkage's closed loop M(θ) θ'' + ½ M'(θ) θ'² = u + load, M(θ)
    from the linkage's own kinematics and solve_ivp (flexmech_py.studies.pi_motor): the free crank's
    inertia, the rotor, the torque's point of action and the law's sign.  Measured over the whole
    case: 5.8e-7 rad, 7.2e-5 rad/s."""
    res = run_case(stiffness=1e4, t_end=0.25)
    ode = rigid_closed_loop(res.case, res.t)
    assert np.abs(res.columns["crank_angle"] - ode["angle"]).max() < 1e-5
    assert np.abs(res.columns["motor_speed"] - ode["speed"]).max() < 1e-3
    assert np.abs(res.columns["control_motor_pi"] - ode["torque"]).max() < 1e-3 * np.abs(ode["torque"]).max()


def test_bundled_pi_fourbar_holds_its_speed_with_the_rigid_loops_ripple_inside_validity():
    """The bundled case (coupled model, 2 elements per link, the spin-up and two cycles at 30 rad/s):
    no validity warning; over the last cycle the motor (hub) speed's mean is the target to 0.1 % and
    its peak to peak within 30 % of the rigid closed loop's (ODE, the same law; measured 1.64 against
    1.40 rad/s: the rest is the linkage's vibration), the motor torque within 20 % of the ODE's range
    and never at its limit; the hub speed output is what the controller reads (its PD law on the angle
    and speed at the joint gives its output); the energy balance holds with the actuator's work."""
    target = 30.0
    res = run_case(model="coupled", elements=2, t_end=0.2 + 2 * 2 * np.pi / target,
                   sets=['outputs.motor_angle={kind = "joint_angle", joint = "crank_pivot", measure = "joint"}'])
    c = res.columns
    assert not [w for w in res.extra["warnings_raised"] if "validity" in w or "Euler" in w or "%" in w], \
        res.extra["warnings_raised"]
    assert res.extra["validity_overall"]["max_compression_over_euler"] < 0.5
    ode = rigid_closed_loop(res.case, res.t)
    got = ripple(res.t, c["motor_speed"], c["control_motor_pi"], target)
    rigid = ripple(res.t, ode["speed"], ode["torque"], target)
    assert abs(got["mean"] - target) < 1e-3 * target and got["peak_to_peak"] < 0.1 * target, got
    assert abs(got["peak_to_peak"] - rigid["peak_to_peak"]) < 0.3 * rigid["peak_to_peak"], (got, rigid)
    span = np.ptp(rigid["torque_range"])
    assert np.allclose(got["torque_range"], rigid["torque_range"], atol=0.2 * span), (got, rigid)
    ctl = res.case["controllers"][0]
    assert np.abs(c["control_motor_pi"]).max() < ctl["limits"][1]
    r, rd = reference(ctl["reference"], res.t)
    law = ctl["kp"] * (r - c["motor_angle"]) + ctl["kd"] * (rd - c["motor_speed"])
    assert np.abs(law - c["control_motor_pi"]).max() < 1e-6 * np.abs(law).max()
    e = c["energy_kinetic"] + c["energy_potential"] - c["work_inputs"]
    assert np.abs(e).max() < 1e-5 * np.abs(c["work_inputs"]).max()          # measured 5.8e-7 (whole case)


def test_a_validity_warning_names_the_controlled_cranks_own_speed():
    """The PI four-bar driven to 40 rad/s (coupled, 2 elements per link) passes 2 % deflection after the
    spin-up; the warning's "(crank speed ...)" is the run's own crank speed then, not the rigid-body
    solution's, which knows no controller (it said 5.93 rad/s: the load torque alone turning the crank
    backwards)."""
    res = run_case(model="coupled", elements=2, t_end=0.3,
                   sets=['controllers.motor_pi.reference={law = "spinup", final_speed = 40.0, spinup_time = 0.2}'])
    (first,) = [w for w in res.extra["warnings_raised"] if "outside its validity" in w]
    t0, speed = (float(x) for x in re.search(r"after t = ([0-9.e+-]+) s \(crank speed ([0-9.e+-]+) rad/s\)", first).groups())
    own = np.interp(t0, res.t, res.columns["crank_speed"])
    assert own > 30.0 and abs(speed - own) < 1e-3 * own, (speed, own, first)


def test_the_cli_model_choice_is_the_cases_model_when_it_is_validated(tmp_path):
    """``--model coupled`` on a case with a sampled controller whose file names a superposition model runs
    (the case is validated with --model as solver.model); --model hac on it is refused naming the
    controller's sample_time (a one-way model closes continuous loops only), exit 2."""
    from flexmech_py.base.tomlfile import dumps_toml
    from flexmech_py.cli import main

    path = tmp_path / "link.toml"
    path.write_text(dumps_toml(link_case(t_end=0.01, model="hac", sample_time=2e-3)))
    assert main(["run", str(path), "--model", "coupled", "--no-plots", "--quiet", "--out", str(tmp_path / "a")]) == 0
    assert main(["run", str(path), "--model", "hac", "--no-plots", "--quiet", "--out", str(tmp_path / "b")]) == 2
    assert not (tmp_path / "b").exists()


def _gauge_case(at: float) -> dict:
    raw = link_case(t_end=0.2)
    raw["links"][0]["half_depth"] = 0.005
    raw["controllers"].append({"name": "gauge", "joint": "hub", "kp": 1000.0, "measure": {"strain": "arm", "at": at},
                               "reference": {"law": "constant_speed", "speed": 0.0, "start": 0.0}})
    for f in (0.375, 0.5, 0.625):
        raw["outputs"][f"s{round(f * 1000)}"] = {"kind": "strain", "link": "arm", "at": f}
    return raw


@pytest.mark.parametrize("model", ["coupled", "nonlinear"])
def test_a_strain_gauge_controller_measures_the_mean_strain_of_its_elements(model):
    """measure = {strain = link, at = f}: a P law on the strain (reference 0) outputs -kp times the mean
    bending strain over the element holding f, which for the cubic elements' linear curvature is the
    strain output at the element's middle (f = 0.375 of 4 elements), and over the two elements around a
    node (f = 0.5): the mean of their middles' strains."""
    for at, want in ((0.375, lambda c: c["s375"]), (0.5, lambda c: 0.5 * (c["s375"] + c["s625"]))):
        c = run(_gauge_case(at), model).columns
        y = -c["control_gauge"] / 1000.0
        assert np.abs(c["s500"]).max() > 1e-5                 # the link bends
        assert np.abs(y - want(c)).max() < 1e-9 * np.abs(want(c)).max()


@pytest.mark.parametrize("measure, field", [({"strain": "nope", "at": 0.5}, "controllers[1].measure.strain"),
                                            ({"strain": "arm", "at": 1.5}, "controllers[1].measure.at")])
def test_a_strain_measure_on_no_flexible_link_or_off_the_link_is_refused(measure, field):
    raw = _gauge_case(0.5)
    raw["controllers"][1]["measure"] = measure
    with pytest.raises(CaseError) as exc:
        validate_case(raw)
    assert exc.value.field == field


# ---------------------------------------------------------------- superposition models (theory.md 23.3)

def exact_pd(t, kp, kd):
    """J theta'' = kp (r - theta) + kd (r' - theta') of the rigid link with the cycloid itself (not
    sampled), by DOP853 at rtol 1e-12: a reference far below the rigid integration's tolerance."""
    def rhs(tt, x):
        r, rd = cycloid(np.array(tt))
        return [x[1], (kp * (r - x[0]) + kd * (rd - x[1])) / J_HUB]
    return solve_ivp(rhs, (t[0], t[-1]), [0.0, 0.0], t_eval=t, method="DOP853", rtol=1e-12, atol=1e-14,
                     max_step=1e-3).y[0]


@pytest.mark.parametrize("model", ["hac", "classic", "classic-translational"])
def test_superposition_rigid_limit_is_the_exact_closed_loop_to_the_integrator_tolerance(model):
    """The loop closed inside the rigid-body integration (DP5(4), rtol 1e-10): the rigid coordinate
    of a superposition model does not depend on the stiffness (one way), and equals the exact closed
    loop to 3.1e-10 of the peak; the drive torque is the controller's output, and the actuator's
    work equals the rigid link's kinetic energy (no gravity)."""
    res = run(link_case(stiffness=1e4, model=model), model)
    c = res.columns
    y = exact_pd(res.t, 2.0, 0.3)
    err = np.abs(c["hub_angle"] - y).max()
    assert err < 2e-9 * np.abs(y).max(), err
    assert np.array_equal(c["torque"], c["control_hub_pid"])
    w = res.rigid.joint("hub")[:, 1]
    kinetic = 0.5 * J_HUB * w**2
    assert np.abs(kinetic - c["work_inputs"]).max() < 1e-8 * np.abs(c["work_inputs"]).max()
    soft = run(link_case(stiffness=1.0, model=model), model)
    assert np.array_equal(soft.columns["hub_angle"], c["hub_angle"])


def test_superposition_collocated_pd_on_a_flexible_link_meets_coupled_within_the_one_way_difference():
    """hac against coupled on the flexible link (kp 5, kd 0.5): the hub angles differ by 4.6e-3 rad
    (0.76 % of the 0.6 rad peak) at the link's own stiffness, and the difference falls as 1/stiffness
    (1.15e-3 at 4x, 2.9e-4 at 16x: ratios 4.02, 4.01): the deflection's reaction on the hub, which the
    one-way model leaves out (docs/validation.md)."""
    diffs = []
    for s in (1.0, 4.0, 16.0):
        r = {m: run(link_case(model=m, stiffness=s, kp=5.0, kd=0.5, t_end=0.4), m) for m in ("hac", "coupled")}
        diffs.append(np.abs(r["hac"].columns["hub_angle"] - r["coupled"].columns["hub_angle"]).max())
    assert 1e-3 < diffs[0] < 0.01 * 0.6, diffs
    assert all(3.5 < a / b < 4.5 for a, b in zip(diffs, diffs[1:])), diffs


def test_superposition_saturation_and_clamping_follow_the_continuous_law():
    """Under hac the law is the continuous one (the integral a state of the integration): the hub
    angle meets the clamped continuous PID (saturated_pid) to 9e-8 rad; the wound-up law is 0.58 rad
    away; the output holds its limit."""
    gains, limit = dict(kp=20.0, ki=40.0, kd=1.5), 0.6
    res = run(link_case(stiffness=1e4, limit=limit, t_end=1.5, model="hac", **gains), "hac")
    u, y = res.columns["control_hub_pid"], res.columns["hub_angle"]
    assert np.abs(u).max() <= limit * (1 + 1e-12) and np.isclose(np.abs(u).max(), limit)
    clamped = saturated_pid(res.t, limit=limit, **gains)
    wound = saturated_pid(res.t, limit=limit, clamp=False, **gains)
    err = np.abs(y - clamped).max()
    assert err < 1e-6, err
    assert np.abs(wound - clamped).max() > 0.1
    assert abs(y[-1] - 0.5) < 0.01


@pytest.mark.parametrize("change, field, text", [
    ({"measure": TIP}, "controllers[0].measure", "non-collocated.*never reaches the rigid motion"),
    ({"sample_time": 2e-3}, "controllers[0].sample_time", "continuous loop"),
    ({"delay": 2e-3, "sample_time": 1e-3}, "controllers[0].sample_time", "continuous loop"),
])
def test_superposition_refuses_what_a_one_way_model_cannot_close(change, field, text):
    with pytest.raises(CaseError, match=text) as err:
        fm.validate_case(link_case(model="hac", **change))
    assert err.value.field == field and "'hub_pid'" in str(err.value)
    case = fm.validate_case(link_case(model="coupled", **change))       # the case itself is fine
    with pytest.raises(CaseError, match=text):
        run(case, "classic")
    with pytest.raises(CaseError, match=text):
        Simulation(case, model="hac")


def test_superposition_stepping_keeps_the_controller_and_equals_the_batch_run():
    """Stepped one step at a time the hac run is the batch run bit for bit; an effort added and taken
    away restarts the rigid integration with the controller's integral and the drives' work kept."""
    raw = link_case(t_end=0.05, model="hac", ki=3.0)
    batch = run(raw)
    sim = Simulation(fm.validate_case(copy.deepcopy(raw)))
    for _ in range(50):
        sim.advance(1)
    stepped = sim.result().columns
    for name in ("hub_angle", "torque", "control_hub_pid", "work_inputs"):
        assert np.array_equal(stepped[name], batch.columns[name]), name
    sim = Simulation(fm.validate_case(copy.deepcopy(raw)))
    sim.advance(20)
    sim.advance(10, inputs={"hub": 0.05})
    sim.advance(20, inputs={"hub": 0.0})
    c = sim.result().columns
    assert np.array_equal(c["hub_angle"][:21], batch.columns["hub_angle"][:21])
    push = c["hub_angle"][-1] - batch.columns["hub_angle"][-1]
    assert push > 1e-6                                        # the effort moved the hub ahead ...
    # ... and the energy balance holds across the restarts (work of drive + controller = kinetic energy)
    kinetic = 0.5 * J_HUB * sim.joint("hub")[1] ** 2
    assert abs(c["work_inputs"][-1] - kinetic) < 1e-8 * kinetic
    # a saved point, another effort, and back: the steps after the restore repeat the first ones
    sim = Simulation(fm.validate_case(copy.deepcopy(raw)))
    sim.advance(20)
    saved = sim.state()
    sim.advance(30, inputs={"hub": -0.05})
    sim.restore(saved)
    sim.advance(30, inputs={"hub": 0.0})
    assert np.array_equal(sim.result().columns["control_hub_pid"], batch.columns["control_hub_pid"])


def test_a_restore_takes_back_the_efforts_set_after_the_saved_point():
    """The saved point's force laws come back with it, beyond the rigid samples taken ahead (the rigid
    buffer's description was shared with its saved copies: an effort set after the save stayed in the
    force law after a restore, 0.023 rad off at 0.42 s on this link)."""
    case = fm.validate_case(link_case(t_end=0.6, model="hac"))
    ref = Simulation(case).advance(420)
    sim = Simulation(case).advance(20)
    saved = sim.state()
    sim.advance(30, inputs={"hub": -0.05})
    sim.restore(saved).advance(400)
    assert np.array_equal(sim.result().columns["hub_angle"], ref.result().columns["hub_angle"])


def test_bundled_bricout_pd_runs_under_hac_and_its_residual_is_reported():
    """The bundled Bricout PD case under hac (docs/validation.md): the rigid loop holds the base at
    0.2 rad, but the one-way model cannot let the collocated loop damp the arm's ringing: the base
    strain rings on undamped (residual amplitude 4.05e-3 against coupled's 1.09e-3; a short run here)."""
    case = fm.load_case(fm.case_path("manipulator_bricout_pd"))
    case["solver"].update(t_end=0.3, dt=2e-5)
    res = run(case, "hac")
    c = res.columns
    assert {"control_base_pd", "control_elbow_pd", "work_inputs"} <= set(c)
    assert np.abs(c["base_torque"]).max() < 1000.0
    assert np.allclose(c["base_torque"], c["control_base_pd"], rtol=0, atol=1e-9)
    w = res.t >= 0.13
    assert (c["root_strain"][w].max() - c["root_strain"][w].min()) / 2 > 2e-3
