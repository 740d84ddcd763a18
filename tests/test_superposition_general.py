"""The superposition models on general mechanisms (docs/theory.md section 18): rigid links and bodies as
rigid bodies of the elastic problem, prismatic joints, slave relations with time-varying coefficients,
the joints' elastic reactions."""

import copy

import numpy as np
import pytest
from scipy.optimize import brentq

import flexmech_py as fm
from flexmech_py.base import kernels
from flexmech_py.models.superposition.reactions import joint_equations, least_squares
from flexmech_py.models.superposition.reference import newmark, slave_transformation
from flexmech_py.run.simulate import Prepared
from flexmech_py.models.superposition.loads import drive_loads

MODELS = fm.SUPERPOSITION_MODELS


def _load(cases_dir, name, *overrides, outputs=None):
    case = fm.load_case(cases_dir / f"{name}.toml", overrides=["solver.error_estimate='none'", *overrides])
    if outputs is not None:
        case["outputs"] = outputs
    return case


# ----------------------------------------------------------------------------- a payload at a beam tip
L, AREA, I2, E, RHO = 0.5, 1e-4, 2e-10, 7e10, 2700.0
M_TIP, J_TIP = 0.3, 2e-3


def _tip_case(payload: str, n: int = 16, drive=None, gravity=(0.0, 0.0), offset=0.0, t_end=0.02, mount="weld",
              inertia=J_TIP, motor=False):
    """A flexible beam clamped at O (base joint, kinematic drive) carrying a payload at its tip: a rigid body
    welded to the tip (centre ``offset`` beyond it) or a point mass and rotary inertia at the tip node."""
    d = {"mechanism": {"ground": {"O": [0.0, 0.0]}},
         "links": [{"name": "beam", "start": "ground.O", "end": [L, 0.0], "area": AREA, "second_moment": I2,
                    "youngs_modulus": E, "density": RHO, "elements": n}],
         "joints": [{"name": "base", "type": "revolute", "connects": ["ground.O", "beam.start"]}],
         "drives": [drive or {"joint": "base", "law": "constant_speed", "speed": 0.0}],
         "loads": {"gravity": list(gravity)},
         "solver": {"t_end": t_end, "dt": 1e-4, "model": "classic", "error_estimate": "none"},
         "outputs": {"tip_x": {"kind": "displacement", "at": "beam.end", "component": "x"},
                     "tip_y": {"kind": "displacement", "at": "beam.end", "component": "y"},
                     "tip_rot": {"kind": "displacement", "at": "beam.end", "component": "rotation"},
                     "root": {"kind": "strain", "link": "beam", "at": 0.0}}}
    if payload == "body":
        d["bodies"] = [{"name": "payload", "mass": M_TIP, "inertia": inertia, "centre": [L + offset, 0.0],
                        "points": {"mount": [L, 0.0]}}]
        d["joints"].append({"name": "mount", "type": mount, "connects": ["beam.end", "payload.mount"]})
        if motor:   # the payload turned by a motor at the tip, left free elastically
            d["joints"][-1]["elastic"] = "pin"
            d["drives"].append({"joint": "mount", "law": "constant_speed", "speed": 1.0})
        d["outputs"]["centre_y"] = {"kind": "position", "at": "payload.centre", "component": "y"}
    else:
        d["point_masses"] = [{"at": "beam.end", "mass": M_TIP}]
        d["rotary_inertias"] = [{"at": "beam.end", "inertia": J_TIP, "turns_with": "beam"}]
    return fm.validate_case(d)


def _tip_body_frequencies(k: int, offset: float) -> np.ndarray:
    """First k natural frequencies [rad/s] of an Euler-Bernoulli cantilever carrying a rigid body (mass M,
    inertia J about its centre at distance e beyond the tip): w = A (cos - cosh) + B (sin - sinh) with
    EI w''(L) = J w^2 w'(L) + M e w^2 (w + e w')(L) and EI w'''(L) = -M w^2 (w + e w')(L)."""
    ra, ei = RHO * AREA, E * I2

    def det(b):
        w2 = b ** 4 * ei / ra
        c, s, ch, sh = np.cos(b * L), np.sin(b * L), np.cosh(b * L), np.sinh(b * L)
        w, wp = np.array([c - ch, s - sh]), b * np.array([-s - sh, c - ch])
        wpp, wppp = b ** 2 * np.array([-c - ch, -s - sh]), b ** 3 * np.array([s - sh, -c - ch])
        r1 = ei * wpp - J_TIP * w2 * wp - M_TIP * offset * w2 * (w + offset * wp)
        r2 = ei * wppp + M_TIP * w2 * (w + offset * wp)
        return r1[0] * r2[1] - r1[1] * r2[0]

    grid = np.linspace(0.1, 40.0, 20000)
    vals = np.array([det(b) for b in grid])
    roots = [brentq(det, a, b, xtol=1e-14) for a, b, fa, fb in zip(grid[:-1], grid[1:], vals[:-1], vals[1:])
             if np.sign(fa) != np.sign(fb)]
    return np.array(roots[:k]) ** 2 * np.sqrt(ei / ra)


@pytest.mark.parametrize("offset", [0.0, 0.05])
def test_tip_body_frequencies_match_the_closed_form(offset):
    """A rigid body welded to a cantilever's tip: natural frequencies against the closed form (the slave
    relations d = u_tip - dtheta z x s of an offset body included); fourth order in the mesh."""
    exact = _tip_body_frequencies(3, offset)
    err = []
    for n in (4, 8):
        p = Prepared(_tip_case("body", n, offset=offset))
        w = np.sqrt(p.fe.squared_frequencies(p.rig[:, :, 0], "classic")[:3])
        err.append(np.abs(w - exact) / exact)
    assert err[1][1] < 5e-6 and err[1][2] < 2e-4              # measured 3.6e-6, 8.7e-5 (e = 0.05)
    assert err[0][1] / err[1][1] > 12                           # h^4: 15.9


def test_rigid_tip_body_equals_tip_point_mass_and_inertia():
    """A spinning cantilever with its payload as a welded rigid body (centre at the tip) and as a point mass
    plus a rotary inertia at the tip node: the same equations, equal to round-off in every model."""
    drive = {"joint": "base", "law": "spinup", "final_speed": 20.0, "spinup_time": 0.01}
    for model in MODELS:
        body = Prepared(_tip_case("body", 4, drive, (0.0, -9.81))).run(model)
        lumped = Prepared(_tip_case("lumped", 4, drive, (0.0, -9.81))).run(model)
        for k in ("tip_x", "tip_y", "tip_rot", "root"):
            scale = np.max(np.abs(lumped[k]))
            assert scale > 0
            assert np.max(np.abs(body[k] - lumped[k])) < 1e-10 * scale, (model, k)
        tip_y = body.motion.oy[:, 0] + L * np.sin(body.motion.phi[:, 0]) + body["tip_y"]
        assert np.allclose(body["centre_y"], tip_y, rtol=0, atol=1e-12)   # the payload's centre is the tip


# ----------------------------------------------------------------------------- prismatic joint, rigid limit
def test_slider_crank_rigid_limit(cases_dir):
    """The slider-crank (rigid crank, prismatic ground guide) with the rod E x 10 and x 1000 (stiffness-
    proportional damping removes the start-up transient): the elastic displacements fall as 1/E and the
    model's joint reactions tend to the rigid-body ones."""
    outs = {"slide": {"kind": "joint_displacement", "joint": "slide"}}
    umax, errs = [], []
    for fac in (1e1, 1e3):
        case = _load(cases_dir, "slider_crank", "solver.t_end=0.03", f"links.rod.youngs_modulus={2e11 * fac}",
                     f"solver.rayleigh=[0.0, {2e-5 / np.sqrt(fac)}]", outputs=outs)
        p = Prepared(case)
        res = p.run("classic")
        late = res.t > 0.015
        umax.append(np.max(np.abs(res.u[p.fe.free_translational()])))
        err = 0.0
        for j in ("crank_pivot", "crank_pin", "wrist_pin", "slide"):
            rigid = p.rm_frames.reaction(j)[late]
            err = max(err, np.max(np.abs(res.reactions(j)[late] - rigid)) / np.max(np.abs(rigid[:, :2])))
        errs.append(err)
        assert res.reactions.residual < 1e-9
    assert 80 < umax[0] / umax[1] < 130                         # 1/E: measured 105
    assert errs[1] < 1e-4 and errs[1] < errs[0] / 100           # measured 4.0e-2 -> 2.4e-5


# ----------------------------------------------------------------------------- time-varying slave relations
def _rotating_guide(dt: float, omega: float = 30.0):
    """A rigid guide turning at constant speed about O; on it a slider held by a flexible spring beam pinned
    to the guide at q: a steady rigid motion whose slave relations (the spring's tip and the slider on the
    along DOF, d = s t(t)) turn with the guide."""
    return fm.validate_case({
        "mechanism": {"ground": {"O": [0.0, 0.0]}},
        "links": [{"name": "guide_arm", "start": "ground.O", "end": [0.4, 0.0], "rigid": True, "area": 2e-4,
                   "density": 7850.0, "points": {"q": 0.25}},
                  {"name": "spring", "start": "guide_arm.q", "end": [0.3, 0.0], "area": 4e-5, "second_moment": 3.3e-10,
                   "youngs_modulus": 7.1e10, "density": 2710.0, "elements": 4}],
        "bodies": [{"name": "slider", "mass": 0.5, "inertia": 1e-4, "centre": [0.3, 0.0], "points": {"pin": [0.3, 0.0]}}],
        "joints": [{"name": "pivot", "type": "revolute", "connects": ["ground.O", "guide_arm.start"]},
                   {"name": "root", "type": "revolute", "connects": ["guide_arm.q", "spring.start"]},
                   {"name": "tip", "type": "revolute", "connects": ["spring.end", "slider.pin"]},
                   {"name": "guide", "type": "prismatic", "connects": ["guide_arm.start", "slider.pin"], "axis": [1.0, 0.0]}],
        "drives": [{"joint": "pivot", "law": "constant_speed", "speed": omega}],
        "solver": {"t_end": 0.05, "dt": dt, "output_every": 5, "model": "classic", "error_estimate": "none"},
        "outputs": {"slide": {"kind": "joint_displacement", "joint": "guide"}}})


def _jacobi_integral(res, omega: float):
    """(kinetic, rest) parts of the Jacobi integral of a system turning steadily at omega: in the rotating
    frame the superposition equations are time-invariant, so H = 1/2 v_r^T M v_r + 1/2 u^T (K - omega^2 M) u
    + F^T u is conserved (v_r = u' - omega z x u on the translations; rigid bodies: exact rotary inertia)."""
    fe, u, v = res.fe, res.u, res.v
    om = np.array([[0.0, -1.0], [1.0, 0.0]])
    kin, pot = np.zeros(res.t.size), np.zeros(res.t.size)
    for e in range(fe.nel):
        Le, _, ra, ea, ei = fe.el_prop[:, e]
        m, k, *_ = kernels.element_matrices(ra, ea, ei, Le)
        d = fe.el_dof[:, e] - 1
        for n in range(res.t.size):
            c, s = np.cos(res.rig[0, fe.el_link[e] - 1, n]), np.sin(res.rig[0, fe.el_link[e] - 1, n])
            t = np.eye(6)
            t[0:2, 0:2] = t[3:5, 3:5] = [[c, s], [-s, c]]
            x, vr = u[d, n], v[d, n].copy()
            vr[[0, 1, 3, 4]] -= omega * np.concatenate([om @ x[0:2], om @ x[3:5]])
            mg, kg = t.T @ m @ t, t.T @ k @ t
            kin[n] += 0.5 * vr @ mg @ vr
            pot[n] += 0.5 * x @ (kg - omega ** 2 * mg) @ x
    for i in range(fe.lm_link.size):
        d = fe.lm_dof[:, i] - 1
        vr = v[d] - omega * (om @ u[d])
        kin += 0.5 * fe.lm_prop[0, i] * np.sum(vr * vr, axis=0)
        pot -= 0.5 * fe.lm_prop[0, i] * omega ** 2 * np.sum(u[d] ** 2, axis=0)
    for i in range(fe.ri_link.size):
        kin += 0.5 * fe.ri_prop[i] * v[fe.ri_dof[i] - 1] ** 2
    return kin, pot + np.sum(fe.loads(res.rig, "classic") * u, axis=0)


def test_jacobi_integral_with_turning_slave_relations():
    """Undamped, the steady rotation keeps the Jacobi integral: its drift is the integrator's, second order
    in dt (a wrong T' or T'' in the reduced equations would make it drift at first order or worse)."""
    drift = []
    for dt in (4e-5, 2e-5):
        p = Prepared(_rotating_guide(dt))
        assert p.fe.slaving.nsl == 4          # the spring's tip (x, y) and the slider (x, y) on the along DOF
        res = p.run("classic")
        kin, rest = _jacobi_integral(res, 30.0)
        h = kin + rest
        assert np.max(np.abs(res.u[p.fe.slides[0].dof])) > 1e-5                  # it really slides elastically
        drift.append(np.max(np.abs(h - h[0])) / np.max(kin))
    assert drift[1] < 3e-8 and drift[0] / drift[1] > 3.5                          # measured 5.3e-8, 1.3e-8


def test_slave_row_derivatives_match_finite_differences(cases_dir):
    """T', T'' of the quick-return's rows (a slider on a turning rigid guide, contact point moving along it)
    against central differences of T and T' on a fine grid."""
    p = Prepared(_load(cases_dir, "quick_return", "solver.t_end=0.01", "solver.dt=1e-6"))
    t = p.fe.slave_values(p.rig)
    h = p.dt
    d1 = (t[0, :, 2:] - t[0, :, :-2]) / (2 * h)
    d2 = (t[1, :, 2:] - t[1, :, :-2]) / (2 * h)
    assert np.max(np.abs(t[1])) > 0 and np.max(np.abs(t[2])) > 0
    assert np.max(np.abs(d1 - t[1, :, 1:-1])) < 1e-6 * np.max(np.abs(t[1]))     # measured 1.3e-7
    assert np.max(np.abs(d2 - t[2, :, 1:-1])) < 1e-6 * np.max(np.abs(t[2]))     # measured 7e-8


@pytest.mark.parametrize("name, extra", [("quick_return", ()), ("sixbar_plate", ()),
                                         ("slider_crank_torque", ("joints.crank_pivot.elastic='torque'",))])
def test_general_path_matches_numpy_reference(cases_dir, name, extra):
    """The Fortran assembly of items with slaved DOFs against the NumPy reference (dense all-DOF matrices of
    its own, reduced with u = T w), with Rayleigh damping and, for the torque-driven slider-crank left free,
    the drive's torque on the rigid crank's rotation projected onto the masters."""
    p = Prepared(_load(cases_dir, name, "solver.t_end=0.002", "solver.dt=2e-5", "solver.output_every=1",
                       "mesh.elements_per_link=2", *extra))
    ray = (20.0, 1e-6)
    for model in MODELS:
        uf, _, _ = p.fe.run(p.rig, model, p.dt, rayleigh=ray, q_free=p.q_free, q_val=p.q_val)
        q_all = drive_loads(p.fe, p.rm, [d.joint for d in p.case.mechanism.drives if not d.kinematic])
        ref = newmark(p.fe, p.rig, model, p.dt, rayleigh=ray, q_all=q_all)
        assert np.max(np.abs(ref)) > 0
        assert np.max(np.abs(uf - ref)) < 1e-9 * np.max(np.abs(ref)), model


def test_chunked_run_equals_unchunked_with_slaves(cases_dir):
    case = _load(cases_dir, "quick_return", "solver.t_end=0.01")
    whole = Prepared(case, chunk_steps=10 ** 9).run()
    chunked = Prepared(case, chunk_steps=130).run()
    for k in whole.columns:
        assert np.max(np.abs(chunked[k] - whole[k])) <= 1e-12 * max(np.max(np.abs(whole[k])), 1e-300), k


def _fourbar_coupler(cases_dir, rigid: bool, factor: float = 1.0, *overrides):
    case = _load(cases_dir, "fourbar_constant_speed", *overrides)
    raw = copy.deepcopy(dict(case))
    raw["case"].pop("path", None)
    raw["outputs"] = {"follower": {"kind": "strain", "link": "follower", "at": 0.5},
                      "crank": {"kind": "strain", "link": "crank", "at": 0.0}}
    if rigid:
        raw["links"][1]["rigid"] = True
    else:
        raw["links"][1]["youngs_modulus"] *= factor
    return fm.validate_case(raw)


def test_stiff_coupler_tends_to_the_rigid_coupler(cases_dir):
    """The seed four-bar with a rigid coupler (a rigid link: slave relations at both pins) against the coupler
    as a flexible beam made stiffer.  At rest under gravity (sudden load; the stiff modes damped) the
    difference falls as 1/E, as do the differences of the natural frequencies.  Turning at 120 rad/s the
    difference stops near 0.2 % (1.7e-3 at E x 1e5): the linear models' spin softening of a rotation differs
    between a beam and a rigid body (docs/theory.md section 18.4)."""
    still = ("drive.speed=0.0", "loads.gravity=[0.0, -9.81]", "solver.t_end=0.02", "solver.output_every=10",
             "solver.rayleigh=[0.0, 1e-6]")
    ref = Prepared(_fourbar_coupler(cases_dir, True, 1.0, *still))
    rres = ref.run("classic")
    wr = np.sqrt(ref.fe.squared_frequencies(ref.rig[:, :, 0], "classic")[:3])
    diffs = []
    for fac in (1e3, 1e5):
        p = Prepared(_fourbar_coupler(cases_dir, False, fac, *still))
        r = p.run("classic")
        diffs.append(max(np.max(np.abs(r[k] - rres[k])) / np.max(np.abs(rres[k])) for k in ("follower", "crank")))
        w = np.sqrt(p.fe.squared_frequencies(p.rig[:, :, 0], "classic")[:3])
        assert np.max(np.abs(w - wr) / wr) < 1e-3 / fac ** 0.5          # 1/E: 2.2e-5, 1.7e-7
    assert diffs[1] < 1e-3 and diffs[0] / diffs[1] > 50                 # 1/E: 3.0e-2, 2.6e-4
    moving = ("solver.t_end=0.03", "solver.rayleigh=[0.0, 1e-6]", "solver.output_every=10")
    rres = Prepared(_fourbar_coupler(cases_dir, True, 1.0, *moving)).run("classic")
    d = [np.max(np.abs(Prepared(_fourbar_coupler(cases_dir, False, f, *moving)).run("classic")["follower"]
                       - rres["follower"])) / np.max(np.abs(rres["follower"])) for f in (1e1, 1e3)]
    assert d[1] < 5e-3 < d[0]


# ----------------------------------------------------------------------------- force on a prismatic joint
def test_force_on_a_prismatic_joint_loads_the_along_dof(cases_dir):
    """The slider-crank driven by a force on the slider, its prismatic joint left free elastically
    ('force') and the crank pin free: the mechanism's motion is a zero-stiffness mode of the elastic
    problem; the force on the along DOF balances the rigid-inertia load on it (hac and classic: round-off;
    classic-translational drops the crank's J alpha and drives the mode, theory.md section 14)."""
    case = _load(cases_dir, "slider_crank_torque", "solver.t_end=0.02", "drives.0.joint='slide'",
                 "drives.0.constant=-30.0", "joints.slide.elastic='force'", "joints.crank_pivot.elastic='pin'",
                 "links.rod.elements=4", "initial.coordinates.crank_pivot=0.8",
                 outputs={"slide": {"kind": "joint_displacement", "joint": "slide"}})
    p = Prepared(case)
    k = 40
    rig = p.rig[:, :, k]
    t = slave_transformation(p.fe, rig)[0]
    q = drive_loads(p.fe, p.rm.select(slice(k, k + 1)), ["slide"])[:, 0]
    net, drift = {}, {}
    for model in MODELS:
        _, _, km, f = p.fe.matrices(rig, model)
        still = rig.copy()
        still[1:3] = 0.0
        w, v = np.linalg.eigh(p.fe.matrices(still, model)[2])
        assert abs(w[0]) < 1e-9 * w[1]                       # the mechanism mode
        load = t.T @ (q - f)
        net[model] = abs(v[:, 0] @ load) / np.linalg.norm(t.T @ f)
        res = p.run(model)
        drift[model] = np.max(np.abs(res.u[p.fe.slides[0].dof]))
        assert np.max(np.abs(res["slide"] - p.rm_frames.joint("slide")[:, 0])) == pytest.approx(drift[model])
    assert net["hac"] < 1e-12 and net["classic"] < 1e-12 and net["classic-translational"] > 1e-3
    assert drift["classic-translational"] > 100 * drift["classic"]


# ----------------------------------------------------------------------------- reactions, welds
def test_model_reactions_balance_each_rigid_body(cases_dir):
    """The sum of the model's joint forces on the slider (wrist pin from the rod, guide from the ground) is
    the slider's mass times its total acceleration (rigid + elastic); the joint equations close to round-off."""
    case = _load(cases_dir, "slider_crank", "solver.t_end=0.02", "solver.output_every=1")
    p = Prepared(case)
    res = p.run("classic")
    part = p.fe.parts["slider"]
    acc = p.rm_frames.zdd[:, 3 * case.mechanism.body_index(part.body):][:, :2] + res.a[list(part.dofs[:2])].T
    force = res.reactions("wrist_pin")[:, :2] + res.reactions("slide")[:, :2]
    assert np.max(np.abs(force - part.mass * acc)) < 1e-9 * np.max(np.abs(force))
    assert res.extra["reactions"]["equilibrium_residual"] < 1e-10
    rigid = p.rm_frames.reaction("crank_pin")
    assert np.max(np.abs(res.reactions("crank_pin") - rigid)) > 1e-3 * np.max(np.abs(rigid))   # elastic part


def test_joint_equations_least_squares_is_the_pseudo_inverse_solution():
    """Per frame the minimum-norm least-squares solution, as the pseudo-inverse gives it: one matrix for every
    frame, a matrix per frame (QR), frames with dependent columns and underdetermined frames (pseudo-inverse)."""
    rng = np.random.default_rng(3)
    a = rng.standard_normal((40, 9, 5))
    a[7, :, 4] = a[7, :, 0] - 2.0 * a[7, :, 1]           # frame 7: dependent columns
    b = rng.standard_normal((40, 9))
    ref = np.einsum("nuk,nk->nu", np.linalg.pinv(a), b)
    assert np.allclose(least_squares(a, b), ref, rtol=0, atol=1e-12)
    assert np.allclose(least_squares(a[:1], b), b @ np.linalg.pinv(a[0]).T, rtol=0, atol=1e-12)
    wide = a[:, :4, :]
    assert np.allclose(least_squares(wide, b[:, :4]), np.einsum("nuk,nk->nu", np.linalg.pinv(wide), b[:, :4]),
                       rtol=0, atol=1e-12)


def test_joint_equations_one_matrix_only_without_rigid_parts_or_guides(cases_dir):
    """The seed four-bar (flexible links, revolute joints) has one matrix for every frame; the slider-crank
    (a rigid slider on a prismatic guide) one per frame; both close their equations to round-off."""
    for name, constant in (("fourbar_hac", True), ("slider_crank", False)):
        p = Prepared(_load(cases_dir, name, "solver.t_end=0.005", "solver.model=hac"))
        assert joint_equations(p.fe).constant is constant
        assert joint_equations(p.fe) is joint_equations(p.fe)          # built once per mesh
        res = p.run("hac")
        assert np.all(np.isfinite(res.reactions(p.case.mechanism.joints[0].name)))
        assert res.reactions.residual < 1e-10


def test_welded_sixbar_against_the_plate_sixbar(cases_dir):
    """The ternary link as two welded flexible beams and as a rigid plate: the same kinematics and outputs of
    the same order, not equal; the weld shares the beams' rotation and translations at coupler.mid."""
    common = ("solver.t_end=0.05",)
    plate = Prepared(_load(cases_dir, "sixbar_plate", *common)).run("classic")
    weld_case = _load(cases_dir, "sixbar_welded", *common)
    for link in ("coupler", "arm"):
        at = "coupler.mid" if link == "coupler" else "arm.start"
        for comp in ("x", "y", "rotation"):
            weld_case["outputs"][f"{link}_{comp}"] = {"kind": "displacement", "at": at, "component": comp}
    weld = Prepared(weld_case).run("classic")
    for comp in ("x", "y", "rotation"):
        assert np.max(np.abs(weld[f"coupler_{comp}"])) > 0
        assert np.array_equal(weld[f"coupler_{comp}"], weld[f"arm_{comp}"])
    for k in ("d_x", "d_y"):
        assert np.max(np.abs(weld[k] - plate[k])) < 1e-3
    for k in ("strain_rocker_mid", "strain_cd_mid", "joint_c_force"):
        a, b = np.max(np.abs(weld[k])), np.max(np.abs(plate[k]))
        assert np.all(np.isfinite(weld[k])) and np.all(np.isfinite(plate[k]))
        assert 0.2 < a / b < 5 and not np.allclose(weld[k], plate[k]), k


def test_reaction_source_rigid_and_model(cases_dir):
    outs = {"model": {"kind": "reaction", "joint": "guide", "component": "magnitude"},
            "rigid": {"kind": "reaction", "joint": "guide", "component": "magnitude", "source": "rigid"}}
    raw = _raw(cases_dir, "quick_return")
    raw["outputs"] = outs
    raw["solver"].update(t_end=0.01, error_estimate="none")
    case = fm.validate_case(raw)
    assert case["outputs"]["model"]["source"] == "model"
    p = Prepared(case)
    res = p.run("classic")
    r = p.rm_frames.reaction("guide")
    # the run evaluates the reactions chunk by chunk: equal to the whole-grid ones to round-off
    np.testing.assert_allclose(res["rigid"], np.hypot(r[:, 0], r[:, 1]), rtol=1e-13, atol=0)
    # undamped, the crank's start-up vibration (the block on its tip) swings the guide force about the rigid one
    assert np.all(np.isfinite(res["model"])) and np.max(np.abs(res["model"] - res["rigid"])) > 0.1 * np.max(res["rigid"])


# ----------------------------------------------------------------------------- bad input
def _raw(cases_dir, name):
    from flexmech_py.case import read_case_file

    return read_case_file(cases_dir / f"{name}.toml")


def _guide_on_rod(raw):
    """The slider guided along the flexible rod's end instead of the ground (no wrist pin)."""
    del raw["joints"][2]
    raw["joints"][2].update(connects=["rod.end", "slider.pin"])


@pytest.mark.parametrize("edit, field, words", [
    (_guide_on_rod, "joints.slide.connects",
     "a prismatic joint's guide must be the ground or a rigid body"),
    (lambda r: r.update(point_masses=[{"at": "slider.pin", "mass": 0.1}]), "point_masses[0].at",
     "must be a point of a link"),
    (lambda r: r["outputs"].update(bad={"kind": "strain", "link": "crank"}), "outputs.bad.link", "is rigid"),
    (lambda r: r["outputs"].update(bad={"kind": "displacement", "at": "slider.pin", "component": "rotation"}),
     "outputs.bad.component", "defined for link points"),
    (lambda r: r["outputs"].update(bad={"kind": "inertia_load", "at": "crank.end", "component": "x"}),
     "outputs.bad.at", "flexible links"),
    (lambda r: r["outputs"].update(bad={"kind": "reaction", "joint": "slide", "component": "x", "source": "elastic"}),
     "outputs.bad.source", "must be one of"),
])
def test_bad_general_input_names_the_field(cases_dir, edit, field, words):
    raw = _raw(cases_dir, "slider_crank")
    edit(raw)
    with pytest.raises(fm.CaseError) as exc:
        Prepared(fm.validate_case(raw)).run("classic")
    assert exc.value.field == field and words in str(exc.value)


def test_zero_inertia_body_free_to_turn_is_refused():
    """A payload without rotary inertia turned by a motor at its centre, the motor left free elastically
    ('pin'): the payload's elastic rotation has neither mass nor stiffness."""
    with pytest.raises(fm.CaseError) as exc:
        Prepared(_tip_case("body", 2, mount="revolute", inertia=0.0, motor=True)).run("classic")
    assert exc.value.field == "bodies.payload.inertia" and "rotary inertia" in str(exc.value)


def test_rigid_only_mechanisms_are_refused(cases_dir):
    raw = _raw(cases_dir, "slider_crank")
    raw["links"][1].update(rigid=True)
    for key in ("second_moment", "youngs_modulus"):
        raw["links"][1].pop(key)
    raw["outputs"] = {"x": {"kind": "joint_displacement", "joint": "slide"}}
    prepared = Prepared(fm.validate_case(raw))
    for model in ("classic", "coupled"):
        with pytest.raises(fm.CaseError) as exc:
            prepared.run(model)
        assert exc.value.field == "links" and "flexible" in str(exc.value)


def test_periodic_steady_state_with_turning_relations(cases_dir):
    """The quick-return at constant crank speed (slave rows turning with its rigid rocker and its moving
    contact point): the periodic steady state from the monodromy matrix equals the end of a damped
    transient from rest run over six periods on the same grid."""
    from flexmech_py.studies.floquet import PeriodicCase, floquet, steady_state

    damped = ["solver.rayleigh=[60.0, 1e-6]", "mesh.elements_per_link=2", "solver.output_every=1"]
    pc = PeriodicCase(_load(cases_dir, "quick_return", *damped), "classic", dt=2e-4)
    fr = floquet(pc)
    assert fr.stable
    steady = steady_state(pc, fr)
    assert steady.extra["floquet"]["periodicity_residual"] < 1e-8
    tr = Prepared(_load(cases_dir, "quick_return", *damped, f"solver.t_end={6 * pc.period!r}"),
                  dt=pc.dt * (1 + 1e-12)).run("classic")
    assert tr.nsteps == 6 * pc.nsteps
    nf = steady.t.size
    for name in ("strain_crank_start", "crank_tip_transverse", "guide_force"):
        assert np.max(np.abs(tr[name][-nf:] - steady[name])) < 1e-6 * np.max(np.abs(steady[name])), name
