"""A small, straightforward NumPy implementation of the superposition KED equations.

It is the reference the compiled kernels are checked against (tests/test_kernels.py) and
the baseline ``flexmech bench`` times them against: element matrices by Gauss quadrature
of the shape functions, dense global matrices, and the Newmark loop with
``numpy.linalg.solve``.  Written for clarity, not speed; it shares no code with the Fortran.
"""

from __future__ import annotations

import numpy as np

from ...base.families import family

OMEGA = np.array([[0.0, -1.0], [1.0, 0.0]])


def shape_n(xi, L):
    """2 x 6 elastic shape-function matrix (seed Eq. 11-12) at xi = zeta/L."""
    return np.array([[1 - xi, 0, 0, xi, 0, 0],
                     [0, 1 - 3 * xi**2 + 2 * xi**3, L * (xi - 2 * xi**2 + xi**3), 0, 3 * xi**2 - 2 * xi**3,
                      L * (-xi**2 + xi**3)]])


def shape_n0(xi):
    """2 x 4 rigid-body shape function of Hac (seed Eq. 4)."""
    return np.array([[0.5, 0, 0.5, 0], [0, 1 - xi, 0, xi]])


E6 = np.zeros((6, 6))
E6[0:2, 0:2] = OMEGA
E6[3:5, 3:5] = OMEGA


def element_matrices(rho_a, ea, ei, L, npts=6):
    """(m, k, g, c, m0) local element matrices, see flexmech_beam.f90."""
    x, w = np.polynomial.legendre.leggauss(npts)
    xi, w = 0.5 * (x + 1), 0.5 * w * L * rho_a
    m = np.zeros((6, 6)); g = np.zeros((6, 6)); c = np.zeros((6, 6)); m0 = np.zeros((6, 4))
    for xq, wq in zip(xi, w):
        n = shape_n(xq, L)
        d = OMEGA @ n - n @ E6
        m += wq * n.T @ n
        g += wq * n.T @ d
        c += wq * n.T @ (OMEGA @ d - d @ E6)
        m0 += wq * n.T @ shape_n0(xq)
    k = np.zeros((6, 6))
    k[np.ix_([0, 3], [0, 3])] = ea / L * np.array([[1, -1], [-1, 1]])
    b = np.array([[12, 6 * L, -12, 6 * L], [6 * L, 4 * L**2, -6 * L, 2 * L**2],
                  [-12, -6 * L, 12, -6 * L], [6 * L, 2 * L**2, -6 * L, 4 * L**2]])
    k[np.ix_([1, 2, 4, 5], [1, 2, 4, 5])] = ei / L**3 * b
    return m, k, g, c, m0


def transformation(phi):
    c, s = np.cos(phi), np.sin(phi)
    q = np.array([[c, s], [-s, c]])
    t = np.eye(6)
    t[0:2, 0:2] = q
    t[3:5, 3:5] = q
    return t


def system(fe, rig, model, rayleigh=(0.0, 0.0)):
    """Dense M, C, K over ALL DOFs and the rigid-inertia load F over all DOFs at one rigid sample."""
    n = fe.ndof
    M = np.zeros((n, n)); C = np.zeros((n, n)); K = np.zeros((n, n)); F = np.zeros(n)
    for e in range(fe.nel):
        j = fe.el_link[e] - 1
        L, z0, ra, ea, ei = fe.el_prop[:, e]
        m, k, g, c, m0 = element_matrices(ra, ea, ei, L)
        phi, om, al, ax, ay = rig[:, j]
        t = transformation(phi)
        dofs = fe.el_dof[:, e] - 1
        ce = 2 * om * g + rayleigh[0] * m + rayleigh[1] * k
        ke = k + al * g + om**2 * c
        idx = np.ix_(dofs, dofs)
        M[idx] += t.T @ m @ t
        C[idx] += t.T @ ce @ t
        K[idx] += t.T @ ke @ t
        ap = t[0:2, 0:2] @ np.array([ax, ay])
        a1 = [ap[0] - om**2 * z0, ap[1] + al * z0]
        a2 = [ap[0] - om**2 * (z0 + L), ap[1] + al * (z0 + L)]
        fam = family(model)
        if fam.load_mass == "translational":
            fl = m0 @ np.array([a1[0], a1[1], a2[0], a2[1]])
        else:
            rot = al if fam.rotary_loads else 0.0
            fl = m @ np.array([a1[0], a1[1], rot, a2[0], a2[1], rot])
        F[dofs] += t.T @ fl
    for i in range(fe.lm_link.size):
        j = fe.lm_link[i] - 1
        mass, z = fe.lm_prop[:, i]
        phi, om, al, ax, ay = rig[:, j]
        e = np.array([np.cos(phi), np.sin(phi)])
        a = np.array([ax, ay]) + al * z * (OMEGA @ e) - om**2 * z * e
        dofs = fe.lm_dof[:, i] - 1
        M[dofs, dofs] += mass
        C[dofs, dofs] += rayleigh[0] * mass
        F[dofs] += mass * a
    for i in range(fe.ri_link.size):
        d = fe.ri_dof[i] - 1
        M[d, d] += fe.ri_prop[i]
        C[d, d] += rayleigh[0] * fe.ri_prop[i]
        if family(model).rotary_loads:
            F[d] += fe.ri_prop[i] * rig[2, fe.ri_link[i] - 1]
    return M, C, K, F


def slave_transformation(fe, rig1):
    """(T, T', T'') (ndof, nfree): all DOFs u = T w in terms of the free DOFs w at one rigid sample,
    identity rows for the free DOFs, the slave rows of fe.slaving (zero rows for fixed DOFs)."""
    t = np.zeros((3, fe.ndof, fe.nfree))
    free = np.flatnonzero(fe.free_of > 0)
    t[0, free, fe.free_of[free] - 1] = 1.0
    sl = fe.slaving
    if sl is not None and sl.nsl:
        rows = sl._solve(rig1[:, :, None])
        cols = fe.free_of[sl.masters] - 1
        for k in range(3):
            t[k][np.ix_(sl.slaves, cols)] = rows[k][:, 0, :]
    return t


def newmark(fe, rig, model, dt, beta=0.25, gamma=0.5, rayleigh=(0.0, 0.0), q_all=None):
    """Newmark run over rig (5, ncols, nsteps+1); returns u (nfree, nsteps+1).

    q_all (ndof, nsteps+1): applied generalized forces over all DOFs (optional).  With slave
    relations the dense all-DOF system is reduced with u = T w: T^T M T, T^T (2 M T' + C T),
    T^T (M T'' + C T' + K T), T^T (Q - F).
    """
    ns = rig.shape[2]

    def mats(i):
        M, C, K, F = system(fe, rig[:, :, i], model, rayleigh)
        rhs = -F if q_all is None else q_all[:, i] - F
        t, td, tdd = slave_transformation(fe, rig[:, :, i])
        return t.T @ M @ t, t.T @ (2 * M @ td + C @ t), t.T @ (M @ tdd + C @ td + K @ t), t.T @ rhs

    nf = fe.nfree
    u = np.zeros((nf, ns)); v = np.zeros(nf)
    M, C, K, r = mats(0)
    a = np.linalg.solve(M, r)
    for i in range(1, ns):
        up = u[:, i - 1] + dt * v + dt**2 * (0.5 - beta) * a
        vp = v + dt * (1 - gamma) * a
        M, C, K, r = mats(i)
        a = np.linalg.solve(M + gamma * dt * C + beta * dt**2 * K, r - C @ vp - K @ up)
        u[:, i] = up + beta * dt**2 * a
        v = vp + gamma * dt * a
    return u
