"""The coupled and nonlinear models on general mechanisms (issue 10): rigid bodies and rigid links,
prismatic and weld joints, joints at interior points, several drives, force laws in time.  Energy
balance, the rigid limit against the mechanism layer's rigid-body solution (joint coordinates,
reactions, drive forces), constraint satisfaction, second order in dt, and the constraint rows'
derivatives against finite differences."""

import numpy as np
import pytest

import flexmech_py as fm
from flexmech_py.case import read_case_file
from flexmech_py.models.constrained.coupled import CoupledModel
from flexmech_py.run.simulate import Prepared

GENERALIZED_ALPHA = ['solver.integrator="generalized-alpha"', "solver.rho_inf=0.0"]


def _load(cases_dir, name, *overrides):
    return fm.load_case(cases_dir / f"{name}.toml", overrides=list(overrides))


def _outputs(case_dir_case, kinds):
    """--set overrides adding an output of every joint for each kind in kinds (reaction components,
    coordinates) and every drive's force."""
    mech = case_dir_case.mechanism
    ov = []
    for j in mech.joints:
        if "reaction" in kinds:
            for c in ("x", "y", "moment"):
                ov.append(f'outputs.r{c}_{j.name} = {{kind = "reaction", joint = "{j.name}", component = "{c}"}}')
        if "coordinate" in kinds:
            kind = "joint_angle" if j.angular else "joint_displacement"
            ov.append(f'outputs.q_{j.name} = {{kind = "{kind}", joint = "{j.name}"}}')
    for d in mech.drives:
        ov.append(f'outputs.dv_{d.joint} = {{kind = "drive_force", joint = "{d.joint}"}}')
    return ov


# ----------------------------------------------------------------------------- energy balance
ENERGY_CASES = [("slider_crank_torque", "0.05", 1e-7), ("quick_return", "0.05", 1e-5), ("fivebar", "0.05", 1e-5)]


@pytest.mark.parametrize("model", ["coupled", "nonlinear"])
@pytest.mark.parametrize("name, t_end, bound", ENERGY_CASES, ids=[c[0] for c in ENERGY_CASES])
def test_energy_balance_general_mechanisms(cases_dir, name, t_end, bound, model):
    """No damping: the work of the drives (force laws, and the kinematic drives through their
    multipliers) = kinetic + strain + gravity potential energy, rigid bodies included."""
    res = Prepared(_load(cases_dir, name, f"solver.t_end={t_end}"), elements_per_link=4).run(model, estimate=False)
    drift = res.extra["coupled"]["energy_balance"]["relative_drift"]
    print(f"\n{name} {model}: energy drift {drift:.2e} of the work {res['work_inputs'][-1]:.4g} J")
    assert np.max(np.abs(res["work_inputs"])) > 1e-3          # J: the drives do work
    assert drift < bound


@pytest.mark.parametrize("drive", ["time", "slide_force"])
def test_energy_balance_time_laws_and_slide_force(cases_dir, drive):
    """A torque with a harmonic of time and a table in time, and a force along a prismatic guide:
    their work balances the energy too."""
    raw = read_case_file(cases_dir / "slider_crank_torque.toml")
    raw["solver"]["t_end"] = 0.05
    if drive == "time":
        raw["drives"][0].update(time_harmonics=[[1.5, 120.0, 0.3]], table={"t": [0.0, 0.02, 0.05], "value": [0.0, 1.0, -0.5]})
    else:   # a force on the slider instead, the crank free and turned off its dead centre
        raw["drives"] = [{"joint": "slide", "law": "force", "constant": -5.0, "time_harmonics": [[3.0, 200.0, 0.0]]}]
        raw["initial"] = {"coordinates": {"crank_pivot": 0.8}}
    case = fm.validate_case(raw)
    res = Prepared(case, elements_per_link=4).run("coupled", estimate=False)
    drift = res.extra["coupled"]["energy_balance"]["relative_drift"]
    print(f"\n{drive}: energy drift {drift:.2e}, work {res['work_inputs'][-1]:.4g} J")
    assert abs(res["work_inputs"][-1]) > 1e-3 and drift < 1e-6


def test_free_dof_beside_a_kinematic_drive(cases_dir):
    """The five-bar with only motor 1 driven, motor 2 free, under gravity: a dynamic rigid-body
    solution with a drive row; the energy balance holds, its drift falling at second order in dt
    (measured 1.2e-4 at 1e-5 s, 3.0e-5 at 5e-6 s: the free crank whirls at 100 rad/s)."""
    raw = read_case_file(cases_dir / "fivebar.toml")
    raw["drives"] = raw["drives"][:1]
    raw["solver"]["t_end"] = 0.05
    raw["loads"] = {"gravity": [0.0, -9.81]}
    raw["outputs"].pop("torque2")
    case = fm.validate_case(raw)
    drift = [Prepared(case, elements_per_link=4, dt=dt, out_every=int(round(1e-4 / dt))).run("coupled", estimate=False)
             .extra["coupled"]["energy_balance"]["relative_drift"] for dt in (1e-5, 5e-6)]
    print(f"\nfive-bar, one motor: energy drift {drift}")
    assert drift[0] < 5e-4 and 1.8 < np.log2(drift[0] / drift[1]) < 2.2


def test_kinematic_drive_on_a_prismatic_joint(cases_dir):
    """The slider driven harmonically along its guide, drawn off its dead centre (the rigid crank
    follows): the slide follows the law, the drive's force does the work, and the outputs of rigid
    bodies and rigid links are the model's own (the slider pin's position is the guide's origin plus
    the slide; the rigid crank's link angle is its pivot's joint angle)."""
    raw = read_case_file(cases_dir / "slider_crank.toml")
    raw["solver"].update(t_end=0.04)
    c, s = 0.15 * np.cos(0.8), 0.15 * np.sin(0.8)          # drawn at crank angle 0.8 rad
    xs = float(c + np.sqrt(0.3 ** 2 - s * s))
    raw["links"][0]["end"], raw["links"][1]["end"] = [float(c), float(s)], [xs, 0.0]
    raw["bodies"][0].update(centre=[xs, 0.0], points={"pin": [xs, 0.0]})
    raw["drives"] = [{"joint": "slide", "law": "harmonic", "amplitude": 0.02, "frequency": 60.0}]
    raw["outputs"] = {"slide": {"kind": "joint_displacement", "joint": "slide"},
                      "pin_x": {"kind": "position", "at": "slider.pin", "component": "x"},
                      "pin_dx": {"kind": "displacement", "at": "slider.pin", "component": "x"},
                      "crank_link": {"kind": "link_angle", "link": "crank"},
                      "crank_joint": {"kind": "joint_angle", "joint": "crank_pivot"},
                      "push": {"kind": "drive_force", "joint": "slide"}}
    p = Prepared(fm.validate_case(raw), elements_per_link=4)
    res = p.run("coupled", estimate=False)
    law = p.rm_frames.joint("slide")[:, 0]
    assert np.max(np.abs(res["slide"] - law)) < 1e-12
    assert np.max(np.abs(res["pin_x"] - xs - res["slide"])) < 1e-12
    assert np.max(np.abs(res["pin_dx"])) < 1e-12          # on its guide the pin follows the rigid-body solution
    assert np.array_equal(res["push"], res["drive_force"])
    assert np.max(np.abs(res["crank_link"] - res["crank_joint"])) < 1e-12
    drift = res.extra["coupled"]["energy_balance"]["relative_drift"]
    print(f"\nslider driven: energy drift {drift:.2e}, work {res['work_inputs'][-1]:.4g} J")
    assert np.max(np.abs(res["work_inputs"])) > 1e-2 and drift < 1e-5


# ----------------------------------------------------------------------------- rigid limit
RIGID_CASES = [("slider_crank", "0.02", "coupled"), ("sixbar_plate", "0.02", "coupled"),
               ("sixbar_plate", "0.02", "nonlinear")]


@pytest.mark.parametrize("name, t_end, model", RIGID_CASES, ids=[f"{c[0]}-{c[2]}" for c in RIGID_CASES])
def test_rigid_limit_against_rigid_body_solution(cases_dir, name, t_end, model):
    """Flexible links 1e4 times stiffer: joint coordinates, joint reactions (model) and drive torques
    follow the rigid-body solution of the mechanism layer.  The links start undeformed, so the stiff
    modes ring from t = 0; generalized-alpha with rho_inf = 0 damps them within the first 20 % of the
    run, after which the forces are compared."""
    base = _load(cases_dir, name)
    ov = [f"solver.t_end={t_end}", *GENERALIZED_ALPHA]
    ov += [f"links.{ln['name']}.youngs_modulus={ln['youngs_modulus'] * 1e4!r}" for ln in base["links"] if not ln.get("rigid")]
    case = _load(cases_dir, name, *ov, *_outputs(base, ("reaction", "coordinate")))
    p = Prepared(case)
    res = p.run(model, estimate=False)
    rm = p.rm_frames
    late = res.t > 0.2 * res.t[-1]
    worst_q, worst_f = 0.0, 0.0
    for j in case.mechanism.joints:
        worst_q = max(worst_q, np.max(np.abs(res[f"q_{j.name}"] - rm.joint(j.name)[:, 0])))
        r = rm.reaction(j.name)
        scale = np.max(np.abs(r[:, :2]))
        for k, c in enumerate(("x", "y", "moment")):
            worst_f = max(worst_f, np.max(np.abs(res[f"r{c}_{j.name}"] - r[:, k])[late]) / scale)
    dv = rm.drive_force("crank_pivot")
    worst_dv = np.max(np.abs(res["dv_crank_pivot"] - dv)[late]) / np.max(np.abs(dv))
    print(f"\n{name} {model}: coordinates {worst_q:.2e}, reactions {worst_f:.2e}, drive torque {worst_dv:.2e}")
    assert worst_q < 1e-6 and worst_f < 1e-4 and worst_dv < 1e-4
    # the rigid-body solution's reactions on request
    src = _load(cases_dir, name, f"solver.t_end={t_end}",
                'outputs.rigid_x = {kind = "reaction", joint = "crank_pin" , component = "x", source = "rigid"}'
                if name == "slider_crank" else
                'outputs.rigid_x = {kind = "reaction", joint = "joint_a" , component = "x", source = "rigid"}')
    p2 = Prepared(src)
    r2 = p2.run(model, estimate=False)
    ref = p2.rm_frames.reaction("crank_pin" if name == "slider_crank" else "joint_a")[:, 0]
    assert np.allclose(r2["rigid_x"], ref, rtol=1e-9, atol=1e-9 * np.max(np.abs(ref)))


# ----------------------------------------------------------------------------- constraints
def _interior_pin_fourbar(split_check=True):
    """A four-bar whose follower is pinned at 3/4 of the coupler (a revolute at an interior point)."""
    sec = {"area": 4e-5, "second_moment": 3.3333333333333335e-10, "youngs_modulus": 7.1e10, "density": 2710.0}
    return fm.validate_case({
        "mechanism": {"ground": {"O2": [0.0, 0.0], "O4": [0.2, 0.0]}},
        "links": [{"name": "crank", "start": "ground.O2", "end": [0.05, 0.0], **sec},
                  {"name": "coupler", "start": "crank.end", "end": [0.21, 0.12], "points": {"p": 0.75}, **sec},
                  {"name": "follower", "start": "ground.O4", "end": "coupler.p", **sec}],
        "joints": [{"name": "crank_pivot", "type": "revolute", "connects": ["ground.O2", "crank.start"]},
                   {"name": "a", "type": "revolute", "connects": ["crank.end", "coupler.start"]},
                   {"name": "p", "type": "revolute", "connects": ["coupler.p", "follower.end"]},
                   {"name": "follower_pivot", "type": "revolute", "connects": ["ground.O4", "follower.start"]}],
        "drives": [{"joint": "crank_pivot", "law": "constant_speed", "speed": 60.0}],
        "mesh": {"elements_per_link": 4},
        "solver": {"t_end": 0.02, "dt": 1e-5, "output_every": 10, "integrator": "generalized-alpha"},
        "outputs": {"tip": {"kind": "position", "at": "coupler.end", "component": "y"},
                    "fp": {"kind": "reaction", "joint": "p", "component": "magnitude"}}})


CONSTRAINT_CASES = ["slider_crank", "quick_return", "sixbar_welded", "interior_pin"]


@pytest.mark.parametrize("model", ["coupled", "nonlinear"])
@pytest.mark.parametrize("name", CONSTRAINT_CASES)
def test_constraints_hold_over_the_run(cases_dir, name, model):
    """Prismatic normal gap, guide and weld angles, revolute gaps at interior points (the coupled
    model's multiplier rows) and kinematic drives hold to round-off over the run (the Newton
    iteration drives them to zero at every step)."""
    case = _interior_pin_fourbar() if name == "interior_pin" else _load(cases_dir, name, "solver.t_end=0.02")
    res = Prepared(case, elements_per_link=4).run(model, estimate=False)
    v = res.extra["coupled"]["constraint_violation"]
    print(f"\n{name} {model}: {v}")
    L = case.mechanism.characteristic_length()
    assert v["point_m"] < 1e-12 * L and v["guide_normal_m"] < 1e-12 * L and v["slide_m"] < 1e-12 * L
    assert v["angle_rad"] < 1e-12
    assert res.extra["coupled"]["energy_balance"]["relative_drift"] < 1e-5


def test_interior_pin_coupled_against_nonlinear():
    """The revolute at 3/4 of the coupler: rows with multipliers in the coupled model, shared DOFs in the
    nonlinear model; the two agree on the coupler tip and the pin force."""
    res = {m: Prepared(_interior_pin_fourbar()).run(m, estimate=False) for m in ("coupled", "nonlinear")}
    for col in ("tip", "fp"):
        a, b = res["coupled"][col], res["nonlinear"][col]
        err = np.max(np.abs(a - b)) / np.max(np.abs(b))
        print(f"\n{col}: coupled vs nonlinear {err:.2e}")
        assert err < 1e-2


def test_locked_prismatic_holds_its_slide(cases_dir):
    """elastic = 'locked' on an undriven prismatic joint: no relative slide in these models (the torque
    then only deforms the rod)."""
    case = _load(cases_dir, "slider_crank_torque", "solver.t_end=0.01", 'joints.slide.elastic="locked"')
    res = Prepared(case, elements_per_link=4).run("coupled", estimate=False)
    assert np.max(np.abs(res["slider_x"] - res["slider_x"][0])) < 1e-12
    assert res.extra["coupled"]["constraint_violation"]["slide_m"] < 1e-12


# ----------------------------------------------------------------------------- convergence in dt
def test_second_order_in_dt_generalized_alpha(cases_dir):
    """Slider-crank from rest under a torque growing as 2 sin(100 t) N m (a smooth start: a step torque
    sets the stiff rod ringing, whose phase errors dominate the differences at these steps),
    generalized-alpha (rho_inf 0.8): crank angle, slider position and the rod's midspan deflection
    converge at second order in dt (measured 1.98, 2.01, 1.83 on the finest pair; the joint forces
    converge at about first order here, dominated by the rod's 6-9 kHz vibrations: docs/theory.md
    section 11.6)."""
    case = _load(cases_dir, "slider_crank_torque", "solver.t_end=0.02", 'solver.integrator="generalized-alpha"',
                 "solver.rho_inf=0.8", "solver.newton_tol=1e-12", "drives.0.constant=0.0",
                 "drives.0.time_harmonics=[[2.0, 100.0, 0.0]]")
    dts = (4e-5, 2e-5, 1e-5, 5e-6, 2.5e-6)
    runs = [Prepared(case, dt=dt, out_every=int(round(4e-5 / dt)), elements_per_link=4).run("coupled", estimate=False)
            for dt in dts]
    for col in ("crank_angle", "slider_x", "rod_mid_transverse"):
        d = [np.max(np.abs(runs[i][col] - runs[i + 1][col])) for i in range(len(dts) - 1)]
        orders = np.log2(np.array(d[:-1]) / np.array(d[1:]))
        print(f"\n{col}: successive differences {d}, orders {orders}")
        assert 1.75 < orders[-1] < 2.25


# ----------------------------------------------------------------------------- derivatives
@pytest.mark.parametrize("name, model", [("slider_crank", "coupled"), ("quick_return", "coupled"),
                                         ("sixbar_welded", "coupled"), ("sixbar_plate", "nonlinear"),
                                         ("interior_pin", "coupled")])
def test_row_derivatives_against_finite_differences(cases_dir, name, model):
    """Every constraint row and joint coordinate of the kernel (point, angle, projection on segment-node,
    rigid-body and ground markers): its rate g' = G q' and acceleration g'' = G q'' + acc0 against
    central differences of its value and rate along a random trajectory q(t) = q + v t + a t^2/2."""
    case = _interior_pin_fourbar() if name == "interior_pin" else _load(cases_dir, name, "solver.t_end=0.001")
    p = Prepared(case, elements_per_link=3)
    cm = CoupledModel.from_case(case, split=(model == "nonlinear"))
    q, _ = cm.initial_state(p.rm.select(slice(0, 1)))
    rng = np.random.default_rng(1)
    free = cm.free_of > 0
    L = case.mechanism.characteristic_length()
    q[free] += rng.normal(size=free.sum()) * 1e-3 * L
    v, a = np.zeros(cm.ndof), np.zeros(cm.ndof)
    v[free], a[free] = rng.normal(size=free.sum()) * 10, rng.normal(size=free.sum()) * 1e3
    rows = list(cm.rows) + [jm.coordinate for jm in cm.joints.values()]

    def meas(qq, vv, aa):
        lf = np.zeros((max(1, len(cm.rows)), 1))
        return cm.post(qq[:, None], vv[:, None], aa[:, None], lf, np.zeros(1), rows)["measures"][:, :, 0]

    m0 = meas(q, v, a)
    h = 1e-7
    mp = meas(q + h * v + 0.5 * h * h * a, v + h * a, a)
    mm = meas(q - h * v + 0.5 * h * h * a, v - h * a, a)
    dval = mp[0] - mm[0]
    dval = np.where([r.kind == 2 for r in rows], np.arctan2(np.sin(dval), np.cos(dval)), dval)
    rate_fd, acc_fd = dval / (2 * h), (mp[1] - mm[1]) / (2 * h)
    err_rate = np.max(np.abs(rate_fd - m0[1])) / np.max(np.abs(m0[1]))
    err_acc = np.max(np.abs(acc_fd - m0[2])) / np.max(np.abs(m0[2]))
    print(f"\n{name} {model}: {len(rows)} rows, rate error {err_rate:.1e}, acceleration error {err_acc:.1e}")
    assert err_rate < 1e-7 and err_acc < 1e-6


# ----------------------------------------------------------------------------- continuation
def test_continuation_with_time_laws(cases_dir):
    """A run split in two (the second from the first's state and time) equals the whole run with a force
    law in time (the kernel evaluates it at t0 + n dt)."""
    case = _load(cases_dir, "slider_crank_torque", "solver.t_end=0.01", "solver.output_every=1",
                 "drives.0.time_harmonics=[[1.5, 300.0, 0.3]]")
    p = Prepared(case)
    cm = CoupledModel.from_case(case)
    q0, v0 = cm.initial_state(p.rm.select(slice(0, 1)))
    cval = cm.constraint_values(p.rm)
    whole = cm.run(q0, v0, p.t, cval, p.dt, tol=1e-12)[0]
    half = p.nsteps // 2
    cm.run(q0, v0, p.t[:half + 1], np.asfortranarray(cval[:, :, :half + 1]), p.dt, tol=1e-12)
    st = cm.last_run
    out = cm.run(None, None, p.t[half:], np.asfortranarray(cval[:, :, half:]), p.dt, tol=1e-12, state=st)
    second, ef2 = out[0], out[4]
    free = cm.free_of > 0
    assert np.max(np.abs(second[free] - whole[free][:, half:])) < 1e-13 * np.max(np.abs(whole[free]))
    ef = cm.run(q0, v0, p.t, cval, p.dt, tol=1e-12)[4]     # the work of the inputs goes on where it stopped
    assert np.max(np.abs(ef2[2] - ef[2, half:])) < 1e-12 * np.max(np.abs(ef[2]))
