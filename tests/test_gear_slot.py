"""The two joint kinds added on the joint protocol: the gear pair and the pin in a slot.

Closed forms: the gear ratio and the Scotch yoke's x = r cos(theta) in the rigid kinematics; the tooth
force = torque / pitch radius and the slot's normal force = the yoke's m a; the lowest frequency of
two rotors geared together on an elastic shaft (a pinned-pinned beam turned at one end) against the
Euler-Bernoulli frequency equation; energy balance; the elastic models against the nonlinear one.
Short runs and coarse meshes (docs/validation.md has the full-size numbers)."""

from __future__ import annotations

import copy
import tomllib

import numpy as np
import pytest
from scipy.optimize import brentq

import flexmech_py as fm
from flexmech_py.base.families import SUPERPOSITION_MODELS
from flexmech_py.mechanism import MotionSource, prepare_motion
from flexmech_py.studies.modes import modes

E, I_BEAM, A_BEAM, RHO, L_SHAFT = 2.0e11, 3.4133333333333335e-10, 6.4e-5, 7870.0, 0.5
R_A, R_B, J1, J2 = 0.05, 0.10, 1.0e-3, 4.0e-3
_SHAFT_DIR = np.array([0.6, -0.8])          # the shaft leaves gear a's centre away from gear b


def _spec(name: str) -> dict:
    return tomllib.loads(fm.case_path(name).read_text())


def _gear_train(mesh="external", flexible=False) -> dict:
    """Two gears on ground pivots, gear a (r_a, J1) turned by a harmonic motor, gear b (r_b, J2) free;
    ``flexible``: gear a sits on the start of a steel shaft (a beam) pinned there and on a roller along
    its line at its end (pinned-pinned for bending), instead of on a body."""
    d = R_A + R_B if mesh == "external" else R_B - R_A
    spec = {
        "mechanism": {"ground": {"O1": [0.0, 0.0], "O2": [d, 0.0], "Q": list(L_SHAFT * _SHAFT_DIR)}},
        "bodies": [{"name": "gear_b", "mass": 1.0, "inertia": J2, "centre": [d, 0.0], "points": {"c": [d, 0.0]}}],
        "joints": [{"name": "pivot_b", "type": "revolute", "connects": ["ground.O2", "gear_b.c"]},
                   {"name": "mesh", "type": "gear", "connects": ["gear_a.c", "gear_b.c"], "radii": [R_A, R_B],
                    "mesh": mesh}],
        "solver": {"t_end": 0.01, "dt": 1e-4, "model": "coupled"},
        "outputs": {"b": {"kind": "joint_angle", "joint": "pivot_b"}}}
    if flexible:
        spec["links"] = [{"name": "shaft", "start": "ground.O1", "end": "ground.Q", "area": A_BEAM,
                          "second_moment": I_BEAM, "youngs_modulus": E, "density": RHO, "points": {"c": 0.0}}]
        spec["joints"] += [{"name": "pivot_a", "type": "revolute", "connects": ["ground.O1", "shaft.start"]},
                           {"name": "end_q", "type": "revolute", "connects": ["roller.c", "shaft.end"]},
                           {"name": "roll", "type": "prismatic", "connects": ["ground", "roller.c"],
                            "axis": list(_SHAFT_DIR)}]         # a roller: the end slides along the shaft's line
        q = list(L_SHAFT * _SHAFT_DIR)
        spec["bodies"].append({"name": "roller", "mass": 1e-3, "inertia": 0.0, "centre": q, "points": {"c": q}})
        spec["joints"][1]["connects"][0] = "shaft.start"
        spec["rotary_inertias"] = [{"at": "shaft.start", "inertia": J1}]
        spec["mesh"] = {"elements_per_link": 8}
    else:
        spec["bodies"].append({"name": "gear_a", "mass": 1.0, "inertia": J1, "centre": [0.0, 0.0],
                               "points": {"c": [0.0, 0.0]}})
        spec["joints"].insert(0, {"name": "motor", "type": "revolute", "connects": ["ground.O1", "gear_a.c"]})
        spec["drives"] = [{"joint": "motor", "law": "harmonic", "amplitude": 0.5, "frequency": 20.0}]
    return spec


def _rigid(spec, t):
    mech = fm.validate_case(spec).mechanism
    return mech, MotionSource(prepare_motion(mech), rtol=1e-12, atol=1e-14)(t)


# ------------------------------------------------------------------------------ gear pair
@pytest.mark.parametrize("mesh", ["external", "internal"])
def test_gear_ratio_and_tooth_force_against_the_hand_calculation(mesh):
    """dpsi_b = -s r_a / r_b dpsi_a exactly; gear b's only load is the tooth force, so its moment about
    b's centre is J2 alpha_b and the tooth force J2 alpha_b / r_b; the motor's torque (J1 + rho^2 J2)
    alpha_a."""
    t = np.linspace(0.0, 0.3, 301)
    mech, rm = _rigid(_gear_train(mesh), t)
    s = 1.0 if mesh == "external" else -1.0
    rho = -s * R_A / R_B
    a, b = rm.joint("motor"), rm.joint("pivot_b")
    assert np.max(np.abs((b[:, 0] - b[0, 0]) - rho * (a[:, 0] - a[0, 0]))) < 1e-12
    assert np.allclose(b[:, 1:], rho * a[:, 1:], rtol=0, atol=1e-9 * np.max(np.abs(a[:, 2])))
    react = rm.reaction("mesh")                          # gear a on gear b, at b's centre
    assert np.allclose(react[:, 2], J2 * b[:, 2], rtol=0, atol=1e-9 * J2 * np.max(np.abs(b[:, 2])))
    tooth = np.hypot(react[:, 0], react[:, 1])
    assert np.allclose(tooth, np.abs(J2 * b[:, 2]) / R_B, rtol=1e-9, atol=1e-12)
    torque = rm.drive_force("motor")
    assert np.allclose(torque, (J1 + rho ** 2 * J2) * a[:, 2], rtol=1e-9, atol=1e-9)


def test_a_gear_pair_whose_centres_do_not_fit_the_radii_is_refused_naming_the_field():
    spec = _gear_train()
    spec["joints"][2]["radii"] = [0.05, 0.12]
    with pytest.raises(fm.CaseError, match=r"joints\.mesh\.radii.*0\.15 m apart.*r_a \+ r_b = 0\.17"):
        fm.validate_case(spec)


def _geared_shaft_omega() -> float:
    """Lowest root of the Euler-Bernoulli frequency equation of a pinned-pinned beam (E I, rho A, L) with
    a rotary inertia J at x = 0: w(0) = w(L) = w''(L) = 0, E I w''(0) = -J omega^2 w'(0); the geared
    rotor adds (r_a / r_b)^2 J2 to J1 (its rotation is -s r_a / r_b times the shaft end's).  The
    massless-shaft limit is sqrt(3 E I / (L J))."""
    ei, rho_a, j = E * I_BEAM, RHO * A_BEAM, J1 + (R_A / R_B) ** 2 * J2

    def det(w):
        b = (rho_a * w * w / ei) ** 0.25
        s, c, sh, ch = np.sin(b * L_SHAFT), np.cos(b * L_SHAFT), np.sinh(b * L_SHAFT), np.cosh(b * L_SHAFT)
        return np.linalg.det(np.array([[0, 1, 0, 1], [j * w * w * b, -ei * b * b, j * w * w * b, ei * b * b],
                                       [s, c, sh, ch], [-s, -c, sh, ch]]))

    grid = np.linspace(10.0, np.sqrt(3 * ei / (L_SHAFT * j)), 400)
    v = np.array([det(w) for w in grid])
    k = np.flatnonzero(v[:-1] * v[1:] < 0)[0]
    return brentq(det, grid[k], grid[k + 1])


@pytest.mark.parametrize("model", ["classic", "coupled", "nonlinear"])
def test_two_rotors_geared_on_an_elastic_shaft_ring_at_the_closed_form_frequency(model):
    exact = _geared_shaft_omega()
    assert exact == pytest.approx(341.538, abs=1e-3)
    case = fm.validate_case(_gear_train(flexible=True))
    omega = modes(case, count=1, model=model).omega[0]
    print(f"\ngeared shaft ({model}): omega {omega:.6f} rad/s, closed form {exact:.6f}, error {omega / exact - 1:.2e}")
    assert omega == pytest.approx(exact, rel=2e-5)     # 8 elements: 4.4e-6


def test_the_geared_fivebar_holds_the_ratio_and_balances_its_energy():
    """Over 0.11 s crank 1 passes pi: a segment node's frame angle crosses its atan2 cut (con_residual)."""
    case = fm.load_case("geared_fivebar", overrides=["solver.t_end=0.11", "mesh.elements_per_link=2",
                                                     "solver.dt=5e-5"])
    res = fm.simulate(case)
    a1, a2 = res["crank1_angle"], res["crank2_angle"]
    summ = res.summary()["coupled"]
    assert summ["constraint_violation"]["gear_m"] < 1e-9
    assert summ["energy_balance"]["relative_drift"] < 1e-3
    # the mesh reaction: |force| = |moment| / r_b at the joint (the tooth force along the line of action)
    m, f = res["mesh_moment"], np.hypot(res["mesh_force_x"], res["mesh_force_y"])
    assert np.allclose(f, np.abs(m) / 0.075, rtol=1e-9, atol=1e-12)
    assert np.max(np.abs(a1 - a1[0] + a2 - a2[0])) < 2e-3       # the chords: ratio -1 up to the deflection


def test_the_superposition_models_refuse_a_gear_whose_centre_moves_elastically_and_the_others_run_it():
    """Gear a at the middle of the shaft: its centre deflects, so the line of centres turns elastically,
    which the superposition models' rotation relation cannot express; one line naming the joint and
    the models that take it.  The coupled model runs it (its row holds the line of centres' turn)."""
    spec = _gear_train(flexible=True)
    mid = 0.5 * L_SHAFT * _SHAFT_DIR
    spec["mechanism"]["ground"]["O2"] = [mid[0] + R_A + R_B, mid[1]]
    spec["bodies"][0]["centre"] = spec["bodies"][0]["points"]["c"] = spec["mechanism"]["ground"]["O2"]
    spec["joints"][1]["connects"][0] = "shaft.mid"
    for model in SUPERPOSITION_MODELS:
        with pytest.raises(fm.CaseError, match=r"joints\.mesh\.connects: .*gear joint only between points at ground "
                                               r"pivots .*'shaft\.mid'.*model = 'coupled' or 'nonlinear'"):
            modes(fm.validate_case(spec), count=1, model=model)
    assert modes(fm.validate_case(spec), count=1, model="coupled").omega[0] > 0


@pytest.mark.parametrize("model", ["classic", "hac", "coupled"])
def test_the_geared_fivebar_in_every_family_against_the_nonlinear_model(model):
    over = ["solver.t_end=0.02", "mesh.elements_per_link=2", "solver.dt=2e-5", "solver.rayleigh=[0, 1e-5]"]
    ref = fm.simulate(fm.load_case("geared_fivebar", overrides=over + ["solver.model=nonlinear"]))
    res = fm.simulate(fm.load_case("geared_fivebar", overrides=over + [f"solver.model={model}"]))
    for name in ("strain_distal1_mid", "strain_distal2_mid", "mesh_moment"):
        diff = np.max(np.abs(res[name] - ref[name])) / np.max(np.abs(ref[name]))
        print(f"\n{model} {name}: max |difference| / peak of nonlinear = {diff:.3e}")
        assert diff < (0.01 if model == "coupled" else 0.03), name


# ------------------------------------------------------------------------------ pin in a slot
def test_the_scotch_yoke_moves_r_cos_theta_and_the_slot_pushes_with_m_a():
    """Rigid: the yoke's x = r cos(theta) (the guide's coordinate from the drawn x = r), the pin's slide
    in the slot r sin(theta); the slot's force on the pin is normal to the slot (x) and equals -m x''
    of the yoke (its only load), with no moment."""
    case = fm.load_case("scotch_yoke")
    t = np.linspace(0.0, 0.09, 901)
    rm = MotionSource(prepare_motion(case.mechanism), rtol=1e-12, atol=1e-14)(t)
    th, x, s = rm.joint("crank_pivot"), rm.joint("guide"), rm.joint("pin")
    r = 0.1
    assert np.max(np.abs(r + x[:, 0] - r * np.cos(th[:, 0]))) < 1e-12
    assert np.max(np.abs(s[:, 0] - r * np.sin(th[:, 0]))) < 1e-12
    f = rm.reaction("pin")
    assert np.max(np.abs(f[:, 1:])) == 0.0
    assert np.allclose(-f[:, 0], 0.5 * x[:, 2], rtol=1e-9, atol=1e-9 * np.max(np.abs(x[:, 2])))


@pytest.mark.parametrize("model", ["classic", "hac", "coupled"])
def test_the_scotch_yoke_in_every_family_against_the_nonlinear_model(model):
    over = ["solver.t_end=0.02", "mesh.elements_per_link=2", "solver.dt=2e-5"]
    ref = fm.simulate(fm.load_case("scotch_yoke", overrides=over + ["solver.model=nonlinear"]))
    res = fm.simulate(fm.load_case("scotch_yoke", overrides=over + [f"solver.model={model}"]))
    for name in ("crank_tip_transverse", "strain_crank_root", "slot_force_x"):
        diff = np.max(np.abs(res[name] - ref[name])) / np.max(np.abs(ref[name]))
        print(f"\n{model} {name}: max |difference| / peak of nonlinear = {diff:.3e}")
        assert diff < 0.05, name
    if model == "coupled":
        summ = res.summary()["coupled"]
        assert summ["energy_balance"]["relative_drift"] < 1e-4
        assert summ["constraint_violation"]["guide_normal_m"] < 1e-12


def _slotted_lever(flexible: bool) -> dict:
    """The crank-shaper of cases/quick_return.toml with the crank pin running in a slot along the rocker
    (no block): a slotted-lever quick-return; ``flexible``: the rocker, slot and all, is an aluminium
    beam."""
    spec = _spec("quick_return")
    spec["bodies"] = []
    spec["joints"] = [j for j in spec["joints"] if j["name"] not in ("crank_pin", "guide")]
    spec["joints"].append({"name": "slot", "type": "slot", "connects": ["rocker.start", "crank.end"],
                           "axis": [0.4472135954999579, 0.8944271909999159]})
    if flexible:
        rocker = spec["links"][1]
        rocker.pop("rigid")
        rocker.update(second_moment=1.6666666666666667e-9, youngs_modulus=7.1e10, density=2710.0, area=2.0e-4)
    spec["outputs"] = {"rocker": {"kind": "joint_angle", "joint": "rocker_pivot"},
                       "slide": {"kind": "joint_displacement", "joint": "slot"},
                       "slot_force": {"kind": "reaction", "joint": "slot", "component": "magnitude"},
                       "strain": {"kind": "strain", "link": "crank", "at": 0.0}}
    spec["solver"].update(t_end=0.02, dt=2e-5)
    spec["mesh"] = {"elements_per_link": 4}
    return spec


def test_the_slotted_lever_follows_its_closed_form():
    """The rocker points at the crank pin: phi = atan2(0.2 + r sin theta, r cos theta), the slide along
    it |pin - O4| (from the drawn one)."""
    case = fm.validate_case(_slotted_lever(False))
    t = np.linspace(0.0, 0.2, 801)
    rm = MotionSource(prepare_motion(case.mechanism), rtol=1e-12, atol=1e-14)(t)
    th = rm.joint("crank_pivot")[:, 0]
    pin = np.stack([0.1 * np.cos(th), 0.2 + 0.1 * np.sin(th)], axis=1)
    phi = np.unwrap(np.arctan2(pin[:, 1], pin[:, 0]))
    assert np.max(np.abs(rm.joint("rocker_pivot")[:, 0] - (phi - phi[0]) - rm.joint("rocker_pivot")[0, 0])) < 1e-10
    length = np.hypot(pin[:, 0], pin[:, 1])
    assert np.max(np.abs(rm.joint("slot")[:, 0] - rm.joint("slot")[0, 0] - (length - length[0]))) < 1e-10


def test_a_slot_in_a_flexible_link_runs_in_the_coupled_models_and_is_refused_by_superposition():
    spec = _slotted_lever(True)
    for model in SUPERPOSITION_MODELS:
        with pytest.raises(fm.CaseError, match=r"joints\.slot\.connects: a slot joint's guide must be the ground or "
                                               r"a rigid body; 'rocker' is a flexible link"):
            fm.simulate(fm.validate_case({**spec, "solver": {**spec["solver"], "model": model}}))
    ref = fm.simulate(fm.validate_case({**spec, "solver": {**spec["solver"], "model": "nonlinear"}}))
    res = fm.simulate(fm.validate_case({**spec, "solver": {**spec["solver"], "model": "coupled"}}))
    for name in ("strain", "slot_force"):
        diff = np.max(np.abs(res[name] - ref[name])) / np.max(np.abs(ref[name]))
        print(f"\nflexible slotted lever, coupled {name}: max |difference| / peak of nonlinear = {diff:.3e}")
        assert diff < 0.05, name
    assert res.summary()["coupled"]["energy_balance"]["relative_drift"] < 1e-4
