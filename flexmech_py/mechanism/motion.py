"""The rigid-body motion of a mechanism sampled on time grids (docs/theory.md section 17.3-17.4).

:class:`MotionSource` follows the motion from t = 0 with the Fortran layer (flexmech_motion): every
sample is computed as the grid asks, chunk by chunk, continuing from a stored state, so memory does
not grow with the run (a grid earlier than the last sample restarts from t = 0; the trajectory is the
same, so results do not depend on the chunking).  A sample is a :class:`RigidMotion`: the bodies'
coordinates and their derivatives, the joints' coordinates, the constraint multipliers (joint
reactions, drive forces) and, for every link, the motion of its start in the layout the elastic
models use (:class:`LinkMotion`).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, fields

import numpy as np

from ..base import kernels
from ..base.errors import MechanismError
from .analysis import MotionSetup, constraint_matrices, scaled_jacobian
from .system import Mechanism

__all__ = ["LinkMotion", "RigidMotion", "MotionSource", "KINEMATIC_RCOND_MIN", "DYNAMIC_GRAM_MIN"]

KINEMATIC_RCOND_MIN = 1e-9     # the scaled Jacobian of a kinematic mechanism is singular below this
DYNAMIC_GRAM_MIN = 1e-12       # (sigma_min / sigma_max)^2 of the scaled joint Jacobian below this: singular
POSITION_TOL = 1e-12           # positions converge to POSITION_TOL x the mechanism's length


@dataclass
class LinkMotion:
    """Rigid motion of every link's frame, arrays (N, nlinks): axis angle phi [rad], angular velocity
    omega [rad/s] and acceleration alpha [rad/s^2]; position (ox, oy) [m], velocity (vx, vy) [m/s] and
    acceleration (ax, ay) [m/s^2] of the link's start O."""

    phi: np.ndarray
    omega: np.ndarray
    alpha: np.ndarray
    ox: np.ndarray
    oy: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    ax: np.ndarray
    ay: np.ndarray

    def select(self, idx) -> "LinkMotion":
        """The samples ``idx`` (an index, slice or mask along time)."""
        return LinkMotion(**{f.name: getattr(self, f.name)[idx] for f in fields(self)})

    @staticmethod
    def concat(parts) -> "LinkMotion":
        """The samples of consecutive parts, in order."""
        return LinkMotion(**{f.name: np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(LinkMotion)})


class RigidMotion:
    """The motion sampled at times t (N,): body coordinates z, zd, zdd (N, n) (centre of mass and
    frame angle per body), multipliers lam (N, nrow), joint coordinates jq (N, nj, 3) [value, rate,
    acceleration], the drives' generalized forces dv (N, ndrives) (with the outputs of the controllers
    acting through them); q, qd, qdd (N, ndof) the coordinates of the primary joints; ``motion`` the
    links' LinkMotion; ``control`` and ``integral`` (N, nc) the outputs [N m or N] and error integrals
    of the controllers closed in the rigid-body integration (nc = 0 without them), ``work`` (N,) [J]
    the work of the force drives and those controllers on the rigid-body motion (None without them)."""

    def __init__(self, setup: MotionSetup, t, z, zd, zdd, lam, jq, dv, motion: LinkMotion | None = None,
                 control=None, integral=None, work=None):
        self.setup = setup
        self.t, self.z, self.zd, self.zdd, self.lam, self.jq, self.dv = t, z, zd, zdd, lam, jq, dv
        self._motion = motion          # None: computed on first use
        self.control = np.zeros((t.size, 0)) if control is None else control
        self.integral = np.zeros((t.size, 0)) if integral is None else integral
        self.work = work

    def _primary(self, k: int) -> np.ndarray:
        names = [j.name for j in self.setup.mech.joints]
        return self.jq[:, [names.index(p) for p in self.setup.primary], k]

    @property
    def q(self) -> np.ndarray:
        return self._primary(0)

    @property
    def qd(self) -> np.ndarray:
        return self._primary(1)

    @property
    def qdd(self) -> np.ndarray:
        return self._primary(2)

    @property
    def motion(self) -> "LinkMotion":
        """The links' LinkMotion (computed on first use)."""
        if self._motion is None:
            self._motion = _link_motion(self.setup.mech, self.z, self.zd, self.zdd)
        return self._motion

    def select(self, idx) -> "RigidMotion":
        return RigidMotion(self.setup, self.t[idx], self.z[idx], self.zd[idx], self.zdd[idx], self.lam[idx],
                           self.jq[idx], self.dv[idx], None if self._motion is None else self._motion.select(idx),
                           self.control[idx], self.integral[idx], None if self.work is None else self.work[idx])

    @staticmethod
    def concat(parts) -> "RigidMotion":
        """The samples of consecutive parts (one mechanism), in order."""
        return RigidMotion(parts[0].setup, *(np.concatenate([getattr(p, k) for p in parts])
                                             for k in ("t", "z", "zd", "zdd", "lam", "jq", "dv")),
                           None if any(p._motion is None for p in parts)
                           else LinkMotion.concat([p._motion for p in parts]),
                           *(np.concatenate([getattr(p, k) for p in parts]) for k in ("control", "integral")),
                           None if parts[0].work is None else np.concatenate([p.work for p in parts]))

    def joint(self, name: str) -> np.ndarray:
        """(N, 3) [coordinate, rate, acceleration] of a joint (rad or m)."""
        return self.jq[:, [j.name for j in self.setup.mech.joints].index(name)]

    def kernel_samples(self, gravity, idx=slice(None)) -> np.ndarray:
        """(5, nlinks, N) [phi, omega, alpha, a_Ox - g_x, a_Oy - g_y] of the links, for the kernels."""
        m = self.motion
        rig = np.stack([m.phi[idx], m.omega[idx], m.alpha[idx], m.ax[idx] - gravity[0], m.ay[idx] - gravity[1]])
        return np.asfortranarray(rig.transpose(0, 2, 1))

    def reaction(self, name: str) -> np.ndarray:
        """(N, 3) [F_x, F_y, M] that body a exerts on body b at the joint (global components [N],
        moment [N m]; for a guided joint the force is normal to the guide)."""
        mech, packed = self.setup.mech, self.setup.packed
        j = mech.joint(name)
        r0, _ = packed.joint_rows[mech.joints.index(j)]
        out = np.zeros((self.t.size, 3))
        ends = [self.point_positions(p) for p in mech.joint_points(j)]
        own = j.reaction_from(self.lam[:, r0:r0 + j.rows], *ends)
        if own is not None:
            return own
        if j.shares_point:
            out[:, :2] = self.lam[:, r0:r0 + 2]
            if j.ties_rotation:
                out[:, 2] = -self.lam[:, r0 + 2]
        else:
            n = _guide_normal(self, j)
            out[:, :2] = -self.lam[:, [r0]] * n
            if j.ties_rotation:
                out[:, 2] = -self.lam[:, r0 + 1]
        return out

    def point_positions(self, ref) -> np.ndarray:
        """(N, 2) global positions of a resolved point (PointRef) over the samples [m]."""
        if ref.body is None:
            return np.tile(np.asarray(ref.position, float), (self.t.size, 1))
        bi = self.setup.mech.body_index(ref.body)
        s = ref.body.marker(ref.point)
        c, sn = np.cos(self.z[:, 3 * bi + 2]), np.sin(self.z[:, 3 * bi + 2])
        return self.z[:, 3 * bi:3 * bi + 2] + np.stack([c * s[0] - sn * s[1], sn * s[0] + c * s[1]], axis=1)

    def drive_force(self, name: str) -> np.ndarray:
        """(N,) torque [N m] or force [N] the drive of joint ``name`` applies on its coordinate (a force
        drive's law; a kinematic drive's constraint force)."""
        names = [d.joint for d in self.setup.packed.drives]
        return self.dv[:, names.index(name)]


def _guide_normal(rm: RigidMotion, joint) -> np.ndarray:
    """(N, 2) the normal of a guided joint's guide (turning with body a)."""
    mech = rm.setup.mech
    a, _ = mech.joint_points(joint)
    u0 = joint.unit_axis()
    n0 = np.array([-u0[1], u0[0]])
    if a.body is None:
        return np.tile(n0, (rm.t.size, 1))
    bi = mech.body_index(a.body)
    rot = rm.z[:, 3 * bi + 2] - a.body.angle
    c, s = np.cos(rot), np.sin(rot)
    return np.stack([c * n0[0] - s * n0[1], s * n0[0] + c * n0[1]], axis=1)


def _link_motion(mech: Mechanism, z, zd, zdd) -> LinkMotion:
    """The motion of each link's start from its centre of mass: O = C - xc e, v_O = v_C - xc omega Omega e,
    a_O = a_C - xc (alpha Omega e - omega^2 e)."""
    nl = len(mech.links)
    xc = np.array([ln.mass_properties()[1] for ln in mech.links])
    phi, om, al = z[:, 2:3 * nl:3], zd[:, 2:3 * nl:3], zdd[:, 2:3 * nl:3]
    c, s = np.cos(phi), np.sin(phi)
    return LinkMotion(phi=phi, omega=om, alpha=al,
                      ox=z[:, 0:3 * nl:3] - xc * c, oy=z[:, 1:3 * nl:3] - xc * s,
                      vx=zd[:, 0:3 * nl:3] + xc * om * s, vy=zd[:, 1:3 * nl:3] - xc * om * c,
                      ax=zdd[:, 0:3 * nl:3] + xc * (al * s + om * om * c),
                      ay=zdd[:, 1:3 * nl:3] - xc * (al * c - om * om * s))


class MotionSource:
    """The rigid-body motion of a prepared mechanism as a function of time: ``source(t)`` is the
    RigidMotion on any increasing grid t >= 0.  ``rtol``, ``atol``: the dynamic mode's error
    tolerances; ``hmax`` its largest step [s]; ``controls``: the collocated feedback controllers closed
    in the dynamic mode (flexmech_py.mechanism.control: rigid_pack; their integrals are states of the
    integration, docs/theory.md 23.3), or None."""

    def __init__(self, setup: MotionSetup, rtol: float = 1e-10, atol: float = 1e-12, hmax: float = np.inf,
                 controls=None):
        self.setup, self.rtol, self.atol = setup, float(rtol), float(atol)
        self.controls = controls if setup.mode == "dynamic" else None
        self.hmax = float(min(hmax, 1e300))
        self.tol = POSITION_TOL * setup.packed.lref
        self.stats = {"steps": 0, "rejected": 0, "rhs": 0, "rcond_low": np.inf}
        self._restart()

    def _restart(self) -> None:
        st, p = self.setup, self.setup.packed
        if st.mode == "kinematic":
            self._state = np.concatenate([[0.0, 0.0], st.z0, np.zeros(2 * p.n)])
            self._t_from = 0.0
            self._sample(np.array([0.0]))       # velocities and accelerations at t = 0 for the extrapolation
            return
        self._state, status = self._start(0.0, st.z0, st.zd0, None)
        kernels.check_status(status, "rigid-body dynamics (start)", time=0.0, detail=self._detail(st.z0, 0.0))
        self._t_from = 0.0

    def _start(self, t: float, z, zd, extra):
        """(state, status) of the dynamic mode started at (t, z, zd); with controllers, ``extra`` their
        integrals and the drives' work (None: zero, a fresh start) and the references' starts of t = 0
        (kept from the state when it continues)."""
        p, c = self.setup.packed, self.controls
        if c is None:
            nst = kernels.mbs.mbs_state_size(p.n)
            return kernels.mbs.mbs_dynamic_start(nst, p.ispec, p.rspec, t, z, zd, self.rtol, self.atol, self.hmax,
                                                 self.tol)
        nc = len(c.names)
        nst = kernels.mbs.mbs_controlled_state_size(p.n, nc)
        start = np.full(nc, np.nan) if extra is None else self._state[-nc:]
        x0, w0 = (np.zeros(nc), 0.0) if extra is None else (np.asarray(extra[0], float), float(extra[1]))
        return kernels.mbs.mbs_controlled_start(nst, p.ispec, p.rspec, c.cint, c.cpar, c.ctab_t, c.ctab_c, c.dt, t,
                                                z, zd, x0, w0, start, self.rtol, self.atol, self.hmax, self.tol)

    def restart_at(self, t: float, z, zd, extra=None) -> None:
        """Continue the motion from the state (z, zd) at time t [s] with the description as it is now
        (a force drive's law changed at t, flexmech_py.run.stepping): the dynamic mode starts its
        integration afresh there (with controllers, ``extra`` = (their integrals, the drives' work) at t,
        their references as they were); the kinematic mode, whose samples do not depend on the force laws, goes on as it was."""
        if self.setup.mode == "kinematic":
            return
        z, zd = np.asarray(z, float), np.asarray(zd, float)
        if self.controls is not None and extra is None:
            raise ValueError("restart_at: a motion with controllers continues from their integrals and work")
        self._state, status = self._start(float(t), z, zd, extra)
        if status:
            kernels.check_status(status, "rigid-body dynamics (restart)", time=float(t), detail=self._detail(z, float(t)))
        self._t_from = float(t)

    def fork(self) -> "MotionSource":
        """An independent source at the same point of the motion (two grids followed in turn, e.g. a
        run and its step-doubling check, each continue without restarting from t = 0)."""
        other = copy.copy(self)
        other._state = self._state.copy()
        other.stats = dict(self.stats)
        return other

    def __call__(self, t) -> RigidMotion:
        t = np.ascontiguousarray(t, dtype=float).reshape(-1)
        if t.size == 0 or np.any(np.diff(t) < 0) or t[0] < 0:
            raise ValueError("sample times must be a non-empty increasing grid from t >= 0")
        if t[0] < self._t_from - 1e-12 * max(1.0, abs(t[0])):
            self._restart()
        return self._sample(t)

    def _sample(self, t: np.ndarray) -> RigidMotion:
        p, ctl = self.setup.packed, (None, None, None)
        if self.setup.mode == "kinematic":
            zf, zdf, zddf, lamf, jqf, dvf, nvalid, status, fail_t, rlow = kernels.mbs.mbs_kinematic(
                p.nrow, p.nj, max(len(p.drives), 1), p.ispec, p.rspec, t, self._state, self.tol, KINEMATIC_RCOND_MIN)
        elif self.controls is not None:
            c = self.controls
            zf, zdf, zddf, lamf, jqf, dvf, uf, xf, nvalid, status, fail_t, rlow = kernels.mbs.mbs_controlled_dynamic(
                p.n, p.nrow, p.nj, max(len(p.drives), 1), p.ispec, p.rspec, c.cint, c.cpar, c.ctab_t, c.ctab_c, c.dt,
                t, self._state, self.hmax, self.tol, DYNAMIC_GRAM_MIN)
            ctl = (uf.T[:nvalid], xf.T[:nvalid, :-1], xf[-1, :nvalid])
            self.stats.update(steps=int(self._state[1]), rejected=int(self._state[2]), rhs=int(self._state[3]))
            self._t_from = float(self._state[6])
        else:
            zf, zdf, zddf, lamf, jqf, dvf, nvalid, status, fail_t, rlow = kernels.mbs.mbs_dynamic(
                p.n, p.nrow, p.nj, max(len(p.drives), 1), p.ispec, p.rspec, t, self._state, self.hmax, self.tol,
                DYNAMIC_GRAM_MIN)
            self.stats.update(steps=int(self._state[1]), rejected=int(self._state[2]), rhs=int(self._state[3]))
            self._t_from = float(self._state[6])
        self.stats["rcond_low"] = min(self.stats["rcond_low"], float(rlow))
        rm = RigidMotion(self.setup, t[:nvalid], zf.T[:nvalid], zdf.T[:nvalid], zddf.T[:nvalid], lamf.T[:nvalid],
                         jqf.transpose(2, 1, 0)[:nvalid], dvf.T[:nvalid, :len(p.drives)], None, *ctl)
        if status != 0:
            z_at = zf[:, nvalid - 1] if nvalid else self.setup.z0
            try:
                kernels.check_status(status, "the rigid-body motion", time=float(fail_t),
                                     detail=self._detail(z_at, float(fail_t), rm))
            except MechanismError as exc:
                exc.partial = rm
                raise
        if self.setup.mode == "kinematic":
            self._t_from = float(t[nvalid - 1])
        return rm

    def _detail(self, z, t: float, rm: RigidMotion | None = None) -> str:
        """The joints that lose their independence at z and the drive coordinates reached."""
        mech, packed = self.setup.mech, self.setup.packed
        try:
            _, jac, _, _, _ = constraint_matrices(packed, z, t=t)
        except Exception:       # pragma: no cover - the description was checked at set-up
            return ""
        a = scaled_jacobian(mech, packed, jac)
        u, s, _ = np.linalg.svd(a, full_matrices=False)
        w = np.abs(u[:, -1])
        rows = [int(r) for r in np.argsort(-w) if w[r] > 0.3 * w.max()]
        names = []
        for r in rows:
            for j, (r0, nr) in zip(mech.joints, packed.joint_rows):
                if r0 <= r < r0 + nr and j.name not in names:
                    names.append(j.name)
        out = f"; joints involved: {', '.join(names)}" if names else ""
        if rm is not None and rm.t.size:
            coords = [f"{p} = {rm.joint(p)[-1, 0]:.6g} {mech.joint(p).unit}" for p in self.setup.primary]
            out += f"; last valid sample t = {rm.t[-1]:.6g} s with " + ", ".join(coords)
        return out
