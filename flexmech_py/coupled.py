"""The one-pass coupled model (seed Section 3): rigid and elastic coordinates in one system.

Coordinates (docs/theory.md, "Coupled model"): the absolute positions of the link ends
("rigid" DOFs, shared by the links that meet at a joint, fixed at ground pivots) and, per
link, elastic DOFs in the frame of the link's chord: the rotation of every node relative to
the chord and the axial/transverse displacement of the interior nodes.  The rigid motion is
an output; input torques are generalized forces on the tangent angles at the joints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import kernels, rigid
from .errors import CaseError
from .model import FEModel, _UnionFind, rcm_free_numbering

__all__ = ["CoupledModel", "chord_motion"]


@dataclass
class CoupledModel:
    """DOF layout and kernel arguments of the coupled model of a case; build with :meth:`from_case`."""

    case: dict
    fe: FEModel
    n_el: np.ndarray
    ld: np.ndarray           # (maxld, nlinks) 1-based all-DOF numbers of each link's local vector
    ndof: int
    free_of: np.ndarray      # (ndof,) 1-based free numbers, 0 = fixed or prescribed
    q_fixed: np.ndarray      # (ndof,) values of fixed DOFs (ground positions, clamped rotations)
    prop: np.ndarray
    pm: tuple
    ri: tuple
    tq: tuple
    presc_dof: np.ndarray    # 0-based prescribed DOFs
    constraints: list        # rotation constraints: ([link b, link a], [end b, end a], "drive" | "weld", Joint)

    @classmethod
    def from_case(cls, case: dict, fe: FEModel | None = None) -> "CoupledModel":
        fe = FEModel.from_case(case) if fe is None else fe
        links = case["links"]
        nl = len(links)
        n_el = np.array([ln["elements"] for ln in links], np.int32)
        ground = _ground_points(case)
        # rigid nodes: link ends merged at joints
        ends = _UnionFind()
        for j in fe.joints:
            if j.inboard is not None:
                ends.union((j.inboard, j.inboard_end), (j.outboard, j.outboard_end))
        # End rotations relative to the chord are free DOFs at every joint: the physical angle of a
        # link end is the tangent angle psi = phi_chord + th_end.  A torque-driven joint is a hub whose
        # rotation is now free: its torque acts on the tangent angles (the seed's "clamped"/"locked"
        # elastic condition of a driven joint means the link is clamped to its hub).  A kinematic drive
        # prescribes the tangent angle at its joint, and a non-driven clamp or locked joint welds the
        # tangents: both are rotation constraints (Lagrange multipliers, theory.md section 11).
        driven = {t["joint"] for t in case["drive"].get("torques", [])}
        kin = fe.joints[0].name if case["drive"]["type"] == "kinematic" else None
        cons = []   # (links [b, a], ends [b, a], kind) with kind "drive" or "weld"
        for j in fe.joints:
            ends_ = [0 if j.outboard_end == "start" else 1, 0 if j.inboard_end in (None, "start") else 1]
            links_ = [j.outboard + 1, 0 if j.inboard is None else j.inboard + 1]
            if j.name == kin:
                cons.append((links_, ends_, "drive", j))
            elif j.name not in driven and j.elastic in ("clamp", "locked"):
                cons.append((links_, ends_, "weld", j))
        rots = _UnionFind()
        dof, fixed_val, fixed = {}, {}, set()

        def new(key):
            dof[key] = len(dof)
            return dof[key]

        for li in range(nl):
            for end in ("start", "end"):
                r = ends.find((li, end))
                if ("r", r) not in dof:
                    new(("r", r)); dof[("r", r, 1)] = len(dof)
                t = rots.find((li, end))
                if ("t", t) not in dof:
                    new(("t", t))
        for j in fe.joints:  # ground joints: fixed positions, clamp fixes the end rotation
            if j.inboard is None:
                r = ends.find((j.outboard, j.outboard_end))
                for k, key in enumerate((("r", r), ("r", r, 1))):
                    fixed.add(dof[key]); fixed_val[dof[key]] = ground[j.name][k]
        maxld = int(3 * n_el.max() + 3)
        ld = np.zeros((maxld, nl), np.int32)
        for li in range(nl):
            n = int(n_el[li])
            rs, re_ = ends.find((li, "start")), ends.find((li, "end"))
            col = [dof[("r", rs)], dof[("r", rs, 1)], dof[("r", re_)], dof[("r", re_, 1)],
                   dof[("t", rots.find((li, "start")))]]
            for k in range(1, n):
                col += [new(("e", li, k, "p")), new(("e", li, k, "v")), new(("e", li, k, "t"))]
            col.append(dof[("t", rots.find((li, "end")))])
            ld[: len(col), li] = np.array(col) + 1
            ld[len(col):, li] = ld[0, li]   # padding (never read: the kernel uses 3n+3 entries)
        ndof = len({v for v in dof.values()})
        q_fixed = np.zeros(ndof)
        for d, val in fixed_val.items():
            q_fixed[d] = val
        presc = []   # prescribed DOFs: none for now (the kernel supports them)
        mask = np.ones(ndof, bool)
        mask[list(fixed)] = False
        mask[presc] = False
        if not mask.any():
            raise CaseError("joints", "the coupled model has no free DOF")
        free_of = rcm_free_numbering([ld[: 3 * n_el[li] + 3, li] - 1 for li in range(nl)], mask)
        prop = np.array([[ln["length"], ln["density"] * ln["area"], ln["youngs_modulus"] * ln["area"],
                          ln["youngs_modulus"] * ln["second_moment"]] for ln in links]).T
        pm = [(fe.node_ref(p["at"], f"point_masses[{i}].at")[0] + 1, p["mass"],
               fe.node_ref(p["at"], f"point_masses[{i}].at")[2]) for i, p in enumerate(case["point_masses"])]
        ri = []
        for i, r in enumerate(case["rotary_inertias"]):
            _, node, _ = fe.node_ref(r["at"], f"rotary_inertias[{i}].at")
            lw = fe.link_names.index(r["turns_with"])
            ri.append((lw + 1, fe.node_of[lw].index(node), r["inertia"]))
        tq = []
        if case["drive"]["type"] == "torque":
            nh = max(max(len(t["sin"]), len(t["cos"])) for t in case["drive"]["torques"])
            for t in case["drive"]["torques"]:
                j = next(jj for jj in fe.joints if jj.name == t["joint"])
                coef = [t["constant"]] + (t["sin"] + [0.0] * nh)[:nh] + (t["cos"] + [0.0] * nh)[:nh]
                tq.append(([j.outboard + 1, 0 if j.inboard is None else j.inboard + 1],
                           [0 if j.outboard_end == "start" else 1, 0 if j.inboard_end in (None, "start") else 1], coef))
        return cls(case=case, fe=fe, n_el=n_el, ld=np.asfortranarray(ld), ndof=ndof, free_of=free_of,
                   q_fixed=q_fixed, prop=np.asfortranarray(prop), pm=_pack_pm(pm), ri=_pack_ri(ri), tq=_pack_tq(tq),
                   presc_dof=np.array(presc, np.int32), constraints=cons)

    # ------------------------------------------------------------------ helpers
    def link_slice(self, li: int) -> np.ndarray:
        """0-based all-DOF numbers of link li's local vector (length 3n+3)."""
        return self.ld[: 3 * self.n_el[li] + 3, li] - 1

    def _args(self):
        return (self.free_of, self.n_el, self.ld, self.prop) + self.pm + self.ri + self.tq

    def initial_state(self, q_rigid: np.ndarray, qd_rigid: np.ndarray, mech) -> tuple[np.ndarray, np.ndarray]:
        """All-DOF (q, v) at rest elastically, with the link ends on the rigid configuration."""
        km = mech.kinematics(q_rigid[None], qd_rigid[None], None)
        q, v = self.q_fixed.copy(), np.zeros(self.ndof)
        for li in range(len(self.n_el)):
            L = self.prop[0, li]
            c, s = np.cos(km.phi[0, li]), np.sin(km.phi[0, li])
            w = km.omega[0, li]
            dofs = self.link_slice(li)
            pos = [km.ox[0, li], km.oy[0, li], km.ox[0, li] + L * c, km.oy[0, li] + L * s]
            vel = [km.vx[0, li], km.vy[0, li], km.vx[0, li] - w * L * s, km.vy[0, li] + w * L * c]
            for k in range(4):
                if self.free_of[dofs[k]] > 0:
                    q[dofs[k]], v[dofs[k]] = pos[k], vel[k]
        return q, v

    def constraint_values(self, t, q_rigid, qd_rigid, qdd_rigid, mech) -> np.ndarray:
        """(3, nc, nt) [angle, rate, acceleration] of the rotation constraints on the grid: the drive law
        (the rigid joint motion) for a kinematic drive, the initial relative angle for a weld."""
        nc = max(1, len(self.constraints))
        out = np.zeros((3, nc, t.size))
        km0 = mech.kinematics(q_rigid[:1], qd_rigid[:1], None)
        for i, (_, _, kind, j) in enumerate(self.constraints):
            if kind == "drive":
                out[:, i] = [q_rigid[:, 0], qd_rigid[:, 0], qdd_rigid[:, 0]]
            else:
                out[0, i] = km0.phi[0, j.outboard] - (km0.phi[0, j.inboard] if j.inboard is not None else 0.0)
        return np.asfortranarray(out)

    def run(self, q0, v0, t, cval, dt, *, beta=0.25, gamma=0.5, out_every=1, tol=1e-8, maxit=25,
            gravity=(0.0, 0.0), rayleigh=(0.0, 0.0)):
        """Newmark-Newton run; returns (qf, vf, af, lf, ef, iterations).  cval: constraint_values()."""
        nsteps = t.size - 1
        nframes = nsteps // out_every + 1
        # f2py cannot pass empty arrays: with no prescribed DOF, a fixed DOF is prescribed to its own value
        fixed = int(np.flatnonzero(self.free_of == 0)[0])
        presc = np.zeros((3, 1, t.size), order="F")
        presc[0, 0, :] = self.q_fixed[fixed]
        presc_dof = np.array([fixed + 1], np.int32)
        nc = len(self.constraints)
        con_link = np.array([c[0] for c in self.constraints] or [[1, 0]], np.int32).T
        con_end = np.array([c[1] for c in self.constraints] or [[0, 0]], np.int32).T
        q, v, a = np.array(q0, float), np.array(v0, float), np.zeros(self.ndof)
        qf, vf, af, lf, ef, status, fail, iters = kernels.api.cpl_run(
            nframes, nc, *self._args(), np.asfortranarray(con_link), np.asfortranarray(con_end), cval,
            np.asarray(gravity, float), np.asarray(rayleigh, float), presc_dof, presc, dt, beta, gamma, out_every,
            tol, maxit, q, v, a)
        kernels.check_status(status, "coupled Newmark-Newton integration", time=fail * dt if fail else 0.0)
        return qf, vf, af, lf[:nc], ef, iters

    def dense(self, q, v, a, gravity=(0.0, 0.0), rayleigh=(0.0, 0.0)):
        """Residual (all DOFs), M, C_v, K_t (dense, free DOFs), [kinetic, potential] energy at one state."""
        res, mm, cm, km, energy, status = kernels.api.cpl_dense(
            int(self.free_of.max()), *self._args(), np.asarray(gravity, float), np.asarray(rayleigh, float),
            np.asarray(q, float), np.asarray(v, float), np.asarray(a, float))
        kernels.check_status(status, "cpl_dense")
        return res, mm, cm, km, energy


def _ground_points(case: dict) -> dict:
    if case["mechanism"]["type"] == "fourbar":
        return {"crank_pivot": (0.0, 0.0), "follower_pivot": (case["mechanism"]["ground_length"], 0.0)}
    return {"base": tuple(case["mechanism"]["base"])}


def _pack_pm(pm):
    if not pm:  # f2py cannot pass empty arrays: one massless point
        return np.ones(1, np.int32), np.zeros((2, 1), order="F")
    return (np.array([p[0] for p in pm], np.int32), np.asfortranarray(np.array([[p[1], p[2]] for p in pm]).T))


def _pack_ri(ri):
    if not ri:
        return np.ones(1, np.int32), np.zeros(1, np.int32), np.zeros(1)
    return (np.array([r[0] for r in ri], np.int32), np.array([r[1] for r in ri], np.int32),
            np.array([r[2] for r in ri], float))


def _pack_tq(tq):
    if not tq:  # one zero torque on link 1 from the ground
        return np.array([[1], [0]], np.int32, order="F"), np.zeros((2, 1), np.int32, order="F"), np.zeros((1, 1), order="F")
    return (np.asfortranarray(np.array([t[0] for t in tq], np.int32).T),
            np.asfortranarray(np.array([t[1] for t in tq], np.int32).T),
            np.asfortranarray(np.array([t[2] for t in tq], float).T))


def chord_motion(cm: CoupledModel, qf, vf, af) -> rigid.LinkMotion:
    """Rigid motion of every link's chord over the frames (the coupled model's rigid motion)."""
    nl = len(cm.n_el)
    out = {k: np.empty((qf.shape[1], nl)) for k in rigid.LinkMotion.__dataclass_fields__}
    for li in range(nl):
        d = cm.link_slice(li)[:4]
        rs, re_ = qf[d[:2]], qf[d[2:]]
        vs, ve = vf[d[:2]], vf[d[2:]]
        as_, ae = af[d[:2]], af[d[2:]]
        c, cd, cdd = re_ - rs, ve - vs, ae - as_
        l2 = (c ** 2).sum(0)
        g = np.array([-c[1], c[0]]) / l2
        om = (g * cd).sum(0)
        out["phi"][:, li] = np.unwrap(np.arctan2(c[1], c[0]))
        out["omega"][:, li] = om
        out["alpha"][:, li] = (g * cdd).sum(0) - 2 * (c * cd).sum(0) * om / l2
        out["ox"][:, li], out["oy"][:, li] = rs
        out["vx"][:, li], out["vy"][:, li] = vs
        out["ax"][:, li], out["ay"][:, li] = as_
    return rigid.LinkMotion(**out)
