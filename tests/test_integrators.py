"""Time integrators (issue 5, section 1) and the divergence guard, through the real Fortran loops.

The generalized-alpha family in the Arnold-Bruls form (docs/theory.md section 15) runs inside
both time loops: flexmech_newmark (superposition models) and flexmech_coupled_run (coupled and
nonlinear models).  Checked here:

(a) the amplification matrix of a single-DOF oscillator, measured from one-step runs of each loop,
    against an independent NumPy implementation of the recurrence and, for its spectral radius,
    against Chung & Hulbert's (1993) original formulation; rho(Omega -> inf) = rho_inf;
(b) observed order 2 in dt on a spinning-up beam, superposition, coupled and nonlinear models;
(c) energy: average acceleration conserves it, generalized-alpha dissipates, slightly at low Omega;
(d) status 6 (divergence) with the time of the step that crossed the limit, and the valid frames.

Run `pytest -s tests/test_integrators.py` to see the measured numbers (docs/theory.md section 15).
"""

import numpy as np
import pytest

import flexmech_py as fm
from flexmech_py.case import integrator_coefficients
from flexmech_py.cli import main
from flexmech_py.models.constrained.coupled import CoupledModel
from flexmech_py.base.errors import CaseError, SolverError
from flexmech_py.mechanism.control import ControlPack
from flexmech_py.base import kernels
from flexmech_py.base.kernels import api, check_status
from flexmech_py.run.simulate import Prepared

from conftest import beam_case

INTEGRATORS = [("newmark", {}), ("hht", {"hht_alpha": 0.05}), ("hht", {"hht_alpha": 0.2}),
               ("hht", {"hht_alpha": 1 / 3}), ("generalized-alpha", {"rho_inf": 0.0}),
               ("generalized-alpha", {"rho_inf": 0.5}), ("generalized-alpha", {"rho_inf": 0.8}),
               ("generalized-alpha", {"rho_inf": 1.0})]
IDS = [f"{n}-{next(iter(p.values()))}" if p else n for n, p in INTEGRATORS]


def rho_inf_of(name, params):
    if name == "newmark":
        return 1.0
    if name == "hht":
        a = params["hht_alpha"]
        return (1 - a) / (1 + a)
    return params["rho_inf"]


# ----------------------------------------------------------------------------- independent references
def arnold_bruls_matrix(om, am, af, beta, gamma):
    """Amplification of (u, h v, h^2 p) for u'' + w^2 u = 0 by the recurrence of Arnold & Bruls:
    u1 = u + h v + h^2 ((1/2 - beta) p + beta p1), v1 = v + h ((1 - gamma) p + gamma p1),
    (1 - am) p1 + am p = (1 - af) a1 + af a, a = -w^2 u exactly at every step."""
    out = np.zeros((3, 3))
    lhs = np.array([[1, 0, -beta, 0], [0, 1, -gamma, 0], [0, 0, 1 - am, -(1 - af)], [om**2, 0, 0, 1]])
    for j in range(3):
        u, v, p = np.eye(3)[j]
        rhs = [u + v + (0.5 - beta) * p, v + (1 - gamma) * p, -am * p - af * om**2 * u, 0.0]
        out[:, j] = np.linalg.solve(lhs, rhs)[:3]
    return out


def chung_hulbert_matrix(om, am, af, beta, gamma):
    """Chung & Hulbert (J. Appl. Mech. 60, 1993) on (d, h v, h^2 a): the equation of motion at the
    weighted times, (1 - am) a1 + am a + w^2 ((1 - af) d1 + af d) = 0, Newmark updates on a."""
    out = np.zeros((3, 3))
    lhs = np.array([[1, 0, -beta], [0, 1, -gamma], [om**2 * (1 - af), 0, 1 - am]])
    for j in range(3):
        d, v, a = np.eye(3)[j]
        rhs = [d + v + (0.5 - beta) * a, v + (1 - gamma) * a, -am * a - om**2 * af * d]
        out[:, j] = np.linalg.solve(lhs, rhs)
    return out


def spectral_radius(a):
    return float(np.max(np.abs(np.linalg.eigvals(a))))


# ----------------------------------------------------------------------------- single-DOF oscillators
# superposition loop: one bar element along X at rest, only the axial DOF u2 free: m u'' + k u = 0,
# m = rho A L / 3 (consistent mass), k = EA / L
KED_SDOF = (np.array([0, 0, 0, 1, 0, 0], np.int32), np.array([1], np.int32),
            np.asfortranarray(np.arange(1, 7, dtype=np.int32).reshape(6, 1)),
            np.asfortranarray([[1.0], [0.0], [3.0], [1.0], [1.0]]),            # L = 1, rho A = 3, EA = 1
            np.array([1], np.int32), np.asfortranarray([[1], [2]], np.int32), np.zeros((2, 1), order="F"),
            np.array([1], np.int32), np.array([3], np.int32), np.zeros(1),
            np.zeros(6, np.int32), np.ones(1, np.int32), np.ones(1, np.int32))   # no slave relations
KED_OMEGA = 1.0                                                                # sqrt(k / m)

# coupled loop: one segment, one element, fixed chord (ends and th_1 fixed): only th_0 free,
# m th'' + k th = 0 with m = rho A L^3 / 105, k = 4 EI / L (flat description: flexmech_coupled_system, coupled_build); absang = arch = 0, nbd = -1 (no bordered band)
CPL_SDOF = (np.array([1, 0, 6, 1] + [0] * 8 + [1] + list(range(1, 7)) + [0, 0, 0, 0, 1, 0] + [0, 0] + [-1], np.int32),
            np.array([1.0, 105.0, 1e3, 0.25, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0]))   # L, rho A, EA, EI; node fractions
CPL_OMEGA = 1.0
CPL_Q0 = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0])


def ked_steps(h, coef, u, v, p, nsteps=1):
    """nsteps of the superposition loop from (u, v, p), a consistent; returns frames and final state."""
    rig = np.zeros((5, 1, nsteps + 1), order="F")
    u0, v0, p0 = np.array([u], float), np.array([v], float), np.array([p], float)
    a0 = -KED_OMEGA**2 * u0
    uf, vf, af, _, status, _, _, nvalid = api.ked_run(
        *KED_SDOF, 1, np.zeros(2), rig, np.zeros((3, 1, nsteps + 1), order="F"), np.ones(1, np.int32),
        np.zeros((1, nsteps + 1), order="F"),
        h, *coef, 1, 0, 0, 1e-8, 50, 1e300, u0, v0, a0, p0)
    check_status(status, "ked_run")
    assert nvalid == nsteps + 1
    return uf[0], vf[0], (u0[0], v0[0], a0[0], p0[0])


def cpl_steps(h, coef, u, v, p, nsteps=1):
    """The same with the coupled loop (th_0 of the fixed-chord link is the oscillator)."""
    q, vv, a, pp = CPL_Q0.copy(), np.zeros(6), np.zeros(6), np.zeros(6)
    q[4], vv[4], pp[4] = u, v, p
    zeros3 = np.zeros((3, 1, nsteps + 1), order="F")
    ctl = ControlPack([], [], set(), h, {})      # no controller (a padding one with drive 0)
    qf, vf, af, lf, _, ef, _, status, _, _, nvalid, _ = kernels.cpl.cpl_run(
        *CPL_SDOF, zeros3, 0.0, h, *coef, 1, 1e-14, 25, 0, 1e300, np.array([1], np.int32), q, vv, a, pp,
        np.zeros(3), ctl.cint, ctl.cpar, ctl.ctab_t, ctl.ctab_c, ctl.cst)
    check_status(status, "cpl_run")
    assert nvalid == nsteps + 1
    return qf[4], vf[4], (q[4], vv[4], a[4], pp[4])


def measured_matrix(loop, om, coef):
    """Amplification matrix on (u, h v, h^2 p) from three one-step runs of a compiled loop."""
    h = om / (KED_OMEGA if loop is ked_steps else CPL_OMEGA)
    out = np.zeros((3, 3))
    for j in range(3):
        x = np.eye(3)[j]
        _, _, (u, v, _, p) = loop(h, coef, x[0], x[1] / h, x[2] / h**2)
        out[:, j] = [u, h * v, h * h * p]
    return out


def test_sdof_oscillators_are_what_they_claim():
    """The coupled-loop oscillator: its mass and stiffness from the kernel are rho A L^3/105 and 4 EI/L."""
    res, mm, cm, km, energy, status = kernels.cpl.cpl_dense(1, *CPL_SDOF, CPL_Q0, np.zeros(6), np.zeros(6), 0.0)
    check_status(status, "cpl_dense")
    assert mm[0, 0] == pytest.approx(1.0, rel=1e-12) and km[0, 0] == pytest.approx(1.0, rel=1e-12)
    assert cm[0, 0] == 0.0


# ----------------------------------------------------------------------------- (a) spectral radius
OMEGAS = np.logspace(-2, 4, 13)


@pytest.mark.parametrize("loop", [ked_steps, cpl_steps], ids=["superposition", "coupled"])
@pytest.mark.parametrize("name, params", INTEGRATORS, ids=IDS)
def test_amplification_matrix(loop, name, params):
    coef = integrator_coefficients(name, params)
    radii = []
    for om in OMEGAS:
        got = measured_matrix(loop, om, coef)
        ab = arnold_bruls_matrix(om, *coef)
        assert np.allclose(got, ab, rtol=1e-8, atol=1e-7), (om, got, ab)
        r = spectral_radius(got)
        # Arnold-Bruls' scheme has Chung-Hulbert's spectral radius on linear systems
        assert r == pytest.approx(spectral_radius(chung_hulbert_matrix(om, *coef)), abs=1e-8)
        radii.append(r)
    radii = np.array(radii)
    rinf = rho_inf_of(name, params)
    assert np.all(radii <= 1.0 + 1e-7)                     # unconditionally stable (round-off of a double root)
    assert np.all(np.diff(radii) <= 1e-7)                  # dissipation grows with Omega
    assert radii[0] > 1 - 1e-4                             # Omega = 0.01: no dissipation of resolved modes
    # Omega -> infinity: the radius approaches rho_inf as Omega^(-2/3) (a triple root at infinity)
    r_big = spectral_radius(measured_matrix(loop, 1e6, coef))
    assert r_big == pytest.approx(rinf, abs=2e-4)
    print(f"\n{loop.__name__} {name} {params}: rho at Omega = 0.1, 1, 10, 1e4, 1e6: "
          + ", ".join(f"{x:.6f}" for x in (radii[2], radii[4], radii[6], radii[-1], r_big)))


# ----------------------------------------------------------------------------- (b) order in dt
ORDER_INTEGRATORS = [("newmark", {}), ("hht", {"hht_alpha": 0.1}), ("hht", {"hht_alpha": 1 / 3}),
                     ("generalized-alpha", {"rho_inf": 0.8}), ("generalized-alpha", {"rho_inf": 0.0})]


@pytest.mark.parametrize("model", ["classic", "coupled", "nonlinear"])
@pytest.mark.parametrize("name, params", ORDER_INTEGRATORS,
                         ids=[f"{n}-{next(iter(p.values()))}" if p else n for n, p in ORDER_INTEGRATORS])
def test_second_order_in_dt(model, name, params):
    """Tip deflection of a cantilever spun up smoothly (time-varying matrices; the coupled and
    nonlinear models also hold the drive as a Lagrange-multiplier constraint)."""
    drive = {"type": "kinematic", "law": "spinup", "final_speed": 6.0, "spinup_time": 0.4}
    case = beam_case(n_el=4, drive=drive, t_end=0.3, dt=1e-3, integrator=name, **params)
    ys = [fm.simulate(case, model=model, dt=dt, out_every=int(round(2e-3 / dt)))["tip_v"]
          for dt in (2e-3, 1e-3, 5e-4, 2.5e-4)]
    d = [np.max(np.abs(ys[i] - ys[i + 1])) for i in range(3)]
    orders = np.log2(np.array(d[:-1]) / np.array(d[1:]))
    print(f"\n{model} {name} {params}: successive differences {', '.join(f'{x:.3g}' for x in d)}, "
          f"orders {', '.join(f'{o:.3f}' for o in orders)}")
    assert np.all((orders > 1.9) & (orders < 2.1)), orders
    assert d[-1] < 5e-4 * np.max(np.abs(ys[-1]))          # measured 3e-5 (newmark) to 1.6e-4 (rho_inf = 0)


# ----------------------------------------------------------------------------- (c) energy
def _sdof_energy(loop, om, coef, periods=20):
    h = om / KED_OMEGA
    nsteps = int(round(periods * 2 * np.pi / om))
    uf, vf, _ = loop(h, coef, 1.0, 0.0, -1.0, nsteps=nsteps)   # fresh start: p0 = a0 = -u0
    return 0.5 * vf**2 + 0.5 * uf**2, int(round(2 * np.pi / om))


@pytest.mark.parametrize("loop", [ked_steps, cpl_steps], ids=["superposition", "coupled"])
def test_energy_of_linear_oscillator(loop):
    """Average acceleration conserves the energy of a linear oscillator exactly; generalized-alpha
    dissipates it period after period at the rate its spectral radius predicts, and only
    slightly at low Omega."""
    e, _ = _sdof_energy(loop, 1.0, integrator_coefficients("newmark"))
    assert np.max(np.abs(e - e[0])) < 1e-13
    for rho in (0.0, 0.5, 0.8):
        coef = integrator_coefficients("generalized-alpha", {"rho_inf": rho})
        for om in (0.3, 1.0):
            e, per = _sdof_energy(loop, om, coef)
            peaks = np.array([e[i:i + per].max() for i in range(per, e.size - per + 1, per)])
            assert np.all(np.diff(peaks) < 0), (rho, om)                          # monotone decay per period
            rate = np.log(peaks[-1] / peaks[0]) / (per * (peaks.size - 1))       # per step
            expected = 2 * np.log(spectral_radius(arnold_bruls_matrix(om, *coef)))
            assert rate == pytest.approx(expected, rel=0.02), (rho, om)
        e, per = _sdof_energy(loop, 0.05, coef, periods=5)
        loss = 1 - e[-1] / e[0]
        print(f"\n{loop.__name__} rho_inf {rho}: energy lost over 5 periods at Omega = 0.05: {loss:.3g}")
        assert 0 < loss < 1e-2 * (1 - rho) + 1e-5


def _pendulum(name, params, dt):
    links = [{"name": f"l{k}", "length": 0.5, "area": 1e-4, "second_moment": 2e-10, "youngs_modulus": 7e10,
              "density": 2700.0, "elements": 2} for k in (1, 2)]
    return fm.validate_case({
        "mechanism": {"type": "serial"}, "links": links, "joints": {"base": "pin", "joint_2": "pin"},
        "drive": {"type": "torque", "torques": [{"joint": "base", "constant": 0.0}]},
        "initial": {"angles": [0.3, 0.8]}, "loads": {"gravity": [0.0, -9.81]},
        "solver": {"t_end": 0.3, "dt": dt, "output_every": int(round(2e-3 / dt)), "integrator": name, **params},
        "outputs": {"a": {"kind": "joint_angle", "joint": "base"}}})


@pytest.mark.parametrize("model", ["coupled", "nonlinear"])
def test_free_pendulum_energy(model):
    """Flexible double pendulum under gravity: average acceleration keeps the energy to 1e-6 of the
    peak kinetic energy; generalized-alpha with rho_inf = 0 loses more, but only slightly (the
    swing is at low Omega)."""
    drift = {}
    for name, params in [("newmark", {}), ("generalized-alpha", {"rho_inf": 0.8}),
                         ("generalized-alpha", {"rho_inf": 0.0})]:
        res = fm.simulate(_pendulum(name, params, 1e-4), model=model)
        e = res["energy_kinetic"] + res["energy_potential"]
        kmax = np.max(res["energy_kinetic"])
        assert kmax > 0.1
        drift[(name, params.get("rho_inf"))] = (e[-1] - e[0]) / kmax
        assert np.max(np.abs(e - e[0])) < 1e-6 * kmax
    print(f"\n{model} pendulum, relative energy change over 0.3 s at dt = 1e-4 s: {drift}")
    assert drift[("generalized-alpha", 0.0)] < 5 * drift[("newmark", None)] < 0


# ----------------------------------------------------------------------------- continuation
@pytest.mark.parametrize("name, params", [("hht", {"hht_alpha": 0.2}), ("generalized-alpha", {"rho_inf": 0.5})])
@pytest.mark.parametrize("case_name", ["fourbar_hac", "manipulator_bricout"])
def test_superposition_run_continues_in_chunks(cases_dir, case_name, name, params):
    """The state (u, v, a, p) returned by one chunk continues the run exactly."""
    case = fm.load_case(cases_dir / f"{case_name}.toml", overrides=["solver.t_end=0.01", "solver.output_every=1"])
    p = Prepared(case)
    coef = dict(zip(("alpha_m", "alpha_f", "beta", "gamma"), integrator_coefficients(name, params)))
    half = p.nsteps // 2

    def loads(steps):
        return {} if p.q_free is None else {"q_free": p.q_free, "q_val": np.asfortranarray(p.q_val[:, steps])}

    whole = p.fe.run(p.rig, "hac", p.dt, **loads(slice(None)), **coef)[0]
    first = p.fe.run(p.rig[:, :, :half + 1], "hac", p.dt, **loads(slice(0, half + 1)), **coef)[0]
    st = p.fe.last_run
    second = p.fe.run(p.rig[:, :, half:], "hac", p.dt, **loads(slice(half, None)), u0=st["u"],
                      v0=st["v"], a0=st["a"], p0=st["p"], t0=half * p.dt, **coef)[0]
    assert not np.allclose(st["a"], st["p"])          # the pseudo-acceleration is a state of its own
    assert np.array_equal(np.hstack([first, second[:, 1:]]), whole)


def test_coupled_run_continues_in_chunks(cases_dir):
    case = fm.load_case(cases_dir / "fourbar_hac.toml", overrides=["solver.t_end=0.01", "solver.output_every=1"])
    p = Prepared(case)
    cm = CoupledModel.from_case(case)
    coef = dict(zip(("alpha_m", "alpha_f", "beta", "gamma"),
                    integrator_coefficients("generalized-alpha", {"rho_inf": 0.5})))
    q0, v0 = cm.initial_state(p.rm.select(slice(0, 1)))
    cval = cm.constraint_values(p.rm)
    whole = cm.run(q0, v0, p.t, cval, p.dt, tol=1e-12, **coef)[0]
    half = p.nsteps // 2
    cm.run(q0, v0, p.t[:half + 1], np.asfortranarray(cval[:, :, :half + 1]), p.dt, tol=1e-12, **coef)
    st = cm.last_run
    second = cm.run(None, None, p.t[half:], np.asfortranarray(cval[:, :, half:]), p.dt, tol=1e-12,
                    state=st, **coef)[0]
    free = cm.free_of > 0
    scale = np.max(np.abs(whole[free]))
    # the same steps: only the step times t0 + n dt round differently from n dt
    assert np.max(np.abs(second[free] - whole[free][:, half:])) < 1e-13 * scale


# ----------------------------------------------------------------------------- (d) divergence
def test_lagged_geometric_stiffness_diverges_with_status_6(cases_dir):
    """The lagged axial forces make the seed four-bar unstable: the run stops with status 6 at the
    step where a translation exceeds the limit (the longest link, 0.2794 m); the frames before it
    are those of a shorter run."""
    case = fm.load_case(cases_dir / "fourbar_hac.toml",
                        overrides=["solver.t_end=0.16", "solver.geometric_stiffness='lagged'"])
    p = Prepared(case, chunk_steps=10**9)   # one chunk: fe.last_run is the whole run
    with pytest.raises(SolverError) as err:
        p.run()
    assert err.value.code == 6 and "divergence_limit" in str(err.value)
    lr = p.fe.last_run
    # run in chunks (as by default), the failure and the kept frames are the same
    with pytest.raises(SolverError) as err_chunked:
        Prepared(case, chunk_steps=3000).run(diagnose=False)
    assert err_chunked.value.step == err.value.step and err_chunked.value.time == pytest.approx(err.value.time)
    np.testing.assert_array_equal(err_chunked.value.partial.u, err.value.partial.u)
    t_fail = lr["fail_step"] * p.dt
    assert err.value.time == pytest.approx(t_fail)
    assert f"t = {t_fail:.6g} s" in str(err.value)
    print(f"\nlagged geometric stiffness: diverged at t = {t_fail:.5f} s, {lr['frames_valid']} valid frames")
    assert 0.1 < t_fail < 0.16
    assert lr["frames_valid"] == (lr["fail_step"] - 1) // p.out_every + 1
    trans = p.fe.restrict(np.isin(np.arange(p.fe.ndof), p.fe.trans_dof.ravel()).astype(float)) > 0
    assert np.max(np.abs(lr["u"][trans])) > 0.2794 >= np.max(np.abs(lr["uf"][trans, :lr["frames_valid"]]))
    short = fm.load_case(cases_dir / "fourbar_hac.toml",
                         overrides=["solver.t_end=0.05", "solver.geometric_stiffness='lagged'"])
    ok = Prepared(short).run()      # the same steps; the rigid ODE solution differs at its tolerance
    n = ok.t.size
    assert np.allclose(lr["uf"][:, :n], p.fe.restrict(ok.u), rtol=0, atol=1e-6 * np.max(np.abs(ok.u)))


def _first_crossing(measure, limit):
    return int(np.flatnonzero(measure > limit)[0])


def test_divergence_limit_superposition_matches_the_free_translations(cases_dir):
    base = ["solver.t_end=0.02", "solver.output_every=1"]
    case = fm.load_case(cases_dir / "fourbar_hac.toml", overrides=base)
    free = Prepared(case).run()
    tr = free.u[np.sort(free.fe.trans_dof.ravel())]
    measure = np.max(np.abs(tr), axis=0)
    limit = float(0.5 * measure.max())
    k = _first_crossing(measure, limit)
    bad = fm.load_case(cases_dir / "fourbar_hac.toml", overrides=base + [f"solver.divergence_limit={limit!r}"])
    with pytest.raises(SolverError) as err:
        Prepared(bad).run()
    assert err.value.code == 6 and err.value.time == pytest.approx(free.t[k])


@pytest.mark.parametrize("model", ["coupled", "nonlinear"])
def test_divergence_limit_coupled_matches_the_chord_measure(cases_dir, model):
    """Coupled loop: the measure is the largest node offset from the straight link chord (with the
    interior chord-frame translations) or change of chord length; computed here from the frames."""
    base = ["solver.t_end=0.02", "solver.output_every=1", f"solver.model='{model}'", "solver.error_estimate='none'"]
    case = fm.load_case(cases_dir / "fourbar_hac.toml", overrides=base)
    p = Prepared(case, chunk_steps=10**9)    # one chunk: last_run holds the whole run
    p.run()
    cm = p.coupled[model]
    qf = cm.last_run["qf"]
    measure = np.zeros(qf.shape[1])
    for li, ln in enumerate(case["links"]):
        segs = [si for si, sg in enumerate(cm.segments) if sg[0] == li]
        r0, r1 = qf[cm.seg_slice(segs[0])[0:2]], qf[cm.seg_slice(segs[-1])[2:4]]
        c = r1 - r0
        measure = np.maximum(measure, np.abs(np.hypot(*c) - ln["length"]))
        for si in segs:
            _, k0, k1 = cm.segments[si]
            d, n = cm.seg_slice(si), int(cm.n_el[si])
            for kk, w in ((0, k0 / ln["elements"]), (2, k1 / ln["elements"])):
                measure = np.maximum(measure, np.hypot(*(qf[d[kk:kk + 2]] - (r0 + w * c))))
            for k in range(1, n):
                measure = np.maximum(measure, np.hypot(qf[d[3 * k + 2]], qf[d[3 * k + 3]]))
    assert measure.max() > 0
    limit = float(0.5 * measure.max())
    k = _first_crossing(measure, limit)
    bad = fm.load_case(cases_dir / "fourbar_hac.toml", overrides=base + [f"solver.divergence_limit={limit!r}"])
    pb = Prepared(bad)
    with pytest.raises(SolverError) as err:
        pb.run()
    assert err.value.code == 6 and err.value.time == pytest.approx(p.t[k])
    assert err.value.partial.t.size == k       # the frames before the failed step, over the run's chunks


# ----------------------------------------------------------------------------- case keys and CLI
def test_integrator_coefficients():
    assert integrator_coefficients("newmark") == (0.0, 0.0, 0.25, 0.5)
    assert integrator_coefficients("hht", {"hht_alpha": 0.0}) == (0.0, 0.0, 0.25, 0.5)
    assert integrator_coefficients("generalized-alpha", {"rho_inf": 1.0}) == (0.5, 0.5, 0.25, 0.5)
    am, af, beta, gamma = integrator_coefficients("generalized-alpha", {"rho_inf": 0.5})
    assert (am, af) == pytest.approx((0.0, 1 / 3)) and (beta, gamma) == pytest.approx(
        integrator_coefficients("hht", {"hht_alpha": 1 / 3})[2:])      # rho_inf = 1/2 is HHT with alpha = 1/3
    assert integrator_coefficients("hht")[1] == 0.05 and integrator_coefficients("generalized-alpha")[1] == pytest.approx(0.8 / 1.8)


@pytest.mark.parametrize("solver, field, words", [
    ({"integrator": "hht", "beta": 0.3}, "solver.beta", "applies to integrator = 'newmark'"),
    ({"integrator": "generalized-alpha", "gamma": 0.6}, "solver.gamma", "applies to integrator = 'newmark'"),
    ({"integrator": "generalized-alpha", "hht_alpha": 0.1}, "solver.hht_alpha", "applies to integrator = 'hht'"),
    ({"rho_inf": 0.5, "beta": 0.3}, "solver.rho_inf", "set solver.integrator = 'generalized-alpha'"),
    ({"integrator": "hht", "hht_alpha": 0.5}, "solver.hht_alpha", "[0, 1/3]"),
    ({"integrator": "hht", "hht_alpha": -0.1}, "solver.hht_alpha", "[0, 1/3]"),
    ({"integrator": "generalized-alpha", "rho_inf": 1.2}, "solver.rho_inf", "[0, 1]"),
    ({"integrator": "rk4"}, "solver.integrator", "must be one of"),
    ({"divergence_limit": 0.0}, "solver.divergence_limit", "> 0"),
])
def test_integrator_case_errors(solver, field, words):
    with pytest.raises(CaseError) as err:
        beam_case(**solver)
    assert err.value.field == field and words in str(err.value)


def test_resolved_solver_and_summary():
    case = beam_case(length=0.7)
    assert "integrator" not in case["solver"] and case["solver"]["divergence_limit"] == 0.7   # the family's default
    assert "rho_inf" not in case["solver"] and "hht_alpha" not in case["solver"]
    assert beam_case(rho_inf=0.6)["solver"]["integrator"] == "generalized-alpha"   # a parameter names its integrator
    assert beam_case(gamma=0.6, beta=0.3025)["solver"]["integrator"] == "newmark"
    ga = beam_case(integrator="generalized-alpha")
    assert ga["solver"]["rho_inf"] == 0.8 and "beta" not in ga["solver"]
    assert fm.validate_case(_raw_from(ga))["solver"] == ga["solver"]   # a resolved case validates as itself
    s = fm.simulate(ga).summary()
    assert s["integrator"]["name"] == "generalized-alpha" and s["integrator"]["rho_inf"] == 0.8
    assert (s["integrator"]["am"], s["integrator"]["af"]) == pytest.approx((0.6 / 1.8, 0.8 / 1.8))


def _raw_from(case):
    """A resolved case's tables as a raw input (the general form it is written in)."""
    return {k: v for k, v in case.items() if k != "case"}


def test_cli_integrator_flags(cases_dir, tmp_path):
    import json

    out = tmp_path / "run"
    rc = main(["run", str(cases_dir / "fourbar_hac.toml"), "--set", "solver.t_end=0.002", "--rho-inf", "0.3",
               "--out", str(out), "--no-plots"])
    assert rc == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["integrator"]["name"] == "generalized-alpha" and s["integrator"]["rho_inf"] == 0.3
    assert s["input"]["solver"]["integrator"] == "generalized-alpha"
    rc = main(["run", str(cases_dir / "fourbar_hac.toml"), "--set", "solver.t_end=0.002", "--integrator", "hht",
               "--out", str(out), "--no-plots"])
    s = json.loads((out / "summary.json").read_text())
    assert rc == 0 and s["integrator"]["name"] == "hht" and s["integrator"]["af"] == 0.05
    assert main(["run", str(cases_dir / "fourbar_hac.toml"), "--integrator", "newmark", "--rho-inf", "0.5",
                 "--out", str(out)]) == 2
