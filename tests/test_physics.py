"""System-level physics of the superposition solver: frame invariance, Newmark order,
FE mass = rigid mass, and the relations between the three rigid-inertia load models."""

import numpy as np
import pytest
from conftest import beam_case
from flexmech_py.models.superposition.reference import OMEGA, element_matrices, shape_n

import flexmech_py as fm
from flexmech_py.base import kernels
from flexmech_py.mechanism.drives import spinup
from flexmech_py.run.simulate import Prepared


# ----------------------------------------------------------------------------- frame invariance
def _body_frame_cantilever(n_el, L, ra, ea, ei, t, w, al, beta=0.25, gamma=0.5):
    """Spinning cantilever in the co-rotating frame (local DOFs delta, written independently):
    m d'' + 2 w G d' + (k + al G - w^2 m) d = -rho A int N^T a_rigid,  G = rho A int N^T Omega N."""
    le = L / n_el
    nd = 3 * (n_el + 1)
    x, wq = np.polynomial.legendre.leggauss(6)
    xi, wq = 0.5 * (x + 1), 0.5 * wq * le * ra
    m_e, k_e, *_ = element_matrices(ra, ea, ei, le)
    G_e = sum(wi * shape_n(xq, le).T @ OMEGA @ shape_n(xq, le) for xq, wi in zip(xi, wq))
    # consistent load of a unit axial field zeta and a unit transverse field zeta, per element
    M = np.zeros((nd, nd)); K = np.zeros((nd, nd)); G = np.zeros((nd, nd))
    fa = np.zeros(nd); ft = np.zeros(nd)
    for e in range(n_el):
        d = slice(3 * e, 3 * e + 6)
        M[d, d] += m_e; K[d, d] += k_e; G[d, d] += G_e
        for xq, wi in zip(xi, wq):
            zeta = (e + xq) * le
            n = shape_n(xq, le)
            fa[d] += wi * n.T @ np.array([zeta, 0.0])
            ft[d] += wi * n.T @ np.array([0.0, zeta])
    f = slice(3, nd)  # clamp node 0
    M, K, G, fa, ft = M[f, f], K[f, f], G[f, f], fa[f], ft[f]
    dt = t[1] - t[0]
    u = np.zeros((M.shape[0], t.size)); v = np.zeros(M.shape[0])

    def ops(i):
        C = 2 * w[i] * G
        Kt = K + al[i] * G - w[i] ** 2 * M
        r = -(-w[i] ** 2 * fa + al[i] * ft)
        return C, Kt, r

    C, Kt, r = ops(0)
    a = np.linalg.solve(M, r)
    for i in range(1, t.size):
        up = u[:, i - 1] + dt * v + dt**2 * (0.5 - beta) * a
        vp = v + dt * (1 - gamma) * a
        C, Kt, r = ops(i)
        a = np.linalg.solve(M + gamma * dt * C + beta * dt**2 * Kt, r - C @ vp - Kt @ up)
        u[:, i] = up + beta * dt**2 * a
        v = vp + gamma * dt * a
    return u[-3:-1]  # tip [p, v]


def test_frame_invariance_spinning_cantilever():
    """The global-frame formulation (Cg, Kc from u = R N T s) equals the co-rotating-frame one to
    integrator precision: the difference shrinks as dt^2."""
    L, n_el = 1.0, 4
    drive = {"type": "kinematic", "law": "spinup", "final_speed": 6.0, "spinup_time": 0.4}
    errs = []
    for dt in (1e-3, 5e-4):
        case = beam_case(n_el=n_el, length=L, drive=drive, t_end=0.5, dt=dt)
        res = fm.simulate(case, model="classic")
        ln = case["links"][0]
        t = np.linspace(0, 0.5, res.nsteps + 1)
        _, qd, qdd = spinup(t, 6.0, 0.4)
        tip = _body_frame_cantilever(n_el, L, ln["density"] * ln["area"], ln["youngs_modulus"] * ln["area"],
                                     ln["youngs_modulus"] * ln["second_moment"], t, qd, qdd)
        ref = np.vstack([tip[0], tip[1]])
        got = np.vstack([res["tip_u"], res["tip_v"]])
        assert np.max(np.abs(ref[1])) > 1e-4  # a real deflection (m)
        errs.append(np.max(np.abs(got - ref)) / np.max(np.abs(ref)))
    assert errs[0] < 5e-5  # measured 1.3e-5 at dt = 1e-3 s
    order = np.log2(errs[0] / errs[1])
    assert 1.8 < order < 2.3, (errs, order)


# ----------------------------------------------------------------------------- Newmark order
def test_newmark_second_order_in_dt():
    """Average-acceleration Newmark converges as dt^2 (smooth spin-up so that every excited mode is resolved)."""
    drive = {"type": "kinematic", "law": "spinup", "final_speed": 6.0, "spinup_time": 0.4}
    case = beam_case(n_el=4, drive=drive, t_end=0.3, dt=1e-3)
    finals = []
    for dt in (2e-3, 1e-3, 5e-4, 2.5e-4):
        res = fm.simulate(case, model="classic", dt=dt, out_every=int(round(2e-3 / dt)))
        finals.append(res.u)
    e = [np.max(np.abs(finals[i] - finals[i + 1])) for i in range(3)]
    orders = np.log2(np.array(e[:-1]) / np.array(e[1:]))
    assert np.all((orders > 1.9) & (orders < 2.1)), orders


# ----------------------------------------------------------------------------- mass properties
@pytest.mark.parametrize("name", ["fourbar_hac", "manipulator_bricout", "manipulator_bricout_no_payload"])
def test_rigid_mass_properties_equal_fe_mass(cases_dir, name):
    """Kinetic energy of the rigid motion computed with the FE mass (consistent element mass
    under each element's own rigid nodal velocities, plus lumped inertias) equals the rigid model's
    (each body's mass at its centre of mass and its rotary inertia there)."""
    case = fm.load_case(cases_dir / f"{name}.toml", overrides=["solver.t_end=0.02"])
    p = Prepared(case)
    fe, rm = p.fe, p.rm
    mech = case.mechanism
    for i in (rm.t.size // 3, rm.t.size - 1):
        km = rm.motion.select(slice(i, i + 1))
        ke_fe = 0.0
        for e in range(fe.nel):
            j = fe.el_link[e] - 1
            L, z0, ra, ea, ei = fe.el_prop[:, e]
            m = kernels.element_matrices(ra, ea, ei, L)[0]
            ph, w = km.phi[0, j], km.omega[0, j]
            vel = []
            for z in (z0, z0 + L):  # rigid nodal velocities in the element frame, rotation rate w
                vg = np.array([km.vx[0, j], km.vy[0, j]]) + w * z * np.array([-np.sin(ph), np.cos(ph)])
                vel += [np.cos(ph) * vg[0] + np.sin(ph) * vg[1], -np.sin(ph) * vg[0] + np.cos(ph) * vg[1], w]
            vel = np.array(vel)
            ke_fe += 0.5 * vel @ m @ vel
        for k in range(fe.lm_link.size):
            j = fe.lm_link[k] - 1
            mass, z = fe.lm_prop[:, k]
            ph, w = km.phi[0, j], km.omega[0, j]
            vg = np.array([km.vx[0, j], km.vy[0, j]]) + w * z * np.array([-np.sin(ph), np.cos(ph)])
            ke_fe += 0.5 * mass * vg @ vg
        for k in range(fe.ri_link.size):
            ke_fe += 0.5 * fe.ri_prop[k] * km.omega[0, fe.ri_link[k] - 1] ** 2
        ke_rigid = 0.0
        for b, body in enumerate(mech.bodies):
            mass, _, j_c = body.mass_properties()
            ke_rigid += 0.5 * mass * (rm.zd[i, 3 * b] ** 2 + rm.zd[i, 3 * b + 1] ** 2) + 0.5 * j_c * rm.zd[i, 3 * b + 2] ** 2
        assert ke_fe == pytest.approx(ke_rigid, rel=1e-12)


# ----------------------------------------------------------------------------- load models
def test_load_models_relations(cases_dir):
    """classic - classic-translational is exactly the M-weighted angular-acceleration load;
    hac and classic differ only through the axial distribution (transverse loads agree for a
    link whose axial rigid acceleration is uniform, i.e. omega = 0)."""
    p = Prepared(fm.load_case(cases_dir / "fourbar_hac.toml", overrides=["solver.t_end=0.05"]))
    rig = p.rig[:, :, -1]
    _, _, _, f_c = p.fe.matrices(rig, "classic")
    _, _, _, f_t = p.fe.matrices(rig, "classic-translational")
    # the difference is M_all applied to the angular accelerations at the rotational entries
    diff = np.zeros(p.fe.ndof)
    for e in range(p.fe.nel):
        j = p.fe.el_link[e] - 1
        L, _, ra, ea, ei = p.fe.el_prop[:, e]
        m = kernels.element_matrices(ra, ea, ei, L)[0]
        ph = rig[0, j]
        t = np.eye(6); c, s = np.cos(ph), np.sin(ph)
        t[0:2, 0:2] = t[3:5, 3:5] = [[c, s], [-s, c]]
        diff[p.fe.el_dof[:, e] - 1] += t.T @ m @ np.array([0, 0, rig[2, j], 0, 0, rig[2, j]])
    assert np.allclose(f_c - f_t, diff, atol=1e-12 * np.max(np.abs(f_c)))
    # hac and classic differ only through the centripetal axial field -w^2 zeta: with w = 0 the
    # rigid acceleration is uniform axially and linear transversally, and both loads are exact
    rig0 = rig.copy(); rig0[1] = 0.0
    _, _, _, f_h = p.fe.matrices(rig0, "hac")
    _, _, _, f_c = p.fe.matrices(rig0, "classic")
    assert np.max(np.abs(f_h - f_c)) < 1e-13 * np.max(np.abs(f_c))
    # with w != 0, per element: classic - hac = rho A w^2 L^2 / 12 * (+1 at p1, -1 at p2) (local axial)
    _, _, _, f_h = p.fe.matrices(rig, "hac")
    _, _, _, f_c = p.fe.matrices(rig, "classic")
    expect = np.zeros(p.fe.ndof)
    for e in range(p.fe.nel):
        j = p.fe.el_link[e] - 1
        L, _, ra, _, _ = p.fe.el_prop[:, e]
        d = ra * rig[1, j] ** 2 * L**2 / 12
        c, s = np.cos(rig[0, j]), np.sin(rig[0, j])
        dofs = p.fe.el_dof[:, e] - 1
        expect[dofs[[0, 1]]] += d * np.array([c, s])
        expect[dofs[[3, 4]]] -= d * np.array([c, s])
    assert np.allclose(f_c - f_h, expect, atol=1e-12 * np.max(np.abs(f_c)))
