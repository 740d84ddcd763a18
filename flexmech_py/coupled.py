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

from . import kernels
from .mechanism.motion import LinkMotion
from .errors import CaseError
from .model import FEModel, rcm_free_numbering

__all__ = ["CoupledModel", "chord_motion"]


@dataclass
class CoupledModel:
    """DOF layout and kernel arguments of the coupled model of a case; build with :meth:`from_case`.

    The kernel works on *segments*: a segment is a stretch of one link between two mesh nodes with
    its own chord frame.  The coupled model (``split=False``) has one segment per link; the
    nonlinear co-rotational model (``split=True``) one per element, with the tangents welded at the
    interior nodes (theory.md, sections 11-12).
    """

    case: dict
    fe: FEModel
    segments: list           # (link, k0, k1): mesh nodes k0..k1 of the link
    n_el: np.ndarray         # elements per segment
    ld: np.ndarray           # (maxld, nseg) 1-based all-DOF numbers of each segment's local vector
    ndof: int
    free_of: np.ndarray      # (ndof,) 1-based free numbers, 0 = fixed
    q_fixed: np.ndarray      # (ndof,) values of fixed DOFs (ground positions)
    prop: np.ndarray
    pm: tuple
    ri: tuple
    tq: tuple
    constraints: list        # rotation constraints: ([seg b, seg a], [end b, end a], kind, value or joint)
    last_run: dict | None = None   # the last run's frames and final state (run())

    @classmethod
    def from_case(cls, case: dict, fe: FEModel | None = None, split: bool = False) -> "CoupledModel":
        fe = FEModel.from_case(case) if fe is None else fe
        links = case["links"]
        n_link = [ln["elements"] for ln in links]
        segments = [(li, k, k + 1) for li, n in enumerate(n_link) for k in range(n)] if split else \
                   [(li, 0, n) for li, n in enumerate(n_link)]
        first = {li: next(i for i, sg in enumerate(segments) if sg[0] == li and sg[1] == 0) for li in range(len(links))}
        last = {li: next(i for i, sg in enumerate(segments) if sg[0] == li and sg[2] == n_link[li])
                for li in range(len(links))}

        def seg_end(li, end):   # (segment index, 0 start / 1 end) of a link end
            if end not in ("start", "end"):
                raise CaseError("joints", f"a joint at fraction {end} of link {links[li]['name']!r}: the coupled and "
                                          "nonlinear models join links at their ends only (for now)")
            return (first[li], 0) if end == "start" else (last[li], 1)

        # A torque-driven joint is a hub whose rotation is now free: its torque acts on the tangent
        # angles psi = phi_chord + th_end (the seed's "clamped"/"locked" elastic condition of a driven
        # joint means the link is clamped to its hub).  A kinematic drive prescribes the tangent angle
        # at its joint; a non-driven clamp or locked joint welds the tangents; interior nodes of a
        # split link are welded too.  All are rotation constraints (Lagrange multipliers).
        mech = case.mechanism
        driven = {d.joint for d in mech.drives if not d.kinematic}
        kin = {d.joint for d in mech.drives if d.kinematic}
        cons = []
        for j in fe.joints:
            sb, eb = seg_end(j.outboard, j.outboard_end)
            sa, ea = seg_end(j.inboard, j.inboard_end) if j.inboard is not None else (-1, 0)
            if j.name in kin:
                cons.append(([sb + 1, sa + 1], [eb, ea], "drive", j))
            elif j.name not in driven and j.shares_rotation:
                cons.append(([sb + 1, sa + 1], [eb, ea], "weld", j))
        for i in range(1, len(segments)):
            if segments[i][0] == segments[i - 1][0]:   # consecutive elements of one link
                cons.append(([i + 1, i], [0, 1], "weld", 0.0))
        # DOFs: positions of the segment-end nodes (FE global nodes: shared at joints), end rotations
        # relative to each segment's chord, interior elastic DOFs
        dof, fixed_val = {}, {}

        def new(key):
            dof[key] = len(dof)
            return dof[key]

        ground = _ground_points(case, fe)
        ld_cols = []
        for si, (li, k0, k1) in enumerate(segments):
            col = []
            for k in (k0, k1):
                node = fe.node_of[li][k]
                if ("r", node) not in dof:
                    new(("r", node)); new(("r", node, 1))
                col += [dof[("r", node)], dof[("r", node, 1)]]
            col.append(new(("t", si, 0)))
            for k in range(1, k1 - k0):
                col += [new(("e", si, k, "p")), new(("e", si, k, "v")), new(("e", si, k, "t"))]
            col.append(new(("t", si, 1)))
            ld_cols.append(col)
        for j in fe.joints:  # ground joints: fixed positions
            if j.inboard is None:
                node = fe.node_of[j.outboard][0 if j.outboard_end == "start" else -1]
                fixed_val[dof[("r", node)]], fixed_val[dof[("r", node, 1)]] = ground[j.name]
        ndof = len(dof)
        n_el = np.array([k1 - k0 for _, k0, k1 in segments], np.int32)
        maxld = int(3 * n_el.max() + 3)
        ld = np.zeros((maxld, len(segments)), np.int32)
        for si, col in enumerate(ld_cols):
            ld[: len(col), si] = np.array(col) + 1
            ld[len(col):, si] = ld[0, si]   # padding (never read: the kernel uses 3n+3 entries)
        q_fixed = np.zeros(ndof)
        mask = np.ones(ndof, bool)
        for d, val in fixed_val.items():
            q_fixed[d], mask[d] = val, False
        if not mask.any():
            raise CaseError("joints", "the coupled model has no free DOF")
        free_of = rcm_free_numbering([np.array(c) for c in ld_cols], mask)
        prop = np.array([[links[li]["length"] * (k1 - k0) / n_link[li], links[li]["density"] * links[li]["area"],
                          links[li]["youngs_modulus"] * links[li]["area"],
                          links[li]["youngs_modulus"] * links[li]["second_moment"]] for li, k0, k1 in segments]).T

        def seg_at(li, k):   # (segment, node index within it) holding mesh node k of link li
            for si, (l2, k0, k1) in enumerate(segments):
                if l2 == li and k0 <= k <= k1:
                    return si, k - k0
            raise AssertionError((li, k))

        pm = []
        for i, p in enumerate(case["point_masses"]):
            li, _, zeta = fe.node_ref(p["at"], f"point_masses[{i}].at")
            si, kk = seg_at(li, int(round(zeta / links[li]["length"] * n_link[li])))
            pm.append((si + 1, p["mass"], kk * prop[0, si] / n_el[si]))
        ri = []
        for i, r in enumerate(case["rotary_inertias"]):
            _, node, _ = fe.node_ref(r["at"], f"rotary_inertias[{i}].at")
            lw = fe.link_names.index(r["turns_with"])
            si, kk = seg_at(lw, fe.node_of[lw].index(node))
            ri.append((si + 1, kk, r["inertia"]))
        tq = []
        forces = [d for d in mech.drives if not d.kinematic]
        if forces:
            nh = max(max(len(d.params["sin"]), len(d.params["cos"])) for d in forces)
            for d in forces:
                if d.params.get("time_harmonics") or d.params.get("table"):
                    raise CaseError(f"drives.{d.joint}", "the coupled and nonlinear models take force laws in the "
                                                         "joint angle only (constant, sin, cos) for now")
                j = fe.joint(d.joint)
                sb, eb = seg_end(j.outboard, j.outboard_end)
                sa, ea = seg_end(j.inboard, j.inboard_end) if j.inboard is not None else (-1, 0)
                coef = [j.sign * c for c in [d.params["constant"]] + (d.params["sin"] + [0.0] * nh)[:nh]
                        + (d.params["cos"] + [0.0] * nh)[:nh]]
                tq.append(([sb + 1, sa + 1], [eb, ea], coef))
        return cls(case=case, fe=fe, segments=segments, n_el=n_el, ld=np.asfortranarray(ld), ndof=ndof,
                   free_of=free_of, q_fixed=q_fixed, prop=np.asfortranarray(prop), pm=_pack_pm(pm), ri=_pack_ri(ri),
                   tq=_pack_tq(tq), constraints=cons)

    # ------------------------------------------------------------------ helpers
    def seg_slice(self, si: int) -> np.ndarray:
        """0-based all-DOF numbers of segment si's local vector (length 3n+3)."""
        return self.ld[: 3 * self.n_el[si] + 3, si] - 1

    def link_ends(self, li: int) -> tuple[np.ndarray, np.ndarray]:
        """0-based DOF pairs (x, y) of the start and end node of link li."""
        segs = [si for si, sg in enumerate(self.segments) if sg[0] == li]
        return self.seg_slice(segs[0])[0:2], self.seg_slice(segs[-1])[2:4]

    def _args(self):
        return (self.free_of, self.n_el, self.ld, self.prop) + self.pm + self.ri + self.tq

    def initial_state(self, rm0) -> tuple[np.ndarray, np.ndarray]:
        """All-DOF (q, v) at rest elastically, with every node on the rigid configuration of the first
        sample of the rigid motion rm0."""
        km = rm0.motion
        q, v = self.q_fixed.copy(), np.zeros(self.ndof)
        for si, (li, k0, k1) in enumerate(self.segments):
            L = self.case["links"][li]["length"] / self.case["links"][li]["elements"]
            c, s = np.cos(km.phi[0, li]), np.sin(km.phi[0, li])
            w = km.omega[0, li]
            dofs = self.seg_slice(si)
            pos, vel = [], []
            for k in (k0, k1):
                pos += [km.ox[0, li] + k * L * c, km.oy[0, li] + k * L * s]
                vel += [km.vx[0, li] - w * k * L * s, km.vy[0, li] + w * k * L * c]
            for k in range(4):
                if self.free_of[dofs[k]] > 0:
                    q[dofs[k]], v[dofs[k]] = pos[k], vel[k]
        return q, v

    def constraint_values(self, rm) -> np.ndarray:
        """(3, nc, nt) [angle, rate, acceleration] of the rotation constraints on the rigid motion's grid:
        the drive law (the rigid joint motion) for a kinematic drive, the initial relative angle for a weld
        (in the FE joint's orientation)."""
        nc = max(1, len(self.constraints))
        out = np.zeros((3, nc, rm.t.size))
        for i, (_, _, kind, j) in enumerate(self.constraints):
            if kind == "drive":
                out[:, i] = j.sign * rm.joint(j.name).T
            elif not isinstance(j, float):   # weld at a joint: its initial relative angle
                out[0, i] = j.sign * rm.joint(j.name)[0, 0]
        return np.asfortranarray(out)

    def run(self, q0, v0, t, cval, dt, *, beta=0.25, gamma=0.5, alpha_m=0.0, alpha_f=0.0, out_every=1, tol=1e-8,
            maxit=25, gravity=(0.0, 0.0), rayleigh=(0.0, 0.0), p0=None, div_limit=None, t0=0.0):
        """Generalized-alpha-Newton run (Newmark (beta, gamma) for ``alpha_m = alpha_f = 0``; see
        :func:`flexmech_py.case.integrator_coefficients`); returns (qf, vf, af, lf, ef, iterations).
        cval: constraint_values().  ``p0`` (ndof): the pseudo-acceleration of a run being continued
        (None: a fresh start, p0 = the consistent initial acceleration).  ``div_limit`` [m]: the
        divergence guard (default DIVERGENCE_FACTOR x the longest link length).  After the call
        ``self.last_run`` holds the frames, ``frames_valid``, the final state ``q, v, a, p``,
        ``status`` and ``fail_step`` (also when the run failed)."""
        from .case import DIVERGENCE_FACTOR

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
        p = np.zeros(self.ndof) if p0 is None else np.array(p0, float)
        if div_limit is None:
            div_limit = DIVERGENCE_FACTOR * max(ln["length"] for ln in self.case["links"])
        seg_link = np.array([li + 1 for li, _, _ in self.segments], np.int32)
        qf, vf, af, lf, ef, status, fail, iters, nvalid = kernels.api.cpl_run(
            nframes, nc, *self._args(), np.asfortranarray(con_link), np.asfortranarray(con_end), cval,
            np.asarray(gravity, float), np.asarray(rayleigh, float), presc_dof, presc, dt, alpha_m, alpha_f, beta,
            gamma, out_every, tol, maxit, int(p0 is None), float(div_limit), seg_link, q, v, a, p)
        self.last_run = {"qf": qf, "vf": vf, "af": af, "lf": lf[:nc], "ef": ef, "frames_valid": int(nvalid),
                         "q": q, "v": v, "a": a, "p": p, "status": int(status), "fail_step": int(fail)}
        kernels.check_status(status, "coupled time integration", time=t0 + fail * dt if fail else t0,
                             step=int(fail), data={"qf": qf, "vf": vf, "af": af, "lf": lf[:nc], "ef": ef, "iters": iters,
                                                   "q": q, "v": v, "a": a, "p": p})
        return qf, vf, af, lf[:nc], ef, iters

    def dense(self, q, v, a, gravity=(0.0, 0.0), rayleigh=(0.0, 0.0)):
        """Residual (all DOFs), M, C_v, K_t (dense, free DOFs), [kinetic, potential] energy at one state."""
        res, mm, cm, km, energy, status = kernels.api.cpl_dense(
            int(self.free_of.max()), *self._args(), np.asarray(gravity, float), np.asarray(rayleigh, float),
            np.asarray(q, float), np.asarray(v, float), np.asarray(a, float))
        kernels.check_status(status, "cpl_dense")
        return res, mm, cm, km, energy


def _ground_points(case: dict, fe: FEModel) -> dict:
    """{joint: (x, y)} of every ground joint's fixed point."""
    mech = case.mechanism
    out = {}
    for j in fe.joints:
        if j.inboard is None:
            a, b = mech.joint_points(mech.joint(j.name))
            out[j.name] = tuple(a.position if a.body is None else b.position)
    return out


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


def chord_motion(cm: CoupledModel, qf, vf, af) -> LinkMotion:
    """Rigid motion of every link's chord (start node to end node) over the frames: the rigid
    motion the coupled and nonlinear models compute."""
    nl = len(cm.case["links"])
    out = {k: np.empty((qf.shape[1], nl)) for k in LinkMotion.__dataclass_fields__}
    for li in range(nl):
        ds, de = cm.link_ends(li)
        rs, re_ = qf[ds], qf[de]
        vs, ve = vf[ds], vf[de]
        as_, ae = af[ds], af[de]
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
    return LinkMotion(**out)


def _th(d, n: int, k: int) -> int:
    """All-DOF number of the rotation of node k (0..n) in a segment's local vector d (0-based layout
    [xs ys xe ye th_0 (p_k v_k th_k)_{k=1..n-1} th_n])."""
    return d[3 * n + 2] if k == n else d[3 * k + 4]


def _seg_chord(qf, d):
    c = qf[d[2:4]] - qf[d[0:2]]
    return c, np.arctan2(c[1], c[0])


def node_state(cm: CoupledModel, qf, li: int, k: int):
    """Total position (2, nf) and tangent angle (nf,) of mesh node k of link li."""
    for si, (l2, k0, k1) in enumerate(cm.segments):
        if l2 == li and k0 <= k <= k1:
            break
    d, n = cm.seg_slice(si), int(cm.n_el[si])
    kk = k - k0
    c, phi = _seg_chord(qf, d)
    w = kk / n
    p, v = (qf[d[3 * kk + 2]], qf[d[3 * kk + 3]]) if 0 < kk < n else (0.0, 0.0)
    cs, sn = np.cos(phi), np.sin(phi)
    pos = (1 - w) * qf[d[0:2]] + w * qf[d[2:4]] + np.array([cs * p - sn * v, sn * p + cs * v])
    return pos, phi + qf[_th(d, n, kk)]


def deviation(cm: CoupledModel, qf, ref) -> np.ndarray:
    """Displacement from the rigid-body solution in the superposition DOF layout (ndof_fe, nf):
    node translations = total position - rigid-body-solution position; rotations = total tangent
    angle - rigid-body-solution link angle (principal value)."""
    fe = cm.fe
    u = np.zeros((fe.ndof, qf.shape[1]))
    for li, ln in enumerate(cm.case["links"]):
        n, L = ln["elements"], ln["length"]
        cr, sr = np.cos(ref.phi[:, li]), np.sin(ref.phi[:, li])
        for k in range(n + 1):
            pos, psi = node_state(cm, qf, li, k)
            node = fe.node_of[li][k]
            u[fe.trans_dof[node]] = pos - np.array([ref.ox[:, li] + k / n * L * cr, ref.oy[:, li] + k / n * L * sr])
            dphi = psi - ref.phi[:, li]
            u[fe.rot_dof[(node, li)]] = np.arctan2(np.sin(dphi), np.cos(dphi))
    return u


def curvature(cm: CoupledModel, qf, li: int, frac: float) -> np.ndarray:
    """Curvature [1/m] of link li at frac of its length, from the chord-frame elastic DOFs."""
    n_link = cm.case["links"][li]["elements"]
    s = frac * n_link
    k = int(round(s))
    parts = []   # (segment, element within it, xi)
    for si, (l2, k0, k1) in enumerate(cm.segments):
        if l2 != li:
            continue
        if abs(s - k) < 1e-9:     # at a mesh node: the elements that meet there
            if k0 < k <= k1:
                parts.append((si, k - k0 - 1, 1.0))
            if k0 <= k < k1:
                parts.append((si, k - k0, 0.0))
        elif k0 <= s < k1 or (s == k1 == n_link):
            e = min(int(np.floor(s)), k1 - 1)
            parts.append((si, e - k0, s - e))
    out = 0.0
    for si, e, xi in parts:
        d, n = cm.seg_slice(si), int(cm.n_el[si])
        loc = np.zeros((6, qf.shape[1]))
        for j, kk in enumerate((e, e + 1)):
            if 0 < kk < n:
                loc[3 * j], loc[3 * j + 1] = qf[d[3 * kk + 2]], qf[d[3 * kk + 3]]
            loc[3 * j + 2] = qf[_th(d, n, kk)]
        out = out + kernels.element_curvatures(loc, np.zeros(qf.shape[1]), cm.prop[0, si] / n, xi)
    return out / len(parts)


def joint_angles(cm: CoupledModel, qf) -> dict:
    """{joint: angle (nf,)} measured at the joint: difference of the tangent angles of the outboard
    and the inboard link there (ground: 0), unwrapped in time."""
    out = {}
    for j in cm.fe.joints:
        tot = 0.0
        for li, end, sign in ((j.outboard, j.outboard_end, 1.0), (j.inboard, j.inboard_end, -1.0)):
            if li is not None:
                tot = tot + sign * node_state(cm, qf, li, 0 if end == "start" else cm.case["links"][li]["elements"])[1]
        out[j.name] = np.unwrap(tot)
    return out


def diagnostics(cm: CoupledModel, qf, ef, chord, ref, iters: int, nsteps: int) -> dict:
    """Energy balance, Newton statistics, link-length drift and drift from the rigid-body solution."""
    e = ef[0] + ef[1] - ef[2]
    scale = max(np.max(np.abs(ef[0])), np.max(np.abs(ef[2])), 1e-300)
    stretch = []
    for si in range(len(cm.segments)):
        d = cm.seg_slice(si)
        ell = np.hypot(*(qf[d[2:4]] - qf[d[0:2]]))
        stretch.append(float(np.max(np.abs(ell / cm.prop[0, si] - 1.0))))
    tangents = joint_angles(cm, qf)
    drift = {}
    for j in cm.fe.joints:
        th_r = np.unwrap(ref.phi[:, j.outboard] - (ref.phi[:, j.inboard] if j.inboard is not None else 0.0))
        th_c = np.unwrap(chord.phi[:, j.outboard] - (chord.phi[:, j.inboard] if j.inboard is not None else 0.0))
        dth = th_c - th_r
        dth -= 2 * np.pi * np.round(dth[0] / (2 * np.pi))
        dhub = tangents[j.name] - th_r
        dhub -= 2 * np.pi * np.round(dhub[0] / (2 * np.pi))
        drift[j.name] = {"max_abs_rad": float(np.max(np.abs(dth))), "final_rad": float(dth[-1]),
                         "at_joint_tangents_max_abs_rad": float(np.max(np.abs(dhub)))}
    return {"energy_balance": {"max_abs_drift_J": float(np.max(np.abs(e - e[0]))),
                               "relative_drift": float(np.max(np.abs(e - e[0])) / scale),
                               "final_kinetic_J": float(ef[0, -1]), "final_work_J": float(ef[2, -1])},
            "newton": {"iterations": int(iters), "mean_per_step": iters / max(nsteps, 1),
                       "max_per_step": int(np.max(ef[3]))},
            "link_length_drift": {"max_relative": max(stretch), "bound": 1e-3, "within_bound": max(stretch) < 1e-3},
            "joint_closure_error_m": 0.0,
            "rigid_drift_from_rigid_body_solution": drift}


def axial_forces(cm: CoupledModel, qf) -> np.ndarray:
    """(nel, nf) axial force [N] of every FE element (link order): EA times the chord stretch of its
    segment plus its elastic axial strain."""
    fe = cm.fe
    out = np.empty((fe.nel, qf.shape[1]))
    for si, (li, k0, k1) in enumerate(cm.segments):
        d, n = cm.seg_slice(si), int(cm.n_el[si])
        ls = cm.prop[0, si]
        eps_c = np.hypot(*(qf[d[2:4]] - qf[d[0:2]])) / ls - 1.0
        els = fe.link_elements(li)
        for e in range(n):
            p1 = qf[d[3 * e + 2]] if 0 < e < n else 0.0
            p2 = qf[d[3 * (e + 1) + 2]] if 0 < e + 1 < n else 0.0
            out[els[k0 + e]] = cm.prop[2, si] * (eps_c + (p2 - p1) / (ls / n))
    return out


def validity(fe: FEModel, axial: np.ndarray, u_dev: np.ndarray) -> dict:
    """Per link: the largest compressive and tensile axial force over the Euler load
    pi^2 EI / L^2 of the link, and the largest displacement from the rigid motion over its length."""
    out = {}
    for li, ln in enumerate(fe.case["links"]):
        if ln.get("rigid"):   # no deformation
            continue
        ne = np.pi ** 2 * ln["youngs_modulus"] * ln["second_moment"] / ln["length"] ** 2
        n = axial[fe.link_elements(li)]
        disp = max(float(np.max(np.hypot(u_dev[fe.trans_dof[node, 0]], u_dev[fe.trans_dof[node, 1]])))
                   for node in fe.node_of[li])
        out[ln["name"]] = {"euler_load_N": ne, "max_compression_over_euler": float(max(0.0, -n.min()) / ne),
                           "max_tension_over_euler": float(max(0.0, n.max()) / ne),
                           "max_displacement_over_length": disp / ln["length"]}
    return out
