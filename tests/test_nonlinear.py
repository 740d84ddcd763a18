"""The fully nonlinear (co-rotational) model: the large-deflection static cantilever against the
elastica, the small-load limit (= the coupled model), energy in free motion, and mesh convergence."""

import numpy as np
import pytest
from scipy.integrate import solve_bvp

from conftest import assert_free_pendulum_conserves_energy

import flexmech_py as fm
from flexmech_py.models.constrained.coupled import CoupledModel
from flexmech_py.models.constrained.outputs import node_state
from flexmech_py.run.simulate import simulate_models

# Mattiasson (1981), tip-loaded cantilever: (PL^2/EI, vertical tip deflection / L, shortening / L);
# the test computes the elastica itself (solve_bvp) and checks it against these published values first.
MATTIASSON = [(1.0, 0.30172, 0.05643), (5.0, 0.71379, 0.38763)]


def elastica_tip(k):
    """Tip (x, y)/L of the elastica theta'' = -k cos(theta), theta(0) = 0, theta'(1) = 0."""
    def f(s, y):
        return np.vstack([y[1], -k * np.cos(y[0]), np.cos(y[0]), np.sin(y[0])])

    def bc(ya, yb):
        return np.array([ya[0], yb[1], ya[2], ya[3]])

    s = np.linspace(0.0, 1.0, 201)
    y0 = np.zeros((4, s.size))
    y0[2] = s
    sol = solve_bvp(f, bc, s, y0, tol=1e-10, max_nodes=100000)
    assert sol.success
    return sol.y[2, -1], sol.y[3, -1]


def static_cantilever_tip(k, n):
    """Static tip position of a cantilever (clamped at the origin along +X) under a downward tip load
    P = k EI/L^2, nonlinear model with n elements: Newton on [R(q) - F + G^T lam; g(q)] = 0 with the
    compiled residual R and its static tangent K_t, the weld constraints g by finite differences."""
    L, E, I = 1.0, 2e11, 1e-9
    case = fm.validate_case({
        "mechanism": {"type": "serial"},
        "links": [{"name": "b", "length": L, "area": 1e-2, "second_moment": I, "youngs_modulus": E,
                   "density": 1.0, "elements": n}],
        "drive": {"type": "torque", "torques": [{"joint": "base", "constant": 0.0}]},
        "solver": {"t_end": 1.0, "dt": 1.0}, "outputs": {"a": {"kind": "joint_angle", "joint": "base"}}})
    cm = CoupledModel.from_case(case, split=True)
    q = cm.q_fixed.copy()
    for si, (_, k0, k1) in enumerate(cm.segments):
        d = cm.seg_slice(si)
        q[d[0]], q[d[2]] = k0 * L / n, k1 * L / n
    free = np.flatnonzero(cm.free_of > 0)
    free = free[np.argsort(cm.free_of[free])]
    tip = cm.seg_slice(n - 1)[2:4]
    zero = np.zeros(cm.ndof)

    def g(qq):   # base tangent welded to the ground; tangents continuous at interior nodes
        out = [node_state(cm, qq[:, None], 0, 0)[1][0]]
        for si in range(1, n):
            da, db = cm.seg_slice(si - 1), cm.seg_slice(si)
            ca, cb = qq[da[2:4]] - qq[da[0:2]], qq[db[2:4]] - qq[db[0:2]]
            out.append(np.arctan2(cb[1], cb[0]) + qq[db[4]] - np.arctan2(ca[1], ca[0]) - qq[da[5]])
        return np.array(out)

    def grad(qq, h=1e-7):
        G = np.zeros((n, free.size))
        for j, i in enumerate(free):
            e = np.zeros(cm.ndof)
            e[i] = h
            G[:, j] = (g(qq + e) - g(qq - e)) / (2 * h)
        return G

    lam = np.zeros(n)
    for frac in np.linspace(0.1, 1.0, 10):     # load stepping
        F = np.zeros(cm.ndof)
        F[tip[1]] = -frac * k * E * I / L**2
        for _ in range(200):   # quasi-Newton: the constraint curvature (lam d2g/dq2) is left out
            res, _, _, K, _ = cm.dense(q, zero, zero)
            G = grad(q)
            J = np.block([[K, G.T], [G, np.zeros((n, n))]])
            r = np.concatenate([res[free] - F[free] + G.T @ lam, g(q)])
            dx = np.linalg.solve(J, -r)
            q[free] += dx[:free.size]
            lam += dx[free.size:]
            if np.max(np.abs(dx[:free.size])) < 1e-12 * L:
                break
    return q[tip[0]], q[tip[1]]


def test_elastica_reference_matches_mattiasson():
    for k, w, u in MATTIASSON:
        x, y = elastica_tip(k)
        assert y == pytest.approx(w, abs=1e-5) and 1 - x == pytest.approx(u, abs=1e-5)


@pytest.mark.parametrize("k", [1.0, 5.0])
def test_large_deflection_cantilever_against_elastica(k):
    """Tip deflection of 30 % and 71 % of the length: the error falls as h^4 with the mesh (the
    shallow-arch axial strain of docs/theory.md 12.4; h^2 without it). EA L^2/EI = 1e8: the stretch
    (P/EA <= 5e-7) stays below the errors measured, so the inextensible elastica is the reference."""
    x_ex, y_ex = elastica_tip(k)
    errs = []
    for n in (4, 8):
        x, y = static_cantilever_tip(k, n)
        errs.append(max(abs(x - x_ex), abs(-y - y_ex)))
    print(f"\nelastica k={k}: tip error {errs} (L = 1)")
    assert errs[1] < 3e-5                       # measured 3.4e-7 (k=1), 1.0e-5 (k=5) with 8 elements
    assert np.log2(errs[0] / errs[1]) > 3.5     # fourth order: measured 4.07 (k=1), 4.0 (k=5)


def test_small_motion_limit_equals_coupled(cases_dir):
    """Small deflections (the seed manipulator): the nonlinear and the coupled model agree."""
    case = fm.load_case(cases_dir / "manipulator_bricout.toml", overrides=["solver.t_end=0.1"])
    rr = simulate_models(case, ("coupled", "nonlinear"))
    for col in ("tip_dy_elastic", "tip_transverse_elastic", "alpha", "beta"):
        a, b = rr["coupled"][col], rr["nonlinear"][col]
        assert np.max(np.abs(a - b)) < 2e-2 * np.max(np.abs(a)), col


def test_energy_balance_and_mesh_convergence_fourbar(cases_dir):
    """Seed four-bar over its first 0.1 s (before the deflections grow large): energy balance, and
    the midspan strain converging with the mesh."""
    case = fm.load_case(cases_dir / "fourbar_hac.toml", overrides=["solver.t_end=0.1"])
    ys = []
    for n in (2, 4, 8):
        res = fm.simulate(case, model="nonlinear", elements_per_link=n)
        assert res.extra["coupled"]["energy_balance"]["relative_drift"] < 1e-4
        ys.append(res["strain_coupler_mid"])
    e = [np.max(np.abs(ys[i] - ys[-1])) / np.max(np.abs(ys[-1])) for i in range(2)]
    print(f"\nnonlinear four-bar coupler strain vs 8 elements: {e}")
    assert e[0] > e[1]


def test_rigid_limit_fourbar(cases_dir):
    """Links 1e4 times stiffer: the nonlinear model's crank follows the rigid-body solution."""
    ov = [f"links.{k}.youngs_modulus=0.71e15" for k in ("crank", "coupler", "follower")] + ["solver.t_end=0.15"]
    res = fm.simulate(fm.load_case(cases_dir / "fourbar_hac.toml", overrides=ov), model="nonlinear")
    assert res.extra["coupled"]["rigid_drift_from_rigid_body_solution"]["crank_pivot"]["max_abs_rad"] < 1e-3


def test_energy_conserved_in_free_motion():
    """A flexible double pendulum swinging under gravity, no inputs: T + V constant."""
    assert_free_pendulum_conserves_energy("nonlinear", elements=3)


def test_time_step_convergence_manipulator(cases_dir):
    case = fm.load_case(cases_dir / "manipulator_bricout.toml", overrides=["solver.t_end=0.05"])
    from flexmech_py.run.simulate import Prepared
    ys = [Prepared(case, dt=dt, out_every=int(round(2e-5 / dt))).run("nonlinear")["tip_dy_elastic"]
          for dt in (2e-5, 1e-5, 5e-6, 2.5e-6)]
    d = [np.max(np.abs(ys[i] - ys[i + 1])) for i in range(3)]
    assert 1.7 < np.log2(d[-2] / d[-1]) < 2.3


def test_gap_study_reduced(cases_dir):
    """The model-gap study at reduced size: rows, validity times, and on the manipulator the torque-free
    driven joints with K_sigma far closer to the nonlinear model than the seed's clamped joints."""
    from flexmech_py.studies.gap import gap_study, gap_table
    case = fm.load_case(cases_dir / "manipulator_bricout.toml", overrides=["solver.t_end=0.02"])
    study = gap_study(case, "tip_dy_elastic", (0.01, 0.02), elements=2, ref_elements=4,
                      configs=[("classic", "none", "seed"), ("classic", "quasi_static", "torque"), ("coupled", "none", "seed")])
    rows = {(r["model"], r["geometric"], r["joint"]): r for r in study["rows"]}
    assert not any(r["failed"] for r in rows.values())
    assert rows[("classic", "quasi_static", "torque")]["errors"][-1] < 0.2 * rows[("classic", "none", "seed")]["errors"][-1]
    text = "\n".join(gap_table("manipulator", study))
    assert "Closest over" in text and "| coupled | none | seed | 2 |" in text


# ----------------------------------------------------------------------------- shared node angles (theory.md 12.1-12.2)
def _seed_state(cases_dir, epl, dt, t_end):
    """The nonlinear seed four-bar run to t_end; (prepared, model, kernel state q, v, a)."""
    from flexmech_py.run.simulate import Prepared

    case = fm.load_case(cases_dir / "fourbar_hac.toml",
                        overrides=[f"solver.dt={dt}", f"solver.t_end={t_end}", "solver.error_estimate='none'",
                                   "solver.node_angles='shared'"])
    p = Prepared(case, elements_per_link=epl)
    p.run("nonlinear")
    cm = p.coupled["nonlinear"]
    return p, cm, cm.last_run["q"], cm.last_run["v"], cm.last_run["a"]


def test_shared_angles_round_trip(cases_dir):
    """Layout -> kernel -> layout gives back the chord-relative angles, rates and accelerations."""
    _, cm, q, v, a = _seed_state(cases_dir, 4, 1e-4, 0.02)
    qr, vr, ar = cm.shared.from_kernel(q, v, a)
    qk, vk, ak = cm.shared.to_kernel(qr, vr, ar)
    used = np.setdiff1d(np.arange(cm.ndof), cm.shared.unused)
    for x, y in ((q, qk), (v, vk), (a, ak)):
        assert np.abs(x[used] - y[used]).max() <= 1e-12 * max(1.0, np.abs(x).max())
    assert len(cm.shared.keep) == len(cm.rows) - sum(r.role == "interior" for r in cm.rows)


def test_iteration_matrix_is_the_derivative_of_the_residual(cases_dir):
    """S = M + gamma' dt C_v + beta' dt^2 K_t of the kernel against central differences of the Fortran
    residual at a state of the seed four-bar (16 el/link, the issue's step; with Rayleigh damping, so
    that C_v holds its angle-column terms of absolute angles): M to 1e-8, C_v to 1e-6, the
    contraction rho(S^-1 (S_fd - S)) of a Newton iteration below 1e-3."""
    from flexmech_py.base import kernels

    dt, t = 1.25e-5, 2.5e-4
    p, cm, q, v, a = _seed_state(cases_dir, 16, dt, t)
    ispec, rspec = cm._spec(p.gravity, (2.0, 1e-4), kernel=True)
    res, mm, cmat, km, _, status = kernels.cpl.cpl_dense(int(cm.shared.free_of.max()), ispec, rspec, q, v, a, t)
    assert status == 0
    free = np.flatnonzero(cm.shared.free_of > 0)
    free = free[np.argsort(cm.shared.free_of[free])]

    def residual(x):
        return kernels.cpl.cpl_residuals(ispec, rspec, np.asfortranarray(x[0][:, None]), x[1], x[2], t)[0][free, 0]

    bp, gp = 0.25 * dt * dt, 0.5 * dt
    parts = [np.zeros((free.size, free.size)) for _ in range(3)]        # d/dq, d/dv, d/da
    for j, d in enumerate(free):
        for k, (x, rel) in enumerate(((q, 1e-7), (v, 1e-5), (a, 1e-3))):
            h = rel * max(1.0, abs(x[d]))
            up, dn = [q.copy(), v.copy(), a.copy()], [q.copy(), v.copy(), a.copy()]
            up[k][d] += h
            dn[k][d] -= h
            parts[k][:, j] = (residual(up) - residual(dn)) / (2 * h)
    assert np.abs(mm - parts[2]).max() <= 1e-8 * np.abs(mm).max()
    assert np.abs(cmat - parts[1]).max() <= 1e-6 * np.abs(cmat).max()
    s = mm + gp * cmat + bp * km
    s_fd = parts[2] + gp * parts[1] + bp * parts[0]
    assert np.abs(np.linalg.eigvals(np.linalg.solve(s, s_fd - s))).max() < 1e-3


def test_shallow_arch_stiffness_is_the_derivative_of_its_residual(cases_dir):
    """The shallow-arch part of the element (docs/theory.md 12.4) alone: K_t with it minus K_t
    without it (the same state, its flags switched off in the flat description) against central
    differences of the residual with and without it, to 1e-6 of its largest entry; the part is not
    small (above 1e-6 of the whole stiffness) and the whole static stiffness stays symmetric."""
    from flexmech_py.base import kernels

    _, cm, q, v, a = _seed_state(cases_dir, 4, 1e-5, 0.02)        # bent links: th of 1e-3..1e-2
    v, a = np.zeros_like(v), np.zeros_like(a)                      # the static stiffness
    ispec, rspec = cm._spec((0.0, 0.0), (0.0, 0.0), kernel=True)
    plain = ispec.copy()
    plain[-len(cm.segments):] = 0                                  # the arch flags close the layout
    free = np.flatnonzero(cm.shared.free_of > 0)
    free = free[np.argsort(cm.shared.free_of[free])]
    nf = free.size

    def stiffness(isp):
        km = kernels.cpl.cpl_dense(nf, isp, rspec, q, v, a, 0.0)[3]
        fd = np.zeros((nf, nf))
        for j, d in enumerate(free):
            h = 1e-7 * max(1.0, abs(q[d]))
            qs = np.repeat(q[:, None], 2, axis=1)
            qs[d, 0] += h
            qs[d, 1] -= h
            r = kernels.cpl.cpl_residuals(isp, rspec, np.asfortranarray(qs), v, a, 0.0)[0][free]
            fd[:, j] = (r[:, 0] - r[:, 1]) / (2 * h)
        return km, fd

    (k1, f1), (k0, f0) = stiffness(ispec), stiffness(plain)
    d_an, d_fd = k1 - k0, f1 - f0
    assert np.abs(d_fd).max() > 1e-6 * np.abs(f1).max()
    assert np.abs(d_an - d_fd).max() <= 1e-6 * np.abs(d_fd).max()
    assert np.abs(f1 - f1.T).max() <= 1e-9 * np.abs(f1).max()


def test_damping_matrices_are_the_derivatives_of_its_residual(cases_dir):
    """Rayleigh damping alone (a0 M + a1 K on the elements' angles, acting on th' = psi' - omega(c, c')
    with absolute node angles): its part of C_v and of K_t (damped minus undamped, the same state)
    against central differences of its residual in v and in q, to 1e-6 of their largest entries (the
    part is exact: linear in th', whose chord term omega depends on the end positions and rates)."""
    from flexmech_py.base import kernels

    _, cm, q, v, a = _seed_state(cases_dir, 4, 1e-5, 0.02)        # moving: omega of the chords nonzero
    free = np.flatnonzero(cm.shared.free_of > 0)
    free = free[np.argsort(cm.shared.free_of[free])]
    nf = free.size
    specs = [cm._spec((0.0, 0.0), ray, kernel=True) for ray in ((2.0, 1e-4), (0.0, 0.0))]

    def residual(spec, qq, vv):
        return kernels.cpl.cpl_residuals(*spec, np.asfortranarray(qq[:, None]), vv, a, 0.0)[0][free, 0]

    def matrices(spec):
        cmat, km = kernels.cpl.cpl_dense(nf, *spec, q, v, a, 0.0)[2:4]
        fq, fv = np.zeros((nf, nf)), np.zeros((nf, nf))
        for j, d in enumerate(free):
            for f, rel, k in ((fq, 1e-7, 0), (fv, 1e-5, 1)):
                h = rel * max(1.0, abs((q, v)[k][d]))
                up, dn = [q.copy(), v.copy()], [q.copy(), v.copy()]
                up[k][d] += h
                dn[k][d] -= h
                f[:, j] = (residual(spec, *up) - residual(spec, *dn)) / (2 * h)
        return cmat, km, fv, fq

    (c1, k1, fv1, fq1), (c0, k0, fv0, fq0) = matrices(specs[0]), matrices(specs[1])
    for an, fd in ((c1 - c0, fv1 - fv0), (k1 - k0, fq1 - fq0)):
        assert np.abs(fd).max() > 0
        assert np.abs(an - fd).max() <= 1e-6 * np.abs(fd).max()


def _seed_newton(cases_dir, epl, dt, t_end, start, mode):
    from flexmech_py.base import kernels
    from flexmech_py.run.simulate import Prepared

    case = fm.load_case(cases_dir / "fourbar_hac.toml",       # the iteration counts of theory.md 12.2: Newmark
                        overrides=[f"solver.dt={dt}", f"solver.t_end={t_end}", "solver.error_estimate='none'",
                                   "solver.node_angles='shared'", "solver.integrator='newmark'"])
    try:
        assert kernels.cpl.cpl_set_start(start) == 0 and kernels.cpl.cpl_set_newton(mode) == 0
        return Prepared(case, elements_per_link=epl).run("nonlinear").extra["coupled"]["newton"]
    finally:
        kernels.cpl.cpl_set_start(1)
        kernels.cpl.cpl_set_newton(2)


def test_newton_start_and_matrix_refresh(cases_dir):
    """Seed four-bar, 16 el/link, dt = 1.25e-5 s (theory.md 12.2).  Started at the last acceleration
    (start 0), the first iterate lies beta' dt^2 |a_n| away (the crank's node angle accelerates at
    ~1e9 rad/s^2) and the matrix of the predictor contracts slowly: full Newton (1) < automatic
    refresh (2) < modified Newton (0) in iterations per step.  Started at q_n + dt v_n (start 1, the
    default) every policy takes 2 iterations and the automatic one factorizes once per step."""
    old = {m: _seed_newton(cases_dir, 16, 1.25e-5, 2.5e-3, 0, m)["mean_per_step"] for m in (0, 1, 2)}
    assert old[1] < old[2] < old[0]
    for m in (0, 1, 2):
        nw = _seed_newton(cases_dir, 16, 1.25e-5, 2.5e-3, 1, m)
        assert nw["mean_per_step"] <= 2.0 + 1e-9
        if m != 1:
            assert nw["factorizations_per_step"] < 1.01
    from flexmech_py.base import kernels
    assert kernels.cpl.cpl_set_newton(5) != 0 and kernels.cpl.cpl_set_start(3) != 0


def test_newton_converges_at_64_elements_per_link(cases_dir):
    """At 64 el/link and dt = 1e-5 s Newton started at the last acceleration fails at the first step
    (the first iterate turns the crank's node angle by radians); started at q_n + dt v_n it takes 2
    iterations per step."""
    from flexmech_py.base.errors import SolverError

    with pytest.raises(SolverError) as info:
        _seed_newton(cases_dir, 64, 1e-5, 2e-4, 0, 2)
    assert info.value.code == 5
    assert _seed_newton(cases_dir, 64, 1e-5, 2e-4, 1, 2)["max_per_step"] <= 2


def test_restart_at_the_last_position_keeps_the_factorized_matrix(cases_dir):
    """Relative node angles at 64 el/link, dt = 1e-5 s: the ringing node angles make some steps start
    again at q_n (3 iterations there: more than 2.2 per step on average); those steps converge with
    the matrix factorized at q_n + dt v_n, so one factorization per step (1.6 when every restart
    rebuilt it; theory.md 12.2)."""
    from flexmech_py.run.simulate import Prepared

    case = fm.load_case(cases_dir / "fourbar_hac.toml",
                        overrides=["solver.dt=1e-5", "solver.t_end=3e-3", "solver.error_estimate='none'"])
    newton = Prepared(case, elements_per_link=64).run("nonlinear").extra["coupled"]["newton"]
    assert newton["mean_per_step"] > 2.2
    assert newton["factorizations_per_step"] < 1.05


def test_newton_converges_at_256_elements_per_link_with_generalized_alpha(cases_dir):
    """At 256 el/link (dt = 1.25e-5 s, generalized-alpha) the crank's node angle rings at ~1e12
    rad/s^2 and its velocity makes q_n + dt v_n a far start: the step starts again at q_n (theory.md
    12.2) and converges, in at most 4 iterations per step on average (3.35 measured)."""
    from flexmech_py.base import kernels
    from flexmech_py.run.simulate import Prepared

    case = fm.load_case(cases_dir / "fourbar_hac.toml",
                        overrides=["solver.dt=1.25e-5", "solver.t_end=1e-3", "solver.error_estimate='none'",
                                   "solver.integrator='generalized-alpha'", "solver.node_angles='shared'"])
    assert kernels.cpl.cpl_set_start(1) == 0
    newton = Prepared(case, elements_per_link=256).run("nonlinear").extra["coupled"]["newton"]
    assert newton["mean_per_step"] <= 4.0


def test_closed_form_inertia_of_longer_segments_equals_the_gauss_points(cases_dir):
    """The coupled model's segments of several elements: the residual and the blocks of M, C_v and K_t
    in closed form over each element's Gram matrix (flexmech_coupled_element.f90: long_element_inertia)
    against the Gauss-point evaluation, at states of the seed four-bar (point masses), the manipulator
    (payload, hub), the slider-crank, the plate six-bar and the quick-return: the residual equal to
    1e-13 of the inertia terms M a, the matrices to 1e-13 of their largest entries (K_t: of its inertial
    part, K_t less the elastic stiffness, which both evaluations share)."""
    from flexmech_py.base import kernels
    from flexmech_py.run.simulate import Prepared

    for name, epl in (("fourbar_hac", 4), ("manipulator_bricout", 3), ("slider_crank", 2), ("sixbar_plate", 2),
                      ("quick_return", 4)):
        case = fm.load_case(cases_dir / f"{name}.toml", overrides=["solver.t_end=0.01", "solver.error_estimate='none'"])
        p = Prepared(case, elements_per_link=epl)
        p.run("coupled")
        cm = p.coupled["coupled"]
        st = cm.last_run
        ispec, rspec = cm._spec(p.gravity, (0.0, 0.0))
        qs = np.asfortranarray(st["q"][:, None])
        out, dense = [], []
        try:
            for mode in (1, 0):
                assert kernels.cpl.cpl_set_inertia(mode) == 0
                out.append(kernels.cpl.cpl_residuals(ispec, rspec, qs, st["v"], st["a"], 0.01)[0][:, 0])
                dense.append(kernels.cpl.cpl_dense(cm.nfree, ispec, rspec, st["q"], st["v"], st["a"], 0.01)[1:4])
        finally:
            kernels.cpl.cpl_set_inertia(0)
        free = np.flatnonzero(cm.free_of > 0)
        free = free[np.argsort(cm.free_of[free])]
        mm = dense[1][0]
        scale = np.abs(mm @ st["a"][free]).max()
        assert max(cm.n_el) > 1
        assert np.abs(out[0] - out[1]).max() <= 1e-13 * scale, name
        zero = np.zeros_like(st["v"])
        k_at_rest = kernels.cpl.cpl_dense(cm.nfree, ispec, rspec, st["q"], zero, zero, 0.01)[3]
        for k, (gauss, closed) in enumerate(zip(*dense)):
            ref = gauss - k_at_rest if k == 2 else gauss        # K_t's inertial part vanishes at rest
            assert np.abs(ref).max() > 0, (name, k)
            assert np.abs(closed - gauss).max() <= 1e-13 * np.abs(ref).max(), (name, k)


@pytest.mark.parametrize("angles", ["shared", "relative"])
def test_closed_form_inertia_equals_the_gauss_points(cases_dir, angles):
    """One-element segments in one pass (flexmech_coupled_corot.f90; theory.md 12.3) against the
    general path's Gauss-point evaluation of the same inertia integrals (the two share the rotary,
    axial and bending terms, whose derivatives have their own tests), at a state of the seed
    four-bar (point masses on elements), the manipulator (payload, hub; with Rayleigh damping here)
    and the slider-crank, with absolute (shared) and chord-relative node angles: M, C_v, K_t and the
    energies equal to 1e-13, the residual to 1e-13 of its inertia terms M a (its own size is a
    cancellation of larger terms), and the residual alone (cpl_residuals, the Newton iterations'
    path) equal to it."""
    from flexmech_py.base import kernels
    from flexmech_py.run.simulate import Prepared

    for name, epl, ray in (("fourbar_hac", 4, (0.0, 0.0)), ("manipulator_bricout", 3, (2.0, 1e-4)),
                           ("slider_crank", 2, (0.0, 0.0))):
        case = fm.load_case(cases_dir / f"{name}.toml", overrides=["solver.t_end=0.01", "solver.error_estimate='none'",
                                                                   f"solver.node_angles='{angles}'"])
        p = Prepared(case, elements_per_link=epl)
        p.run("nonlinear")
        cm = p.coupled["nonlinear"]
        st = cm.last_run
        ispec, rspec = cm._spec(p.gravity, ray, kernel=True)
        lay = cm.shared if angles == "shared" else cm
        nf = int(lay.free_of.max())
        out, alone = [], []
        try:
            for mode in (1, 0):
                assert kernels.cpl.cpl_set_inertia(mode) == 0
                out.append(kernels.cpl.cpl_dense(nf, ispec, rspec, st["q"], st["v"], st["a"], 0.01))
                alone.append(kernels.cpl.cpl_residuals(ispec, rspec, np.asfortranarray(st["q"][:, None]),
                                                       st["v"], st["a"], 0.01)[0][:, 0])
        finally:
            kernels.cpl.cpl_set_inertia(0)
        free = np.flatnonzero(lay.free_of > 0)
        free = free[np.argsort(lay.free_of[free])]
        for i in (1, 2, 3, 4):
            x, y = out[0][i], out[1][i]
            assert np.abs(x - y).max() <= 1e-13 * max(np.abs(x).max(), 1e-300), (name, i)
        scale = np.abs(out[0][1] @ st["a"][free]).max()
        assert np.abs(out[0][0][free] - out[1][0][free]).max() <= 1e-13 * scale, name
        assert np.abs(alone[1][free] - out[1][0][free]).max() <= 1e-13 * scale, name
        assert np.abs(alone[0][free] - alone[1][free]).max() <= 1e-13 * scale, name
    assert kernels.cpl.cpl_set_inertia(3) != 0
