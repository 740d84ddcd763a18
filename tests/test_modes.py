"""Natural frequencies and mode shapes of the frozen mechanism (flexmech_py.models.modal, flexmech_py.studies.modes,
`flexmech modes`; docs/theory.md section 20) against closed forms and the frequencies the other
analyses use."""

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import beam_case

import flexmech_py as fm
from flexmech_py.cli import main
from flexmech_py.studies.modes import frequencies_along, modes

E, I, A, RHO, L = 2e11, 1e-9, 1e-4, 7800.0, 1.0
#: roots beta_n L of 1 + cos(bL) cosh(bL) = 0 (clamped-free Euler-Bernoulli beam)
CLAMPED_FREE = np.array([1.875104069, 4.694091133, 7.854757438])


def _exact(beta_l):
    return (beta_l / L) ** 2 * np.sqrt(E * I / (RHO * A))


def test_clamped_free_beam_converges_with_order_four():
    errs = []
    for n in (2, 4, 8):
        ms = modes(beam_case(n_el=n), count=3, model="classic")
        assert not ms.rigid.any()
        errs.append(np.abs(ms.omega / _exact(CLAMPED_FREE) - 1))
    errs = np.array(errs)
    order = np.log2(errs[1, :2] / errs[2, :2])
    print(f"\nclamped-free errors at 8 el: {errs[-1]}, observed orders {order}")
    assert errs[-1, 0] < 3e-6 and errs[-1, 1] < 1e-4
    assert np.all(order > 3.8)                       # cubic Hermite elements: frequencies O(h^4)


@pytest.mark.parametrize("model", ["hac", "coupled", "nonlinear"])
def test_every_model_gives_the_beam_frequencies_at_rest(model):
    ms = modes(beam_case(n_el=8), count=2, model=model)
    err = np.abs(ms.omega / _exact(CLAMPED_FREE[:2]) - 1)
    assert err[0] < 5e-6 and err[1] < 2e-4, err


def _pinned_roller_beam(n_el):
    """The beam pinned at (0, 0) and on a roller at (L, 0): a massless-like slider body on a horizontal
    guide, pinned to the beam's end (the beam's end is free to slide axially and to turn)."""
    return fm.validate_case({
        "mechanism": {"ground": {"O": [0.0, 0.0]}},
        "links": [{"name": "beam", "start": "ground.O", "end": [L, 0.0], "area": A, "second_moment": I,
                   "youngs_modulus": E, "density": RHO, "elements": n_el}],
        "bodies": [{"name": "roller", "mass": 1e-6, "inertia": 0.0, "centre": [L, 0.0], "points": {"pin": [L, 0.0]}}],
        "joints": [{"name": "pivot", "type": "revolute", "connects": ["ground.O", "beam.start"]},
                   {"name": "pin", "type": "revolute", "connects": ["beam.end", "roller.pin"]},
                   {"name": "slot", "type": "prismatic", "connects": ["ground", "roller.pin"], "axis": [1.0, 0.0]}],
        "solver": {"t_end": 0.01, "dt": 1e-4},
        "outputs": {"mid": {"kind": "strain", "link": "beam", "at": 0.5}}})


@pytest.mark.parametrize("model", ["classic", "coupled", "nonlinear"])
def test_pinned_pinned_beam_converges_with_order_four(model):
    """omega_n = (n pi / L)^2 sqrt(EI / rho A): a zero-DOF mechanism (pivot, roller) in every model."""
    exact = (np.arange(1, 4) * np.pi / L) ** 2 * np.sqrt(E * I / (RHO * A))
    errs = np.array([np.abs(modes(_pinned_roller_beam(n), count=3, model=model).omega / exact - 1) for n in (2, 4, 8)])
    order = np.log2(errs[:-1, :2] / errs[1:, :2])
    print(f"\npinned-pinned ({model}) errors at 8 el: {errs[-1]}, observed orders {order.ravel()}")
    assert errs[-1, 0] < 2e-5 and errs[-1, 2] < 2e-3
    assert np.all(order > 3.8)


def _tip_mass_roots(mu, count=3):
    """Roots beta L of 1 + cos cosh + mu beta L (cos sinh - sin cosh) = 0: a clamped-free beam with a
    tip mass mu rho A L (no rotary inertia; e.g. Blevins, Formulas for natural frequency and mode
    shape, table 8-8: beta_1 L = 1.2479 at mu = 1)."""
    from scipy.optimize import brentq

    def f(b):
        return 1 + np.cos(b) * np.cosh(b) + mu * b * (np.cos(b) * np.sinh(b) - np.sin(b) * np.cosh(b))

    grid = np.linspace(0.1, 15.0, 3000)
    v = f(grid)
    return np.array([brentq(f, grid[i], grid[i + 1]) for i in np.flatnonzero(v[:-1] * v[1:] < 0)][:count])


@pytest.mark.parametrize("model", ["classic", "coupled", "nonlinear"])
def test_cantilever_with_a_tip_mass(model):
    mu = 1.0
    roots = _tip_mass_roots(mu)
    assert roots[0] == pytest.approx(1.2479, abs=1e-4)
    exact = (roots / L) ** 2 * np.sqrt(E * I / (RHO * A))
    case = fm.validate_case({
        "mechanism": {"type": "serial"},
        "links": [{"name": "beam", "length": L, "area": A, "second_moment": I, "youngs_modulus": E,
                   "density": RHO, "elements": 8}],
        "drive": {"type": "kinematic", "law": "constant_speed", "speed": 0.0},
        "point_masses": [{"at": "beam.end", "mass": mu * RHO * A * L}],
        "solver": {"t_end": 0.01, "dt": 1e-4},
        "outputs": {"tip": {"kind": "displacement", "at": "beam.end", "component": "transverse"}}})
    err = np.abs(modes(case, count=3, model=model).omega / exact - 1)
    print(f"\ntip mass ({model}) errors at 8 el: {err}")
    assert err[0] < 1e-6 and err[1] < 1e-4 and err[2] < 1e-3


@pytest.mark.parametrize("model", ["classic", "coupled", "nonlinear"])
def test_four_bar_rings_at_its_natural_frequencies(model):
    """The seed four-bar held at rest (crank speed 0) under gravity applied at t = 0 rings about its
    static deflection: the peaks of the spectrum of the coupler and follower midspan strains sit on
    frequencies of modes() (within the period elongation of the average-acceleration rule,
    (omega dt)^2 / 12 <= 5e-4 here)."""
    case = fm.load_case("fourbar_constant_speed", overrides=[
        "drive.speed=0.0", "loads.gravity=[0.0,-9.81]", "solver.t_end=1.0", "solver.dt=2e-4", "solver.output_every=1"])
    res = fm.simulate(case, model=model)
    hz = modes(case, count=4, model=model).hz
    found = set()
    for key in ("strain_coupler_mid", "strain_follower_mid"):
        y = res[key] - res[key].mean()
        pad = 64 * y.size
        spec = np.abs(np.fft.rfft(y * np.hanning(y.size), pad))
        f = np.fft.rfftfreq(pad, res.t[1] - res.t[0])
        peak = f[1 + np.argmax(spec[1:])]
        nearest = int(np.argmin(np.abs(hz - peak)))
        print(f"\n{model} {key}: spectrum peak {peak:.3f} Hz, mode {nearest + 1} at {hz[nearest]:.3f} Hz")
        assert peak == pytest.approx(hz[nearest], rel=1e-3)
        found.add(nearest)
    assert found <= {0, 1, 2}


def test_spinning_cantilever_stiffens_by_the_southwell_coefficient():
    """Superposition model with the quasi-static axial forces (K_sigma) frozen on a cantilever spinning
    at Omega about its clamped end: w^2 = w0^2 + S Omega^2, S = 1.1933 for the first mode (Southwell;
    the frozen analysis holds the rigid motion, so the transverse centrifugal (-Omega^2 M) and
    Coriolis terms are not in it)."""
    omega_spin = 20.0
    spin = {"type": "kinematic", "law": "constant_speed", "speed": omega_spin}
    w0 = modes(beam_case(n_el=8), count=1, model="classic").omega[0]
    w = modes(beam_case(n_el=8, drive=spin), count=1, model="classic", geometric="quasi_static").omega[0]
    w_none = modes(beam_case(n_el=8, drive=spin), count=1, model="classic", geometric="none").omega[0]
    s = (w ** 2 - w0 ** 2) / omega_spin ** 2
    print(f"\nSouthwell coefficient {s:.5f} (1.1933), without K_sigma {(w_none ** 2 - w0 ** 2) / omega_spin ** 2:.2e}")
    assert s == pytest.approx(1.1933, rel=3e-3)
    assert abs(w_none ** 2 - w0 ** 2) < 1e-3 * omega_spin ** 2      # no stiffening without K_sigma


def test_frequencies_are_those_the_stability_guards_use(cases_dir):
    """modes() at the samples of extreme.lowest_frequencies gives the same frequencies."""
    from flexmech_py.studies.extreme import lowest_frequencies
    from flexmech_py.run.simulate import Prepared

    case = fm.load_case(cases_dir / "fourbar_constant_speed.toml", overrides=["solver.t_end=0.02"])
    prep = Prepared(case)
    low = lowest_frequencies(prep, nmodes=2, samples=3)
    for k, i in enumerate(np.linspace(0, prep.nsteps, 3).round().astype(int)):
        ms = modes(case, at=float(prep.t[i]), count=2, model="hac")
        np.testing.assert_allclose(ms.omega, low[k], rtol=1e-9)


def test_along_the_cycle_is_periodic_and_finds_harmonic_crossings(cases_dir):
    case = fm.load_case(cases_dir / "fourbar_constant_speed.toml")
    al = frequencies_along(case, 24, count=3)
    assert al.xlabel == "crank angle [deg]" and al.hz.shape == (24, 3)
    assert np.all(np.diff(al.hz, axis=1) >= 0)                       # k-th lowest at each position
    first = modes(case, at=float(al.t[0]), count=3)
    np.testing.assert_allclose(al.omega[0], first.omega, rtol=1e-10)
    for c in al.crossings():                                          # f_i = k Omega / 2 pi there
        assert c["f_hz"] == pytest.approx(c["harmonic"] * 120.0 / (2 * np.pi), rel=1e-9)
    assert al.crossings()


def test_cli_modes_writes_its_files_and_refuses_bad_input(cases_dir, tmp_path, capsys):
    out = tmp_path / "m"
    assert main(["modes", str(cases_dir / "fourbar_constant_speed.toml"), "--crank-angle", "90",
                 "--along-cycle", "12", "--count", "3", "--out", str(out)]) == 0
    names = {p.name for p in out.iterdir()}
    assert {"modes.csv", "modes.json", "mode_shapes.csv", "frequencies_along.csv", "frequencies_along.json"} <= names
    js = json.loads((out / "modes.json").read_text())
    assert len(js["modes"]) == 3 and js["crank_angle_deg"] == pytest.approx(90.0, abs=1e-6)
    capsys.readouterr()
    bad = tmp_path / "bad"
    assert main(["modes", str(cases_dir / "fourbar_constant_speed.toml"), "--at", "5", "--out", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--at" in err and not bad.exists()
    assert main(["modes", str(cases_dir / "fourbar_constant_speed.toml"), "--at", "0", "--crank-angle", "10"]) == 2


def test_mode_shapes_file_reads_back(cases_dir, tmp_path):
    from flexmech_py.models.shapes import read_shape_csv

    ms = modes(fm.load_case(cases_dir / "sixbar_plate.toml"), count=3, elements_per_link=4)
    ms.write(tmp_path)
    sf, key, _ = read_shape_csv(tmp_path / "mode_shapes.csv")
    assert key == "f_hz"
    np.testing.assert_allclose(sf.key, ms.hz, rtol=1e-9)
    np.testing.assert_allclose(sf.d, ms.shapes.d, rtol=1e-6, atol=1e-9 * np.max(np.abs(ms.shapes.d)))  # 7 digits
    np.testing.assert_allclose(sf.x, ms.shapes.x, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("name", fm.case_names())
def test_every_case_file_has_modes_in_every_model(name):
    """Every bundled mechanism, every model family, at t = 0: finite frequencies, elastic ones
    positive unless the case is built past buckling (extreme/flexible_fourbar: the superposition
    models report negative omega there, the coupled model finds no equilibrium and says so, the
    nonlinear model finds its post-buckled one, about which the frequencies are positive)."""
    case = fm.load_case(name)
    for model in ("classic", "coupled", "nonlinear"):
        if name == "extreme/flexible_fourbar" and model == "coupled":
            with pytest.raises(fm.SolverError, match="past buckling"):
                modes(case, count=2, model=model)
            continue
        ms = modes(case, count=2, model=model)
        elastic = ms.omega[~ms.rigid]
        assert elastic.size == 2 and np.all(np.isfinite(ms.omega))
        assert np.all(elastic > 0) or name == "extreme/flexible_fourbar"


def test_run_draw_keeps_frames_and_draw_redraws_them(cases_dir, tmp_path, capsys):
    """`run --draw N` keeps the points of N frames spread over the run, streamed block by block; their
    displacements are the run's own (the coupler's midpoint against the displacement output)."""
    from flexmech_py.models.shapes import read_shape_csv

    out = tmp_path / "r"
    assert main(["run", str(cases_dir / "fourbar_hac.toml"), "--set", "solver.t_end=0.05", "--draw", "5",
                 "--out", str(out), "--quiet"]) == 0
    sf, key, _ = read_shape_csv(out / "shape.csv")
    assert key == "t" and sf.key.size == 5
    np.testing.assert_allclose(sf.key, np.linspace(0.0, 0.05, 5), atol=1e-12)
    summary = json.loads((out / "summary.json").read_text())
    assert "shape.csv" in summary["files"] and "drawing.png" in summary["files"]
    res = fm.simulate(fm.load_case(cases_dir / "fourbar_hac.toml", overrides=["solver.t_end=0.05"]))
    coupler = next(b for b in sf.bodies if b.name == "coupler")
    mid = coupler.sl.start + coupler.labels.index("0.5")
    ux = np.interp(sf.key, res.t, res.u[res.fe.trans_dof[res.fe.node_of[1][1]][0]])
    np.testing.assert_allclose(sf.d[:, mid, 0], ux, rtol=1e-6, atol=1e-12)
    capsys.readouterr()
    assert main(["draw", str(out), "--frames", "3", "--out", str(tmp_path / "three.png")]) == 0
    assert (tmp_path / "three.png").stat().st_size > 10_000
    assert main(["draw", str(out), "--gif"]) == 0
    from PIL import Image

    with Image.open(out / "drawing.gif") as gif:            # every kept frame, one GIF frame each
        assert gif.n_frames == 5 and gif.size[0] > 300
    assert main(["draw", str(tmp_path)]) == 2 and "no shape.csv" in capsys.readouterr().err


WATT = Path(__file__).parent / "data" / "watt_sixbar_spinup.toml"


@pytest.mark.parametrize("t", [0.09, 0.099, 0.2, 0.25, 0.3])
def test_modes_at_any_instant_of_a_spin_up_run(t):
    """A Watt six-bar whose crank is spun up from rest (issue 24): the configuration at any instant the run
    passes through is found when asked for alone (the kinematic substeps follow the drive law from rest),
    and it is the run's own: the rigid motion sampled at t alone equals the one sampled along the run."""
    from flexmech_py.run.simulate import motion_source

    case = fm.load_case(WATT)
    ms = modes(case, at=t, count=2)
    assert ms.t == t and np.all(ms.omega > 0) and not ms.rigid.any()
    grid = np.linspace(0.0, t, int(round(t / 1e-4)) + 1)
    along, alone = motion_source(case)(grid), motion_source(case)(np.array([t]))
    np.testing.assert_allclose(alone.z[0], along.z[-1], atol=1e-9)
    np.testing.assert_allclose(alone.zd[0], along.zd[-1], rtol=1e-9, atol=1e-9)


def test_crank_angle_on_a_whole_turn_is_0_deg_not_360():
    """A crank drawn a hair below the x axis: the loop closure leaves its angle at -1e-11 rad, which is
    0 deg on the turn (the table said 'crank_pivot at 360 deg')."""
    from flexmech_py.studies.modes import turn_angle

    case = fm.load_case(WATT, overrides=["links.crank.end=[0.08, -1e-12]"])
    ms = modes(case, count=1)
    assert ms.crank_angle == 0.0 and "crank_pivot at 0 deg" in ms.table()
    assert turn_angle(-5e-11) == 0.0 and turn_angle(360.0 - 1e-12) == 0.0 and turn_angle(720.0) == 0.0
    assert turn_angle(-90.0) == 270.0 and turn_angle(359.5) == 359.5 and turn_angle(1e-6) == 1e-6
    steady = fm.load_case(WATT, overrides=["links.crank.end=[0.08, -1e-12]", "drives.0.law=constant_speed",
                                           "drives.0.speed=60.0", "drives.0.final_speed=", "drives.0.spinup_time="])
    al = frequencies_along(steady, 4, count=1)
    assert al.x[0] == pytest.approx(0.0, abs=1e-6) and al.x[-1] == pytest.approx(270.0, abs=1e-6)


@pytest.mark.parametrize("model", ["coupled", "nonlinear"])
def test_coupled_modes_hold_a_clamped_torque_driven_joint(model):
    """The seed four-bar's crank is torque-driven with the elastic condition clamp: the frozen coupled
    models hold it as the superposition models do (no rigid-body mode; it was -2.86 Hz) and their first
    frequencies at rest agree with classic's (43.42, 48.93 Hz at 2 elements per link)."""
    case = fm.load_case("fourbar_hac")
    ref = modes(case, count=2, model="classic").hz
    ms = modes(case, count=2, model=model)
    assert not ms.rigid.any()
    np.testing.assert_allclose(ms.hz, ref, rtol=0.03)


@pytest.mark.parametrize("model", ["classic", "coupled", "nonlinear"])
def test_a_free_torque_joint_is_a_rigid_mode_at_zero_frequency(model, tmp_path):
    """With the crank left free (torque), the mechanism's own degree of freedom is one rigid-body mode
    reported at frequency 0 exactly and kind 'rigid', in every model, also at speed (t = 0.1 s: it was
    +16.5 Hz in the coupled models, -0.69 Hz in the superposition ones); the elastic modes are those
    M-orthogonal to it, and agree across the model families where their physics agrees (the coupled model
    and classic: no axial-force stiffness in either)."""
    case = fm.load_case("fourbar_hac", overrides=["joints.crank_pivot=torque"])
    ms = modes(case, at=0.1, count=2, model=model)
    assert ms.rigid.sum() == 1 and ms.omega[ms.rigid][0] == 0.0 and ms.hz[0] == 0.0
    js = ms.summary()
    assert [m["kind"] for m in js["modes"]] == ["rigid", "elastic", "elastic"]
    elastic = ms.hz[~ms.rigid]
    if model == "coupled":
        np.testing.assert_allclose(elastic, modes(case, at=0.1, count=2, model="classic").hz[1:], rtol=0.01)
    assert np.all(elastic > 30.0)
    ms.write(tmp_path)
    assert ",rigid," in (tmp_path / "modes.csv").read_text()
