"""The layout of the coupled and nonlinear models (flexmech_py.models.constrained.coupled) built from a mechanism:
segments and their DOFs, rigid bodies, markers, constraint rows per joint, force drives, lumped
inertias, and the kernel's flat description (fortran/flexmech_coupled_system.f90: coupled_build).

- Every flexible link is one beam *segment* (coupled model) or one segment per element (nonlinear
  model): the absolute positions of the segment ends (shared by the segments that meet there) and
  elastic DOFs in the segment's chord frame.
- Every rigid link and rigid body is a rigid body with coordinates [x_C, y_C, phi].
- Joints are constraint rows on *markers* (a segment node, a rigid-body point, a ground point) of the
  kinds of ``fortran/flexmech_markers.f90``, with Lagrange multipliers (the constraint forces); a
  revolute or weld joint between two segment-end nodes shares their position DOFs instead (no
  multipliers), a ground joint there fixes them.
- A kinematic drive is a row on its joint's coordinate, a force drive a generalized force on it.

The rows of each joint kind are its class's ``coupled_rows`` and ``coupled_coordinate``
(flexmech_py.mechanism.joints): a new joint kind declares them in its own module (and one row
routine in Fortran when its rows are new).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .ordering import bordered_numbering
from ...base.errors import CaseError
from ...mechanism.packing import drawn_coordinates, joint_pose
from ...mechanism.rows import CON_ANGLE, CON_POINT, CON_PROJECTION
from ..mesh import mesh_fractions, uniform_mesh
from ..numbering import rcm_free_numbering

__all__ = ["Layout", "SharedAngles", "Row", "JointModel", "LinkMesh", "CON_POINT", "CON_ANGLE",
           "CON_PROJECTION", "MK_GROUND", "MK_NODE", "MK_BODY", "mesh_node", "node_segment", "marker_key",
           "start_value", "flat_description", "force_constant_positions"]

# marker kinds (flexmech_coupled_system); the constraint kinds: mechanism.rows
MK_GROUND, MK_NODE, MK_BODY = 0, 1, 2
J_FLOOR = 1e-6     # a rigid body without rotary inertia: J_S = J_FLOOR m lref^2 in the iteration matrix



@dataclass
class Row:
    """A constraint row (or a measure) between markers a and b: ``kind`` CON_*, ``aux`` (the component
    of a point row; 1 for a row whose value moves), ``d`` the direction of a projection in a's frame,
    ``value``: ("zero",), ("start", joint, what) its initial value, ("drive", joint), or ("rigid", joint,
    role) a kind's own row's value on the rigid motion (Joint.held_values)."""

    kind: int
    a: int
    b: int
    aux: int = 0
    d: tuple = (0.0, 0.0)
    value: tuple = ("zero",)
    joint: str | None = None
    role: str = ""


@dataclass
class JointModel:
    """How the model holds one joint: its markers, whether it shares DOFs, its rows by role
    (x, y, normal, angle, hold, drive), its coordinate (a measure Row) and force drive."""

    name: str
    kind: str
    markers: tuple
    shared: object = None          # the position node the two sides share (None: point rows)
    rows: dict = field(default_factory=dict)
    coordinate: Row | None = None
    force: int | None = None
    axis: tuple = (1.0, 0.0)       # a guided joint's guide direction in a's frame
    guided: bool = False           # point b slides along a guide on body a (Joint.guided)
    own: list = field(default_factory=list)    # the roles of the kind's own rows (Joint.own_rows)


@dataclass
class LinkMesh:
    """The flexible links' mesh nodes and elements as a result's ``fe`` (what the guards, the gap
    study and the summary read): one node per (link, mesh node), no nodes for rigid links; ``ndof``
    the size of the displacement layout, ``nfree`` and ``bandwidth`` the model's own."""

    case: dict
    link_names: list
    n_el: list
    node_frac: list
    node_of: list
    nnodes: int
    trans_dof: np.ndarray
    rot_dof: dict
    ndof: int
    el_link: np.ndarray
    nfree: int = 0
    bandwidth: int = 0
    uniform: list = field(default_factory=list)     # per link: equal elements

    @property
    def nel(self) -> int:
        return int(self.el_link.size)

    def link_elements(self, li: int) -> np.ndarray:
        return np.flatnonzero(self.el_link == li + 1)

    def node_ref(self, ref: str, where: str) -> tuple[int, int, float]:
        """(link, node, zeta [m]) of a flexible link's point; CaseError when it is not a mesh node."""
        link, pos = ref.split(".", 1)
        li = self.link_names.index(link)
        k = mesh_node(self.case, self.node_frac, li, pos, where)
        return li, self.node_of[li][k], self.node_frac[li][k] * self.case["links"][li]["length"]


def mesh_node(case, fracs, li: int, point: str, where: str) -> int:
    link = case.mechanism.links[li]
    frac = link.fraction(point, where)
    f = fracs[li]
    k = int(np.argmin(np.abs(f - frac)))
    if abs(f[k] - frac) > 1e-9:
        n = len(f) - 1
        raise CaseError(where, f"'{link.name}.{point}' is not at a mesh node ({link.name} has {n} elements: "
                               f"fractions k/{n}); choose a node, name the point in links.points, or change "
                               "elements_per_link")
    return k


def node_segment(segments, li: int, k: int) -> tuple[int, int]:
    """(segment, node within it) of mesh node k of link li: the first segment holding it."""
    for si, (l2, k0, k1) in enumerate(segments):
        if l2 == li and k0 <= k <= k1:
            return si, k - k0
    raise AssertionError((li, k))


def marker_key(m, pr, where: str) -> tuple:
    """(kind, segment or body, node, (x, y)) of a resolved point: a segment node of a flexible link, a
    rigid-body point (from its centre of mass, body frame) or a ground point; m: a Layout or a
    CoupledModel (case, fracs, segments, bodies)."""
    if pr.body is None:
        return (MK_GROUND, 0, 0, tuple(map(float, pr.position)))
    mech = m.case.mechanism
    bi = mech.body_index(pr.body)
    if pr.body.kind == "link" and not pr.body.rigid:
        li = mech.link_index(pr.body.name)
        k = mesh_node(m.case, m.fracs, li, pr.point, where)
        si, kk = node_segment(m.segments, li, k)
        return (MK_NODE, si, kk, (0.0, 0.0))
    body = next(i for i, b in enumerate(m.bodies) if b[0] == bi)
    return (MK_BODY, body, 0, tuple(map(float, pr.body.marker(pr.point, where))))


def start_value(mech, rm, joint: str, what: str) -> float:
    """Initial value of a held quantity of a joint: its relative body angle ("angle") or its coordinate
    ("coordinate") on the first sample of the rigid motion."""
    if what == "coordinate":
        return float(rm.joint(joint)[0, 0])
    a, b = mech.joint_points(mech.joint(joint))
    ang = [0.0 if p.body is None else float(rm.z[0, 3 * mech.body_index(p.body) + 2]) for p in (a, b)]
    return ang[1] - ang[0]


class Layout:
    """The layout of a case's coupled (``split=False``) or nonlinear (``split=True``) model, built
    step by step on construction: ``segments`` (link, k0, k1), ``fracs`` (node fractions per link,
    None for rigid links), ``bodies`` (mechanism body index, 0-based DOFs (3,), m, J_C, J_S),
    ``markers`` (kind, segment or body, node, (x, y)), ``rows`` the constraint rows, ``joints``
    {name: JointModel}, ``forces`` [(coordinate Row, Drive)], ``pm`` (segment, element, xi, mass),
    ``ri`` (segment, node, J), ``node_ends`` {position node: [(segment, 0 start / 1 end)]}; then
    ``ld``, ``n_el``, ``free_of``, ``q_fixed`` and ``mesh``.  ``hold_forced``: a force-driven joint
    whose elastic condition holds it (Joint.holding: a torque-driven crank's default ``clamp``) also gets a
    ``hold`` row, as the superposition models' elastic problem holds it; the frozen eigenproblem of
    ``flexmech modes`` uses it (a run leaves the joint to its force, whatever its condition).
    The nonlinear model's free numbering is that of its bordered saddle band
    (:mod:`flexmech_py.models.constrained.ordering`): ``border`` = (border DOFs, border flag per row); the coupled
    model's is reverse Cuthill-McKee (``border`` None)."""

    def __init__(self, case, split: bool, hold_forced: bool = False):
        self.case, self.split, self.mech = case, split, case.mechanism
        self.hold_forced = hold_forced
        if not any(not ln.rigid for ln in self.mech.links):
            raise CaseError("links", "no link is flexible: flexmech's models need at least one flexible link; make one flexible "
                                     "(rigid = false); the rigid-body motion alone is Prepared(case).rm (docs/api.md)")
        self.fracs = [None if ln.rigid else mesh_fractions(self.mech, ln, self.case["links"][li]["elements"])
                      for li, ln in enumerate(self.mech.links)]
        self.segments = []
        for li, f in enumerate(self.fracs):
            if f is not None:
                n = f.size - 1
                self.segments += [(li, k, k + 1) for k in range(n)] if split else [(li, 0, n)]
        self.bodies, self.markers, self.rows, self.joints, self.forces = [], [], [], {}, []
        self.dof, self.fixed, self.node_ends, self.parent = {}, {}, {}, {}
        self._positions()
        self._joints()
        self.control_scales: dict = {}
        self.control_rows = self._control_rows()
        self._lumped()
        self.n_el = np.array([k1 - k0 for _, k0, k1 in self.segments], np.int32)
        self.ld = self._ld_array()
        self.border = None
        self.free_of = self._free_numbering()
        self.q_fixed = self._q_fixed()
        self.mesh = self._mesh()

    # --------------------------------------------------------------- position nodes and DOFs
    def _find(self, x):
        while self.parent.get(x, x) != x:
            x = self.parent[x]
        return x

    def _end_node(self, pr):
        """The position node (link, mesh node) of a flexible link's point when it is a segment end, or None."""
        if pr.body is None or pr.body.kind != "link" or pr.body.rigid:
            return None
        li = self.mech.link_index(pr.body.name)
        k = mesh_node(self.case, self.fracs, li, pr.point, f"joints (point {pr.label})")
        if any(l2 == li and k in (k0, k1) for l2, k0, k1 in self.segments):
            return (li, k)
        return None

    def _positions(self) -> None:
        """Shared position nodes (revolute and weld joints between segment ends), the DOFs of every
        segment (in the order the seed cases always had) and of the rigid bodies."""
        for j in self.mech.joints:
            if j.shares_point:
                na, nb = (self._end_node(p) for p in self.mech.joint_points(j))
                if na is not None and nb is not None:
                    self.parent[self._find(na)] = self._find(nb)
        for si, (li, k0, k1) in enumerate(self.segments):
            for end, k in enumerate((k0, k1)):
                root = self._find((li, k))
                if ("r", root) not in self.dof:
                    self._new(("r", root)), self._new(("r", root, 1))
                self.node_ends.setdefault(root, []).append((si, end))
            self._new(("t", si, 0))
            for k in range(1, k1 - k0):
                self._new(("e", si, k, "p")), self._new(("e", si, k, "v")), self._new(("e", si, k, "t"))
            self._new(("t", si, 1))
        lref = self.mech.characteristic_length()
        for bi, body in enumerate(self.mech.bodies):
            if body.kind == "link" and not body.rigid:
                continue
            m, _, jc = body.mass_properties()
            dofs = np.array([self._new(("b", bi, c)) for c in range(3)])
            self.bodies.append((bi, dofs, m, jc, jc if jc > 0 else J_FLOOR * m * lref ** 2))

    def _new(self, key) -> int:
        self.dof[key] = len(self.dof)
        return self.dof[key]

    def seg_cols(self) -> list:
        """0-based all-DOF numbers of every segment's local vector."""
        out = []
        for si, (li, k0, k1) in enumerate(self.segments):
            col = []
            for k in (k0, k1):
                root = self._find((li, k))
                col += [self.dof[("r", root)], self.dof[("r", root, 1)]]
            col.append(self.dof[("t", si, 0)])
            for k in range(1, k1 - k0):
                col += [self.dof[("e", si, k, c)] for c in ("p", "v", "t")]
            col.append(self.dof[("t", si, 1)])
            out.append(col)
        return out

    def _ld_array(self) -> np.ndarray:
        ld = np.zeros((3 * int(self.n_el.max()) + 3, len(self.segments)), np.int32)
        for si, col in enumerate(self.seg_cols()):
            ld[:len(col), si] = np.array(col) + 1
            ld[len(col):, si] = ld[0, si]   # padding (never read: the kernel uses 3n+3 entries)
        return np.asfortranarray(ld)

    def _free_numbering(self) -> np.ndarray:
        mask = np.ones(len(self.dof), bool)
        for node in self.fixed:
            mask[[self.dof[("r", node)], self.dof[("r", node, 1)]]] = False
        if not mask.any():
            raise CaseError("joints", "the coupled model has no free DOF")
        cols = [np.array(c) for c in self.seg_cols()]
        if self.split:
            free_of, nbd, rb = bordered_numbering(cols, [b[1] for b in self.bodies], self.row_patterns(cols), mask)
            self.border = (nbd, rb)
            return free_of
        return rcm_free_numbering(cols + [b[1] for b in self.bodies], mask)

    def row_patterns(self, cols, rows=None) -> list:
        """The DOFs every row's gradient can touch (its markers' columns; a node of a one-element
        segment: the segment's end positions and the node's angle) given the segments' DOFs cols."""
        def marker_dofs(m):
            kind, idx, node, _ = self.markers[m]
            if kind == MK_NODE:
                return list(cols[idx][:4]) + [cols[idx][4 if node == 0 else 5]]
            return list(self.bodies[idx][1]) if kind == MK_BODY else []
        return [np.array(marker_dofs(r.a) + marker_dofs(r.b), int) for r in (self.rows if rows is None else rows)]

    def _q_fixed(self) -> np.ndarray:
        q = np.zeros(len(self.dof))
        for node, pos in self.fixed.items():
            q[self.dof[("r", node)]], q[self.dof[("r", node, 1)]] = pos
        return q

    # --------------------------------------------------------------- joints and drives
    def marker(self, key) -> int:
        """Index of a marker (added when new)."""
        if key not in self.markers:
            self.markers.append(key)
        return self.markers.index(key)

    def _control_rows(self) -> dict:
        """{controller: (row kind, marker a, marker b (0-based), direction)} of the feedback controllers
        that measure a point (non-collocated, flexmech_py.mechanism.control): the point's position along
        the direction (fixed in the frame of the joint's body a) from the joint's point a."""
        out = {}
        for c in self.case.get("controllers", []):
            if c["measure"] == "joint":
                continue
            if "strain" in c["measure"]:
                out[c["name"]] = self._strain_row(c)
                continue
            where = f"controllers.{c['name']}.measure.point"
            pr = self.mech.point(c["measure"]["point"], where)
            out[c["name"]] = (CON_PROJECTION, self.joints[c["joint"]].markers[0],
                              self.marker(marker_key(self, pr, where)), tuple(c["measure"]["direction"]))
        return out

    def _strain_row(self, c) -> tuple:
        """A strain measure ({strain = link, at = f}): the relative rotation psi_b - psi_a (CON_ANGLE) of
        the mesh nodes bounding the element that holds f (the two elements around f when f is a node),
        whose integral of the curvature it is; the signal c (psi_b - psi_a) / span, its scale in
        control_scales."""
        li = next(i for i, ln in enumerate(self.mech.links) if ln.name == c["measure"]["strain"])
        f, at = self.fracs[li], c["measure"]["at"]
        k = int(np.argmin(np.abs(f - at)))
        if abs(f[k] - at) <= 1e-9:
            ka, kb = max(k - 1, 0), min(k + 1, f.size - 1)
        else:
            kb = int(np.searchsorted(f, at))
            ka = kb - 1
        marks = [self.marker((MK_NODE, *node_segment(self.segments, li, kk), (0.0, 0.0))) for kk in (ka, kb)]
        link = self.mech.links[li]
        self.control_scales[c["name"]] = float(link.half_depth) / (float(f[kb] - f[ka]) * link.length)
        return (CON_ANGLE, marks[0], marks[1], (0.0, 0.0))

    def _joints(self) -> None:
        """Markers and rows of every joint (its kind's coupled_rows), its drive, and the welds between the
        consecutive segments of a link (nonlinear model)."""
        for j in self.mech.joints:
            a, b = self.mech.joint_points(j)
            where = f"joints.{j.name}.connects"
            jm = JointModel(j.name, j.kind, (self.marker(marker_key(self, a, where)),
                                             self.marker(marker_key(self, b, where))))
            base, coord = j.coupled_rows, j.coupled_coordinate
            jm.guided = j.guided
            if j.guided:    # the guide direction in the frame of body a
                ang = 0.0 if a.body is None else a.body.angle
                u = j.unit_axis()
                jm.axis = (np.cos(ang) * u[0] + np.sin(ang) * u[1], -np.sin(ang) * u[0] + np.cos(ang) * u[1])
            for role in base:
                self._joint_rows(jm, role, a, b)
            c = jm.coordinate = (Row(CON_ANGLE, *jm.markers, joint=j.name, role="coordinate") if coord == "angle" else
                                 Row(CON_PROJECTION, *jm.markers, d=jm.axis, joint=j.name, role="coordinate"))
            drive = self.mech.drive_of(j.name)
            if drive is not None and drive.kinematic:
                self._add_row(jm, "drive", Row(c.kind, *jm.markers, aux=1, d=c.d, value=("drive", j.name)))
            elif drive is not None:
                jm.force = len(self.forces)
                self.forces.append((c, drive))
            held = drive is None or (self.hold_forced and not drive.kinematic)
            if held and self.mech.condition(j) in j.holding:
                what = "angle" if coord == "angle" else "coordinate"
                self._add_row(jm, "hold", Row(c.kind, *jm.markers, d=c.d, value=("start", j.name, what)))
            self.joints[j.name] = jm
        for si in range(1, len(self.segments)):
            if self.segments[si][0] == self.segments[si - 1][0]:    # consecutive elements of one link
                n = self.segments[si - 1][2] - self.segments[si - 1][1]
                ma = self.marker((MK_NODE, si - 1, n, (0.0, 0.0)))
                self.rows.append(Row(CON_ANGLE, ma, self.marker((MK_NODE, si, 0, (0.0, 0.0))), role="interior"))

    def _add_row(self, jm: JointModel, role: str, row: Row) -> None:
        row.joint, row.role = jm.name, role
        jm.rows[role] = len(self.rows)
        self.rows.append(row)

    def _joint_rows(self, jm: JointModel, role: str, a, b) -> None:
        ma, mb = jm.markers
        if role == "point":
            na, nb = self._end_node(a), self._end_node(b)
            if (na is not None or a.body is None) and (nb is not None or b.body is None):
                jm.shared = self._find(nb if nb is not None else na)
                if a.body is None or b.body is None:     # a ground joint: the node is fixed
                    self.fixed[jm.shared] = tuple(map(float, (a if a.body is None else b).position))
                return
            for comp, name in ((1, "x"), (2, "y")):
                self._add_row(jm, name, Row(CON_POINT, ma, mb, aux=comp))
        elif role == "normal":
            self._add_row(jm, "normal", Row(CON_PROJECTION, ma, mb, d=(-jm.axis[1], jm.axis[0])))
        elif role == "own":     # the kind's own rows (Joint.own_rows), held at their rigid-motion values
            j = self.mech.joint(jm.name)
            for name, kind, aux, d in j.own_rows(joint_pose(self.mech, j, drawn_coordinates(self.mech))):
                jm.own.append(name)
                self._add_row(jm, name, Row(kind, ma, mb, aux=aux, d=d, value=("rigid", jm.name, name)))
        else:   # the relative angle held at its initial value
            self._add_row(jm, "angle", Row(CON_ANGLE, ma, mb, value=("start", jm.name, "angle")))

    # --------------------------------------------------------------- masses, mesh view
    def _lumped(self) -> None:
        """Point masses and hubs of the flexible links, at the first segment holding their node."""
        self.pm, self.ri = [], []
        for li, link in enumerate(self.mech.links):
            if link.rigid:      # a rigid link's lumped inertias are in its mass properties
                continue
            for frac, mass in link.lumped:
                si, kk = node_segment(self.segments, li, mesh_node(self.case, self.fracs, li, repr(frac), "point_masses"))
                n = self.segments[si][2] - self.segments[si][1]
                self.pm.append((si, min(kk + 1, n), 1.0 if kk == n else 0.0, mass))
            for frac, j in link.hubs:
                si, kk = node_segment(self.segments, li, mesh_node(self.case, self.fracs, li, repr(frac), "rotary_inertias"))
                self.ri.append((si, kk, j))

    def _mesh(self) -> LinkMesh:
        node_of, rot, el_link, nn = [], {}, [], 0
        for li, f in enumerate(self.fracs):
            ids = [] if f is None else list(range(nn, nn + f.size))
            node_of.append(ids)
            nn += len(ids)
            el_link += [li + 1] * max(0, len(ids) - 1)
        for li, ids in enumerate(node_of):
            for node in ids:
                rot[(node, li)] = 2 * nn + node
        return LinkMesh(case=self.case, link_names=[ln.name for ln in self.mech.links],
                        n_el=[0 if f is None else f.size - 1 for f in self.fracs],
                        node_frac=[np.zeros(0) if f is None else f for f in self.fracs], node_of=node_of, nnodes=nn,
                        trans_dof=np.arange(2 * nn).reshape(nn, 2), rot_dof=rot, ndof=3 * nn,
                        el_link=np.array(el_link, np.int32), nfree=int(self.free_of.max()), bandwidth=self._bandwidth(),
                        uniform=[f is not None and uniform_mesh(f) for f in self.fracs])

    def _bandwidth(self) -> int:
        """The half width of S's band over the free DOFs (the nonlinear model: its interior chains')."""
        kl, top = 0, int(self.free_of.max()) - (self.border[0] if self.border else 0)
        for col in self.seg_cols():
            f = self.free_of[np.array(col)]
            f = f[(f > 0) & (f <= top)]
            if f.size:
                kl = max(kl, int(f.max() - f.min()))
        return kl


# ----------------------------------------------------------------------------- shared node angles
@dataclass
class SharedAngles:
    """The nonlinear model as its kernel integrates it (docs/theory.md section 12.1): the angle DOFs of
    every element are the absolute angles psi of its end nodes, shared by the two elements that meet
    at an interior node, instead of angles from each element's chord tied by a weld row per interior
    node.  The layout (:class:`Layout`) keeps the chord-relative angles, which every output reads;
    :meth:`to_kernel` and :meth:`from_kernel` carry states and frames between the two.

    ``ld``, ``free_of``: the kernel's segment DOFs and free numbering (a later element's th_0 DOF is
    unused, its start angle is the th_1 DOF of the element before; numbered for the bordered saddle
    band, ``border`` = (border DOFs, border flag per kept row)); ``keep``: indices of the layout's
    rows the kernel enforces (all but the interior welds); ``pos`` (nseg, 4) the 0-based DOFs of
    xs, ys, xe, ye; ``rel`` and ``abs`` (nseg, 2): the DOFs of th_0, th_1 in the layout and of the node
    angles in the kernel; ``unused`` the DOFs the kernel does not use."""

    ld: np.ndarray
    free_of: np.ndarray
    border: tuple
    keep: np.ndarray
    pos: np.ndarray
    rel: np.ndarray
    abs: np.ndarray
    unused: np.ndarray

    @classmethod
    def of(cls, lay: "Layout") -> "SharedAngles":
        assert lay.split and np.all(lay.n_el == 1)
        cols = np.array(lay.seg_cols())                  # (nseg, 6): xs ys xe ye th_0 th_1
        rel = cols[:, 4:6].copy()
        ab = rel.copy()
        for si in range(1, len(lay.segments)):
            if lay.segments[si][0] == lay.segments[si - 1][0]:
                ab[si, 0] = ab[si - 1, 1]
        unused = np.setdiff1d(rel.ravel(), ab.ravel())
        kcols = np.concatenate([cols[:, :4], ab], axis=1)
        mask = lay.free_of > 0
        mask[unused] = False
        keep = np.array([i for i, r in enumerate(lay.rows) if r.role != "interior"], int)
        free_of, nbd, rb = bordered_numbering(list(kcols), [b[1] for b in lay.bodies],
                                              lay.row_patterns(kcols, [lay.rows[i] for i in keep]), mask)
        ld = lay.ld.copy(order="F")
        ld[4:6] = ab.T + 1
        return cls(ld, free_of, (nbd, rb), keep, cols[:, :4].copy(), rel, ab, unused)

    def _chord(self, q, v, a):
        """Chord angle, angular velocity and acceleration of every element (nseg, ...)."""
        p = self.pos
        cx, cy = q[p[:, 2]] - q[p[:, 0]], q[p[:, 3]] - q[p[:, 1]]
        dx, dy = v[p[:, 2]] - v[p[:, 0]], v[p[:, 3]] - v[p[:, 1]]
        l2 = cx * cx + cy * cy
        gx, gy = -cy / l2, cx / l2
        om = gx * dx + gy * dy
        al = -2.0 * (cx * dx + cy * dy) * om / l2 + gx * (a[p[:, 2]] - a[p[:, 0]]) + gy * (a[p[:, 3]] - a[p[:, 1]])
        return np.arctan2(cy, cx), om, al

    def to_kernel(self, q, v, a):
        """(q, v, a) of the layout (all DOFs, one state or frames as columns) in the kernel's DOFs."""
        phi, om, al = self._chord(q, v, a)
        out = []
        for x, add in ((q, phi), (v, om), (a, al)):
            y = np.array(x, float, copy=True)
            for end in (0, 1):                 # a shared node takes the angle of the element before
                y[self.abs[:, end]] = x[self.rel[:, end]] + add
            y[self.unused] = 0.0
            out.append(y)
        return tuple(out)

    def from_kernel(self, q, v, a):
        """The kernel's (q, v, a) (all DOFs, one state or frames) in the layout's DOFs."""
        phi, om, al = self._chord(q, v, a)
        out = []
        for x, sub, wrap in ((q, phi, True), (v, om, False), (a, al, False)):
            y = np.array(x, float, copy=True)
            for end in (0, 1):
                d = x[self.abs[:, end]] - sub
                y[self.rel[:, end]] = np.arctan2(np.sin(d), np.cos(d)) if wrap else d
            out.append(y)
        return tuple(out)


# ----------------------------------------------------------------------------- the flat description
def force_constant_positions(lay: Layout, rspec_size: int, ispec: np.ndarray) -> dict:
    """{joint: index in rspec} of the ``constant`` of every force drive in a flat description (ispec,
    rspec of :func:`flat_description`, with or without shared angles): its law's first parameter,
    counted from the end of rspec (the laws' parameters, harmonics and tables, then gravity and
    Rayleigh damping close it)."""
    nforce, nh, nth, ntab = (int(x) for x in ispec[8:12])
    first = rspec_size - 4 - 5 * ntab - 3 * nth * nforce - 2 * nh * nforce - 4 * nforce
    return {d.joint: first + 4 * k for k, (_, d) in enumerate(lay.forces)}


def flat_description(lay: Layout, gravity=(0.0, 0.0), rayleigh=(0.0, 0.0),
                     shared: SharedAngles | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(ispec, rspec) of flexmech_coupled_system: coupled_build (layout documented there); with ``shared``
    the nonlinear model's kernel description (shared node angles, no interior welds)."""
    ld, free_of, rows, border = lay.ld, lay.free_of, lay.rows, lay.border
    if shared is not None:
        ld, free_of, rows, border = shared.ld, shared.free_of, [lay.rows[i] for i in shared.keep], shared.border
    nseg, maxn = len(lay.segments), int(lay.n_el.max())
    links = lay.case["links"]
    laws = [d.packed(0.0) for _, d in lay.forces]
    nh = max([max(len(k["sin"]), len(k["cos"])) for k in laws] + [0])
    nth = max([len(k["time_harmonics"]) for k in laws] + [0])
    tab_t, tab_c, dv = [], [], []
    for (row, _), k in zip(lay.forces, laws):
        first, knots = 0, 0
        if k["table"] is not None:
            first, knots = len(tab_t) + 1, len(k["table"][0])
            tab_t += list(k["table"][0])
            tab_c += list(k["table"][1].T)
        dv += [row.kind, row.a + 1, row.b + 1, first, knots]
    mk = lay.markers
    ispec = [nseg, len(lay.bodies), len(lay.dof), maxn, len(lay.pm), len(lay.ri), len(mk), len(rows),
             len(lay.forces), nh, nth, len(tab_t)]
    ispec += list(lay.n_el) + list(ld.T.ravel()) + [d + 1 for body in lay.bodies for d in body[1]]
    ispec += list(free_of) + [p[0] + 1 for p in lay.pm] + [p[1] for p in lay.pm]
    ispec += [r[0] + 1 for r in lay.ri] + [r[1] for r in lay.ri]
    ispec += [m[0] for m in mk] + [0 if m[0] == MK_GROUND else m[1] + 1 for m in mk] + [m[2] for m in mk]
    ispec += [i for r in rows for i in (r.kind, r.a + 1, r.b + 1, r.aux)] + dv
    ispec += [int(shared is not None)] * nseg
    ispec += [int(lay.split)] * nseg          # shallow-arch axial strain: the nonlinear model's elements
    ispec += [-1] + [0] * len(rows) if border is None else [border[0]] + list(border[1])
    wn = np.zeros((nseg, maxn + 1))
    prop = []
    for si, (li, k0, k1) in enumerate(lay.segments):
        f = lay.fracs[li][k0:k1 + 1]
        wn[si, :k1 - k0 + 1] = (f - f[0]) / (f[-1] - f[0])
        wn[si, k1 - k0 + 1:] = 2.0 + np.arange(maxn - (k1 - k0))     # padding, increasing (never read)
        ln = links[li]
        prop += [ln["length"] * (f[-1] - f[0]), ln["density"] * ln["area"], ln["youngs_modulus"] * ln["area"],
                 ln["youngs_modulus"] * ln["second_moment"]]
    rspec = prop + list(wn.ravel()) + [x for _, _, m, jc, js in lay.bodies for x in (m, jc, js)]
    rspec += [x for p in lay.pm for x in (p[2], p[3])] + [r[2] for r in lay.ri] + [x for m in mk for x in m[3]]
    rspec += [x for r in rows for x in r.d] + [x for r, _ in lay.forces for x in r.d]
    rspec += [x for k in laws for x in k["par"]]
    for k in laws:
        rspec += list(k["sin"]) + [0.0] * (nh - len(k["sin"])) + list(k["cos"]) + [0.0] * (nh - len(k["cos"]))
    for k in laws:
        rspec += [x for h in list(k["time_harmonics"]) + [[0.0, 0.0, 0.0]] * (nth - len(k["time_harmonics"])) for x in h]
    rspec += tab_t + [x for c in tab_c for x in c] + [float(gravity[0]), float(gravity[1]), float(rayleigh[0]),
                                                      float(rayleigh[1])]
    return np.array(ispec, np.int32), np.array(rspec, float)
