"""Physics tests of flexmech_py.rigid (rigid-body kinematics and dynamics)."""
import numpy as np
import pytest

from flexmech_py import rigid as R  # the installed package

MechanismError = R.MechanismError

TM = (0.10795, 0.2794, 0.27051, 0.254)          # Turcic-Midha crank-rocker [m]
NON_GRASHOF = (0.2, 0.05, 0.05, 0.254)
G = 9.81


def tm_masses(mech):
    rho = 2710.0
    crank = R.LinkMass.from_bar(rho * 1.07e-4, mech.a).add_point_mass(0.045, mech.a)    # pin A
    coupler = R.LinkMass.from_bar(rho * 0.406e-4, mech.b).add_point_mass(0.0375, mech.b)  # pin B
    return [crank, coupler, R.LinkMass.from_bar(rho * 0.406e-4, mech.c)]


def chain_masses():
    rho_a = 7800 * 4e-4
    return [R.LinkMass.from_bar(rho_a, 1.0).add_point_mass(0.5, 1.0),
            R.LinkMass.from_bar(rho_a, 1.0).add_rotary_inertia(0.04).add_point_mass(0.3, 1.0)]


def wrap(x):
    return (x + np.pi) % (2 * np.pi) - np.pi


# ----------------------------------------------------------------- kinematics
def test_fourbar_loop_closure_and_branch():
    fb = R.FourBar.open_assembly(*TM, q0=0.0)
    q = np.linspace(0, 2 * np.pi, 721)
    P = fb.joint_positions(q)
    O2, A, B, O4 = (P[:, i] for i in range(4))
    assert np.max(np.abs(np.linalg.norm(A - O2, axis=1) - fb.a)) < 1e-12
    assert np.max(np.abs(np.linalg.norm(B - A, axis=1) - fb.b)) < 1e-12
    assert np.max(np.abs(np.linalg.norm(B - O4, axis=1) - fb.c)) < 1e-12
    assert P[0, 2, 1] > 0                      # open branch: B above ground at q = 0
    cross = (O4 - A)[:, 0] * (B - A)[:, 1] - (O4 - A)[:, 1] * (B - A)[:, 0]
    assert np.all(np.sign(cross) == fb.branch)  # branch kept over the whole turn
    k = fb.kinematics(q)
    assert np.allclose(k.ox[:, 1], A[:, 0], atol=1e-15) and np.allclose(k.oy[:, 2], 0.0)
    assert np.allclose(k.phi[:, 1], np.arctan2(*(B - A).T[::-1]), atol=1e-12)
    assert np.allclose(k.phi[:, 2], np.arctan2(*(B - O4).T[::-1]), atol=1e-12)
    other = R.FourBar(*TM, branch=-fb.branch)   # the mirror branch has B below
    assert other.joint_positions(0.0)[0, 2, 1] < 0


def test_fourbar_derivatives_against_finite_differences():
    fb = R.FourBar.open_assembly(*TM)
    t = np.linspace(0, 1.5, 301)
    law = lambda t: (0.3 + 1.0 * t + 2.2 * t ** 2, 1.0 + 4.4 * t, 4.4 + 0 * t)  # > one turn
    h = 1e-5
    k0 = fb.kinematics(*law(t))
    kp, km = fb.kinematics(*law(t + h)), fb.kinematics(*law(t - h))
    for pos, vel, acc in (("phi", "omega", "alpha"), ("ox", "vx", "ax"), ("oy", "vy", "ay")):
        dpos = getattr(kp, pos) - getattr(km, pos)
        if pos == "phi":
            dpos = wrap(dpos)
        for num, ref in ((dpos / (2 * h), getattr(k0, vel)),
                         ((getattr(kp, vel) - getattr(km, vel)) / (2 * h), getattr(k0, acc))):
            scale = np.max(np.abs(ref), axis=0) + 1e-300
            assert np.max(np.abs(num - ref) / scale) < 1e-6, (pos, vel, acc)
    J = fb.jacobian(law(t)[0])                  # d(ox, oy, phi)/dq
    assert np.allclose(J[:, :, 0, 0] * law(t)[1][:, None], k0.vx, rtol=1e-12, atol=1e-14)
    assert np.allclose(J[:, :, 2, 0] * law(t)[1][:, None], k0.omega, rtol=1e-12, atol=1e-14)


def test_crank_ranges_and_assembly_errors():
    assert R.FourBar.open_assembly(*TM).crank_range() is None   # crank-rocker
    a, b, c, d = NON_GRASHOF
    ng = R.FourBar.open_assembly(*NON_GRASHOF, q0=0.0)          # assembles near q = 0 only
    qlim = np.arccos((a * a + d * d - (b + c) ** 2) / (2 * a * d))
    assert np.allclose(ng.crank_range(), (-qlim, qlim), atol=1e-12)
    assert np.allclose(ng.crank_range(2 * np.pi + 0.1), (2 * np.pi - qlim, 2 * np.pi + qlim))
    lo, hi = R.FourBar(0.1, 0.3, 0.2, 0.12).crank_range(-3.0)  # cannot pass q = 0: |b-c| > |d-a|
    qlo = np.arccos((0.1 ** 2 + 0.12 ** 2 - 0.1 ** 2) / (2 * 0.1 * 0.12))
    assert np.allclose((lo, hi), (qlo - 2 * np.pi, -qlo), atol=1e-12)
    with pytest.raises(MechanismError, match="cannot assemble.*exceeds coupler"):
        R.FourBar.open_assembly(*NON_GRASHOF, q0=np.pi)
    with pytest.raises(MechanismError, match="cannot assemble at any crank angle"):
        R.FourBar(0.2, 0.02, 0.02, 0.254)        # b + c < |d - a|: never closes
    with pytest.raises(MechanismError, match="toggle|cannot assemble"):
        ng.kinematics(qlim * (1 + 1e-15), 1.0)
    with pytest.raises(MechanismError, match="at t = 0.5 s"):
        R.check_motion(ng, [0.0, 0.2, 0.4], t=[0.0, 0.25, 0.5])
    R.check_motion(ng, [0.0, 0.2, -0.3])
    with pytest.raises(MechanismError, match="ambiguous"):
        R.FourBar.open_assembly(0.2, 0.15, 0.12, 0.1, q0=np.pi / 3)   # A right above O4


def test_serial_chain_tip_closed_form():
    L1, L2, base = 0.7, 0.4, (0.3, -0.2)
    ch = R.SerialChain([L1, L2], base=base)
    q = np.random.default_rng(0).uniform(-4, 4, (50, 2))
    tip = ch.joint_positions(q)[:, -1]
    ref = np.stack([base[0] + L1 * np.cos(q[:, 0]) + L2 * np.cos(q[:, 0] + q[:, 1]),
                    base[1] + L1 * np.sin(q[:, 0]) + L2 * np.sin(q[:, 0] + q[:, 1])], -1)
    assert np.max(np.abs(tip - ref)) < 1e-14
    J, h = ch.jacobian(q), 1e-6                   # Jacobian against central differences
    for i in range(2):
        dq = np.zeros(2)
        dq[i] = h
        kp, km = ch.kinematics(q + dq), ch.kinematics(q - dq)
        for c, f in enumerate(("ox", "oy", "phi")):
            num = (getattr(kp, f) - getattr(km, f)) / (2 * h)
            assert np.max(np.abs(J[:, :, c, i] - num)) < 1e-8


# -------------------------------------------------------------------- masses
def test_single_link_and_double_pendulum_mass_matrix():
    rho_a, L = 3.0, 0.8
    m = rho_a * L
    one = R.SerialChain([L])
    M = R.mass_matrix(one, [R.LinkMass.from_bar(rho_a, L)], np.linspace(0, 6, 7)[:, None])
    assert np.allclose(M[:, 0, 0], m * L ** 2 / 3, rtol=1e-14)
    L1, L2, m1, m2 = 1.0, 0.6, 2.0, 1.5
    dp = R.SerialChain([L1, L2])
    q = np.random.default_rng(1).uniform(-3, 3, (20, 2))
    M = R.mass_matrix(dp, [R.LinkMass.from_bar(m1 / L1, L1), R.LinkMass.from_bar(m2 / L2, L2)], q)
    c2 = np.cos(q[:, 1])
    M11 = m1 * L1 ** 2 / 3 + m2 * (L1 ** 2 + L2 ** 2 / 3 + L1 * L2 * c2)
    M12 = m2 * (L2 ** 2 / 3 + L1 * L2 * c2 / 2)
    assert np.allclose(M[:, 0, 0], M11, rtol=1e-13) and np.allclose(M[:, 1, 1], m2 * L2 ** 2 / 3)
    assert np.allclose(M[:, 0, 1], M12, rtol=1e-13) and np.allclose(M[:, 1, 0], M12, rtol=1e-13)


def test_fourbar_mass_matrix_and_kinetic_energy():
    fb = R.FourBar.open_assembly(*TM)
    ms = tm_masses(fb)
    q = np.linspace(0, 2 * np.pi, 361)
    qd = 50 + 30 * np.sin(q)
    M = R.mass_matrix(fb, ms, q)
    assert np.all(M[:, 0, 0] > 0)
    ke = R.kinetic_energy(fb, ms, q, qd)
    assert np.allclose(ke, 0.5 * M[:, 0, 0] * qd ** 2, rtol=1e-12)
    ch = R.SerialChain([1.0, 1.0])
    Mc = R.mass_matrix(ch, chain_masses(), np.random.default_rng(2).uniform(-3, 3, (30, 2)))
    assert np.allclose(Mc, Mc.transpose(0, 2, 1), rtol=1e-14, atol=0)
    assert np.all(np.linalg.eigvalsh(Mc) > 0)
    # independent: sum 0.5 dm |v|^2 over material points, v by central differences of positions
    rho = [2710 * 1.07e-4, 2710 * 0.406e-4, 2710 * 0.406e-4]
    n, h = 2000, 1e-6
    zeta = (np.arange(n) + 0.5) / n               # midpoint rule, fraction of length
    kp, km = fb.kinematics(q + h), fb.kinematics(q - h)
    ke_ref = 0.0
    for k, L in enumerate(fb.lengths):
        z = zeta * L
        pos = lambda kk: (kk.ox[:, k, None] + z * np.cos(kk.phi[:, k, None]),
                          kk.oy[:, k, None] + z * np.sin(kk.phi[:, k, None]))
        (xp, yp), (xm, ym) = pos(kp), pos(km)
        v2 = ((xp - xm) ** 2 + (yp - ym) ** 2) / (2 * h) ** 2 * qd[:, None] ** 2
        ke_ref = ke_ref + 0.5 * rho[k] * L / n * v2.sum(1)
    dP = fb.joint_positions(q + h) - fb.joint_positions(q - h)    # pins A and B
    vA2, vB2 = (dP[:, 1] ** 2).sum(1), (dP[:, 2] ** 2).sum(1)
    ke_ref = ke_ref + 0.5 * (0.045 * vA2 + 0.0375 * vB2) / (2 * h) ** 2 * qd ** 2
    assert np.max(np.abs(ke - ke_ref) / ke_ref) < 1e-6


def test_bias_forces_match_lagrange():
    """h = Mdot qd - 0.5 d(qd^T M qd)/dq, derivatives of M by central differences."""
    ch = R.SerialChain([1.0, 1.0])
    ms = chain_masses()
    rng = np.random.default_rng(3)
    q, qd = rng.uniform(-3, 3, (10, 2)), rng.uniform(-5, 5, (10, 2))
    hstep = 1e-6
    dM = []
    for i in range(2):
        dq = np.zeros(2)
        dq[i] = hstep
        dM.append((R.mass_matrix(ch, ms, q + dq) - R.mass_matrix(ch, ms, q - dq)) / (2 * hstep))
    dM = np.stack(dM, axis=1)                      # (N, k, i, j) = dM_ij/dq_k
    ref = (np.einsum("nkij,nk,nj->ni", dM, qd, qd) - 0.5 * np.einsum("nijk,nj,nk->ni", dM, qd, qd))
    h = R.bias_forces(ch, ms, q, qd)
    assert np.max(np.abs(h - ref)) < 1e-6 * np.max(np.abs(ref))


def test_joint_torque_generalized_force():
    fb = R.FourBar.open_assembly(*TM)
    q = np.linspace(0, 6, 13)
    Q = R.joint_torque_generalized_force(fb, q, 2, None, 3.0)   # on the follower from ground
    h = 1e-6
    dphi4 = wrap(fb.kinematics(q + h).phi[:, 2] - fb.kinematics(q - h).phi[:, 2]) / (2 * h)
    assert np.allclose(Q[:, 0], 3.0 * dphi4, rtol=1e-7)
    Q = R.joint_torque_generalized_force(fb, q, 1, 0, 2.0)      # coupler against crank
    dphi3 = wrap(fb.kinematics(q + h).phi[:, 1] - fb.kinematics(q - h).phi[:, 1]) / (2 * h)
    assert np.allclose(Q[:, 0], 2.0 * (dphi3 - 1.0), rtol=1e-7)
    ch = R.SerialChain([1.0, 1.0])
    assert np.allclose(R.joint_torque_generalized_force(ch, [0.1, 0.2], 1, 0, -10.0), [[0, -10]])


# ------------------------------------------------------------------ dynamics
def test_fourbar_energy_balance():
    fb = R.FourBar.open_assembly(*TM)
    ms = tm_masses(fb)
    t = np.linspace(0, 0.25, 2501)
    q, qd, qdd = R.integrate(fb, ms, 0.0, 0.0, t, lambda t, q, qd: 1 + 0.5 * np.sin(q))
    work = q[:, 0] + 0.5 * (1 - np.cos(q[:, 0]))     # int (1 + 0.5 sin q) dq, exact
    ke = R.kinetic_energy(fb, ms, q, qd)
    rel = np.abs(ke - work)[1:] / work[1:]
    print(f"\nfour-bar at t = 0.25 s: q = {q[-1, 0]:.9f} rad, qd = {qd[-1, 0]:.9f} rad/s, "
          f"KE = {ke[-1]:.9f} J, max rel energy error = {rel.max():.2e}")
    assert abs(ke[0]) < 1e-15 and rel.max() < 1e-7
    assert q[-1, 0] > 2 * np.pi                        # more than one full turn
    M = R.mass_matrix(fb, ms, q)                       # qdd satisfies the equations of motion
    res = M[:, 0, 0] * qdd[:, 0] + R.bias_forces(fb, ms, q, qd)[:, 0] - (1 + 0.5 * np.sin(q[:, 0]))
    assert np.max(np.abs(res)) < 1e-12


def test_serial_chain_energy_balance():
    ch = R.SerialChain([1.0, 1.0])
    ms = chain_masses()
    q0 = np.array([0.0, 0.5])
    Qc = (R.joint_torque_generalized_force(ch, q0, 0, None, 10.0)
          + R.joint_torque_generalized_force(ch, q0, 1, 0, -10.0))[0]
    assert np.allclose(Qc, [10.0, -10.0])
    t = np.linspace(0, 0.25, 1001)
    q, qd, qdd = R.integrate(ch, ms, q0, [0.0, 0.0], t, lambda t, q, qd: Qc)
    work = (q - q0) @ Qc                                # constant joint torques
    ke = R.kinetic_energy(ch, ms, q, qd)
    rel = np.abs(ke - work)[1:] / work[1:]
    print(f"\nchain at t = 0.25 s: q = {q[-1]} rad, qd = {qd[-1]} rad/s, "
          f"max rel energy error = {rel.max():.2e}")
    assert rel.max() < 1e-7


def test_gravity_pinned_bar_and_double_pendulum():
    L, rho_a = 1.2, 2.0
    bar = R.SerialChain([L])
    ms = [R.LinkMass.from_bar(rho_a, L)]
    g = (0.0, -G)
    t = np.linspace(0, 2.0, 801)
    q, qd, qdd = R.integrate(bar, ms, 0.0, 0.0, t, None, gravity=g)
    assert np.isclose(qdd[0, 0], -3 * G / (2 * L), rtol=1e-13)
    e = R.kinetic_energy(bar, ms, q, qd) + R.potential_energy(bar, ms, q, g)
    assert np.max(np.abs(e - e[0])) < 1e-8 * rho_a * L * G * L
    assert q[:, 0].min() < -np.pi + 1e-3                # swings down to the other horizontal
    dp = R.SerialChain([1.0, 1.0])
    ms2 = chain_masses()
    q, qd, _ = R.integrate(dp, ms2, [0.3, 1.0], [0.0, 0.0], t, None, gravity=(0.5, -G))
    e = R.kinetic_energy(dp, ms2, q, qd) + R.potential_energy(dp, ms2, q, (0.5, -G))
    assert np.max(np.abs(e - e[0])) < 1e-7 * np.max(R.kinetic_energy(dp, ms2, q, qd))


def test_torque_drives_non_grashof_into_limit():
    ng = R.FourBar.open_assembly(*NON_GRASHOF)
    ms = [R.LinkMass.from_bar(1.0, L) for L in ng.lengths]
    qlim = ng.crank_range()[1]
    with pytest.raises(MechanismError, match=r"t = [0-9.e-]+ s, crank angle") as err:
        R.integrate(ng, ms, 0.0, 0.0, np.linspace(0, 1, 11), lambda t, q, qd: np.array([1.0]))
    qe = float(str(err.value).split("crank angle ")[1].split()[0])
    assert qlim - 1e-4 < qe <= qlim                    # stopped just before the limit
    with pytest.raises(MechanismError, match="at t = 0 s"):
        R.integrate(ng, ms, qlim, 0.0, [0.0, 1.0])


# -------------------------------------------------------------------- drives
def test_spinup_and_constant_speed():
    ws, T = 150.0, 0.3
    eps = 1e-9
    q, qd, qdd = R.spinup([T - eps, T, T + eps], ws, T, q0=0.2)
    assert np.allclose(q[:, 0], 0.2 + ws * T / 2, atol=1e-6) and np.allclose(qd[:, 0], ws)
    assert np.allclose(qdd[:, 0], 0.0, atol=1e-6)
    q, qd, qdd = R.spinup([0.0], ws, T)
    assert q[0, 0] == 0 and qd[0, 0] == 0 and qdd[0, 0] == 0
    t, h = np.linspace(0.001, 0.6, 300), 1e-6
    q, qd, qdd = R.spinup(t, ws, T)
    (qp, qdp, _), (qm, qdm, _) = R.spinup(t + h, ws, T), R.spinup(t - h, ws, T)
    assert np.max(np.abs((qp - qm) / (2 * h) - qd)) < 1e-6 * ws
    assert np.max(np.abs((qdp - qdm) / (2 * h) - qdd)) < 1e-5 * ws / T
    q, qd, qdd = R.constant_speed(t, 0.5, 20.0)
    assert q.shape == (300, 1) and np.allclose(q[:, 0], 0.5 + 20 * t) and np.all(qd == 20)
    fb = R.FourBar.open_assembly(*TM)
    R.check_motion(fb, R.spinup(np.linspace(0, 1, 500), 150.0, 0.3)[0])   # crank-rocker: fine
