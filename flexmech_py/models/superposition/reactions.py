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
elastic problem (``locked``/``clamp``, welds), the moment; a guided joint's normal force, its moment
and, when ``locked``, the force along the guide.  The equations of all the joint nodes and rigid bodies
are solved per frame by least squares; the solution satisfies them to round-off (the elastic solution
satisfies its equations of motion), reported as ``equilibrium_residual``.  With very stiff links the
elastic reactions tend to the rigid-body ones (tests/test_superposition_general.py).
"""

from __future__ import annotations

import weakref

import numpy as np

from ...base import kernels
from ...base.families import family

__all__ = ["ModelReactions", "JointEquations", "joint_equations", "least_squares"]

#: a frame's joint equations count as rank deficient (solved by pseudo-inverse, minimum norm) when the
#: smallest diagonal entry of their R factor is below this fraction of the largest
RANK_TOLERANCE = 1e-10


class ModelReactions:
    """Callable ``reactions(joint) -> (N, 3) [F_x, F_y, M]`` (force and moment body a exerts on body b,
    global components) of a superposition run; computed for every joint on the first call."""

    def __init__(self, fe, model: str, rm, rig, state, sol: dict, axial=None):
        self.fe, self.model, self.rm, self.rig, self.state = fe, model, rm, rig, state
        self.mech = fe.case.mechanism
        self.family = family(model)
        self.rayleigh = sol["rayleigh"]
        self.axial = axial if sol.get("geometric_stiffness", "none") != "none" else None
        self._out = None
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
        eq = joint_equations(self.fe)
        nf = self.rm.t.size
        n = 1 if eq.constant else nf           # the matrix of every frame, or one per frame
        b = self._right_hand_sides(eq)
        a = self._matrix(eq, n)
        x = least_squares(a, b)
        res = np.linalg.norm((a @ x[:, :, None])[:, :, 0] - b, axis=1)
        self.residual = float(np.max(res / np.maximum(np.linalg.norm(b, axis=1), 1e-300)))
        out = {}
        for j, comps, c0 in eq.unknowns:
            r = np.zeros((nf, 3))
            for k, comp in enumerate(comps):
                f, m = self._sides(j, comp, n)[0]
                r[:, :2] += f * x[:, c0 + k, None]
                r[:, 2] += m * x[:, c0 + k]
            out[j.name] = r
        return out

    def _right_hand_sides(self, eq: "JointEquations") -> np.ndarray:
        """(N, rows) the bodies' own generalized forces less the drives'."""
        b = np.zeros((self.rm.t.size, eq.rows))
        residuals = self._element_residuals(eq)
        for key, r0 in eq.eqs.items():
            b[:, r0:r0 + 3] = self._body_residual(eq, key, residuals).T
        self._applied(eq, b)
        return b

    def _matrix(self, eq: "JointEquations", n: int) -> np.ndarray:
        """(n, rows, nu) the joint equations' matrix: n = 1 when it is the same in every frame."""
        a = np.zeros((n, eq.rows, eq.nu))
        for j, comps, c0 in eq.unknowns:
            pa, pb = eq.points[j.name]
            ka, kb = eq.keys[j.name]
            for k, comp in enumerate(comps):
                for (f, m), key, ref, at in zip(self._sides(j, comp, n), (kb, ka), (pb, pa), (pb, pb if j.guided else pa)):
                    if key is None:
                        continue
                    r0 = eq.eqs[key]
                    a[:, r0:r0 + 2, c0 + k] += f
                    a[:, r0 + 2, c0 + k] += m + self._moment_arm(key, at, ref, j, f)
        return a

    def _sides(self, j, comp: str, n: int) -> list:
        """[(force (n, 2), moment (n,)) on body b, the same on body a] of a unit value of a joint's unknown:
        equal and opposite, or a kind's own units (Joint.reaction_units: a gear pair's tooth force)."""
        if comp == "own":
            pa, pb = self.mech.joint_points(j)
            return list(j.reaction_units(self.rm.point_positions(pa), self.rm.point_positions(pb)))
        f, m = self._unit(j, comp, n)                      # (n, 2), (n,)
        return [(f, m), (-f, -m)]

    def _guide(self, j) -> tuple[np.ndarray, np.ndarray]:
        """(t, n) (N, 2) of a guided joint's guide in the rigid motion."""
        sl = next(s for s in self.fe.slides if s.joint is j)
        a, _ = self.mech.joint_points(j)
        if a.body is None:
            return np.tile(sl.t_body, (self.rm.t.size, 1)), np.tile(sl.n_body, (self.rm.t.size, 1))
        phi = self.rig[0, self.fe.parts[a.body.name].col]
        return _rot(phi, sl.t_body), _rot(phi, sl.n_body)

    def _unit(self, j, comp, n: int):
        """(force (n, 2), moment (n,)) of a unit value of a joint's unknown component over n frames
        (n = 1: a revolute joint's or weld's, the same in every frame)."""
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
        """(N, 2) from a rigid part's centre of mass to a point: a point of the part, or (a guided joint's
        guide body) the contact point, where the slider point b is."""
        mech, part = self.mech, self.fe.parts[part_name]
        i = 3 * mech.body_index(part.body)
        z = self.rm.z
        if at.body is not None and at.body.name == part_name:
            return _rot(z[:, i + 2], part.body.marker(at.point))
        pos = _point_position(mech, z, at)                  # the slider point on the other body
        return pos - z[:, i:i + 2]

    def _applied(self, eq: "JointEquations", b: np.ndarray) -> None:
        """Subtract the drives' generalized forces acting on the bodies from the right-hand sides."""
        mech = self.mech
        for d in mech.drives:
            j = mech.joint(d.joint)
            f = self.rm.drive_force(d.joint)
            pa, pb = eq.points[j.name]
            ka, kb = eq.keys[j.name]
            if j.guided:
                t, _ = self._guide(j)
                for sign, ref, key in ((1.0, pb, kb), (-1.0, pa, ka)):
                    if key is None:
                        continue
                    force = sign * f[:, None] * t
                    r0 = eq.eqs[key]
                    b[:, r0:r0 + 2] -= force
                    b[:, r0 + 2] -= self._moment_arm(key, pb, ref, j, force)
                continue
            for sign, key in ((1.0, kb), (-1.0, ka)):
                if key is not None:
                    b[:, eq.eqs[key] + 2] -= sign * f

    # ------------------------------------------------------------------ the bodies' own residuals
    def _body_residual(self, eq: "JointEquations", key, residuals: np.ndarray) -> np.ndarray:
        """(3, N) generalized force of a body's own items at a joint node (flexible link) or at its centre
        of mass (rigid part): inertia, damping, stiffness and rigid-inertia load; ``residuals`` the
        (E, 6, N) of the elements at joint nodes (:meth:`_element_residuals`)."""
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
            if self.family.rotary_loads:
                out[2] += p.inertia * self.rig[2, p.col]
            return out
        _, node, li = key
        tr, rot = fe.trans_dof[node], fe.rot_dof[(node, li)]
        elements, masses, inertias = eq.items[key]
        for row, half in elements:
            out += residuals[row, half:half + 3]
        for i in masses:
            m, z = fe.lm_prop[:, i]
            out[:2] += m * (acc[tr] + ray_m * v[tr] + self.rig[3:5, li] + _accel_along(self.rig[:, li], z))
        for i in inertias:
            jr = fe.ri_prop[i]
            out[2] += jr * (acc[rot] + ray_m * v[rot])
            if self.family.rotary_loads:
                out[2] += jr * self.rig[2, li]
        return out

    def _element_residuals(self, eq: "JointEquations") -> np.ndarray:
        """(E, 6, N) M u'' + C u' + K u + F_rigid of the elements at joint nodes (``eq.elements``),
        global components (docs/theory.md §3-4), all elements and frames at once."""
        fe, el = self.fe, eq.elements
        if el.size == 0:
            return np.zeros((0, 6, self.rm.t.size))
        m, k, g, c, m0, kg = eq.matrices
        L, z1 = fe.el_prop[0, el][:, None], fe.el_prop[1, el][:, None]
        phi, om, al, ax, ay = self.rig[:, fe.el_link[el] - 1]           # each (E, N)
        dofs = fe.el_dof[:, el] - 1                                        # (6, E)
        u, v, acc = (_to_local(x[dofs], phi).transpose(1, 0, 2) for x in self.state)   # (E, 6, N)
        ray_m, ray_k = self.rayleigh
        om2 = om * om
        # M u'' + 2 om G u' + ray_m M u' + ray_k K u' + K u + al G u + om^2 C u (+ N Kg u), by matrix
        r = m @ (acc + ray_m * v) + g @ (2.0 * om[:, None] * v + al[:, None] * u) + k @ (u + ray_k * v)
        r += c @ (om2[:, None] * u)
        if self.axial is not None:
            r += kg @ (self.axial[el][:, None] * u)
        cs, sn = np.cos(phi), np.sin(phi)
        ap = (cs * ax + sn * ay, -sn * ax + cs * ay)
        z2 = z1 + L
        w = [ap[0] - om2 * z1, ap[1] + al * z1, ap[0] - om2 * z2, ap[1] + al * z2]
        if self.family.load_mass == "translational":
            r += m0 @ np.stack(w, axis=1)
        else:
            rot = al if self.family.rotary_loads else 0.0 * al
            r += m @ np.stack([w[0], w[1], rot, w[2], w[3], rot], axis=1)
        return _to_global(r.transpose(1, 0, 2), phi).transpose(1, 0, 2)


class JointEquations:
    """The layout of a mesh's joint equations, the same for every frame of every run on it: a row
    offset per body equation (``eqs``; key ``("node", node, link)`` or ``("part", name)``), each joint's
    unknown components and column offset (``unknowns``), and per joint node the items whose generalized
    forces sum there (element halves, point masses, rotary inertias) with the elements' local matrices.
    Built once per mesh (:func:`joint_equations`)."""

    def __init__(self, fe):
        mech = fe.case.mechanism
        self.points = {j.name: mech.joint_points(j) for j in mech.joints}
        self.keys = {name: tuple(_body_key(fe, ref) for ref in refs) for name, refs in self.points.items()}
        self.eqs = {}
        self.unknowns = []
        nu = 0
        for j in mech.joints:
            for key in self.keys[j.name]:
                if key is not None and key not in self.eqs:
                    self.eqs[key] = 3 * len(self.eqs)
            comps = _components(j, mech.condition(j))
            self.unknowns.append((j, comps, nu))
            nu += len(comps)
        self.rows, self.nu = 3 * len(self.eqs), nu
        #: the matrix is the same in every frame: no rigid part (its moment arms turn), no guided joint
        #: (its guide turns) and no kind with its own units (they follow the points)
        self.constant = not any(k[0] == "part" for k in self.eqs) and all(j.shares_point for j in mech.joints)
        self.items, elements = {}, []
        for key in self.eqs:
            if key[0] == "node":
                self.items[key] = _node_items(fe, key, elements)
        self.elements = np.array(elements, dtype=int)
        mats = [kernels.api.element_matrices(ra, ea, ei, length)
                for length, _, ra, ea, ei in fe.el_prop[:, self.elements].T]
        #: the local (m, k, g, c, m0, kg) of the elements, each stacked (E, 6, 6) (m0: (E, 6, 4))
        self.matrices = [np.array([mt[i] for mt in mats]) for i in range(6)]


def _body_key(fe, ref):
    """The body-equation key of a joint point (None: the ground)."""
    if ref.body is None:
        return None
    if ref.body.name in fe.parts:
        return ("part", ref.body.name)
    li = fe.link_names.index(ref.body.name)
    return ("node", fe.node_of[li][fe.node_index(li, ref.body.fraction(ref.point))], li)


def _node_items(fe, key, elements: list) -> tuple[list, list, list]:
    """(element rows and halves, point masses, rotary inertias) at a flexible link's joint node;
    the node's elements are appended to ``elements`` (their row: the index there)."""
    _, node, li = key
    tr, rot = fe.trans_dof[node], fe.rot_dof[(node, li)]
    halves = []
    for e in fe.link_elements(li):
        dofs = fe.el_dof[:, e] - 1
        for half in (0, 3):
            if dofs[half] == tr[0]:
                if e not in elements:
                    elements.append(int(e))
                halves.append((elements.index(e), half))
    masses = [i for i in range(fe.lm_link.size) if fe.lm_link[i] == li + 1 and fe.lm_dof[0, i] - 1 == tr[0]]
    inertias = [i for i in range(fe.ri_link.size) if fe.ri_link[i] == li + 1 and fe.ri_dof[i] - 1 == rot]
    return halves, masses, inertias


_EQUATIONS: dict[int, tuple] = {}     # id(mesh) -> (weak reference to the mesh, its JointEquations)


def joint_equations(fe) -> JointEquations:
    """The :class:`JointEquations` of a mesh, built on its first run's first block and kept while the mesh
    lives (a mesh is not changed once built): every block of every run on it shares them."""
    hit = _EQUATIONS.get(id(fe))
    if hit is not None and hit[0]() is fe:
        return hit[1]
    eq = JointEquations(fe)
    _EQUATIONS[id(fe)] = (weakref.ref(fe), eq)
    weakref.finalize(fe, _EQUATIONS.pop, id(fe), None)
    return eq


def _components(j, cond: str) -> list[str]:
    """A joint's unknown components (docs/theory.md §18.5) given its condition in the elastic problem."""
    if not j.shares_point and not j.guided:         # a kind's own row (Joint.reaction_units)
        return ["own"]
    if j.shares_point and j.ties_rotation:
        return ["x", "y", "m"]
    if j.guided:
        return ["n"] + (["m"] if j.ties_rotation else []) + (["t"] if cond == "locked" else [])
    return ["x", "y"] + (["m"] if cond in ("locked", "clamp") else [])


def least_squares(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, u) per frame the minimum-norm least-squares solution of ``a[n] x = b[n]`` (a (N, k, u) or, the
    same matrix in every frame, (1, k, u); b (N, k)).

    One pseudo-inverse serves every frame when the matrix is one (flexible links at revolute joints
    and welds: unit forces and moments only); else a batched QR factorization per frame (Householder,
    as stable as the pseudo-inverse and a third of its cost), the pseudo-inverse only for the frames
    whose matrix has (numerically) dependent columns, where it picks the minimum-norm solution."""
    if a.shape[0] == 1:
        return b @ np.linalg.pinv(a[0]).T
    if a.shape[1] < a.shape[2]:
        return np.einsum("nuk,nk->nu", np.linalg.pinv(a), b)
    q, r = np.linalg.qr(a)
    diag = np.abs(np.diagonal(r, axis1=1, axis2=2))
    full = diag.min(axis=1) > RANK_TOLERANCE * np.maximum(diag.max(axis=1), 1e-300)
    x = np.empty((a.shape[0], a.shape[2]))
    if np.any(full):
        qb = np.einsum("nku,nk->nu", q[full], b[full])
        x[full] = np.linalg.solve(r[full], qb[..., None])[..., 0]
    if not np.all(full):
        x[~full] = np.einsum("nuk,nk->nu", np.linalg.pinv(a[~full]), b[~full])
    return x


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
