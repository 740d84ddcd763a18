"""The one-pass coupled model (seed Section 3): kernel consistency, energy balance, rigid limit,
massive-hub limit (= superposition), convergence, and its error messages."""

import json
import numpy as np
import pytest

from conftest import assert_free_pendulum_conserves_energy

import flexmech_py as fm
from flexmech_py.cli import main
from flexmech_py.models.constrained.coupled import CoupledModel
from flexmech_py.run.simulate import Prepared, simulate_models


def _beam(J=None, tau=10.0, n=4, t_end=0.05, dt=1e-5, out=250, **extra):
    case = {
        "mechanism": {"type": "serial"},
        "links": [{"name": "beam", "length": 1.0, "area": 4e-4, "second_moment": 16 / 3 * 1e-8,
                   "youngs_modulus": 2.1e11, "density": 7800.0, "elements": n}],
        "drive": {"type": "torque", "torques": [{"joint": "base", "constant": tau}]},
        "solver": {"t_end": t_end, "dt": dt, "output_every": out},
        "outputs": {"tip_v": {"kind": "displacement", "at": "beam.end", "component": "transverse"},
                    "eps": {"kind": "strain", "link": "beam", "at": 0.5},
                    "ang": {"kind": "joint_angle", "joint": "base"}},
    }
    if J is not None:
        case["rotary_inertias"] = [{"at": "beam.start", "inertia": J}]
    case.update(extra)
    return fm.validate_case(case)


# ----------------------------------------------------------------------------- kernel consistency
@pytest.mark.parametrize("name, overrides, gravity", [
    ("manipulator_bricout", ["initial.speeds=[3.0, -2.0]"], (0.0, 0.0)),
    ("sixbar_plate", [], (0.0, -9.81))])      # a rigid body (the plate), flexible links, gravity
def test_kernel_matrices_are_the_derivatives_of_the_residual(cases_dir, name, overrides, gravity):
    """M = dR/da exactly, C_v = dR/dv exactly (R is quadratic in v), K_t = dR/dq up to the inertia's
    configuration dependence through the chord (left out of the iteration matrix, theory.md §11)."""
    case = fm.load_case(cases_dir / f"{name}.toml", overrides=["solver.t_end=0.001"] + overrides)
    p = Prepared(case, elements_per_link=2)
    cm = CoupledModel.from_case(case)
    q, v = cm.initial_state(p.rm.select(slice(0, 1)))
    rng = np.random.default_rng(0)
    free = np.flatnonzero(cm.free_of > 0)
    free = free[np.argsort(cm.free_of[free])]
    q[free] += rng.normal(size=free.size) * 1e-4
    v[free] += rng.normal(size=free.size) * 1e-2
    a = np.zeros(cm.ndof)
    a[free] = rng.normal(size=free.size) * 10
    res, M, C, K, energy = cm.dense(q, v, a, gravity=gravity)
    eye = np.eye(cm.ndof)

    def fd(which, h):
        cols = []
        for i in free:
            args_p, args_m = [q, v, a], [q, v, a]
            args_p = [x + h * eye[i] if k == which else x for k, x in enumerate(args_p)]
            args_m = [x - h * eye[i] if k == which else x for k, x in enumerate(args_m)]
            cols.append((cm.dense(*args_p, gravity=gravity)[0][free] - cm.dense(*args_m, gravity=gravity)[0][free])
                        / (2 * h))
        return np.column_stack(cols)

    # R is linear in a and quadratic in v: central differences are exact, large steps keep the
    # round-off of the stiff elastic forces small
    assert np.max(np.abs(fd(2, 1.0) - M)) < 1e-8 * np.max(np.abs(M))
    assert np.max(np.abs(fd(1, 1e-2) - C)) < 1e-7 * np.max(np.abs(C))
    assert np.max(np.abs(fd(0, 1e-7) - K)) < 1e-6 * np.max(np.abs(K))
    # kinetic energy = 1/2 v^T M v (ground DOFs are at rest)
    assert energy[0] == pytest.approx(0.5 * v[free] @ M @ v[free], rel=1e-12)


# ----------------------------------------------------------------------------- energy balance
@pytest.mark.parametrize("name, bound", [("fourbar_hac", 1e-5), ("manipulator_bricout", 1e-7)])
def test_energy_balance_seed_runs(cases_dir, name, bound):
    """No damping: kinetic + strain energy = work of the input torques over the whole seed run, under
    average acceleration (which conserves energy); the coupled model's default, generalized-alpha
    rho_inf = 0.8, removes only the unresolved modes' energy: within 10x the bound."""
    for integrator, tol in (("newmark", bound), ("generalized-alpha", 10 * bound)):
        res = fm.simulate(fm.load_case(cases_dir / f"{name}.toml", overrides=[f"solver.integrator='{integrator}'"]),
                          model="coupled")
        e = res["energy_kinetic"] + res["energy_potential"] - res["work_inputs"]
        drift = np.max(np.abs(e - e[0])) / np.max(res["work_inputs"])
        print(f"\n{name} {integrator}: energy drift {drift:.2e} "
              f"(reported {res.extra['coupled']['energy_balance']['relative_drift']:.2e})")
        assert res["work_inputs"][-1] > 1.0          # J: real work was done
        assert drift < tol


def test_energy_conserved_in_free_motion_under_gravity():
    """A flexible double pendulum released under gravity (no torques): kinetic + strain + gravity
    potential energy is constant."""
    assert_free_pendulum_conserves_energy("coupled", elements=2)


# ----------------------------------------------------------------------------- limits
def test_rigid_limit_fourbar(cases_dir):
    """Links made 1e4 times stiffer: the coupled crank follows the rigid-body solution."""
    ov = [f"links.{k}.youngs_modulus=0.71e15" for k in ("crank", "coupler", "follower")]
    res = fm.simulate(fm.load_case(cases_dir / "fourbar_hac.toml", overrides=ov), model="coupled")
    drift = res.extra["coupled"]["rigid_drift_from_rigid_body_solution"]
    assert drift["crank_pivot"]["max_abs_rad"] < 1e-3     # measured 1.9e-4 rad (5.1 rad at the real E)
    assert res["crank_angle"][-1] > 24.0


def test_rigid_limit_manipulator(cases_dir):
    ov = [f"links.{k}.youngs_modulus=2.1e15" for k in ("link1", "link2")]
    res = fm.simulate(fm.load_case(cases_dir / "manipulator_bricout.toml", overrides=ov), model="coupled")
    for d in res.extra["coupled"]["rigid_drift_from_rigid_body_solution"].values():
        assert d["max_abs_rad"] < 1e-6            # measured 1.0e-7 rad


def test_massive_hub_limit_equals_superposition():
    """A beam clamped to a hub of huge inertia moves as the superposition model assumes (clamped to a
    prescribed rigid motion): the coupled strains and tip deflection match `classic`."""
    rr = simulate_models(_beam(J=1000.0, tau=1000.0), models=("classic", "coupled"))
    a, b = rr["classic"], rr["coupled"]
    for k in ("tip_v", "eps"):
        err = np.max(np.abs(a[k] - b[k])) / np.max(np.abs(a[k]))
        print(f"\n{k}: coupled vs classic {err:.2e}")
        assert err < 1e-2                        # measured 3e-3
    # the hub (the beam's tangent at the base) follows the rigid-body solution; the chord, which is the
    # coupled model's rigid coordinate, lags it by the tip deflection over the length
    drift = b.extra["coupled"]["rigid_drift_from_rigid_body_solution"]["base"]
    assert drift["at_joint_tangents_max_abs_rad"] < 1e-6                     # measured 4.5e-8 rad
    assert np.max(np.abs((b["ang"] - a["ang"]) - b["tip_v"] / 1.0)) < 1e-3 * np.max(np.abs(b["tip_v"]))


def test_light_hub_differs_from_superposition():
    """Without a hub the torque acts on the beam itself: the tip deviates far less from the rigid-body
    solution than the superposition model's clamped beam deflects (the seed manipulator shows it too)."""
    rr = simulate_models(_beam(J=None, tau=10.0), models=("classic", "coupled"))
    assert np.max(np.abs(rr["coupled"]["tip_v"])) < 0.5 * np.max(np.abs(rr["classic"]["tip_v"]))


# ----------------------------------------------------------------------------- convergence
def test_time_step_convergence(cases_dir):
    case = fm.load_case(cases_dir / "manipulator_bricout.toml", overrides=["solver.t_end=0.05"])
    dts = (2e-5, 1e-5, 5e-6, 2.5e-6)
    ys = [Prepared(case, dt=dt, out_every=int(round(2e-5 / dt))).run("coupled")["tip_dy_elastic"] for dt in dts]
    d = [np.max(np.abs(ys[i] - ys[i + 1])) for i in range(3)]
    orders = np.log2(np.array(d[:-1]) / np.array(d[1:]))
    print(f"\ncoupled manipulator tip: successive differences {d}, orders {orders}")
    assert 1.8 < orders[-1] < 2.2    # the step torques excite modes the coarsest steps do not resolve


def test_mesh_convergence(cases_dir):
    case = fm.load_case(cases_dir / "manipulator_bricout.toml", overrides=["solver.t_end=0.05"])
    ys = [Prepared(case, dt=1e-5, elements_per_link=n, out_every=4).run("coupled")["tip_dy_elastic"] for n in (2, 4, 8, 16)]
    errs = [np.max(np.abs(y - ys[-1])) / np.max(np.abs(ys[-1])) for y in ys[:-1]]
    print(f"\ncoupled manipulator tip vs 16 elements: {errs}")
    assert errs[0] > errs[1] > errs[2] and errs[2] < 0.05   # measured 0.165, 0.066, 0.019


# ----------------------------------------------------------------------------- outputs and errors
def test_same_outputs_as_superposition_plus_energy(cases_dir):
    case = fm.load_case(cases_dir / "fourbar_hac.toml", overrides=["solver.t_end=0.02"])
    rr = simulate_models(case, models=("hac", "coupled"))
    assert set(rr["hac"].columns) <= set(rr["coupled"].columns)
    extra = set(rr["coupled"].columns) - set(rr["hac"].columns)
    assert extra == {"energy_kinetic", "energy_potential", "work_inputs", "newton_iterations"}
    s = rr["coupled"].summary()["coupled"]
    assert s["link_length_drift"]["within_bound"] and s["joint_closure_error_m"] == 0.0
    # at the start the coupled crank follows the rigid-body solution closely
    assert rr["coupled"]["crank_angle"][-1] == pytest.approx(rr["hac"]["crank_angle"][-1], rel=0.1)


def test_newton_failure_is_reported_with_time(cases_dir, tmp_path, capsys):
    case = fm.load_case(cases_dir / "fourbar_hac.toml", overrides=["solver.t_end=0.01", "solver.newton_maxit=1",
                                                                   "solver.newton_tol=1e-14"])
    with pytest.raises(fm.SolverError, match=r"at t = .* s: Newton iterations did not converge") as exc:
        fm.simulate(case, model="coupled")
    assert exc.value.code == 5 and exc.value.time > 0
    out = tmp_path / "none"
    rc = main(["run", str(cases_dir / "fourbar_hac.toml"), "--model", "coupled", "--set", "solver.t_end=0.01",
               "--set", "solver.newton_maxit=1", "--set", "solver.newton_tol=1e-14", "--out", str(out)])
    err = capsys.readouterr().err
    errors = [ln for ln in err.splitlines() if ln.startswith("flexmech: error: ")]
    # the solver stopped: one error line, exit code 3, the frames before the failure kept (tests/test_guards.py)
    assert rc == 3 and len(errors) == 1 and "Newton" in errors[0]
    assert json.loads((out / "summary.json").read_text())["status"] == "failed"
    assert exc.value.failure["cause"] == "solver_settings"   # nothing grew, and it fails again at dt/2


def test_kinematic_drive_prescribes_the_hub(cases_dir):
    """A kinematic drive is a rotation constraint on the tangent at the driven joint (Lagrange
    multiplier = the drive torque); the energy balance includes the drive's work."""
    case = fm.load_case(cases_dir / "fourbar_constant_speed.toml", overrides=["solver.t_end=0.1"])
    res = fm.simulate(case, model="coupled")
    c = res.extra["coupled"]
    assert c["rigid_drift_from_rigid_body_solution"]["crank_pivot"]["at_joint_tangents_max_abs_rad"] < 1e-10
    assert "drive_torque" in res.columns and np.max(np.abs(res["drive_torque"])) > 1.0      # N m
    assert c["energy_balance"]["relative_drift"] < 2e-5                                      # measured 7e-6 (0.26 s)


def test_weld_keeps_the_relative_angle(cases_dir):
    """A non-driven locked joint welds the two tangents: the relative angle at the joint stays at its
    initial value (the elbow torque is removed; the base torque turns the welded arm)."""
    case = fm.load_case(cases_dir / "manipulator_bricout.toml",
                        overrides=["solver.t_end=0.05", "drive.torques.1.constant=0.0", "solver.integrator='newmark'"])
    case["drives"] = case["drives"][:1]
    res = fm.simulate(case, model="coupled")        # average acceleration: the energy balance holds to 1e-6
    c = res.extra["coupled"]
    beta_ref = res["beta"][0]
    assert beta_ref == pytest.approx(0.5)
    # tangents welded: the joint angle at the tangents equals the initial one (drift from the rigid
    # solution, whose elbow is a free revolute, is large; the weld itself is exact)
    from flexmech_py.models.constrained.outputs import joint_angles
    p = Prepared(case)
    cm = CoupledModel.from_case(case)
    q0, v0 = cm.initial_state(p.rm.select(slice(0, 1)))
    qf, vf, af, lf, ef, _ = cm.run(q0, v0, p.t, cm.constraint_values(p.rm), p.dt, out_every=p.out_every)
    ang = joint_angles(cm, qf)["joint_2"]
    assert np.max(np.abs(ang - 0.5)) < 1e-10
    assert c["energy_balance"]["relative_drift"] < 1e-6
