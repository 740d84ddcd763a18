"""Joint reactions of the superposition models (docs/theory.md §18.5).

The force (and moment) a joint transmits in the elastic model, from the equations of motion of the
bodies it joins:

- a flexible link b at a joint node N: the generalized force its own items exert there,
  ``f_b(N) = sum over b's elements at N of (M_e u'' + C_e u' + K_e u + F_e)`` at N's translations and
  b's rotation (plus b's point masses and rotary inertias at N), is what the joints at N apply to b;
- a rigid body or rigid link: ``[m (d'' + a_C - g), J (theta'' + alpha)]`` at its centre of mass is the
  resultant of the joint forces on it (a force f at a point s from the centre adds the moment s x f);
- the drives' generalized forces (the law of a force drive, the rigid-body solution's torque or force
  of a kinematic one) act on the joint's bodies besides the reactions.

Each joint's unknowns: the force of a revolute joint (x, y) and, when it transmits a moment in the
elastic problem (``locked``/``clamp``, welds), the moment; a prismatic joint's normal force, its moment
and, when ``locked``, the force along the guide.  The equations of all the joint nodes and rigid bodies
are solved per frame by least squares; the solution satisfies them to round-off (the elastic solution
satisfies its equations of motion), reported as ``equilibrium_residual``.  With very stiff links the
elastic reactions tend to the rigid-body ones (tests/test_superposition_general.py).
"""

from __future__ import annotations

import numpy as np

from . import kernels

__all__ = ["ModelReactions"]


class ModelReactions:
    """Callable ``reactions(joint) -> (N, 3) [F_x, F_y, M]`` (force and moment body a exerts on body b,
    global components) of a superposition run; computed for every joint on the first call."""

    def __init__(self, fe, model: str, rm, rig, state, sol: dict, axial=None):
        self.fe, self.model, self.rm, self.rig, self.state = fe, model, rm, rig, state
        self.rayleigh = sol["rayleigh"]
        self.axial = axial if sol.get("geometric_stiffness", "none") != "none" else None
        self._out = None
        self._elements = {}
        self.residual = None

    @property
    def checked(self) -> bool:
        return self._out is not None

    def over(self, res, sel=None) -> "ModelReactions":
        """The same reactions over the frames of ``res`` (a block, or blocks joined); ``sel``: when
        ``res`` holds this one's frames ``sel``, the reactions already solved are kept."""
        other = ModelReactions.__new__(ModelReactions)
        other.__dict__.update(self.__dict__)
        other.rm, other.rig, other.state = res.rigid, res.rig, (res.u, res.v, res.a)
        other.axial = None if self.axial is None else res.axial
        other._elements = {}
        other._out = None if (self._out is None or sel is None) else {k: v[sel] for k, v in self._out.items()}
        return other

    def __call__(self, name: str) -> np.ndarray:
        if self._out is None:
            self._out = self._solve()
        return self._out[name]

    def summary(self) -> dict:
        return {"source": "model", "equilibrium_residual": self.residual,
                "note": "reaction outputs with source = 'model': the forces the joints transmit in the elastic model "
                        "(docs/theory.md section 18.5); max over the frames of |A f - b| / |b| of the joint equations"}

    # ------------------------------------------------------------------ the equations
    def _solve(self) -> dict:
        mech = self.fe.case.mechanism
        nf = self.rm.t.size
        eqs = {}                 # body key -> row offset; key: ("node", node, link) or ("part", name)
        unknowns = []            # (joint, component kind, offset)
        for j in mech.joints:
            for ref in mech.joint_points(j):
                key = self._key(ref)
                if key is not None and key not in eqs:
                    eqs[key] = 3 * len(eqs)
            comps = self._components(j)
            unknowns.append((j, comps, sum(len(c) for _, c, _ in unknowns)))
        nu = sum(len(c) for _, c, _ in unknowns)
        a = np.zeros((nf, 3 * len(eqs), nu))
        b = np.zeros((nf, 3 * len(eqs)))
        for key, r0 in eqs.items():
            b[:, r0:r0 + 3] = self._body_residual(key).T
        self._applied(eqs, b)
        for j, comps, c0 in unknowns:
            pa, pb = mech.joint_points(j)
            for k, comp in enumerate(comps):
                f, m = self._unit(j, comp)                      # (N, 2), (N,)
                for sign, ref, at in ((1.0, pb, pb), (-1.0, pa, pb if j.kind == "prismatic" else pa)):
                    key = self._key(ref)
                    if key is None:
                        continue
                    r0 = eqs[key]
                    a[:, r0:r0 + 2, c0 + k] += sign * f
                    a[:, r0 + 2, c0 + k] += sign * (m + self._moment_arm(key, at, ref, j, f))
        x = np.einsum("nuk,nk->nu", np.linalg.pinv(a), b)
        res = np.linalg.norm(np.einsum("nku,nu->nk", a, x) - b, axis=1)
        self.residual = float(np.max(res / np.maximum(np.linalg.norm(b, axis=1), 1e-300)))
        out = {}
        for j, comps, c0 in unknowns:
            r = np.zeros((nf, 3))
            for k, comp in enumerate(comps):
                f, m = self._unit(j, comp)
                r[:, :2] += f * x[:, c0 + k, None]
                r[:, 2] += m * x[:, c0 + k]
            out[j.name] = r
        return out

    def _key(self, ref):
        if ref.body is None:
            return None
        if ref.body.name in self.fe.parts:
            return ("part", ref.body.name)
        li = self.fe.link_names.index(ref.body.name)
        return ("node", self.fe.node_of[li][self.fe.node_index(li, ref.body.fraction(ref.point))], li)

    def _components(self, j) -> list[str]:
        cond = self.fe.case.mechanism.condition(j)
        if j.kind == "weld":
            return ["x", "y", "m"]
        if j.kind == "prismatic":
            return ["n", "m"] + (["t"] if cond == "locked" else [])
        return ["x", "y"] + (["m"] if cond in ("locked", "clamp") else [])

    def _guide(self, j) -> tuple[np.ndarray, np.ndarray]:
        """(t, n) (N, 2) of a prismatic joint's guide in the rigid motion."""
        sl = next(s for s in self.fe.slides if s.joint is j)
        a, _ = self.fe.case.mechanism.joint_points(j)
        if a.body is None:
            return np.tile(sl.t_body, (self.rm.t.size, 1)), np.tile(sl.n_body, (self.rm.t.size, 1))
        phi = self.rig[0, self.fe.parts[a.body.name].col]
        return _rot(phi, sl.t_body), _rot(phi, sl.n_body)

    def _unit(self, j, comp):
        """(force (N, 2), moment (N,)) of a unit value of a joint's unknown component."""
        n = self.rm.t.size
        if comp in ("x", "y"):
            return np.tile([1.0, 0.0] if comp == "x" else [0.0, 1.0], (n, 1)), np.zeros(n)
        if comp == "m":
            return np.zeros((n, 2)), np.ones(n)
        t, nrm = self._guide(j)
        return (nrm if comp == "n" else t), np.zeros(n)

    def _moment_arm(self, key, at, ref, j, f) -> np.ndarray:
        """(s x f)_z of a force f applied to a rigid part at point ``at`` (0 for a flexible node)."""
        if key[0] != "part":
            return 0.0
        s = self._point_offset(key[1], at, j)
        return s[:, 0] * f[:, 1] - s[:, 1] * f[:, 0]

    def _point_offset(self, part_name: str, at, j=None) -> np.ndarray:
        """(N, 2) from a rigid part's centre of mass to a point: a point of the part, or (a prismatic joint's
        guide body) the contact point, where the slider point b is."""
        mech, part = self.fe.case.mechanism, self.fe.parts[part_name]
        i = 3 * mech.body_index(part.body)
        z = self.rm.z
        if at.body is not None and at.body.name == part_name:
            return _rot(z[:, i + 2], part.body.marker(at.point))
        pos = _point_position(mech, z, at)                  # the slider point on the other body
        return pos - z[:, i:i + 2]

    def _applied(self, eqs: dict, b: np.ndarray) -> None:
        """Subtract the drives' generalized forces acting on the bodies from the right-hand sides."""
        mech = self.fe.case.mechanism
        for d in mech.drives:
            j = mech.joint(d.joint)
            f = self.rm.drive_force(d.joint)
            pa, pb = mech.joint_points(j)
            if j.kind == "prismatic":
                t, _ = self._guide(j)
                for sign, ref in ((1.0, pb), (-1.0, pa)):
                    key = self._key(ref)
                    if key is None:
                        continue
                    force = sign * f[:, None] * t
                    r0 = eqs[key]
                    b[:, r0:r0 + 2] -= force
                    b[:, r0 + 2] -= self._moment_arm(key, pb, ref, j, force)
                continue
            for sign, ref in ((1.0, pb), (-1.0, pa)):
                key = self._key(ref)
                if key is not None:
                    b[:, eqs[key] + 2] -= sign * f

    # ------------------------------------------------------------------ the bodies' own residuals
    def _body_residual(self, key) -> np.ndarray:
        """(3, N) generalized force of a body's own items at a joint node (flexible link) or at its centre
        of mass (rigid part): inertia, damping, stiffness and rigid-inertia load."""
        fe = self.fe
        u, v, acc = self.state
        ray_m, _ = self.rayleigh
        out = np.zeros((3, self.rm.t.size))
        if key[0] == "part":
            p = fe.parts[key[1]]
            dofs = list(p.dofs)
            a_c = self.rig[3:5, p.col] + (_accel_along(self.rig[:, p.col], p.zeta) if p.zeta else 0.0)
            out[:2] = p.mass * (acc[dofs[:2]] + ray_m * v[dofs[:2]] + a_c)
            out[2] = p.inertia * (acc[dofs[2]] + ray_m * v[dofs[2]])
            if self.model != "classic-translational":
                out[2] += p.inertia * self.rig[2, p.col]
            return out
        _, node, li = key
        tr, rot = fe.trans_dof[node], fe.rot_dof[(node, li)]
        for e in fe.link_elements(li):
            dofs = fe.el_dof[:, e] - 1
            for half in (0, 3):
                if dofs[half] == tr[0]:
                    out += self._element_residual(e)[half:half + 3]
        for i in range(fe.lm_link.size):
            if fe.lm_link[i] == li + 1 and fe.lm_dof[0, i] - 1 == tr[0]:
                m, z = fe.lm_prop[:, i]
                out[:2] += m * (acc[tr] + ray_m * v[tr] + self.rig[3:5, li] + _accel_along(self.rig[:, li], z))
        for i in range(fe.ri_link.size):
            if fe.ri_link[i] == li + 1 and fe.ri_dof[i] - 1 == rot:
                jr = fe.ri_prop[i]
                out[2] += jr * (acc[rot] + ray_m * v[rot])
                if self.model != "classic-translational":
                    out[2] += jr * self.rig[2, li]
        return out

    def _element_residual(self, e: int) -> np.ndarray:
        """(6, N) M u'' + C u' + K u + F_rigid of element e, global components (docs/theory.md §3-4)."""
        if e not in self._elements:
            self._elements[e] = self._element_residual_new(e)
        return self._elements[e]

    def _element_residual_new(self, e: int) -> np.ndarray:
        fe = self.fe
        L, z1, ra, ea, ei = fe.el_prop[:, e]
        m, k, g, c, m0, kg = kernels.api.element_matrices(ra, ea, ei, L)
        li = fe.el_link[e] - 1
        phi, om, al, ax, ay = self.rig[:, li]
        dofs = fe.el_dof[:, e] - 1
        u, v, acc = (_to_local(x[dofs], phi) for x in self.state)
        ray_m, ray_k = self.rayleigh
        r = m @ acc + 2.0 * om * (g @ v) + ray_m * (m @ v) + ray_k * (k @ v)
        r += k @ u + al * (g @ u) + om * om * (c @ u)
        if self.axial is not None:
            r += self.axial[e] * (kg @ u)
        cs, sn = np.cos(phi), np.sin(phi)
        ap = (cs * ax + sn * ay, -sn * ax + cs * ay)
        z2 = z1 + L
        w = [ap[0] - om * om * z1, ap[1] + al * z1, ap[0] - om * om * z2, ap[1] + al * z2]
        if self.model == "hac":
            r += m0 @ np.array(w)
        else:
            rot = al if self.model == "classic" else 0.0 * al
            r += m @ np.array([w[0], w[1], rot, w[2], w[3], rot])
        return _to_global(r, phi)


def _accel_along(r: np.ndarray, z: float) -> np.ndarray:
    """(2, N) rigid acceleration of the point z along a column's axis relative to its origin."""
    phi, om, al = r[0], r[1], r[2]
    c, s = np.cos(phi), np.sin(phi)
    return np.array([-al * s * z - om * om * c * z, al * c * z - om * om * s * z])


def _rot(phi, v) -> np.ndarray:
    """(N, 2) R(phi) v."""
    c, s = np.cos(phi), np.sin(phi)
    return np.stack([c * v[0] - s * v[1], s * v[0] + c * v[1]], axis=1)


def _point_position(mech, z, ref) -> np.ndarray:
    """(N, 2) position of a point in the rigid motion (z the bodies' coordinates)."""
    if ref.body is None:
        return np.tile(np.asarray(ref.position, float), (z.shape[0], 1))
    i = 3 * mech.body_index(ref.body)
    return z[:, i:i + 2] + _rot(z[:, i + 2], ref.body.marker(ref.point))


def _to_local(x: np.ndarray, phi) -> np.ndarray:
    c, s = np.cos(phi), np.sin(phi)
    return np.array([c * x[0] + s * x[1], -s * x[0] + c * x[1], x[2], c * x[3] + s * x[4], -s * x[3] + c * x[4], x[5]])


def _to_global(y: np.ndarray, phi) -> np.ndarray:
    c, s = np.cos(phi), np.sin(phi)
    return np.array([c * y[0] - s * y[1], s * y[0] + c * y[1], y[2], c * y[3] - s * y[4], s * y[3] + c * y[4], y[5]])
