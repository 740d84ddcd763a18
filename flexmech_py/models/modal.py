"""The frozen eigenproblem of each model at one configuration of the rigid motion (docs/theory.md
section 19): natural frequencies, mass-normalized mode vectors and the rigid-body (mechanism) modes
among them.  User-facing commands and files: :mod:`flexmech_py.studies.modes`.

- Superposition models: (K + K_c [+ K_sigma]) x = w^2 M x over the free DOFs after the slave
  relations, the matrices the run uses at that rigid sample (flexmech_py.models.superposition.model.FEModel.matrices);
  K_sigma from the quasi-static axial forces there (the run's ``quasi_static`` source).
- Coupled and nonlinear models: linearized about their quasi-static state at that instant (the
  rigid motion's velocities and accelerations held, the elastic DOFs in equilibrium with the inertia,
  gravity and drive loads), K_T = dR/dq + sum_i lambda_i d2g_i/dq2 by central differences of the
  kernel's residual and of its constraint gradients, the constraints eliminated on the null space
  N of their Jacobian G: (N^T K_T N) y = w^2 (N^T M N) y.

In both, the velocity-dependent terms (gyroscopic, Coriolis, damping) are left out and K and M are
symmetrized: undamped frozen frequencies.  The zero-stiffness subspace of the elastic stiffness alone
(the mechanism's own free degrees of freedom: a force-driven joint left free with ``torque`` or
``force``; the coupled models hold one whose condition is ``clamp``/``locked``, as the superposition
models do) is set apart: its M-orthonormal vectors are the rigid-body modes, reported at frequency 0,
and the elastic modes are those of the problem restricted to its M-orthogonal complement (the frozen
inertia terms along a free motion are no vibration: left in, they gave the seed four-bar's free crank
-2.86 Hz in the coupled models and 16.5 Hz at t = 0.1 s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .constrained.layout import CON_ANGLE
from ..base.errors import SolverError
from .superposition.model import squared_frequencies

__all__ = ["Eigen", "signed_sqrt", "select_modes", "rigid_apart", "superposition_eigen", "superposition_frequencies",
           "quasi_static_axial", "coupled_eigen", "coupled_linearized", "Linearized", "free_order", "rigid_subspace",
           "ZERO_STIFFNESS", "RIGID_FRACTION"]

#: eigenvalues of (K_elastic, M) below this fraction of the largest are zero-stiffness (rigid-body)
#: modes: they sit at round-off (~1e-16 of the largest), real modes above ~1e-10 even with 256 elements
#: per link (flexmech_py.run.simulate.check_elastic_problem uses the same separation)
ZERO_STIFFNESS = 1e-12
#: a mode with more than this fraction of its kinetic energy in the rigid-body subspace is reported as a
#: rigid-body mode
RIGID_FRACTION = 0.5
QS_MAXIT = 40           # Newton iterations of the coupled models' quasi-static state at most
QS_TOL = 1e-11          # ... until the update is below QS_TOL x the mechanism's length
QS_MAXSTEP = 0.1        # an update larger than this x the mechanism's length is scaled down to it
FD_STEP = 1e-6          # central-difference step x the mechanism's length (positions; angles alike)


@dataclass
class Eigen:
    """Frozen eigenpairs at one configuration: ``lam`` w^2 [rad^2/s^2] ascending, ``x`` (nfree, n)
    mass-normalized vectors over the model's free DOFs (None without vectors), ``rigid_fraction`` (n,)
    the share of each mode's kinetic energy in the rigid-body subspace, ``q`` the state linearized
    about (coupled models: all DOFs; None for the superposition models)."""

    lam: np.ndarray
    x: np.ndarray | None
    rigid_fraction: np.ndarray
    q: np.ndarray | None = None

    @property
    def omega(self) -> np.ndarray:
        return signed_sqrt(self.lam)

    @property
    def rigid(self) -> np.ndarray:
        return self.rigid_fraction > RIGID_FRACTION


def signed_sqrt(lam) -> np.ndarray:
    """sign(w^2) sqrt|w^2| [rad/s]: a negative value marks a frozen configuration unstable in that mode."""
    lam = np.asarray(lam, float)
    return np.sign(lam) * np.sqrt(np.abs(lam))


def rigid_subspace(m: np.ndarray, k_el: np.ndarray, basis: np.ndarray | None = None) -> np.ndarray:
    """M-orthonormal basis (n, r) of the zero-stiffness modes of the elastic stiffness k_el (the
    mechanism's free motions), in the coordinates of m (on the columns of ``basis`` when given:
    m and k_el reduced onto it, the result mapped back)."""
    if basis is not None:
        m, k_el = basis.T @ m @ basis, basis.T @ k_el @ basis
    lam, x = squared_frequencies(m, k_el, vectors=True)
    z = x[:, np.abs(lam) < ZERO_STIFFNESS * max(np.max(np.abs(lam)), 1e-300)]
    return z if basis is None else basis @ z


def rigid_apart(m: np.ndarray, k: np.ndarray, z: np.ndarray) -> Eigen:
    """Eigenpairs of (k, m) with the rigid-body motions z (n, r) set apart: the r rigid modes (the
    columns of z made M-orthonormal, w^2 = 0 exactly) and the elastic modes of the problem restricted
    to the M-orthogonal complement of z, in ascending w^2 (without rigid motions: the plain problem)."""
    m = 0.5 * (m + m.T)
    if z.shape[1] == 0:
        lam, x = squared_frequencies(m, k, vectors=True)
        return Eigen(lam, x, np.zeros(lam.size))
    g, v = np.linalg.eigh(z.T @ m @ z)
    keep = g > ZERO_STIFFNESS * g.max()
    z = z @ (v[:, keep] / np.sqrt(g[keep]))
    w = _null_space((m @ z).T, m.shape[0])
    lam, y = squared_frequencies(w.T @ m @ w, w.T @ k @ w, vectors=True)
    lam = np.concatenate([np.zeros(z.shape[1]), lam])
    x = np.hstack([z, w @ y])
    order = np.argsort(lam, kind="stable")
    return Eigen(lam[order], x[:, order], _rigid_fraction(x, m, z)[order])


def _rigid_fraction(x: np.ndarray, m: np.ndarray, z: np.ndarray) -> np.ndarray:
    """||Z^T M x_i||^2 per mass-normalized column x_i (Z M-orthonormal)."""
    if z.shape[1] == 0 or x.shape[1] == 0:
        return np.zeros(x.shape[1])
    return np.sum((z.T @ (0.5 * (m + m.T)) @ x) ** 2, axis=0)


# ------------------------------------------------------------------------------ superposition
def select_modes(ev: Eigen, count: int | None) -> Eigen:
    """The rigid-body modes and the ``count`` lowest elastic modes of ev (all when count is None)."""
    if count is None:
        return ev
    rigid = ev.rigid
    keep = np.sort(np.concatenate([np.flatnonzero(rigid), np.flatnonzero(~rigid)[:count]]))
    return Eigen(ev.lam[keep], None if ev.x is None else ev.x[:, keep], ev.rigid_fraction[keep], ev.q)


def superposition_eigen(fe, rig1: np.ndarray, model: str, nax=None, count: int | None = None) -> Eigen:
    """Frozen eigenpairs of a superposition model at one rigid sample rig1 (5, ncols) (FEModel.rig_samples);
    ``nax`` (nel,) axial forces for K_sigma or None; the rigid-body modes and the ``count`` lowest
    elastic ones (all when None)."""
    m, _, k, _ = fe.matrices(rig1, model)
    if nax is not None:
        k = k + fe.geometric_matrix(rig1, nax)
    k_el = fe.matrices(rig1 * np.array([1, 0, 0, 0, 0])[:, None], model)[2]   # the angle only: K elastic
    return select_modes(rigid_apart(m, k, rigid_subspace(m, k_el)), count)


def quasi_static_axial(fe, rig1: np.ndarray, model: str, q_free=None, q_val=None) -> np.ndarray:
    """(nel,) axial forces [N] of the quasi-static solution K u = Q - F_rigid at one rigid sample (the
    run's ``quasi_static`` geometric-stiffness source, driven joints locked): the kernel's own
    computation, through a one-step run from that sample (its first frame's axial forces)."""
    rig = np.asfortranarray(np.repeat(np.asarray(rig1, float)[:, :, None], 2, axis=2))
    if q_val is not None:
        q_val = np.asfortranarray(np.repeat(np.asarray(q_val, float).reshape(-1, 1), 2, axis=1))
    out = fe.run(rig, model, 1e-9, q_free=q_free, q_val=q_val, geometric="quasi_static", full=True,
                 div_limit=1e300)
    return np.array(out[3][:, 0])


def superposition_frequencies(fe, rig: np.ndarray, model: str, count: int, nax=None) -> np.ndarray:
    """(N, count) the lowest frozen natural frequencies [rad/s] (signed, :func:`signed_sqrt`; rigid-body
    modes not told apart) at the rigid samples rig (5, ncols, N); ``nax`` (nel, N) the axial forces of
    K_sigma per sample, or None."""
    count = min(count, fe.nfree)
    out = np.empty((rig.shape[2], count))
    for i in range(rig.shape[2]):
        out[i] = signed_sqrt(fe.squared_frequencies(rig[:, :, i], model, None if nax is None else nax[:, i])[:count])
    return out


# ------------------------------------------------------------------------------ coupled models
def free_order(cm) -> np.ndarray:
    """All-DOF numbers (0-based) of the free DOFs in the order of the free numbering."""
    free = np.flatnonzero(cm.free_of > 0)
    out = np.empty(free.size, int)
    out[cm.free_of[free] - 1] = free
    return out


class _Linearization:
    """The coupled model's residual, constraint rows and their central-difference derivatives at
    configurations near one state (v, a, t held)."""

    def __init__(self, cm, v, a, t, gravity):
        self.cm, self.v, self.a, self.t, self.gravity = cm, v, a, t, gravity
        self.free = free_order(cm)
        self.h = FD_STEP * cm.case.mechanism.characteristic_length()
        self.angle_rows = np.array([r.kind == CON_ANGLE for r in cm.rows], bool)

    def at(self, q, lam):
        """(R + G^T lam on the free DOFs, g, G (nc, nfree), K_T (nfree, nfree)) at configuration q."""
        cm, f, h = self.cm, self.free, self.h
        n = f.size
        qs = np.repeat(q[:, None], 2 * n + 1, axis=1)
        qs[f, np.arange(n)] += h
        qs[f, n + np.arange(n)] -= h
        res = cm.residuals(qs, self.v, self.a, self.t, gravity=self.gravity)
        g, gq = cm.row_values(qs, self.v)
        gq = gq[:, f, :]                                   # (nc, nfree, ns)
        force = res[f] + np.einsum("i,ijs->js", lam, gq)   # (nfree, ns): R + G^T lam
        k = (force[:, :n] - force[:, n:2 * n]) / (2.0 * h)
        return force[:, -1], g[:, -1], gq[:, :, -1], k

    def violation(self, g, cval):
        e = g - cval
        e[self.angle_rows] = np.arctan2(np.sin(e[self.angle_rows]), np.cos(e[self.angle_rows]))
        return e


def _null_space(g: np.ndarray, n: int) -> np.ndarray:
    """Orthonormal basis (n, n - rank) of the null space of g (nc, n) (rank by SVD, redundant rows
    allowed)."""
    if g.shape[0] == 0:
        return np.eye(n)
    _, s, vt = np.linalg.svd(g)
    rank = int(np.sum(s > 1e-10 * max(s.max(), 1e-300)))
    return vt[rank:].T


def coupled_rigid_subspace(cm, q0: np.ndarray, m: np.ndarray) -> np.ndarray:
    """M-orthonormal basis (nfree, r) of the coupled model's rigid-body motions at the undeformed
    configuration q0: the zero-stiffness modes of its elastic stiffness (at rest, no gravity) that
    satisfy its constraints."""
    zero = np.zeros(cm.ndof)
    k_el = cm.dense(q0, zero, zero)[3]
    _, gq = cm.row_values(q0[:, None])
    n = _null_space(gq[:, free_order(cm), 0], cm.nfree)
    return rigid_subspace(m, k_el, n)


def quasi_static_state(lin: _Linearization, q0, cval, m, z):
    """Newton on the quasi-static equations R(q) + G^T lam = 0, g(q) = cval, the update kept
    M-orthogonal to the rigid-body motions z (the mechanism's free DOFs are not moved by it).
    An update longer than QS_MAXSTEP x the mechanism's length is shortened to it (the inertia loads
    of a fast mechanism can put the first full Newton step far beyond the equilibrium; measured on
    extreme/critical_fourbar, nonlinear model: 19 iterations, diverging without the limit).
    Returns (q, lam, K_T, G)."""
    cm, f = lin.cm, lin.free
    nc = len(cm.rows)
    q, lam = q0.copy(), np.zeros(nc)
    lref = cm.case.mechanism.characteristic_length()
    mz = 0.5 * (m + m.T) @ z
    for _ in range(QS_MAXIT):
        r, g, gm, k = lin.at(q, lam)
        n, nz = f.size, z.shape[1]
        a = np.zeros((n + nc + nz, n + nc + nz))
        a[:n, :n], a[:n, n:n + nc], a[:n, n + nc:] = k, gm.T, mz
        a[n:n + nc, :n], a[n + nc:, :n] = gm, mz.T
        rhs = -np.concatenate([r, lin.violation(g, cval), np.zeros(nz)])
        sol = np.linalg.lstsq(a, rhs, rcond=None)[0]
        step = np.max(np.abs(sol[:n]))
        scale = min(1.0, QS_MAXSTEP * lref / max(step, 1e-300))
        q[f] += scale * sol[:n]
        lam += scale * sol[n:n + nc]
        if step < QS_TOL * lref:
            break
    else:
        raise SolverError("the quasi-static state of the modal analysis did not converge (the frozen "
                          "configuration has no elastic equilibrium near the rigid one: is it past buckling?)")
    _, g, gm, k = lin.at(q, lam)
    return q, lam, k, gm


@dataclass
class Linearized:
    """A coupled or nonlinear model linearized about its quasi-static state at one sample of the rigid
    motion, over its free DOFs: ``q`` the state (all DOFs), ``m`` the mass matrix, ``c`` the velocity
    matrix dR/dv (Rayleigh damping and the gyroscopic terms of the frozen motion), ``k`` the tangent
    stiffness K_T (symmetric parts of m and k are what :func:`coupled_eigen` takes), ``n`` an
    orthonormal basis (nfree, nfree - rank G) of the null space of the constraint Jacobian (the motions
    the constraints allow), ``z`` the M-orthonormal rigid-body motions (nfree, r)."""

    q: np.ndarray
    m: np.ndarray
    c: np.ndarray
    k: np.ndarray
    n: np.ndarray
    z: np.ndarray


def coupled_linearized(cm, rm, i: int, gravity, rayleigh=(0.0, 0.0)) -> Linearized:
    """The coupled or nonlinear model cm linearized about its quasi-static state at sample i of the
    rigid motion rm (the velocities and accelerations of the rigid motion held); ``rayleigh`` [1/s, s]
    the damping that enters ``c``."""
    q0, v, a = cm.rigid_state(rm, i)
    t = float(rm.t[i])
    cval = cm.constraint_values(rm.select(slice(i, i + 1)))[0, :len(cm.rows), 0]
    m0 = cm.dense(q0, v, a, gravity=gravity)[1]
    z = coupled_rigid_subspace(cm, q0, m0)
    lin = _Linearization(cm, v, a, t, gravity)
    q, lam_c, k, gm = quasi_static_state(lin, q0, cval, m0, z)
    _, m, c, _, _ = cm.dense(q, v, a, gravity=gravity, rayleigh=rayleigh, t=t)
    return Linearized(q, m, c, k, _null_space(gm, cm.nfree), z)


def coupled_eigen(cm, rm, i: int, gravity, count: int | None = None) -> Eigen:
    """Frozen eigenpairs of a coupled or nonlinear model linearized about its quasi-static state at
    sample i of the rigid motion rm; the ``count`` lowest elastic modes plus the rigid-body modes."""
    lz = coupled_linearized(cm, rm, i, gravity)
    n = lz.n
    mr, kr = n.T @ (0.5 * (lz.m + lz.m.T)) @ n, n.T @ (0.5 * (lz.k + lz.k.T)) @ n
    ev = rigid_apart(mr, kr, n.T @ lz.z)     # z satisfies the constraints at q0: n.T z keeps it (to O(q - q0))
    return select_modes(Eigen(ev.lam, n @ ev.x, ev.rigid_fraction, lz.q), count)
