"""Physics tests of the planar Euler-Bernoulli beam element and its KED assembly.

Local element DOFs [p1, v1, th1, p2, v2, th2]; global [u1, w1, th1, u2, w2, th2]
with delta_local = T(phi) s.  Everything below is checked against closed forms or
against independent NumPy re-implementations (own shape functions, own quadrature).
"""
import numpy as np
import pytest
import scipy.linalg as sl
from numpy.polynomial import Polynomial
from scipy.optimize import brentq

import flexmech_py as fm
from flexmech_py.base import kernels
from flexmech_py.models.superposition.model import FEModel

OMEGA = np.array([[0.0, -1.0], [1.0, 0.0]])
RNG_SEED = 20240611


# ----------------------------------------------------------------------------- helpers
def rot(phi):
    """R(phi): element -> global components (rotation by +phi)."""
    c, s = np.cos(phi), np.sin(phi)
    return np.array([[c, -s], [s, c]])


def tmat(phi):
    """T(phi) = blockdiag(Q, 1, Q, 1), Q = R^T: delta_local = T s_global."""
    t = np.eye(6)
    t[0:2, 0:2] = t[3:5, 3:5] = rot(phi).T
    return t


def shape_n(xi, length):
    """Seed Eq. 11-12 shape functions N(xi), shape (..., 2, 6)."""
    xi = np.asarray(xi, float)
    n = np.zeros(xi.shape + (2, 6))
    n[..., 0, 0], n[..., 0, 3] = 1 - xi, xi
    n[..., 1, 1] = 1 - 3 * xi**2 + 2 * xi**3
    n[..., 1, 2] = length * (xi - 2 * xi**2 + xi**3)
    n[..., 1, 4] = 3 * xi**2 - 2 * xi**3
    n[..., 1, 5] = length * (-xi**2 + xi**3)
    return n


def shape_n0(xi):
    """Hac's rigid shape function N0(xi), shape (..., 2, 4) on [a_p1, a_v1, a_p2, a_v2]."""
    xi = np.asarray(xi, float)
    n0 = np.zeros(xi.shape + (2, 4))
    n0[..., 0, 0] = n0[..., 0, 2] = 0.5
    n0[..., 1, 1], n0[..., 1, 3] = 1 - xi, xi
    return n0


def gauss01(npts=8):
    """Gauss-Legendre points on [0, 1] and weights summing to 1."""
    x, w = np.polynomial.legendre.leggauss(npts)
    return 0.5 * (x + 1), 0.5 * w


def rel(a, b):
    return np.linalg.norm(np.asarray(a) - np.asarray(b)) / np.linalg.norm(b)


def cantilever(n_el, length=1.0, area=1e-4, second_moment=1e-9, youngs=2e11, density=7800.0):
    """A one-link serial chain clamped at (0, 0), meshed with n_el elements."""
    case = fm.validate_case({
        "mechanism": {"type": "serial"},
        "links": [{"name": "beam", "length": length, "area": area, "second_moment": second_moment,
                   "youngs_modulus": youngs, "density": density, "elements": n_el}],
        "drive": {"type": "kinematic", "law": "constant_speed", "speed": 0.0},
        "solver": {"t_end": 0.01, "dt": 1e-4},
        "outputs": {"tip_v": {"kind": "displacement", "at": "beam.end", "component": "transverse"}}})
    return FEModel.from_case(case)


def element_dofs(fe, link, k):
    """0-based global DOFs [u1, w1, th1, u2, w2, th2] of element k of a link (from node bookkeeping)."""
    n1, n2 = fe.node_of[link][k], fe.node_of[link][k + 1]
    return np.r_[fe.trans_dof[n1], fe.rot_dof[(n1, link)], fe.trans_dof[n2], fe.rot_dof[(n2, link)]]


def rig_sample(phi, omega=0.0, alpha=0.0, aox=0.0, aoy=0.0):
    return np.array([[phi], [omega], [alpha], [aox], [aoy]], float)


PROPS = [(0.78, 1.0), (2.7 * 0.406, 0.09)]   # (rho*A [kg/m], element length [m])


# ----------------------------------------------------------------------------- 1. closed forms
@pytest.mark.parametrize("rho_a, length", PROPS)
def test_mass_stiffness_coupling_closed_forms(rho_a, length):
    ea, ei, L = 2e7, 200.0, length
    m, k, g, c, m0 = kernels.element_matrices(rho_a, ea, ei, L)
    ax, tr = [0, 3], [1, 2, 4, 5]
    m_ref = np.zeros((6, 6))
    m_ref[np.ix_(ax, ax)] = rho_a * L / 6 * np.array([[2, 1], [1, 2]])
    m_ref[np.ix_(tr, tr)] = rho_a * L / 420 * np.array([
        [156, 22 * L, 54, -13 * L], [22 * L, 4 * L**2, 13 * L, -3 * L**2],
        [54, 13 * L, 156, -22 * L], [-13 * L, -3 * L**2, -22 * L, 4 * L**2]])
    k_ref = np.zeros((6, 6))
    k_ref[np.ix_(ax, ax)] = ea / L * np.array([[1, -1], [-1, 1]])
    k_ref[np.ix_(tr, tr)] = ei / L**3 * np.array([
        [12, 6 * L, -12, 6 * L], [6 * L, 4 * L**2, -6 * L, 2 * L**2],
        [-12, -6 * L, 12, -6 * L], [6 * L, 2 * L**2, -6 * L, 4 * L**2]])
    # m0 = rho_a int N^T N0, integrated by hand (axial: int (1-xi)/2 = 1/4, ...)
    m0_ref = np.zeros((6, 4))
    m0_ref[np.ix_(ax, [0, 2])] = L / 4
    m0_ref[np.ix_(tr, [1, 3])] = np.array([[7 * L / 20, 3 * L / 20], [L**2 / 20, L**2 / 30],
                                           [3 * L / 20, 7 * L / 20], [-L**2 / 30, -L**2 / 20]])
    m0_ref *= rho_a
    # 4-point Gauss is exact for these degree <= 6 polynomials: only rounding remains (1e-13).
    for got, ref in ((m, m_ref), (k, k_ref), (m0, m0_ref)):
        np.testing.assert_allclose(got, ref, rtol=1e-13, atol=1e-13 * np.abs(ref).max())


# ----------------------------------------------------------------------------- 2. rigid modes
@pytest.mark.parametrize("phi", [0.0, 0.7, -2.3])
def test_rigid_body_modes_store_no_strain_energy(phi):
    L = 0.37   # EA/L ~ EI/L^3 so neither block hides rounding-level errors of the other
    k = kernels.element_matrices(1.0, 3.0, 0.5, L)[1]
    local = [np.array([1.0, 0, 0, 1, 0, 0]), np.array([0, 1.0, 0, 0, 1, 0]), np.array([0, 0, 1.0, 0, L, 1])]
    c, s = np.cos(phi), np.sin(phi)
    glob = [np.array([1.0, 0, 0, 1, 0, 0]), np.array([0, 1.0, 0, 0, 1, 0]),
            np.array([0, 0, 1.0, -L * s, L * c, 1])]   # small rotation about node 1, global components
    kg = tmat(phi).T @ k @ tmat(phi)
    # k x is a difference of O(|k||x|) terms: 1e-12 relative leaves room for rounding only.
    for kk, modes in ((k, local), (kg, glob)):
        for x in modes:
            assert np.linalg.norm(kk @ x) <= 1e-12 * np.linalg.norm(kk) * np.linalg.norm(x)


# ----------------------------------------------------------------------------- 3. Lagrange check
def central_diff(f, x, h):
    """Fourth-order central difference f'(x) (5-point stencil)."""
    return (f(x - 2 * h) - 8 * f(x - h) + 8 * f(x + h) - f(x + 2 * h)) / (12 * h)


def lagrange_residual(rho_a, L, phi0, om0, al, s0, sd0, sdd0):
    """d/dt(dT/d sdot) - dT/ds at t = 0, all derivatives by finite differences of T."""
    xq, wq = gauss01(8)
    nq = shape_n(xq, L)

    def brt(t):  # R N T at all Gauss points, (nq, 2, 6)
        ph = phi0 + om0 * t + 0.5 * al * t**2
        return rot(ph) @ nq @ tmat(ph)

    def kinetic(t, s, sd):
        vel = central_diff(brt, t, 1e-3) @ s + brt(t) @ sd          # (nq, 2)
        return 0.5 * rho_a * L * np.sum(wq * np.sum(vel**2, axis=1))

    def grad(fun, x, d=1.0):  # T is quadratic in s and in sdot: central differences are exact
        return np.array([(fun(x + d * e) - fun(x - d * e)) / (2 * d) for e in np.eye(6)])

    def p_of_t(t):
        s, sd = s0 + sd0 * t + 0.5 * sdd0 * t**2, sd0 + sdd0 * t
        return grad(lambda v: kinetic(t, s, v), sd)

    return central_diff(p_of_t, 0.0, 1e-3) - grad(lambda v: kinetic(0.0, v, sd0), s0)


@pytest.mark.parametrize("part", ["mass", "gyroscopic", "inertia_stiffness", "all"])
def test_coriolis_and_inertia_stiffness_from_kinetic_energy(part):
    rng = np.random.default_rng(RNG_SEED)
    rho_a, L, phi0, om0, al = 1.7, 0.45, 0.8, 3.1, -4.7
    s0, sd0, sdd0 = (rng.standard_normal(6) for _ in range(3))
    s0 = s0 if part in ("inertia_stiffness", "all") else 0 * s0
    sd0 = sd0 if part in ("gyroscopic", "all") else 0 * sd0
    sdd0 = sdd0 if part in ("mass", "all") else 0 * sdd0
    m, k, g, c, m0 = kernels.element_matrices(rho_a, 1.0, 1.0, L)
    t = tmat(phi0)
    ref = t.T @ m @ t @ sdd0 + 2 * om0 * t.T @ g @ t @ sd0 + t.T @ (al * g + om0**2 * c) @ t @ s0
    got = lagrange_residual(rho_a, L, phi0, om0, al, s0, sd0, sdd0)
    # 5-point stencils with h = 1e-3 s, |omega| ~ 3: truncation ~ (omega h)^4 ~ 1e-10,
    # rounding ~ eps/h^2 ~ 1e-10; 1e-6 is far above both and far below any term error.
    assert rel(got, ref) < 1e-6, (got, ref)


# ----------------------------------------------------------------------------- 4. static cantilever
@pytest.mark.parametrize("n_el", [1, 3, 8])
@pytest.mark.parametrize("phi", [0.0, 0.7])
def test_static_cantilever_tip_load(n_el, phi):
    L, E, A, I, P = 1.0, 2e11, 1e-4, 1e-8, 3.0
    fe = cantilever(n_el, length=L, area=A, second_moment=I, youngs=E)
    K = fe.matrices(rig_sample(phi), model="classic")[2]
    tip = fe.node_of[0][-1]
    e, n = np.array([np.cos(phi), np.sin(phi)]), np.array([-np.sin(phi), np.cos(phi)])

    def solve(direction):
        f = np.zeros(fe.ndof)
        f[fe.trans_dof[tip]] = P * direction
        x = fe.expand(np.linalg.solve(K, fe.restrict(f)))
        return x[fe.trans_dof[tip]], x[fe.rot_dof[(tip, 0)]]

    # Hermite cubics contain the exact cubic deflection: only rounding is left, ~eps*cond(K)
    # (cond ~ EA Le^2/EI * n^4 after rotation mixes axial and bending rows): 1e-10 relative.
    d, th = solve(n)
    assert d @ n == pytest.approx(P * L**3 / (3 * E * I), rel=1e-10)
    assert th == pytest.approx(P * L**2 / (2 * E * I), rel=1e-10)
    assert abs(d @ e) <= 1e-10 * (d @ n)
    d, th = solve(e)
    assert d @ e == pytest.approx(P * L / (E * A), rel=1e-10)
    assert abs(d @ n) <= 1e-10 * (d @ e) and abs(th) <= 1e-10 * (d @ e) / L


def test_static_cantilever_curvature_is_bending_moment_over_ei():
    L, E, I, P, n_el, phi = 1.2, 2e11, 1e-8, 5.0, 4, 0.7
    fe = cantilever(n_el, length=L, second_moment=I, youngs=E)
    K = fe.matrices(rig_sample(phi), model="classic")[2]
    f = np.zeros(fe.ndof)
    f[fe.trans_dof[fe.node_of[0][-1]]] = P * np.array([-np.sin(phi), np.cos(phi)])
    x = fe.expand(np.linalg.solve(K, fe.restrict(f)))
    le = L / n_el
    for k in range(n_el):
        dg = x[element_dofs(fe, 0, k)][:, None]
        for xi in (0.0, 0.3, 1.0):
            kappa = kernels.element_curvatures(dg, np.array([phi]), le, xi)[0]
            # exact (the FE solution is the exact cubic); rounding as in the test above
            assert kappa == pytest.approx(P * (L - (k + xi) * le) / (E * I), rel=1e-9, abs=1e-12 * P * L / (E * I))


# ----------------------------------------------------------------------------- 5. frequencies
BETA_L = [1.8751041, 4.6940911, 7.8547574]


def exact_beta_l():
    """Roots of 1 + cos(x) cosh(x) = 0 to machine precision (the 8-digit table limits errors to ~1e-7)."""
    roots = np.array([brentq(lambda x: 1 + np.cos(x) * np.cosh(x), a, b) for a, b in ((1, 3), (4, 5.5), (7, 9))])
    np.testing.assert_allclose(roots, BETA_L, rtol=1e-7)
    return roots


def bending_frequencies(n_el, phi, E=2e11, A=1e-4, I=1e-9, rho=7800.0, L=1.0):
    """Bending natural frequencies [rad/s] of the cantilever from eig(K, M) at omega = alpha = 0.

    Modes are told apart by their shape, not by magnitude: a mode is 'axial' if its
    displacements along the beam axis e carry kinetic energy, 'bending' if they carry
    none (< 1e-8 of x^T M x: at omega = alpha = 0 the two families decouple exactly).
    """
    fe = cantilever(n_el, length=L, area=A, second_moment=I, youngs=E, density=rho)
    M, _, K, _ = fe.matrices(rig_sample(phi), model="classic")
    lam, X = sl.eigh(K, M)
    e = np.array([np.cos(phi), np.sin(phi)])
    P = np.zeros((fe.ndof, fe.ndof))
    for node in fe.node_of[0]:
        P[np.ix_(fe.trans_dof[node], fe.trans_dof[node])] = np.outer(e, e)
    Xa = fe.restrict(P @ fe.expand(X))                       # axial part of each mode
    frac = np.einsum("ij,ij->j", Xa, M @ Xa) / np.einsum("ij,ij->j", X, M @ X)
    assert np.all((frac < 1e-8) | (frac > 1 - 1e-8)), "modes mix axial and bending motion"
    return np.sqrt(lam[frac < 1e-8])


@pytest.mark.parametrize("phi", [0.0, 0.7])
def test_cantilever_bending_frequencies_converge_at_fourth_order(phi):
    E, A, I, rho, L = 2e11, 1e-4, 1e-9, 7800.0, 1.0
    exact = exact_beta_l() ** 2 * np.sqrt(E * I / (rho * A * L**4))
    meshes = [2, 4, 8, 16]
    err = np.array([bending_frequencies(n, phi)[:3] / exact - 1 for n in meshes])   # (mesh, mode)
    assert np.all(err > 0), "consistent-mass Rayleigh-Ritz frequencies are upper bounds"
    assert np.all(np.diff(err, axis=0) < 0), err
    order = np.log2(err[:-1] / err[1:])
    # Hermite cubics: frequency error O(h^4).  Mode 2 is pre-asymptotic on 2 elements
    # (observed order 2->4 elements ~2.9), so its order is checked from 4 elements on.
    assert np.all((3.5 < order[:, 0]) & (order[:, 0] < 4.5)), order
    assert np.all((3.5 < order[1:, 1]) & (order[1:, 1] < 4.5)), order
    assert err[-1, 0] < 1e-5


# ----------------------------------------------------------------------------- 6. rigid-inertia loads
def reference_loads(fe, rig, model):
    """rho_a int (R N T)^T a dzeta over each element, own quadrature, assembled over all DOFs."""
    phi, om, al, aox, aoy = rig[:, 0]
    R, T = rot(phi), tmat(phi)
    e = np.array([np.cos(phi), np.sin(phi)])
    ln = fe.case["links"][0]
    rho_a, n_el = ln["density"] * ln["area"], fe.n_el[0]
    le = ln["length"] / n_el
    xq, wq = gauss01(8)

    def a_rigid(z):  # (..., 2) rigid acceleration of the point zeta
        z = np.asarray(z)[..., None]
        return np.array([aox, aoy]) + al * (OMEGA @ e) * z - om**2 * e * z

    f = np.zeros(fe.ndof)
    for k in range(n_el):
        z1 = k * le
        B = R @ shape_n(xq, le) @ T                          # (nq, 2, 6)
        if model == "classic":
            a = a_rigid(z1 + xq * le)
        else:   # hac: R N0 T0 xdd0, xdd0 = global rigid accelerations of the two nodes
            T0 = sl.block_diag(R.T, R.T)
            xdd0 = np.r_[a_rigid(z1), a_rigid(z1 + le)]
            a = R @ shape_n0(xq) @ (T0 @ xdd0)
        fe_el = rho_a * le * np.einsum("q,qji,qj->i", wq, B, a)
        f[element_dofs(fe, 0, k)] += fe_el
    return f


@pytest.mark.parametrize("model", ["classic", "hac"])
@pytest.mark.parametrize("n_el", [1, 3])
def test_rigid_inertia_loads(model, n_el):
    fe = cantilever(n_el, length=0.8, area=3e-4, density=2700.0)
    rig = rig_sample(phi=0.7, omega=3.0, alpha=-5.0, aox=1.2, aoy=-9.81 + 0.4)
    f = fe.matrices(rig, model=model)[3]
    # all integrands are polynomials of degree <= 4 in xi: 8-point Gauss is exact; rounding only.
    assert rel(f, reference_loads(fe, rig, model)) < 1e-12


# ----------------------------------------------------------------------------- 7. curvature kernel
def hermite_curvature_by_hand(dloc, length, xi):
    """v'' = d^2/dzeta^2 of the Hermite field, from polynomials in xi differentiated twice."""
    L = length
    polys = [Polynomial([1, 0, -3, 2]), Polynomial([0, L, -2 * L, L]),
             Polynomial([0, 0, 3, -2]), Polynomial([0, 0, -L, L])]
    return sum(p.deriv(2)(xi) * d for p, d in zip(polys, dloc[[1, 2, 4, 5]])) / L**2


@pytest.mark.parametrize("xi", [0.0, 0.25, 0.5, 0.9, 1.0])
def test_element_curvatures(xi):
    rng = np.random.default_rng(RNG_SEED + 7)
    n, length = 5, 0.23
    dloc = rng.standard_normal((6, n)) * np.array([[1e-3], [1e-3], [1e-2], [1e-3], [1e-3], [1e-2]])
    phi = rng.uniform(-np.pi, np.pi, n)
    dglob = np.stack([tmat(p).T @ d for p, d in zip(phi, dloc.T)], axis=1)
    got = kernels.element_curvatures(dglob, phi, length, xi)
    ref = np.array([hermite_curvature_by_hand(d, length, xi) for d in dloc.T])
    # a few flops on O(1e-3/L^2) terms: rounding only
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-14 * np.abs(ref).max())
