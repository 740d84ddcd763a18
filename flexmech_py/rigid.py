"""Rigid-body kinematics and forward dynamics of planar mechanisms.

Conventions: SI units; angles in rad, counter-clockwise positive; global frame
X right, Y up.  Every link is a straight bar with a reference point O (its
"start") and an absolute axis angle phi, e = (cos phi, sin phi), Omega e =
(-sin phi, cos phi); the material point at distance zeta from O along the axis
is at O + zeta*e.  Link indices are 0-based.

Everything is vectorised over N time samples: generalized coordinates are
arrays (N, ndof) (a 1-D array (ndof,) means N = 1; for ndof = 1 a 1-D array
(N,) holds N samples), link quantities are arrays (N, nlinks).

Mechanisms
    FourBar      links [crank, coupler, follower], q = crank angle
    SerialChain  q_1 absolute angle of link 1, q_2.. relative joint angles

Dynamics (inertial wrench / virtual power):  M(q) qdd + h(q, qd) = Q, where
h = (inertial bias forces, qdd = 0) - (generalized gravity forces) and Q holds
the applied generalized forces (see joint_torque_generalized_force).
"""
import math
from dataclasses import dataclass

import numpy as np

from flexmech_py.dop853 import dop853
from flexmech_py.errors import MechanismError, SolverError

__all__ = [
    "LinkMotion", "LinkMass", "FourBar", "SerialChain",
    "mass_matrix", "bias_forces", "kinetic_energy", "potential_energy",
    "joint_torque_generalized_force", "integrate", "integrate_dense",
    "constant_speed", "spinup", "check_motion",
]

TOGGLE_TOL = 1e-9   # |sin(theta4 - theta3)| below which kinematics raise
EVENT_TOL = 1e-6    # |sin(theta4 - theta3)| at which integrate() stops ...
EVENT_CAP = 1e-2    # ... raised up to this when q cannot resolve it (FourBar._stop_margin)


@dataclass
class LinkMotion:
    """Rigid motion of every link, arrays (N, nlinks): axis angle phi [rad],
    angular velocity omega [rad/s] and acceleration alpha [rad/s^2]; position
    (ox, oy) [m], velocity (vx, vy) [m/s], acceleration (ax, ay) [m/s^2] of O."""
    phi: np.ndarray
    omega: np.ndarray
    alpha: np.ndarray
    ox: np.ndarray
    oy: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    ax: np.ndarray
    ay: np.ndarray


def _as2d(x, ndof, name="q"):
    """Coordinates as a float array (N, ndof)."""
    x = np.asarray(x, dtype=float)
    if x.ndim == 0 and ndof == 1:
        x = x.reshape(1, 1)
    elif x.ndim == 1:
        x = x[:, None] if ndof == 1 else x[None, :]
    if x.ndim != 2 or x.shape[1] != ndof:
        raise ValueError(f"{name} must have shape (N, {ndof}) or ({ndof},), got {np.shape(x)}")
    return x


class _Mechanism:
    """Common interface: nlinks, ndof, lengths, kinematics(), jacobian()."""
    nlinks: int
    ndof: int
    lengths: np.ndarray

    def _state(self, q, qd, qdd):
        q = _as2d(q, self.ndof)
        out = [q]
        for v, name in ((qd, "qd"), (qdd, "qdd")):
            out.append(np.zeros_like(q) if v is None else
                       np.broadcast_to(_as2d(v, self.ndof, name), q.shape))
        return out

    def jacobian(self, q):
        """d(ox, oy, phi)/dq of every link, array (N, nlinks, 3, ndof) [m/rad, -]."""
        q = _as2d(q, self.ndof)
        cols = []
        for i in range(self.ndof):
            u = np.zeros_like(q)
            u[:, i] = 1.0
            k = self.kinematics(q, u, None)
            cols.append(np.stack([k.vx, k.vy, k.omega], axis=-1))
        return np.stack(cols, axis=-1)

    def _motion_and_jacobian(self, q, qd, strict=True):
        """Kinematics with qdd = 0 (bias accelerations) and the Jacobian."""
        return self.kinematics(q, qd, None), self.jacobian(q)


class FourBar(_Mechanism):
    """Planar four-bar: crank a, coupler b, follower c, ground d [m].

    Ground pivots O2 = (0, 0), O4 = (d, 0); links [crank, coupler, follower]
    start at O2, A = O2 + a e(q) and O4; the coupler and the follower point to
    B.  ``branch`` = sign of the cross product (O4 - A) x (B - A), kept fixed
    (+1 puts B above the ground line at q = 0 when d > a).
    """
    nlinks = 3
    ndof = 1

    def __init__(self, crank, coupler, follower, ground, branch=1):
        lens = np.array([crank, coupler, follower, ground], dtype=float)
        if not np.all(np.isfinite(lens)) or np.any(lens <= 0):
            raise MechanismError(f"four-bar lengths must be positive and finite, got {lens.tolist()}")
        if branch not in (1, -1):
            raise MechanismError(f"four-bar branch must be +1 or -1, got {branch!r}")
        self.a, self.b, self.c, self.d = (float(v) for v in lens)
        self.lengths, self.ground, self.branch, self.q0 = lens[:3], self.d, int(branch), None
        a, b, c, d = self.a, self.b, self.c, self.d
        if d + a < abs(b - c) or abs(d - a) > b + c:
            raise MechanismError(
                f"four-bar cannot assemble at any crank angle: |A-O4| ranges over "
                f"[{abs(d - a):.6g}, {d + a:.6g}] m but coupler and follower reach only "
                f"[{abs(b - c):.6g}, {b + c:.6g}] m")

    @classmethod
    def open_assembly(cls, crank, coupler, follower, ground, q0=0.0):
        """Four-bar on the branch with the higher B (B_y > 0) at crank angle q0 [rad]."""
        mech = cls(crank, coupler, follower, ground, 1)
        yp = mech.joint_positions(q0)[0, 2, 1]
        mech.branch = -1
        ym = mech.joint_positions(q0)[0, 2, 1]
        if abs(yp - ym) <= 1e-12 * max(mech.a, mech.b, mech.c, mech.d):
            raise MechanismError(f"open assembly is ambiguous at crank angle {float(q0):.6g} rad: "
                                 f"both assembly solutions have B_y = {yp:.6g} m")
        mech.branch = 1 if yp > ym else -1
        mech.q0 = float(q0)
        return mech

    def _sin2(self, q):
        """sin^2(theta4 - theta3) from the triangle A-B-O4 (negative: cannot assemble)."""
        a, b, c, d = self.a, self.b, self.c, self.d
        r2 = a * a + d * d - 2 * a * d * np.cos(q)
        return (4 * r2 * b * b - (b * b - c * c + r2) ** 2) / (4 * b * b * c * c)

    def _stop_margin(self, q, rtol):
        """s^2 - stop^2 with s = sin(theta4 - theta3), smooth through the assembly limit.
        Near a limit s^2 ~ (q_lim - q), so M ~ 1/s^2 carries the rounding error of q
        (eps*|q|) amplified by |ds^2/dq|/s^2; once that exceeds rtol the step size collapses.
        stop = 1e-6, raised (at most to 1e-2) to where this noise equals rtol."""
        a, b, c, d = self.a, self.b, self.c, self.d
        r2 = a * a + d * d - 2 * a * d * np.cos(q)
        ds2 = (b * b + c * c - r2) * a * d * np.sin(q) / (b * b * c * c)
        noise = np.finfo(float).eps * (abs(ds2) * max(1.0, abs(q)) + r2 / (c * c))
        return self._sin2(q) - np.clip(noise / rtol, EVENT_TOL ** 2, EVENT_CAP ** 2)

    def _diagnose(self, q, s2):
        """Why crank angle q [rad] with sin^2 = s2 fails."""
        a, b, c, d = self.a, self.b, self.c, self.d
        if not s2 >= 0:
            r = np.sqrt(a * a + d * d - 2 * a * d * np.cos(q))
            why = (f"exceeds coupler+follower = {b + c:.6g} m" if r > 0.5 * (b + c + abs(b - c))
                   else f"is below |coupler-follower| = {abs(b - c):.6g} m")
            return f"cannot assemble at crank angle {q:.6g} rad: |A-O4| = {r:.6g} m {why}"
        return (f"toggle position: transmission angle reaches 0 or pi at crank angle {q:.6g} rad "
                f"(|sin(theta4-theta3)| = {np.sqrt(s2):.3g})")

    def _geometry(self, q, check=2):
        """Position solution for crank angles q (N,).  check: 0 none (clip, for the
        ODE right-hand side), 1 assembly, 2 assembly and toggle."""
        a, b, c, d = self.a, self.b, self.c, self.d
        s2 = self._sin2(q)
        if check:
            bad = ~(s2 >= (TOGGLE_TOL ** 2 if check == 2 else 0.0))
            if bad.any():
                i = int(np.argmax(bad))
                raise MechanismError(self._diagnose(float(q[i]), s2[i]))
        cq, sq = np.cos(q), np.sin(q)
        Ax, Ay = a * cq, a * sq
        dx, dy = d - Ax, -Ay
        r2 = dx * dx + dy * dy
        r = np.sqrt(r2)
        l = (b * b - c * c + r2) / (2 * r)
        bh = self.branch * np.sqrt(np.maximum(b * b - l * l, 0.0)) / r
        Bx, By = Ax + (l / r) * dx - bh * dy, Ay + (l / r) * dy + bh * dx
        s = self.branch * np.sqrt(np.maximum(s2, TOGGLE_TOL ** 2))   # sin(theta4 - theta3)
        return cq, sq, Ax, Ay, Bx, By, (Bx - Ax) / b, (By - Ay) / b, (Bx - d) / c, By / c, s

    def joint_positions(self, q):
        """Points [O2, A, B, O4] as an array (N, 4, 2) [m]."""
        q = _as2d(q, 1)[:, 0]
        _, _, Ax, Ay, Bx, By = self._geometry(q, check=1)[:6]
        z, dd = np.zeros_like(q), np.full_like(q, self.d)
        return np.stack([np.stack([z, z], -1), np.stack([Ax, Ay], -1),
                         np.stack([Bx, By], -1), np.stack([dd, z], -1)], axis=1)

    def _kin(self, q, w2, a2, check):
        a, b, c, d = self.a, self.b, self.c, self.d
        cq, sq, Ax, Ay, Bx, By, e3x, e3y, e4x, e4y, s = self._geometry(q, check)
        K3 = -a * (cq * e4y - sq * e4x) / (b * s)      # omega3 / omega2
        K4 = -a * (cq * e3y - sq * e3x) / (c * s)      # omega4 / omega2
        w3, w4 = K3 * w2, K4 * w2
        Rx = a * a2 * sq + a * w2 * w2 * cq + b * w3 * w3 * e3x - c * w4 * w4 * e4x
        Ry = -a * a2 * cq + a * w2 * w2 * sq + b * w3 * w3 * e3y - c * w4 * w4 * e4y
        z, dd = np.zeros_like(q), np.full_like(q, d)
        st = lambda *cols: np.array(cols).T
        mot = LinkMotion(
            phi=st(q, np.arctan2(e3y, e3x), np.arctan2(e4y, e4x)), omega=st(w2, w3, w4),
            alpha=st(a2, (Rx * e4x + Ry * e4y) / (b * s), (Rx * e3x + Ry * e3y) / (c * s)),
            ox=st(z, Ax, dd), oy=st(z, Ay, z), vx=st(z, -a * w2 * sq, z), vy=st(z, a * w2 * cq, z),
            ax=st(z, -a * (a2 * sq + w2 * w2 * cq), z), ay=st(z, a * (a2 * cq - w2 * w2 * sq), z))
        one = np.ones_like(q)
        J = np.array([[z, z, one], [-a * sq, a * cq, K3], [z, z, K4]])   # (link, comp, N)
        return mot, J.transpose(2, 0, 1)[..., None]

    def kinematics(self, q, qd=None, qdd=None):
        """LinkMotion for crank angle q [rad], speed qd [rad/s], acceleration qdd
        [rad/s^2] (N, 1).  The crank phi is q itself (not wrapped); coupler and
        follower phi are in (-pi, pi].  Raises MechanismError when the loop cannot
        close or at a toggle (|sin(theta4 - theta3)| < 1e-9)."""
        q, qd, qdd = self._state(q, qd, qdd)
        return self._kin(q[:, 0], qd[:, 0], qdd[:, 0], 2)[0]

    def jacobian(self, q):
        """d(ox, oy, phi)/dq, array (N, 3, 3, 1) [m/rad, -]."""
        q = _as2d(q, 1)[:, 0]
        return self._kin(q, np.ones_like(q), np.zeros_like(q), 2)[1]

    def _motion_and_jacobian(self, q, qd, strict=True):
        q, qd, _ = self._state(q, qd, None)
        return self._kin(q[:, 0], qd[:, 0], np.zeros(len(q)), 2 if strict else 0)

    def _dynamics1(self, mk, q, w2, gravity):
        """One-sample generalized mass M, bias h (qdd = 0, gravity included) and link angles phi and
        d(phi)/dq of the ODE right-hand side: the formulas of _geometry(check=0), _kin and _dynamics
        written with floats (math), about 30x cheaper than the vectorised path for N = 1."""
        a, b, c, d = self.a, self.b, self.c, self.d
        cq, sq = math.cos(q), math.sin(q)
        r2 = a * a + d * d - 2 * a * d * cq
        s2 = (4 * r2 * b * b - (b * b - c * c + r2) ** 2) / (4 * b * b * c * c)
        Ax, Ay = a * cq, a * sq
        dx, dy = d - Ax, -Ay
        r2 = dx * dx + dy * dy
        r = math.sqrt(r2)
        l = (b * b - c * c + r2) / (2 * r)
        bh = self.branch * math.sqrt(max(b * b - l * l, 0.0)) / r
        Bx, By = Ax + (l / r) * dx - bh * dy, Ay + (l / r) * dy + bh * dx
        s = self.branch * math.sqrt(max(s2, TOGGLE_TOL ** 2))
        e3x, e3y, e4x, e4y = (Bx - Ax) / b, (By - Ay) / b, (Bx - d) / c, By / c
        K3 = -a * (cq * e4y - sq * e4x) / (b * s)
        K4 = -a * (cq * e3y - sq * e3x) / (c * s)
        w3, w4 = K3 * w2, K4 * w2
        Rx = a * w2 * w2 * cq + b * w3 * w3 * e3x - c * w4 * w4 * e4x
        Ry = a * w2 * w2 * sq + b * w3 * w3 * e3y - c * w4 * w4 * e4y
        phi = (q, math.atan2(e3y, e3x), math.atan2(e4y, e4x))
        om = (w2, w3, w4)
        al = (0.0, (Rx * e4x + Ry * e4y) / (b * s), (Rx * e3x + Ry * e3y) / (c * s))
        acc = ((0.0, 0.0), (-a * w2 * w2 * cq, -a * w2 * w2 * sq), (0.0, 0.0))
        jac = ((0.0, 0.0, 1.0), (-a * sq, a * cq, K3), (0.0, 0.0, K4))
        gx, gy = gravity
        M = h = 0.0
        for k in range(3):
            m, sk, jk = mk[0][k], mk[1][k], mk[2][k]
            ck, sn = math.cos(phi[k]), math.sin(phi[k])
            Jx, Jy, Jp = jac[k]
            M += Jx * (m * Jx - sk * Jp * sn) + Jy * (m * Jy + sk * Jp * ck) + Jp * (jk * Jp + sk * (ck * Jy - sn * Jx))
            w, alk, (ax, ay) = om[k], al[k], acc[k]
            h += (Jx * (m * ax - sk * (alk * sn + w * w * ck) - m * gx)
                  + Jy * (m * ay + sk * (alk * ck - w * w * sn) - m * gy)
                  + Jp * (jk * alk + sk * (ck * ay - sn * ax) - sk * (ck * gy - sn * gx)))
        return M, h, phi, (1.0, K3, K4)

    def crank_range(self, q0=None):
        """None if the crank can turn fully, else the admissible crank interval
        (qmin, qmax) [rad] containing q0 (default: the assembly angle, or 0); its
        ends are toggle positions."""
        a, b, c, d = self.a, self.b, self.c, self.d
        q0 = float((self.q0 or 0.0) if q0 is None else q0)
        c1 = (a * a + d * d - (b + c) ** 2) / (2 * a * d)   # need cos q >= c1
        c2 = (a * a + d * d - (b - c) ** 2) / (2 * a * d)   # need cos q <= c2
        if c1 <= -1 and c2 >= 1:
            return None
        lo, hi = np.arccos(min(c2, 1.0)), np.arccos(max(c1, -1.0))
        qw = (q0 + np.pi) % (2 * np.pi) - np.pi
        if lo == 0.0:
            qmin, qmax = -hi, hi
        elif hi == np.pi:
            qmin, qmax = lo, 2 * np.pi - lo
            qw = qw + 2 * np.pi if qw < 0 else qw
        else:
            qmin, qmax = (lo, hi) if qw >= 0 else (-hi, -lo)
        if not qmin - 1e-12 <= qw <= qmax + 1e-12:
            raise MechanismError(f"crank angle {q0:.6g} rad is outside the admissible crank range")
        return (float(qmin + q0 - qw), float(qmax + q0 - qw))


class SerialChain(_Mechanism):
    """Open chain of straight links [m] from ``base``: link 0 has phi_0 = q_0,
    link i starts at the end of link i-1 with phi_i = q_0 + ... + q_i."""

    def __init__(self, lengths, base=(0.0, 0.0)):
        L = np.atleast_1d(np.asarray(lengths, dtype=float))
        if L.ndim != 1 or not np.all(np.isfinite(L)) or np.any(L <= 0):
            raise MechanismError(f"serial-chain lengths must be positive and finite, got {lengths!r}")
        self.lengths, self.nlinks, self.ndof = L, len(L), len(L)
        self.base = (float(base[0]), float(base[1]))

    def kinematics(self, q, qd=None, qdd=None):
        """LinkMotion for joint angles q [rad], rates qd [rad/s], accelerations qdd
        [rad/s^2], each (N, ndof)."""
        q, qd, qdd = self._state(q, qd, qdd)
        phi, w, al = np.cumsum(q, 1), np.cumsum(qd, 1), np.cumsum(qdd, 1)
        c, s, L = np.cos(phi), np.sin(phi), self.lengths
        ex = lambda x: np.cumsum(x, 1) - x          # sum over the preceding links
        return LinkMotion(phi=phi, omega=w, alpha=al,
                          ox=self.base[0] + ex(L * c), oy=self.base[1] + ex(L * s),
                          vx=ex(-L * w * s), vy=ex(L * w * c),
                          ax=ex(-L * (al * s + w * w * c)), ay=ex(L * (al * c - w * w * s)))

    def joint_positions(self, q):
        """Points [base, joint 1, ..., tip] as an array (N, nlinks + 1, 2) [m]."""
        k = self.kinematics(q)
        tip = np.stack([k.ox[:, -1] + self.lengths[-1] * np.cos(k.phi[:, -1]),
                        k.oy[:, -1] + self.lengths[-1] * np.sin(k.phi[:, -1])], -1)
        return np.concatenate([np.stack([k.ox, k.oy], -1), tip[:, None]], axis=1)


@dataclass
class LinkMass:
    """Mass properties of one link about its O: mass m [kg], first moment
    s = int zeta dm [kg m], second moment j = int zeta^2 dm + rotary inertias [kg m^2]."""
    m: float = 0.0
    s: float = 0.0
    j: float = 0.0

    @classmethod
    def from_bar(cls, rho_a, length):
        """Uniform bar of mass per length rho_a [kg/m] and length [m] starting at O."""
        m = rho_a * length
        return cls(m, m * length / 2, m * length ** 2 / 3)

    def add_point_mass(self, mass, zeta):
        """Add a point mass [kg] at zeta [m] along the axis; returns self."""
        self.m += mass
        self.s += mass * zeta
        self.j += mass * zeta ** 2
        return self

    def add_rotary_inertia(self, inertia):
        """Add a rotary inertia [kg m^2] turning with the link; returns self."""
        self.j += inertia
        return self


def _mass_arrays(mech, masses):
    masses = list(masses)
    if len(masses) != mech.nlinks:
        raise ValueError(f"need {mech.nlinks} LinkMass entries, got {len(masses)}")
    return np.array([[k.m, k.s, k.j] for k in masses], dtype=float).T   # (3, nlinks)


def _wrench(phi, omega, alpha, ax, ay, m, s, j):
    """Inertial wrench about O [F_x, F_y, M_O] on the last axis."""
    c, sn = np.cos(phi), np.sin(phi)
    return np.stack([m * ax - s * (alpha * sn + omega * omega * c),
                     m * ay + s * (alpha * c - omega * omega * sn),
                     j * alpha + s * (c * ay - sn * ax)], axis=-1)


def motion_and_jacobian(mech, q, qd, strict=True):
    """Kinematics (qdd = 0) and Jacobian, remembering the last single-sample call: the ODE right-hand
    side asks for the same state twice (dynamics and generalized forces)."""
    q = np.asarray(q, dtype=float)
    qd = None if qd is None else np.asarray(qd, dtype=float)
    key = (q.tobytes(), None if qd is None else qd.tobytes(), strict)
    cache = getattr(mech, "_mj_cache", None)
    if cache is not None and cache[0] == key:
        return cache[1]
    out = mech._motion_and_jacobian(q, qd, strict)
    if q.size == mech.ndof:
        mech._mj_cache = (key, out)
    return out


def _dynamics(mech, mk, q, qd, gravity, strict=True):
    """M (N, ndof, ndof) and h = inertial bias - gravity (N, ndof)."""
    kin, J = motion_and_jacobian(mech, q, qd, strict)
    m, s, j = mk
    # M: generalized inertial force of the unit accelerations qdd = e_i (qd = 0)
    Wu = _wrench(kin.phi[..., None], 0.0, J[:, :, 2], J[:, :, 0], J[:, :, 1],
                 m[:, None], s[:, None], j[:, None])
    M = np.einsum("nkci,nkjc->nij", J, Wu)
    gx, gy = gravity
    W = _wrench(kin.phi, kin.omega, kin.alpha, kin.ax, kin.ay, m, s, j)
    W[..., 0] -= m * gx
    W[..., 1] -= m * gy
    W[..., 2] -= s * (np.cos(kin.phi) * gy - np.sin(kin.phi) * gx)
    return M, np.einsum("nkci,nkc->ni", J, W)


def mass_matrix(mech, masses, q):
    """Generalized mass matrix M(q), array (N, ndof, ndof) [SI]."""
    return _dynamics(mech, _mass_arrays(mech, masses), q, None, (0.0, 0.0))[0]


def bias_forces(mech, masses, q, qd, gravity=(0.0, 0.0)):
    """h(q, qd) = inertial bias (Coriolis/centrifugal) minus generalized gravity
    force, array (N, ndof) [N m or N]; gravity (g_x, g_y) [m/s^2]."""
    return _dynamics(mech, _mass_arrays(mech, masses), q, qd, gravity)[1]


def kinetic_energy(mech, masses, q, qd):
    """Kinetic energy [J], array (N,)."""
    m, s, j = _mass_arrays(mech, masses)
    k = mech.kinematics(q, qd)
    vt = -np.sin(k.phi) * k.vx + np.cos(k.phi) * k.vy
    return np.sum(0.5 * m * (k.vx ** 2 + k.vy ** 2) + k.omega * s * vt + 0.5 * j * k.omega ** 2, 1)


def potential_energy(mech, masses, q, gravity):
    """Gravitational potential energy -sum(m g.O + s g.e) [J], array (N,)."""
    m, s, _ = _mass_arrays(mech, masses)
    k = mech.kinematics(q)
    gx, gy = gravity
    return -np.sum(m * (gx * k.ox + gy * k.oy) + s * (gx * np.cos(k.phi) + gy * np.sin(k.phi)), 1)


def joint_torque_generalized_force(mech, q, link_b, link_a, tau):
    """Generalized force (N, ndof) of a torque tau [N m] (scalar or (N,)) acting on
    link_b with the reaction on link_a (None = ground): virtual work tau*(dphi_b - dphi_a)."""
    J = mech.jacobian(q)
    dphi = J[:, link_b, 2, :] - (0.0 if link_a is None else J[:, link_a, 2, :])
    return np.reshape(np.asarray(tau, dtype=float), (-1, 1)) * dphi


def _torque_force(phi, J, joint_torques):
    """Generalized force (N, ndof) of joint torques [(tau(theta), link_b, link_a), ...] for link
    angles phi (N, nlinks) and the Jacobian J (N, nlinks, 3, ndof)."""
    Q = 0.0
    for tau, b, a in joint_torques:
        theta = phi[:, b] - (phi[:, a] if a is not None else 0.0)
        dphi = J[:, b, 2, :] - (J[:, a, 2, :] if a is not None else 0.0)
        Q = Q + np.asarray(tau(theta), dtype=float)[:, None] * dphi
    return Q


def integrate(mech, masses, q0, qd0, t, generalized_force=None, gravity=(0.0, 0.0),
              rtol=1e-10, atol=1e-12, joint_torques=()):
    """Torque-driven forward dynamics sampled on the grid t: (q, qd, qdd), each (N, ndof);
    see :func:`integrate_dense` for the arguments."""
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or len(t) < 2 or np.any(np.diff(t) <= 0):
        raise ValueError("t must be an increasing 1-D time grid with at least 2 samples")
    return integrate_dense(mech, masses, q0, qd0, (t[0], t[-1]), generalized_force, gravity, rtol, atol,
                           joint_torques)(t)


def integrate_dense(mech, masses, q0, qd0, t_span, generalized_force=None, gravity=(0.0, 0.0),
                    rtol=1e-10, atol=1e-12, joint_torques=()):
    """Torque-driven forward dynamics M qdd + h = Q from (q0, qd0) at t[0].

    t_span: (t0, t1) [s]; generalized_force(t, q, qd) -> Q, vectorised: t (N,),
    q and qd (N, ndof) -> Q (N, ndof) (None: 0; the ODE calls it with N = 1);
    joint_torques: [(tau, link_b, link_a), ...], a torque tau(theta) [N m] (vectorised over
    theta = phi_b - phi_a [rad]) on link_b with the reaction on link_a (None = ground), added to Q
    (a FourBar driven only by joint torques uses a float right-hand side, about 30x cheaper);
    gravity (g_x, g_y) [m/s^2].  Solved with DOP853 (flexmech_py.dop853: scipy's solve_ivp DOP853
    transcribed, without scipy.integrate's import cost), sampled at t.
    Returns sample(t) -> (q, qd, qdd), each (N, ndof), for times t (N,) in t_span: the solver's dense
    output (its memory grows with the solver's steps, not with len(t)), qdd from the equations of
    motion; chunks of a long grid can be sampled one after the other.  A
    FourBar approaching a toggle or assembly limit stops with a MechanismError
    naming the time and the crank angle, at |sin(theta4 - theta3)| = 1e-6 or, when
    the crank angle cannot resolve the motion that close to the limit to rtol, earlier
    (at most at 1e-2; see FourBar._stop_margin).
    """
    nd = mech.ndof
    mk = _mass_arrays(mech, masses)
    t = np.asarray(t_span, dtype=float)
    if t.shape != (2,) or not t[1] > t[0]:
        raise ValueError("t_span must be (t0, t1) with t1 > t0")
    y0 = np.concatenate([_as2d(q0, nd)[0], _as2d(qd0, nd, "qd0")[0]])
    force = generalized_force or (lambda ti, q, qd: np.zeros_like(q))
    joint_torques = list(joint_torques)
    events = None
    if isinstance(mech, FourBar):
        if not mech._stop_margin(y0[0], rtol) > 0:
            raise MechanismError(f"at t = {t[0]:.6g} s: " + mech._diagnose(y0[0], mech._sin2(y0[0])))
        event = lambda ti, y: mech._stop_margin(y[0], rtol)
        event.terminal, event.direction = True, -1
        events = [event]

    if isinstance(mech, FourBar) and generalized_force is None:
        mkl = mk.tolist()

        def rhs(ti, y):
            qs, ws = float(y[0]), float(y[1])
            M, h, phi, dphi = mech._dynamics1(mkl, qs, ws, gravity)
            Q = 0.0
            for tau, b, a in joint_torques:
                theta = phi[b] - (phi[a] if a is not None else 0.0)
                Q += float(tau(theta)) * (dphi[b] - (dphi[a] if a is not None else 0.0))
            return np.array([ws, (Q - h) / M])
    else:
        def rhs(ti, y):
            M, h = _dynamics(mech, mk, y[None, :nd], y[None, nd:], gravity, strict=False)
            Q = np.asarray(force(np.array([ti]), y[None, :nd], y[None, nd:]), dtype=float).reshape(nd)
            if joint_torques:
                km, jac = motion_and_jacobian(mech, y[None, :nd], y[None, nd:], strict=False)   # cached
                Q = Q + _torque_force(km.phi, jac, joint_torques).reshape(nd)
            return np.concatenate([y[nd:], np.linalg.solve(M[0], Q - h[0])])

    status, sol, te, ye, message = dop853(rhs, t[0], y0, t[-1], rtol, atol, events[0] if events else None)
    if status == 1:
        qe = ye[0]
        raise MechanismError(
            f"four-bar reaches a toggle or assembly limit at t = {te:.6g} s, crank angle {qe:.6g} "
            f"rad (|sin(theta4-theta3)| = {np.sqrt(max(mech._sin2(qe), 0.0)):.2g}); the crank "
            f"cannot be driven past it")
    if status != 0:
        raise SolverError(f"rigid-body integration failed: {message}", time=float(te))
    dense, t0, t1 = sol, t[0], t[-1]

    def sample(ts):
        ts = np.asarray(ts, dtype=float)
        if ts.ndim != 1 or ts.size < 1 or ts.min() < t0 - 1e-12 * abs(t1) or ts.max() > t1 + 1e-12 * abs(t1):
            raise ValueError(f"sample times must be a 1-D array within [{t0}, {t1}] s")
        y = dense(ts).reshape(2 * nd, ts.size)
        q, qd = y[:nd].T, y[nd:].T
        M, h = _dynamics(mech, mk, q, qd, gravity)
        Q = np.broadcast_to(np.asarray(force(ts, q, qd), dtype=float), q.shape)
        if joint_torques:
            Q = Q + _torque_force(mech.kinematics(q).phi, mech.jacobian(q), joint_torques)
        return q, qd, np.linalg.solve(M, (Q - h)[..., None])[..., 0]

    return sample


def constant_speed(t, q0, speed):
    """1-DOF drive q = q0 + speed*t [rad, rad/s]; returns (q, qd, qdd), each (N, 1)."""
    t = np.asarray(t, dtype=float).reshape(-1, 1)
    return q0 + speed * t, np.full_like(t, speed), np.zeros_like(t)


def spinup(t, final_speed, spinup_time, q0=0.0):
    """Smooth 1-DOF start from rest at t = 0 to final_speed [rad/s] at spinup_time
    T [s]: theta = (ws/T)(t^2/2 + (T/2pi)^2 (cos(2 pi t/T) - 1)) for t <= T, ws (t - T/2)
    after (at rest for t < 0).  Returns (q, qd, qdd), each (N, 1)."""
    t = np.maximum(np.asarray(t, dtype=float).reshape(-1, 1), 0.0)
    ws, T = float(final_speed), float(spinup_time)
    k = 2 * np.pi / T
    ramp = t <= T
    q = np.where(ramp, ws / T * (t * t / 2 + (np.cos(k * t) - 1) / k ** 2), ws * (t - T / 2))
    qd = np.where(ramp, ws / T * (t - np.sin(k * t) / k), ws)
    qdd = np.where(ramp, ws / T * (1 - np.cos(k * t)), 0.0)
    return q0 + q, qd, qdd


def check_motion(mech, q, t=None):
    """Raise MechanismError if a sampled FourBar crank angle q [rad] (N, 1) cannot
    assemble or is at a toggle (|sin(theta4 - theta3)| < 1e-9); t [s] (N,) optional,
    to name the time.  Other mechanisms only have their shape checked."""
    q = _as2d(q, mech.ndof)
    if not isinstance(mech, FourBar):
        return
    s2 = mech._sin2(q[:, 0])
    bad = ~(s2 >= TOGGLE_TOL ** 2)
    if bad.any():
        i = int(np.argmax(bad))
        when = "" if t is None else f"at t = {np.asarray(t, dtype=float).reshape(-1)[i]:.6g} s: "
        raise MechanismError(when + mech._diagnose(float(q[i, 0]), s2[i]))
