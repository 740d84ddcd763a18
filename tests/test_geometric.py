"""Geometric stiffness K_sigma (axial-force effect) of the superposition models."""

import numpy as np
import pytest
import scipy.linalg as sl

import flexmech_py as fm
from flexmech_py.base import kernels


def _pinned_pinned(n, L=1.0, EI=10.0, EA=1e6, rho_a=1.0):
    """Dense K, K_sigma (unit tension) and M of a pinned-pinned beam of n elements along X (local DOFs)."""
    le = L / n
    nd = 3 * (n + 1)
    K = np.zeros((nd, nd)); G = np.zeros((nd, nd)); M = np.zeros((nd, nd))
    m, k, *_ = kernels.element_matrices(rho_a, EA, EI, le)
    kg = kernels.geometric_stiffness(le)
    for e in range(n):
        s = slice(3 * e, 3 * e + 6)
        K[s, s] += k; G[s, s] += kg; M[s, s] += m
    keep = [i for i in range(nd) if i not in (0, 1, nd - 2)]   # pins: u, v at node 0; v at node n (u free)
    return K[np.ix_(keep, keep)], G[np.ix_(keep, keep)], M[np.ix_(keep, keep)]


def test_geometric_stiffness_closed_form():
    L = 0.7
    kg = kernels.geometric_stiffness(L)
    t = [1, 2, 4, 5]
    ref = 1 / (30 * L) * np.array([[36, 3 * L, -36, 3 * L], [3 * L, 4 * L**2, -3 * L, -L**2],
                                   [-36, -3 * L, 36, -3 * L], [3 * L, -L**2, -3 * L, 4 * L**2]])
    assert np.allclose(kg[np.ix_(t, t)], ref, rtol=1e-14)
    assert np.all(kg[0] == 0) and np.all(kg[3] == 0)


def test_buckling_load_converges_to_euler():
    """Smallest P with det(K - P K_sigma) = 0 tends to pi^2 EI / L^2 (from above, order h^2)."""
    EI, L = 10.0, 1.0
    pe = np.pi**2 * EI / L**2
    errs = []
    for n in (2, 4, 8):
        K, G, _ = _pinned_pinned(n, L, EI)
        lam = sl.eigvals(K, G).real
        p = np.min(lam[lam > 0])
        errs.append(p / pe - 1)
    assert errs[-1] < 1e-4 and all(e > 0 for e in errs)
    assert np.log2(errs[1] / errs[2]) > 1.8


@pytest.mark.parametrize("ratio", [-0.5, 0.5, 2.0])
def test_first_frequency_under_axial_force(ratio):
    """omega_1(N) = omega_1(0) sqrt(1 + N/N_E) for a pinned-pinned beam (the sine mode, exact in the
    mesh limit); N > 0 tension."""
    EI, L = 10.0, 1.0
    pe = np.pi**2 * EI / L**2
    K, G, M = _pinned_pinned(16, L, EI)

    def w1(Kt):
        ev = np.sort(sl.eigvals(Kt, M).real)
        return np.sqrt(ev[ev > 1e-9][0])

    assert w1(K + ratio * pe * G) / w1(K) == pytest.approx(np.sqrt(1 + ratio), rel=1e-4)


def test_seed_fourbar_sources(cases_dir):
    """On the seed four-bar (first 0.1 s, 8 elements per link): the quasi-static K_sigma brings the
    coupler strain much closer to the nonlinear model than no K_sigma; the one-step lag is unstable."""
    base = ["solver.t_end=0.1"]
    nl = fm.simulate(fm.load_case(cases_dir / "fourbar_hac.toml", overrides=base), model="nonlinear",
                     elements_per_link=16)
    ref = nl["strain_coupler_mid"]

    def err(src):
        c = fm.load_case(cases_dir / "fourbar_hac.toml", overrides=base + [f'solver.geometric_stiffness="{src}"'])
        r = fm.simulate(c, model="classic", elements_per_link=8)
        return np.max(np.abs(r["strain_coupler_mid"] - ref)) / np.max(np.abs(ref)), r

    e_none, r0 = err("none")
    e_qs, _ = err("quasi_static")
    e_cur, _ = err("current")
    print(f"\ncoupler strain vs nonlinear, 0.1 s: none {e_none:.3f}, quasi-static {e_qs:.3f}, current {e_cur:.3f}")
    assert e_qs < 0.5 * e_none
    assert r0.extra["validity"]["follower"]["max_compression_over_euler"] > 0.3   # 0.47 by 0.1 s, 4 by 0.15 s
    c = fm.load_case(cases_dir / "fourbar_hac.toml", overrides=["solver.t_end=0.15", 'solver.geometric_stiffness="lagged"'])
    with pytest.raises(fm.SolverError) as err:                # the lagged axial force blows up: the
        fm.simulate(c, model="classic", elements_per_link=8)  # divergence guard stops it (measured t = 0.1432 s)
    assert err.value.code == 6 and 0.1 < err.value.time < 0.15


@pytest.mark.parametrize("model, balanced", [("classic", True), ("hac", True), ("classic-translational", False)])
def test_torque_joint_mode_carries_no_net_rigid_body_load(cases_dir, model, balanced):
    """With the crank pivot left free ('torque'), the mechanism's own motion is a zero-stiffness mode of
    the elastic problem; the applied torque and the rigid-inertia load balance on it (the rigid-body
    equations of motion), so the net load on the mode vanishes to round-off for the exact loads."""
    from flexmech_py.run.simulate import Prepared
    case = fm.load_case(cases_dir / "fourbar_hac.toml", overrides=['joints.crank_pivot="torque"', "solver.t_end=0.05"])
    p = Prepared(case)
    fe = p.fe
    worst = 0.0
    for i in (100, 2500, 5000):
        _, _, k, f = fe.matrices(p.rig[:, :, i] * np.array([1, 0, 0, 0, 0])[:, None], model)
        _, _, _, f = fe.matrices(p.rig[:, :, i], model)
        ev, vec = np.linalg.eigh(0.5 * (k + k.T))
        mode = vec[:, np.argmin(np.abs(ev))]
        q = np.zeros(fe.nfree)
        q[p.q_free - 1] = p.q_val[:, i]
        load = q - fe.restrict(f)
        worst = max(worst, abs(mode @ load) / np.linalg.norm(fe.restrict(f)))
    print(f"\n{model}: net load on the mechanism mode / |F| = {worst:.2e}")
    assert (worst < 1e-8) if balanced else (worst > 1e-4)


def test_torque_joint_needs_a_torque(cases_dir):
    with pytest.raises(fm.CaseError, match="joints.follower_pivot"):
        fm.load_case(cases_dir / "fourbar_hac.toml", overrides=['joints.follower_pivot="torque"'])
