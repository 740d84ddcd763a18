"""Rigid bodies, rigid links and guided joints in the superposition models (docs/theory.md §18).

Elastic DOFs beyond the flexible links' nodes (flexmech_py/models/superposition/model.py):

- every rigid body and rigid link is a rigid body of the elastic problem with three small-motion
  DOFs (dx, dy, dtheta) at its centre of mass (global components): mass diag(m, m, J_C), rigid-inertia
  load m (a_C - g) and J_C alpha (a point mass and a rotary inertia on the body's own rigid-sample
  column), no stiffness;
- every guided joint has an *along* DOF s: the elastic slide of the slider point relative to the
  guide (fixed when the joint's elastic condition is ``locked``).

Joints that DOF sharing cannot express (everything that touches a rigid body, a rigid link or a
guided joint) are linear relations between DOFs with time-varying coefficients, C(t) u = 0, one row
per constrained component:

- revolute / weld at a point P: u_P(b) - u_P(a) = 0 (x, y), and theta(b) - theta(a) = 0 for a weld or
  a ``locked``/``clamp`` revolute; a point of a rigid body moves by u_P = d + dtheta z x s_P(t),
  s_P = R(phi(t)) s_P0 from the centre of mass, a flexible link's point is its mesh node;
- guided (guide fixed to body a, the ground or a rigid body; slider point b):
  n(t).(u_b - u_a(C)) = 0, t(t).(u_b - u_a(C)) - s = 0, theta(b) - theta(a) = 0, with u_a(C) the
  motion of the guide body's material point at the contact C (it moves along the guide with the
  slide d(t)), t, n the guide's direction and normal turning with body a.

One DOF per row is chosen once as its *slave* (preferably a translation of body b, then of body a;
guided rows first, so that a slider's translation is expressed as s t + (n.u_a(C)) n and the 2 x 2
block [n; t] can never become singular).  Per time sample u_slaves = T(t) u_masters with
T = -C_s^-1 C_m and its derivatives from C' T + C T' = 0, C'' T + 2 C' T' + C T'' = 0; the
coefficients are computed here from the rigid samples (vectorised over a chunk) and passed to the
Fortran kernel (flexmech_ked: the reduced equations T^T M T w'' + T^T (2 M T' + C T) w' +
T^T (M T'' + C T' + K T) w = T^T (Q - F)).

The rigid samples of the kernels gain columns (:meth:`flexmech_py.models.superposition.model.FEModel.rig_samples`): after
the links, one per rigid body [phi, omega, alpha, a_C - g] (its frame at the centre of mass) and one
per guided joint [d, d', d'', 0, 0] (its slide).  A case without rigid bodies and guided joints
has none of this (the seed cases keep their path bit for bit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...base.errors import CaseError, SolverError
from ...mechanism.packing import drawn_coordinates, joint_coordinates

__all__ = ["Jet", "RigidPart", "Slide", "Slaving", "build_slaving", "rig_columns"]


class Jet:
    """A time function with its first two derivatives (value, d/dt, d2/dt2), arrays or scalars."""

    __slots__ = ("v", "d", "dd")

    def __init__(self, v, d=0.0, dd=0.0):
        self.v, self.d, self.dd = v, d, dd

    @staticmethod
    def of(x) -> "Jet":
        return x if isinstance(x, Jet) else Jet(x)

    def __add__(self, o):
        o = Jet.of(o)
        return Jet(self.v + o.v, self.d + o.d, self.dd + o.dd)

    __radd__ = __add__

    def __neg__(self):
        return Jet(-self.v, -self.d, -self.dd)

    def __sub__(self, o):
        return self + (-Jet.of(o))

    def __rsub__(self, o):
        return Jet.of(o) - self

    def __mul__(self, o):
        o = Jet.of(o)
        return Jet(self.v * o.v, self.d * o.v + self.v * o.d, self.dd * o.v + 2.0 * self.d * o.d + self.v * o.dd)

    __rmul__ = __mul__


# ------------------------------------------------------------------------------ linear forms
# A linear form is {all-DOF index: Jet}; a point's elastic displacement is a pair of forms (x, y).

def _lin(*terms) -> dict:
    """sum of coef * form over (coef, form) pairs (coef a Jet or a number)."""
    out = {}
    for coef, form in terms:
        for k, c in form.items():
            out[k] = out[k] + coef * c if k in out else coef * c
    return out


def _angle(rig, col: int):
    """(cos, sin) jets of a rig column's angle."""
    phi, om, al = rig[0, col], rig[1, col], rig[2, col]
    c, s = np.cos(phi), np.sin(phi)
    return Jet(c, -s * om, -s * al - c * om * om), Jet(s, c * om, c * al - s * om * om)


def _rotate(cs, v):
    """R(phi) v for a constant body-frame vector v: (x, y) jets (None for the zero vector)."""
    if not np.any(v):
        return None
    c, s = cs
    return c * float(v[0]) - s * float(v[1]), s * float(v[0]) + c * float(v[1])


@dataclass
class RigidPart:
    """A rigid body or rigid link in the elastic problem: DOFs (dx, dy, dtheta) at its centre of mass."""

    body: object
    col: int                 # 0-based rig column of its frame (a rigid link: its own link column)
    dofs: tuple              # (dx, dy, dtheta) all-DOF numbers, 0-based
    mass: float
    inertia: float           # about the centre of mass [kg m^2]
    zeta: float              # centre of mass along the column's axis from its origin [m]

    @property
    def name(self) -> str:
        return self.body.name


@dataclass
class Slide:
    """A guided joint: its along DOF, rig column and guide geometry in body a's frame."""

    joint: object
    dof: int                 # all-DOF number of the along DOF s (elastic slide) [m]
    col: int                 # rig column [d, d', d'', 0, 0]
    t_body: np.ndarray       # guide direction in body a's frame (global for a ground guide)
    a_marker: np.ndarray     # point a relative to a's centre of mass, a's frame (global position on the ground)

    @property
    def n_body(self) -> np.ndarray:
        return np.array([-self.t_body[1], self.t_body[0]])


@dataclass
class Attachment:
    """A joint handled by relations: kind, resolved points a, b, and which rows it has."""

    joint: object
    a: object                # PointRef
    b: object
    rotation: bool           # has a rotation row
    slide: Slide | None = None


class _Points:
    """Linear forms of body points' elastic displacements on one rig chunk."""

    def __init__(self, geo: "Slaving", rig):
        self.geo, self.rig, self._cs = geo, rig, {}

    def cs(self, col):
        if col not in self._cs:
            self._cs[col] = _angle(self.rig, col)
        return self._cs[col]

    def point(self, ref):
        """(x form, y form, rotation form) of the point ``ref`` (a PointRef)."""
        g = self.geo
        if ref.body is None:
            return {}, {}, {}
        part = g.parts.get(ref.body.name)
        if part is None:                       # a flexible link: its mesh node
            node, rot = g.node_dofs(ref)
            return {node[0]: Jet(1.0)}, {node[1]: Jet(1.0)}, {rot: Jet(1.0)}
        dx, dy, dth = part.dofs
        s = _rotate(self.cs(part.col), ref.body.marker(ref.point))
        if s is None:
            return {dx: Jet(1.0)}, {dy: Jet(1.0)}, {dth: Jet(1.0)}
        return {dx: Jet(1.0), dth: -s[1]}, {dy: Jet(1.0), dth: s[0]}, {dth: Jet(1.0)}

    def guide(self, att: Attachment):
        """(t, n, contact x form, contact y form) of a guided joint's guide."""
        sl = att.slide
        if att.a.body is None:
            t, n = sl.t_body, sl.n_body
            return (Jet(float(t[0])), Jet(float(t[1]))), (Jet(float(n[0])), Jet(float(n[1]))), {}, {}
        part = self.geo.parts[att.a.body.name]
        cs = self.cs(part.col)
        t, n = _rotate(cs, sl.t_body), _rotate(cs, sl.n_body)
        d = Jet(self.rig[0, sl.col], self.rig[1, sl.col], self.rig[2, sl.col])
        m = _rotate(cs, sl.a_marker)
        rho = (d * t[0], d * t[1]) if m is None else (m[0] + d * t[0], m[1] + d * t[1])
        dx, dy, dth = part.dofs
        return t, n, {dx: Jet(1.0), dth: -rho[1]}, {dy: Jet(1.0), dth: rho[0]}


class Slaving:
    """The relations of a model and the slave DOFs chosen for them; :meth:`values` gives the slave
    rows T, T', T'' on any rig chunk."""

    def __init__(self, parts: dict, slides: list, attachments: list, node_dofs, fixed: np.ndarray):
        self.parts = parts                    # body name -> RigidPart
        self.slides = slides
        self.attachments = attachments
        self.node_dofs = node_dofs            # PointRef on a flexible link -> ((tx, ty), rot)
        self.fixed = fixed                    # (ndof,) bool, updated by build()
        self.rows_kept: list = []             # indices of the rows in rows() that are kept
        self.slaves: list = []                # slave DOF of each kept row
        self.masters: list = []               # the DOFs the slaves are expressed on (all free)
        self.pattern: list = []               # per slave: indices into masters of its nonzero coefficients
        self.labels: list = []                # (joint name, component) of every row of rows()
        self.ptr = self.col = None            # CSR over free-DOF numbers (finalize)

    # ------------------------------------------------------------------ rows
    def rows(self, rig) -> list[dict]:
        """Every relation row as a linear form {dof: Jet} on the rig chunk (fixed DOFs dropped)."""
        P = _Points(self, rig)
        out, labels = [], []
        for att in self.attachments:
            ua, ub = P.point(att.a), P.point(att.b)
            name = att.joint.name
            if att.slide is None and att.joint.shares_point:
                out += [_lin((1.0, ub[0]), (-1.0, ua[0])), _lin((1.0, ub[1]), (-1.0, ua[1]))]
                labels += [(name, "x"), (name, "y")]
            elif att.slide is not None:
                t, n, cx, cy = P.guide(att)
                rel = (_lin((1.0, ub[0]), (-1.0, cx)), _lin((1.0, ub[1]), (-1.0, cy)))
                out.append(_lin((n[0], rel[0]), (n[1], rel[1])))
                out.append(_lin((t[0], rel[0]), (t[1], rel[1]), (-1.0, {att.slide.dof: Jet(1.0)})))
                labels += [(name, "normal"), (name, "along")]
            if att.rotation:
                wa, wb = att.joint.rotation_weights()
                out.append(_lin((wb, ub[2]), (wa, ua[2])))
                labels.append((name, "rotation"))
        self.labels = labels
        return [{k: c for k, c in r.items() if not self.fixed[k]} for r in out]

    def preferred(self) -> list[list[int]]:
        """Per row, the DOFs preferred as its slave: body b's, then body a's translation (rotation)."""
        out = []
        for att in self.attachments:
            tb, rb = self._own(att.b)
            ta, ra = self._own(att.a)
            if att.slide is None and att.joint.shares_point:
                out += [tb[:1] + ta[:1], tb[1:] + ta[1:]]
            elif att.slide is not None:
                out += [tb + ta, tb + ta]
            if att.rotation:
                out.append(rb + ra)
        return out

    def _own(self, ref):
        """(translation DOFs, rotation DOFs) of a point's own body at that point."""
        if ref.body is None:
            return [], []
        part = self.parts.get(ref.body.name)
        if part is None:
            node, rot = self.node_dofs(ref)
            return list(node), [rot]
        return list(part.dofs[:2]), [part.dofs[2]]

    # ------------------------------------------------------------------ choosing the slaves
    def build(self, rig_drawn, rig_probe) -> None:
        """Fix the DOFs a row pins alone (repeatedly), then choose a slave per row by elimination at the
        drawn configuration (preferred DOFs first); ``rig_probe``: a second, generic sample that gives
        the structure of T."""
        while True:
            rows = self.rows(rig_drawn)
            single = {next(iter(r)) for r in rows if len(r) == 1}
            if not single:
                break
            self.fixed[list(single)] = True
        prefer = self.preferred()
        reduced, kept, slaves = [], [], []
        for i, r in enumerate(rows):
            row = {k: float(np.ravel(c.v)[0]) for k, c in r.items()}
            for piv, prow in reduced:
                c = row.pop(piv, 0.0)
                if c:
                    for k, val in prow.items():
                        row[k] = row.get(k, 0.0) - c * val
            scale = max([abs(x) for x in row.values()] + [0.0])
            row = {k: x for k, x in row.items() if abs(x) > 1e-12 * max(scale, 1e-300)}
            if not row or scale == 0.0:
                continue                                    # redundant with the rows before it
            pick = next((d for d in prefer[i] if abs(row.get(d, 0.0)) >= 1e-3 * scale), None)
            if pick is None:
                pick = max(row, key=lambda k: abs(row[k]))
            reduced.append((pick, {k: x / row[pick] for k, x in row.items() if k != pick}))
            kept.append(i)
            slaves.append(pick)
        self.rows_kept, self.slaves, self._block_order = kept, slaves, None
        if not slaves:                                      # every relation fixed its DOFs
            self.masters, self.pattern = [], []
            return
        sl = set(slaves)
        self.masters = sorted({k for i in kept for k in rows[i] if k not in sl})
        t = [self._solve(rig_drawn), self._solve(rig_probe)]
        nz = np.zeros((len(slaves), len(self.masters)), bool)
        for tt in t:
            for x in tt:
                nz |= np.any(np.abs(x) > 1e-13, axis=1)
        self.pattern = [np.flatnonzero(nz[k]) for k in range(len(slaves))]

    def finalize(self, free_of: np.ndarray) -> None:
        """The CSR rows over free-DOF numbers for the kernel (after the free numbering)."""
        self.ptr = np.cumsum([1] + [p.size for p in self.pattern]).astype(np.int32)
        cols = [free_of[self.masters[j]] for p in self.pattern for j in p]
        self.col = np.array(cols or [1], np.int32)

    @property
    def nsl(self) -> int:
        return len(self.slaves)

    def slave_of(self, ndof: int) -> np.ndarray:
        """(ndof,) 1-based slave number of each DOF, 0 = not slaved."""
        out = np.zeros(ndof, np.int32)
        out[self.slaves] = np.arange(1, self.nsl + 1)
        return out

    # ------------------------------------------------------------------ values
    def _blocks(self, rows) -> list[list[int]]:
        """The kept rows (row k pivots slave k) grouped into the strongly connected blocks of their slave
        coupling, in an order in which each block needs only slaves of the blocks before it: C_s is
        block triangular, and its diagonal blocks are small (1 x 1, a slider's 2 x 2 [n; t])."""
        ns = len(self.slaves)
        sidx = {d: k for k, d in enumerate(self.slaves)}
        reach = np.eye(ns, dtype=bool)
        for k, ri in enumerate(self.rows_kept):
            for d in rows[ri]:
                if d in sidx:
                    reach[k, sidx[d]] = True
        for m in range(ns):                                  # transitive closure (ns is small)
            reach |= reach[:, m:m + 1] & reach[m:m + 1, :]
        blocks, done = [], np.zeros(ns, bool)
        while not done.all():
            for k in np.flatnonzero(~done):
                comp = np.flatnonzero(reach[k] & reach[:, k])
                if np.all(done[np.flatnonzero(reach[k] & ~np.isin(np.arange(ns), comp))]):
                    blocks.append([int(c) for c in comp])
                    done[comp] = True
                    break
        return blocks

    def _solve(self, rig):
        """(T, T', T'') as arrays (nslaves, N, nmasters) on a rig chunk: C_s T = -C_m,
        C_s T' = -(C_s' T + C_m'), C_s T'' = -(C_s'' T + 2 C_s' T' + C_m''), by block substitution."""
        rows = self.rows(rig)
        ns, nm = len(self.slaves), len(self.masters)
        n = rig.shape[2] if rig.ndim == 3 else 1
        sidx = {d: k for k, d in enumerate(self.slaves)}
        midx = {d: j for j, d in enumerate(self.masters)}
        cs = [{} for _ in range(ns)]                         # row k: {slave: (value, d, dd) arrays (N, 1)}
        cm = np.zeros((3, ns, n, nm))
        for k, ri in enumerate(self.rows_kept):
            for d, jet in rows[ri].items():
                x = [np.broadcast_to(np.asarray(y, float), (n,)) for y in (jet.v, jet.d, jet.dd)]
                if d in sidx:
                    cs[k][sidx[d]] = [y[:, None] for y in x]
                else:
                    cm[:, k, :, midx[d]] = x
        if self.__dict__.get("_block_order") is None:
            self._block_order = self._blocks(rows)
        t = np.zeros((3, ns, n, nm))
        for order in range(3):
            rhs = -cm[order].copy()
            for k in range(ns):                              # the known terms of lower orders
                for j, c in cs[k].items():
                    if order >= 1:
                        rhs[k] -= c[order] * t[0, j] if order == 1 else c[2] * t[0, j] + 2.0 * c[1] * t[1, j]
            self._substitute(cs, rhs, t[order])
        return t[0], t[1], t[2]

    def _substitute(self, cs, rhs, out) -> None:
        """Solve C_s Y = rhs (ns, N, nm) into ``out`` block by block (C_s values only)."""
        for block in self._block_order:
            inside = set(block)
            r = [rhs[k] - sum((c[0] * out[j] for j, c in cs[k].items() if j not in inside), 0.0) for k in block]
            a = [[cs[k].get(j, (0.0,))[0] for j in block] for k in block]
            if len(block) == 1:
                out[block[0]] = r[0] / a[0][0]
            elif len(block) == 2:
                det = a[0][0] * a[1][1] - a[0][1] * a[1][0]
                out[block[0]] = (a[1][1] * r[0] - a[0][1] * r[1]) / det
                out[block[1]] = (a[0][0] * r[1] - a[1][0] * r[0]) / det
            else:                                            # a loop of rigid bodies: a general solve
                mat = np.stack([np.stack([np.broadcast_to(x, out.shape[1:2] + (1,))[:, 0] for x in row], -1) for row in a], -2)
                sol = np.linalg.solve(mat, np.stack(r, 1))  # (N, nb, nm)
                out[block] = sol.transpose(1, 0, 2)
            if not np.all(np.isfinite(out[block])):
                names = sorted({self.labels[self.rows_kept[k]][0] for k in block})
                raise SolverError(f"the elastic relations of the joints {', '.join(names)} became singular (a loop of "
                                  "rigid bodies whose slave choice degenerates): make one of its bodies a flexible link")

    def values(self, rig) -> np.ndarray:
        """(3, nnz, N) [T, T', T''] of the CSR rows on a rig chunk (5, ncols, N), Fortran order."""
        rig = rig if rig.ndim == 3 else rig[:, :, None]
        t = self._solve(rig)
        k = np.repeat(np.arange(self.nsl), [p.size for p in self.pattern])
        j = np.concatenate(self.pattern) if self.pattern else np.zeros(0, int)
        out = np.stack([x[k, :, j] for x in t])            # (3, nnz, N)
        if out.shape[1] == 0:
            out = np.zeros((3, 1, out.shape[2]))
        return np.asfortranarray(out)

    def reconstruct(self, x_all: np.ndarray, rig, derivs=None) -> None:
        """Fill the slaved entries of all-DOF frames x_all (ndof, N) in place: u_s = T u_m, or with
        ``derivs = (v_all, a_all)`` also v_s = T' u + T v and a_s = T'' u + 2 T' v + T a."""
        if not self.nsl:
            return
        t0, t1, t2 = self._solve(rig)                     # (ns, N, nm)
        m = x_all[self.masters]                             # (nm, N)
        x_all[self.slaves] = np.einsum("snj,jn->sn", t0, m)
        if derivs is not None:
            v_all, a_all = derivs
            vm, am = v_all[self.masters], a_all[self.masters]
            v_all[self.slaves] = np.einsum("snj,jn->sn", t1, m) + np.einsum("snj,jn->sn", t0, vm)
            a_all[self.slaves] = (np.einsum("snj,jn->sn", t2, m) + 2.0 * np.einsum("snj,jn->sn", t1, vm)
                                  + np.einsum("snj,jn->sn", t0, am))

    def project(self, q_all: np.ndarray, rig) -> np.ndarray:
        """Generalized forces over all DOFs (ndof, N) on the masters: q + T^T q_slaves (in place at the
        masters; the slaved entries are left as they were)."""
        if not self.nsl:
            return q_all
        t0 = self._solve(rig)[0]                            # (ns, N, nm)
        q = q_all.copy()
        q[self.masters] += np.einsum("snm,sn->mn", t0, q_all[self.slaves])
        return q


# ------------------------------------------------------------------------------ construction
def rig_columns(mech) -> tuple[list, list]:
    """The extra rig columns after the links: (rigid bodies, guided joints)."""
    return list(mech.rigid_bodies), [j for j in mech.joints if j.guided]


def build_slaving(mech, ndof: int, fixed: np.ndarray, node_dofs) -> tuple:
    """Rigid parts, slides and the relations of ``mech`` for an FE model whose flexible nodes are numbered
    (``ndof`` DOFs so far, ``fixed`` their mask; ``node_dofs(ref)`` the DOFs of a flexible link's point).
    Returns (parts, slides, slaving or None, ndof, fixed, dof names of the new DOFs)."""
    nl = len(mech.links)
    bodies, prisms = rig_columns(mech)
    parts, names = {}, []
    rigid = [(ln, li) for li, ln in enumerate(mech.links) if ln.rigid] + [(b, nl + k) for k, b in enumerate(bodies)]
    for body, col in rigid:
        m, xc, j = body.mass_properties()
        parts[body.name] = RigidPart(body, col, (ndof, ndof + 1, ndof + 2), m, j, xc if body.kind == "link" else 0.0)
        names += [f"{body.name}.x", f"{body.name}.y", f"{body.name}.rot"]
        ndof += 3
    slides, atts = [], []
    for k, j in enumerate(prisms):
        a, b = mech.joint_points(j)
        if a.body is not None and a.body.name not in parts:
            raise CaseError(f"joints.{j.name}.connects", f"a {j.kind} joint's guide must be the ground or a rigid body; "
                            f"{a.body.name!r} is a flexible link: make it rigid (rigid = true) or swap the joint's points")
        ang = 0.0 if a.body is None else a.body.angle
        u0 = j.unit_axis()
        t_body = np.array([np.cos(-ang) * u0[0] - np.sin(-ang) * u0[1], np.sin(-ang) * u0[0] + np.cos(-ang) * u0[1]])
        marker = np.asarray(a.position, float) if a.body is None else a.body.marker(a.point)
        slides.append(Slide(j, ndof, nl + len(bodies) + k, t_body, marker))
        names.append(f"{j.name}.slide")
        ndof += 1
    fixed = np.concatenate([fixed, np.zeros(ndof - fixed.size, bool)])
    for sl in slides:
        if mech.condition(sl.joint) == "locked":
            fixed[sl.dof] = True
    by_joint = {sl.joint.name: sl for sl in slides}
    for j in sorted(mech.joints, key=lambda j: (not j.guided, not _on_ground(mech, j))):
        a, b = mech.joint_points(j)
        if not j.guided and j.shares_point and all(p.body is None or p.body.name not in parts for p in (a, b)):
            continue                                     # flexible links and the ground: shared DOFs (model.py)
        if not j.guided and not j.shares_point:
            _check_fixed_centres(mech, j)
        rot = j.ties_rotation or (not j.guided and mech.condition(j) in j.holding)   # a guide holds its slide
        atts.append(Attachment(j, a, b, rot, by_joint.get(j.name)))
    if not atts:
        return parts, slides, None, ndof, fixed, names
    sl = Slaving(parts, slides, atts, node_dofs, fixed)
    sl.build(drawn_rig(mech), _probe_rig(mech))
    return parts, slides, sl, ndof, sl.fixed, names


def _check_fixed_centres(mech, j) -> None:
    """A joint whose two points do not coincide (a kind with its own rows) is a relation of the elastic
    rotations alone: exact when neither point moves elastically, i.e. each is the ground or a ground
    pivot of its body.  CaseError naming the joint otherwise."""
    pivots = set()
    for other in mech.joints:
        pa, pb = mech.joint_points(other)
        if other.shares_point and (pa.body is None) != (pb.body is None):
            p = pb if pa.body is None else pa
            pivots.add((p.body.name, tuple(np.round(np.asarray(p.position, float), 12))))
    for p in mech.joint_points(j):
        if p.body is not None and (p.body.name, tuple(np.round(np.asarray(p.position, float), 12))) not in pivots:
            raise CaseError(f"joints.{j.name}.connects",
                            f"the superposition models hold a {j.kind} joint only between points at ground pivots "
                            f"('{p.body.name}.{p.point}' is not one: the line between its points would move "
                            "elastically); run it with model = 'coupled' or 'nonlinear'")


def _on_ground(mech, j) -> bool:
    return any(p.body is None for p in mech.joint_points(j))


def drawn_rig(mech) -> np.ndarray:
    """Rig columns (5, ncols, 1) of the drawn configuration at rest (links, rigid bodies, slides)."""
    bodies, prisms = rig_columns(mech)
    cols = [[ln.angle, 0, 0, 0, 0] for ln in mech.links] + [[b.angle, 0, 0, 0, 0] for b in bodies]
    coords = joint_coordinates(mech, drawn_coordinates(mech))
    cols += [[coords[j.name], 0, 0, 0, 0] for j in prisms]
    return np.array(cols, float).T[:, :, None]


def _probe_rig(mech) -> np.ndarray:
    """A generic sample near the drawn configuration (angles turned, nonzero rates), for the structure of T."""
    rng = np.random.default_rng(12345)
    rig = drawn_rig(mech).copy()
    n = rig.shape[1]
    rig[0, :, 0] += rng.uniform(-0.3, 0.3, n)
    rig[1:3, :, 0] = rng.uniform(0.5, 2.0, (2, n))
    return rig
