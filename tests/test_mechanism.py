"""The mechanism hub and its rigid-body mechanics (flexmech_py.mechanism, Fortran flexmech_mbs,
flexmech_motion, flexmech_ode): closed-form kinematics, energy balance, constraints held over long
runs, the integrator's order, assembly, templates against their general form, bad input."""

import copy
import math

import numpy as np
import pytest
from closed_forms import fourbar_angles, fourbar_rates, slider_crank

import flexmech_py as fm
from flexmech_py.case import read_case_file
from flexmech_py.mechanism import MotionSource, prepare_motion
from flexmech_py.base import kernels
from flexmech_py.mechanism.analysis import constraint_matrices
from flexmech_py.mechanism.packing import joint_pose, marker_position
from flexmech_py.mechanism.rows import CON_POINT, ROW_KINDS
from flexmech_py.run.simulate import motion_source

TM = (0.10795, 0.2794, 0.27051, 0.254)        # Turcic-Midha crank-rocker [m]


def _fourbar_general(law: dict, t_end=0.3, q0=0.4) -> dict:
    """The Turcic-Midha four-bar in general form (drawn at crank angle q0) with one crank drive law."""
    a, b, c, d = TM
    th3, th4 = fourbar_angles(a, b, c, d, q0)
    A = [a * math.cos(q0), a * math.sin(q0)]
    B = [A[0] + b * math.cos(th3), A[1] + b * math.sin(th3)]
    sec = {"area": 4.06e-5, "second_moment": 8.67e-12, "youngs_modulus": 7.1e10, "density": 2710.0}
    return {
        "mechanism": {"ground": {"O2": [0.0, 0.0], "O4": [d, 0.0]}},
        "links": [{"name": "crank", "start": "ground.O2", "end": A, **sec},
                  {"name": "coupler", "start": "crank.end", "end": B, **sec},
                  {"name": "follower", "start": "ground.O4", "end": "coupler.end", **sec}],
        "joints": [{"name": "crank_pivot", "type": "revolute", "connects": ["ground.O2", "crank.start"]},
                   {"name": "pin_a", "type": "revolute", "connects": ["crank.end", "coupler.start"]},
                   {"name": "pin_b", "type": "revolute", "connects": ["coupler.end", "follower.end"]},
                   {"name": "follower_pivot", "type": "revolute", "connects": ["ground.O4", "follower.start"]}],
        "drives": [{"joint": "crank_pivot", **law}],
        "solver": {"t_end": t_end, "dt": 1e-4},
        "outputs": {"q": {"kind": "joint_angle", "joint": "crank_pivot"}}}


def _motion(raw: dict, n=3001):
    case = fm.validate_case(raw)
    src = motion_source(case)
    return case, src, src(np.linspace(0.0, case["solver"]["t_end"], n))


# ----------------------------------------------------------------------------- closed forms
def test_fourbar_kinematics_match_the_closed_form():
    """A harmonic crank law (angular acceleration nonzero): coupler and follower angles, rates and
    accelerations from the constraint equations equal the vector-loop solution to round-off."""
    case, src, rm = _motion(_fourbar_general({"law": "harmonic", "amplitude": 1.3, "frequency": 9.0, "phase": 0.2}))
    assert src.setup.mode == "kinematic" and src.setup.primary == ["crank_pivot"]
    a, b, c, d = TM
    m = rm.motion
    err = np.zeros(6)
    for i in range(0, rm.t.size, 7):
        th2, w2, al2 = rm.joint("crank_pivot")[i]
        th3, th4 = fourbar_angles(a, b, c, d, th2)
        w3, w4, al3, al4 = fourbar_rates(a, b, c, th2, th3, th4, w2, al2)
        got = [m.phi[i, 1] - th3, m.phi[i, 2] - th4, m.omega[i, 1] - w3, m.omega[i, 2] - w4,
               m.alpha[i, 1] - al3, m.alpha[i, 2] - al4]
        got[:2] = [math.remainder(x, 2 * math.pi) for x in got[:2]]
        err = np.maximum(err, np.abs(got) / [1, 1, 1 + abs(w3), 1 + abs(w4), 1 + abs(al3), 1 + abs(al4)])
    assert np.all(err < 1e-10), err
    law = 0.4 - 1.3 * math.sin(0.2) + 1.3 * np.sin(9.0 * rm.t + 0.2)      # the law itself, from the drawn angle
    assert np.max(np.abs(rm.joint("crank_pivot")[:, 0] - law)) < 1e-12


def test_slider_crank_kinematics_match_the_closed_form(cases_dir):
    raw = read_case_file(cases_dir / "slider_crank.toml")
    raw["drives"] = [{"joint": "crank_pivot", "law": "harmonic", "amplitude": 2.0, "frequency": 40.0}]
    raw["solver"]["t_end"] = 0.05
    case, src, rm = _motion(raw, 2001)
    slide, crank = rm.joint("slide"), rm.joint("crank_pivot")
    worst = 0.0
    for i in range(0, rm.t.size, 5):
        x, xd, xdd, beta = slider_crank(0.15, 0.30, *crank[i])
        worst = max(worst, abs(slide[i, 0] + 0.45 - x), abs(slide[i, 1] - xd) / 10, abs(slide[i, 2] - xdd) / 1e3,
                    abs(math.remainder(rm.motion.phi[i, 1] - beta, 2 * math.pi)))
    assert worst < 1e-11, worst


# ----------------------------------------------------------------------------- dynamics
def _kinetic(case, rm) -> np.ndarray:
    ke = np.zeros(rm.t.size)
    for b, body in enumerate(case.mechanism.bodies):
        m, _, j = body.mass_properties()
        ke += 0.5 * m * (rm.zd[:, 3 * b] ** 2 + rm.zd[:, 3 * b + 1] ** 2) + 0.5 * j * rm.zd[:, 3 * b + 2] ** 2
    return ke


@pytest.mark.parametrize("name, t_end", [("slider_crank_torque", 0.3), ("fourbar_hac", 0.25),
                                         ("manipulator_bricout", 0.25)])
def test_energy_balance_under_drive_torques(cases_dir, name, t_end):
    """Work of the force drives (trapezoid over a fine grid) = kinetic energy gained."""
    case = fm.load_case(cases_dir / f"{name}.toml", overrides=[f"solver.t_end={t_end}"])
    rm = motion_source(case)(np.linspace(0.0, t_end, 30001))
    work = 0.0
    for d in case.mechanism.drives:
        q = rm.joint(d.joint)
        p = rm.drive_force(d.joint) * q[:, 1]
        work = work + np.concatenate([[0.0], np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(rm.t))])
    ke = _kinetic(case, rm)
    assert np.max(np.abs(ke - ke[0] - work)) < 2e-6 * np.max(ke)


def test_pendulum_on_a_driven_cart_matches_its_equation():
    """A free degree of freedom beside a kinematic one: a rigid rod hinged to a cart that is driven
    harmonically along a rail, under gravity.  Its angle psi from the downward vertical obeys
    J_O psi'' = -m g c sin(psi) - m c x''(t) cos(psi) (solved here with SciPy)."""
    from scipy.integrate import solve_ivp

    m, L = 0.5, 0.5
    raw = {"mechanism": {"ground": {"O": [0.0, 0.0]}},
           "links": [{"name": "rod", "start": [0.0, 0.0], "end": [0.3, -0.4], "rigid": True, "mass": m,
                      "inertia": m * L * L / 12}],
           "bodies": [{"name": "cart", "mass": 2.0, "inertia": 0.01, "centre": [0.0, 0.0], "points": {"pivot": [0.0, 0.0]}}],
           "joints": [{"name": "rail", "type": "prismatic", "connects": ["ground.O", "cart.pivot"], "axis": [1.0, 0.0]},
                      {"name": "hinge", "type": "revolute", "connects": ["cart.pivot", "rod.start"]}],
           "drives": [{"joint": "rail", "law": "harmonic", "amplitude": 0.05, "frequency": 8.0}],
           "loads": {"gravity": [0.0, -9.81]}, "solver": {"t_end": 2.0, "dt": 1e-3},
           "outputs": {"a": {"kind": "joint_angle", "joint": "hinge"}}}
    case, src, rm = _motion(raw, 2001)
    assert (src.setup.mode, src.setup.dof, src.setup.primary) == ("dynamic", 2, ["rail", "hinge"])
    c, jo = L / 2, m * L * L / 3

    def rhs(t, y):
        xdd = -0.05 * 64.0 * math.sin(8.0 * t)
        return [y[1], (-m * 9.81 * c * math.sin(y[0]) - m * c * xdd * math.cos(y[0])) / jo]

    psi0 = math.atan2(-0.4, 0.3) + math.pi / 2
    ref = solve_ivp(rhs, (0, 2.0), [psi0, 0.0], t_eval=rm.t, rtol=1e-12, atol=1e-12).y[0]
    psi = rm.joint("hinge")[:, 0] + math.pi / 2
    assert np.max(np.abs(psi - ref)) < 1e-7 * np.max(np.abs(ref))


def test_constraints_hold_to_round_off_over_a_long_run():
    """2 s of a torque-driven four-bar (about 60 crank turns): positions stay on the constraints to the
    projection tolerance at every step end and to the integration tolerance between (dense output)."""
    raw = _fourbar_general({"law": "force", "constant": 0.05}, t_end=2.0)
    raw["solver"]["rigid_rtol"] = 1e-10
    case, src, rm = _motion(raw, 4001)
    assert src.setup.mode == "dynamic"
    worst = max(np.max(np.abs(constraint_matrices(src.setup.packed, rm.z[i])[0])) for i in range(0, rm.t.size, 40))
    assert worst < 1e-9 * src.setup.packed.lref
    assert rm.joint("crank_pivot")[-1, 0] > 20 * 2 * math.pi


def test_dense_output_is_fourth_order_and_steps_fifth():
    """With error control off (huge tolerance) and fixed steps h, the sampled motion of the torque-driven
    four-bar between step ends converges as h^5 (the continuous extension's local order 5, the method's
    global order 5 on this smooth problem)."""
    raw = _fourbar_general({"law": "force", "constant": 0.002}, t_end=0.2)
    case = fm.validate_case(raw)
    setup = prepare_motion(case.mechanism)
    t = np.linspace(0.0, 0.2, 161)
    ref = MotionSource(setup, rtol=1e-13, atol=1e-15)(t).z
    errs = []
    for h in (8e-3, 4e-3, 2e-3):
        z = MotionSource(setup, rtol=1e3, atol=1e3, hmax=h)(t).z
        errs.append(np.max(np.abs(z - ref)))
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(orders > 4.5), (errs, orders)


def test_torque_drives_a_non_grashof_crank_through_its_limit():
    """A triple-rocker four-bar pushed by a crank torque reaches the crank's limit position (not a
    singular position of the whole mechanism): the crank stops and swings back, energy conserved."""
    a, b, c, d = 0.2, 0.05, 0.05, 0.254
    sec = {"area": 1e-4, "second_moment": 1e-9, "youngs_modulus": 7e10, "density": 2700.0}
    th3, _ = fourbar_angles(a, b, c, d, 0.0)
    B = [a + b * math.cos(th3), b * math.sin(th3)]
    raw = {"mechanism": {"ground": {"O2": [0.0, 0.0], "O4": [d, 0.0]}},
           "links": [{"name": "crank", "start": "ground.O2", "end": [a, 0.0], **sec},
                     {"name": "coupler", "start": "crank.end", "end": B, **sec},
                     {"name": "follower", "start": "ground.O4", "end": "coupler.end", **sec}],
           "joints": [{"name": "crank_pivot", "type": "revolute", "connects": ["ground.O2", "crank.start"]},
                      {"name": "pin_a", "type": "revolute", "connects": ["crank.end", "coupler.start"]},
                      {"name": "pin_b", "type": "revolute", "connects": ["coupler.end", "follower.end"]},
                      {"name": "follower_pivot", "type": "revolute", "connects": ["ground.O4", "follower.start"]}],
           "drives": [{"joint": "crank_pivot", "law": "force", "constant": 0.02}],
           "solver": {"t_end": 0.6, "dt": 1e-4}, "outputs": {"q": {"kind": "joint_angle", "joint": "crank_pivot"}}}
    case, src, rm = _motion(raw, 6001)
    q = rm.joint("crank_pivot")
    qlim = math.acos((a * a + d * d - (b + c) ** 2) / (2 * a * d))
    assert q[:, 0].max() == pytest.approx(qlim, abs=1e-4) and q[:, 1].min() < 0 < q[:, 1].max()
    work = 0.02 * (q[:, 0] - q[0, 0])
    ke = _kinetic(case, rm)
    assert np.max(np.abs(ke - work)) < 1e-6 * np.max(ke)


def test_change_point_driven_through_is_a_singular_position():
    """A parallelogram four-bar (a = c, b = d) driven kinematically through its change point (every link
    collinear at crank angle 0) stops there, naming the joints and the drive coordinate."""
    a, b = 0.1, 0.3
    sec = {"area": 1e-4, "second_moment": 1e-9, "youngs_modulus": 7e10, "density": 2700.0}
    q0 = -0.3
    A = [a * math.cos(q0), a * math.sin(q0)]
    raw = {"mechanism": {"ground": {"O2": [0.0, 0.0], "O4": [b, 0.0]}},
           "links": [{"name": "crank", "start": "ground.O2", "end": A, **sec},
                     {"name": "coupler", "start": "crank.end", "end": [A[0] + b, A[1]], **sec},
                     {"name": "follower", "start": "ground.O4", "end": "coupler.end", **sec}],
           "joints": [{"name": "crank_pivot", "type": "revolute", "connects": ["ground.O2", "crank.start"]},
                      {"name": "pin_a", "type": "revolute", "connects": ["crank.end", "coupler.start"]},
                      {"name": "pin_b", "type": "revolute", "connects": ["coupler.end", "follower.end"]},
                      {"name": "follower_pivot", "type": "revolute", "connects": ["ground.O4", "follower.start"]}],
           "drives": [{"joint": "crank_pivot", "law": "constant_speed", "speed": 1.0}],
           "solver": {"t_end": 0.6, "dt": 1e-3}, "outputs": {"q": {"kind": "joint_angle", "joint": "crank_pivot"}}}
    case = fm.validate_case(raw)
    with pytest.raises(fm.MechanismError, match=r"singular position.*joints involved.*crank_pivot = ") as info:
        motion_source(case)(np.linspace(0.0, 0.6, 601))
    assert info.value.time == pytest.approx(0.3, abs=2e-3)     # the crank angle reaches 0
    assert info.value.partial.t[-1] < info.value.time


# ----------------------------------------------------------------------------- assembly, templates, API
def test_assembly_closes_a_loop_drawn_open():
    """A follower drawn by length and angle 1.5 mm short of the coupler's end: the loop is closed on
    the drawn branch and the report says how far each point moved."""
    raw = _fourbar_general({"law": "constant_speed", "speed": 10.0}, t_end=0.05)
    B = raw["links"][1]["end"]
    d = TM[3]
    raw["links"][2].pop("end")
    raw["links"][2].update(length=math.hypot(B[0] - d, B[1]) - 1.5e-3, angle=math.atan2(B[1], B[0] - d) + 0.01)
    case = fm.validate_case(raw)
    setup = prepare_motion(case.mechanism)
    label, moved = setup.max_moved
    assert 1e-4 < moved < 1e-2
    phi, *_ = constraint_matrices(setup.packed, setup.z0)
    assert np.max(np.abs(phi)) < 1e-11
    assert setup.z0[3 * 1 + 1] > 0          # the coupler's centre stays above the ground line (drawn branch)


def test_template_is_its_general_form(cases_dir, tmp_path):
    """The resolved four-bar template written back as a case file (general form) reads as the same case
    and gives the same run, bit for bit."""
    case = fm.load_case(cases_dir / "fourbar_hac.toml", overrides=["solver.t_end=0.01"])
    path = case.write(tmp_path / "general.toml")
    text = path.read_text()
    assert "[[joints]]" in text and "[[drives]]" in text and "type = \"fourbar\"" in text   # template kept as provenance
    back = fm.load_case(path)
    strip = lambda c: {k: v for k, v in c.items() if k != "case"}
    assert strip(back) == strip(case)
    r1, r2 = fm.simulate(case), fm.simulate(back)
    for col in r1.columns:
        assert np.array_equal(r1[col], r2[col]), col


def test_python_built_mechanism_runs_like_its_file(tmp_path):
    """The Mechanism built with add_* calls is the mechanism the same tables describe."""
    raw = _fourbar_general({"law": "constant_speed", "speed": 20.0}, t_end=0.01)
    mech = fm.Mechanism()
    mech.add_ground_point("O2", (0.0, 0.0))
    mech.add_ground_point("O4", (TM[3], 0.0))
    sec = {k: raw["links"][0][k] for k in ("area", "second_moment", "youngs_modulus", "density")}
    mech.add_link("crank", "ground.O2", raw["links"][0]["end"], **sec)
    mech.add_link("coupler", "crank.end", raw["links"][1]["end"], **sec)
    mech.add_link("follower", "ground.O4", "coupler.end", **sec)
    for j in raw["joints"]:
        mech.add_joint(j["type"], j["name"], *j["connects"])
    mech.add_drive("crank_pivot", "constant_speed", speed=20.0)
    built = fm.Case.from_mechanism(mech, solver=raw["solver"], outputs=raw["outputs"])
    from_tables = fm.validate_case(raw)
    strip = lambda c: {k: v for k, v in c.items() if k != "case"}
    assert strip(built) == strip(from_tables)
    back = fm.load_case(built.write(tmp_path / "built.toml"))
    assert strip(back) == strip(built)


def test_table_law_is_a_smooth_spline():
    """A kinematic table law through samples of a smooth motion reproduces it with fourth-order accuracy
    and continuous accelerations."""
    ts = np.linspace(0.0, 0.3, 31)
    law = lambda t: 0.4 + 2.0 * t + 3.0 * np.sin(7.0 * t)
    raw = _fourbar_general({"law": "table", "t": ts.tolist(), "value": law(ts).tolist()}, t_end=0.3)
    case, src, rm = _motion(raw, 3001)
    q = rm.joint("crank_pivot")
    assert np.max(np.abs(q[:, 0] - law(rm.t))) < 5e-5
    assert np.max(np.abs(np.diff(q[:, 2]))) < 0.05 * np.max(np.abs(q[:, 2]))      # no jumps in the acceleration


# ----------------------------------------------------------------------------- bad input
def _bad(mutate):
    raw = _fourbar_general({"law": "constant_speed", "speed": 10.0}, t_end=0.05)
    mutate(raw)
    return raw


@pytest.mark.parametrize("mutate, field, hint", [
    (lambda r: r["joints"][1].update(connects=["crank.tip", "coupler.start"]), "joints[1].connects", "no point 'tip'"),
    (lambda r: r["joints"][1].update(connects=["crank.end", "crank.start"]), "joints.pin_a.connects", "itself"),
    (lambda r: r["joints"].append({"name": "g", "type": "prismatic", "connects": ["ground.O2", "crank.mid"],
                                   "axis": [0.0, 0.0]}), "joints.g.axis", "zero length"),
    (lambda r: r["drives"].append({"joint": "hinge", "law": "force"}), "drives[1].joint", "unknown joint"),
    (lambda r: r["drives"].append({"joint": "crank_pivot", "law": "force"}), "drives[1].joint", "two drives"),
    (lambda r: r["drives"].append({"joint": "pin_b", "law": "constant_speed", "speed": 1.0}), "drives",
     "2 kinematic drives on a mechanism with 1 degree"),
    (lambda r: r["drives"].append({"joint": "pin_b", "law": "force"}), "drives", "2 drives on a mechanism with 1"),
    (lambda r: r["joints"][0].update(elastic="torque"), "joints.crank_pivot.elastic", "no force drive"),
    (lambda r: r.update(initial={"speeds": {"crank_pivot": 1.0}}), "initial.speeds.crank_pivot", "driven kinematically"),
    (lambda r: r["links"][1].update(start="crank.tip"), "links[1].start", "no point 'tip'"),
    (lambda r: r["links"][2].update(end="rocker.end"), "links[2].end", "unknown body 'rocker'"),
    (lambda r: r["links"].append({"name": "x", "start": [1, 1], "end": [2, 1], "area": 1e-4, "second_moment": 1e-9,
                                  "youngs_modulus": 7e10, "density": 2700.0}), "joints", "floating"),
    (lambda r: r["drives"].__setitem__(0, {"joint": "crank_pivot", "law": "table", "t": [0.0, 0.01],
                                           "value": [0.0, 0.1]}), "drives[0].t", "spans"),
    (lambda r: r["joints"].append({"name": "extra", "type": "revolute", "connects": ["ground.O2", "coupler.mid"]}),
     "joints", "over-constrained"),
    (lambda r: r.update(drive={"type": "torque"}), "drive", "short form"),
])
def test_bad_mechanisms_name_the_field(mutate, field, hint):
    with pytest.raises(fm.CaseError) as exc:
        case = fm.validate_case(_bad(mutate))
        motion_source(case)                      # the checks that need the assembled mechanism
    assert exc.value.field == field, str(exc.value)
    assert hint in str(exc.value)


def test_a_loop_that_cannot_close_is_refused():
    raw = _fourbar_general({"law": "constant_speed", "speed": 10.0}, t_end=0.05)
    raw["links"][2].pop("end")
    raw["links"][2].update(length=0.05, angle=1.0)          # far too short to reach the coupler
    with pytest.raises(fm.MechanismError, match=r"cannot assemble.*violation of .* m"):
        motion_source(fm.validate_case(raw))


def test_free_degree_of_freedom_without_load_is_a_warning():
    """A two-link chain driven at its base only, no gravity: the elbow moves only by the coupling."""
    raw = {"mechanism": {"type": "serial"},
           "links": [{"name": f"l{k}", "length": 0.5, "area": 1e-4, "second_moment": 2e-10, "youngs_modulus": 7e10,
                      "density": 2700.0} for k in (1, 2)],
           "joints": {"base": "pin", "joint_2": "pin"},
           "drive": {"type": "torque", "torques": [{"joint": "base", "constant": 0.1}]},
           "solver": {"t_end": 0.01, "dt": 1e-4}, "outputs": {"a": {"kind": "joint_angle", "joint": "base"}}}
    setup = prepare_motion(fm.validate_case(copy.deepcopy(raw)).mechanism)
    assert len(setup.warnings) == 1 and "joint_2" in setup.warnings[0]
    raw["loads"] = {"gravity": [0.0, -9.81]}
    assert prepare_motion(fm.validate_case(raw).mechanism, (0.0, -9.81)).warnings == []


@pytest.mark.parametrize("name", ["quick_return", "sixbar_welded"])
def test_rigid_rows_are_the_one_vocabulary_and_an_unknown_kind_is_refused(cases_dir, name):
    """flexmech_mbs evaluates every joint as rows of flexmech_markers' kinds (mirror: mechanism/rows.py):
    each joint's packed rows are its kind's own, a revolute's point rows give r_P - r_Q, and a row kind
    outside the table is bad input (status 4) from mbs_eval, never another kind's rows."""
    case = fm.load_case(cases_dir / f"{name}.toml")
    setup = prepare_motion(case.mechanism)
    packed, z = setup.packed, setup.z0
    kinds = {j.kind for j in case.mechanism.joints}
    assert kinds >= ({"revolute", "prismatic"} if name == "quick_return" else {"revolute", "weld"})
    assert set(packed.row_kinds) <= set(ROW_KINDS)
    phi, *_ = constraint_matrices(packed, z + 1e-3 * np.arange(z.size))   # off the assembled position
    zz = z + 1e-3 * np.arange(z.size)
    for i, (j, (r0, nr)) in enumerate(zip(case.mechanism.joints, packed.joint_rows)):
        assert packed.row_kinds[r0:r0 + nr] == [r[0] for r in j.rigid_rows(joint_pose(case.mechanism, j, z))]
        if j.kind == "revolute":
            gap = marker_position(zz, packed.markers[2 * i]) - marker_position(zz, packed.markers[2 * i + 1])
            assert packed.row_kinds[r0:r0 + 2] == [CON_POINT, CON_POINT]
            assert np.allclose(phi[r0:r0 + 2], gap, rtol=0, atol=1e-15)
    header = 8                                     # mbs_nspec_header
    nmk, nj, ncr = packed.ispec[1], packed.ispec[2], packed.ispec[7]
    cr0 = header + nmk + 4 * nj                    # the first row's [joint, kind, aux]
    assert ncr == sum(nr for _, nr in packed.joint_rows)
    for bad_kind in (max(ROW_KINDS) + 1, 0, -1):
        ispec = packed.ispec.copy()
        ispec[cr0 + 3 * (ncr - 1) + 1] = bad_kind  # the last joint row
        *_, status = kernels.mbs.mbs_eval(packed.nrow, ispec, packed.rspec, z, np.zeros_like(z), 0.0)
        assert status == kernels.STATUS_BAD_INPUT, bad_kind
        coord = packed.ispec.copy()
        coord[header + nmk + 2 * nj] = bad_kind    # the first joint's coordinate row
        *_, status = kernels.mbs.mbs_eval(packed.nrow, coord, packed.rspec, z, np.zeros_like(z), 0.0)
        assert status == kernels.STATUS_BAD_INPUT, bad_kind


@pytest.mark.parametrize("name", ["fourbar_hac.toml", "slider_crank_torque.toml", "manipulator_bricout.toml"])
def test_accelerations_solve_the_augmented_system(cases_dir, name):
    """The dynamic mode's accelerations and multipliers (solved through the Gram matrix J M^-1 J^T, or
    the pivoted LU of the whole matrix where that is not definite) solve [M J^T; J 0][z''; lam] = [Q; gamma]
    at every sample, as a dense solve of the whole augmented matrix from the same J, Q, gamma does."""
    case = fm.load_case(cases_dir / name, ["solver.t_end=0.05"])
    src = motion_source(case)
    rm = src(np.linspace(0.0, 0.05, 11))
    p = src.setup.packed
    nb = p.n // 3
    mass = np.repeat(np.asarray(p.rspec[:nb]), 3)
    mass[2::3] = p.rspec[nb:2 * nb]
    for k in range(rm.t.size):
        _, jac, gam, _, q = constraint_matrices(p, rm.z[k], rm.zd[k], t=float(rm.t[k]))
        aug = np.block([[np.diag(mass), jac.T], [jac, np.zeros((p.nrow, p.nrow))]])
        want = np.linalg.solve(aug, np.concatenate([q, gam]))
        got = np.concatenate([rm.zdd[k], rm.lam[k]])
        assert np.allclose(got, want, rtol=1e-9, atol=1e-9 * np.abs(want).max())
