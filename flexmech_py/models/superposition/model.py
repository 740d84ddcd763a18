"""Finite-element model of a mechanism: nodes, DOFs, joints, elements, lumped inertias.

Conventions (docs/theory.md):

- Every flexible link is meshed with beam elements from its *start* (its frame origin O) to its
  *end*; element axes follow the rigid link angle.  The mesh has a node at every named point of the
  link: ``elements`` (or mesh.elements_per_link) equal elements when the link has no named points
  besides its ends, else the segments between named points share them by length (one at least).
- Each mesh node has two elastic translational DOFs (global X, Y components), shared by the links
  joined there by a revolute or weld joint.  Rotational DOFs belong to a (node, link) pair; links
  joined by a ``locked``/``clamp`` revolute or a weld share one.
- Ground joints fix the node's translations; ``clamp``/``locked`` (and welds) also fix the rotation
  of the attached link.  Constrained DOFs are kept in the numbering ("all DOFs") and dropped from the
  solved system ("free DOFs").
- Free DOFs are numbered by reverse Cuthill-McKee to keep the band narrow.
- Rigid links and rigid bodies are rigid bodies of the elastic problem (three DOFs at their centre of
  mass), guided joints have an along DOF, and every joint that touches them is a relation between
  DOFs with time-varying coefficients whose slave DOFs are not solved for (flexmech_py/models/superposition/slaving.py);
  the rigid samples then carry a column per rigid body and guided joint (:meth:`FEModel.rig_samples`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ...base import kernels
from ..mesh import mesh_fractions, uniform_mesh
from ..numbering import rcm_free_numbering
from ...base.families import STUDY_MODEL, SUPERPOSITION_MODELS, family
from ...base.errors import CaseError
from .slaving import build_slaving
from ...case import DIVERGENCE_FACTOR

__all__ = ["FEModel", "Joint"]

GEOMETRIC_CODE = {"none": 0, "current": 1, "lagged": 2, "quasi_static": 3}


@dataclass
class Joint:
    """A joint as the FE model sees it: its ``kind`` and elastic condition, point a on link
    ``inboard`` (None = ground) at fraction ``inboard_frac`` and point b on link ``outboard`` at
    ``outboard_frac`` (0 start, 1 end)."""

    name: str
    inboard: int | None
    inboard_frac: float | None
    outboard: int
    outboard_frac: float
    elastic: str
    kind: str = "revolute"
    sign: float = 1.0       # -1 when a and b were swapped to put the ground on the a side
    ties_rotation: bool = False   # the kind always ties the two rotations (mechanism Joint.ties_rotation)
    holding: tuple = ()           # the elastic conditions that tie them (mechanism Joint.holding)

    @property
    def inboard_end(self) -> str | None:
        return None if self.inboard is None else _end_name(self.inboard_frac)

    @property
    def outboard_end(self) -> str:
        return _end_name(self.outboard_frac)

    @property
    def shares_rotation(self) -> bool:
        return self.ties_rotation or self.elastic in self.holding


def _end_name(frac: float) -> str:
    return {0.0: "start", 1.0: "end"}.get(float(frac), f"{frac:g}")


def mechanism_joints(case: dict) -> list[Joint]:
    """The mechanism's revolute and weld joints between flexible links (and the ground), with their
    elastic conditions: those the FE model expresses by shared or fixed DOFs.  Joints that touch a rigid
    link or body, guided joints and joints whose points do not coincide (a kind with its own rows) are relations
    (flexmech_py/models/superposition/slaving.py)."""
    mech = case.mechanism
    out = []
    for j in mech.joints:
        a, b = mech.joint_points(j)
        if j.guided or not j.shares_point or any(ref.body is not None and ref.body.rigid for ref in (a, b)):
            continue
        sign = 1.0
        if b.body is None:      # the ground on the b side: swap, and flip the sign of the joint coordinate
            a, b, sign = b, a, -1.0
        ai = None if a.body is None else mech.link_index(a.body.name)
        af = None if a.body is None else a.body.fraction(a.point)
        out.append(Joint(j.name, ai, af, mech.link_index(b.body.name), b.body.fraction(b.point), mech.condition(j),
                         j.kind, sign, j.ties_rotation, j.holding))
    return out


def squared_frequencies(m: np.ndarray, k: np.ndarray, vectors: bool = False):
    """Ascending eigenvalues w^2 [rad^2/s^2] of K x = w^2 M x (K and M symmetrized), via the Cholesky
    factor of M (NumPy only).  Negative values: the frozen system is unstable in that mode.  With
    ``vectors``: (w^2, X), the columns of X mass-normalized (X^T M X = I).  Raises
    numpy.linalg.LinAlgError when M is not positive definite."""
    lc = np.linalg.cholesky(0.5 * (m + m.T))
    a = np.linalg.solve(lc, np.linalg.solve(lc, 0.5 * (k + k.T)).T)
    if not vectors:
        return np.linalg.eigvalsh(0.5 * (a + a.T))
    lam, y = np.linalg.eigh(0.5 * (a + a.T))
    return lam, np.linalg.solve(lc.T, y)


class _UnionFind:
    """Disjoint sets of hashable items (joint nodes, locked rotations)."""

    def __init__(self):
        self.parent = {}

    def find(self, x):
        while self.parent.get(x, x) != x:
            x = self.parent[x]
        return x

    def union(self, keep, other):
        self.parent[self.find(other)] = self.find(keep)


def _node_index(fracs: np.ndarray, frac: float) -> int:
    """Index of the mesh node at fraction ``frac`` of a link (it is one: named points are nodes)."""
    k = int(np.argmin(np.abs(fracs - frac)))
    if abs(fracs[k] - frac) > 1e-9:
        raise AssertionError((fracs, frac))
    return k


def _merge_nodes(joints, fracs) -> tuple[list, int]:
    """Global nodes: one per (link, mesh node), merged where a revolute or weld joins two links."""
    nodes = _UnionFind()
    for j in joints:
        if j.inboard is not None:
            nodes.union((j.inboard, _node_index(fracs[j.inboard], j.inboard_frac)),
                        (j.outboard, _node_index(fracs[j.outboard], j.outboard_frac)))
    ids, node_of = {}, []
    for li, f in enumerate(fracs):
        row = []
        for k in range(f.size):
            root = nodes.find((li, k))
            ids.setdefault(root, len(ids))
            row.append(ids[root])
        node_of.append(row)
    return node_of, len(ids)


def _number_dofs(joints, node_of, fracs, nnodes: int, names):
    """(rot, trans, ndof, dof names): translations per node, then one rotation per (node, link)
    group, (node, link) pairs merged by joints that share the rotation."""
    rots = _UnionFind()
    for j in joints:
        if j.inboard is not None and j.shares_rotation:   # "torque" and "pin": separate rotations
            na = node_of[j.inboard][_node_index(fracs[j.inboard], j.inboard_frac)]
            rots.union((na, j.inboard), (na, j.outboard))
    trans = np.arange(2 * nnodes).reshape(nnodes, 2)
    rot, rot_groups = {}, {}
    dof_names = [f"node{n}.{c}" for n in range(nnodes) for c in ("x", "y")]
    for li, row in enumerate(node_of):
        for node in row:
            g = rots.find((node, li))
            if g not in rot_groups:
                rot_groups[g] = 2 * nnodes + len(rot_groups)
                dof_names.append(f"node{node}.rot[{names[g[1]]}]")
            rot[(node, li)] = rot_groups[g]
    return rot, trans, 2 * nnodes + len(rot_groups), dof_names


def _elements(mech, links, fracs, node_of, trans, rot) -> tuple[list, list, list]:
    """(el_link, el_dof (0-based), el_prop) of the flexible links' beam elements, link by link."""
    el_link, el_dof, el_prop = [], [], []
    for li, ln in enumerate(links):
        if mech.links[li].rigid:
            continue
        ra, ea, ei = ln["density"] * ln["area"], ln["youngs_modulus"] * ln["area"], ln["youngs_modulus"] * ln["second_moment"]
        n = fracs[li].size - 1
        uniform, le_u = uniform_mesh(fracs[li]), ln["length"] / n
        for k in range(n):
            n1, n2 = node_of[li][k], node_of[li][k + 1]
            el_link.append(li + 1)
            el_dof.append([trans[n1, 0], trans[n1, 1], rot[(n1, li)], trans[n2, 0], trans[n2, 1], rot[(n2, li)]])
            if uniform:    # equal elements: the same numbers as a uniform mesh always had
                el_prop.append([le_u, k * le_u, ra, ea, ei])
            else:
                el_prop.append([(fracs[li][k + 1] - fracs[li][k]) * ln["length"], fracs[li][k] * ln["length"],
                                ra, ea, ei])
    if not el_dof:
        raise CaseError("links", "no link is flexible: flexmech's models need at least one flexible link; make one flexible "
                                 "(rigid = false); the rigid-body motion alone is Prepared(case).rm (docs/api.md)")
    return el_link, el_dof, el_prop


@dataclass
class FEModel:
    """The discretized mechanism; build it with :meth:`from_case`."""

    case: dict
    joints: list[Joint]
    link_names: list[str]
    n_el: list[int]                     # elements per link
    node_of: list[list[int]]            # node_of[link][k] -> global node, k = 0..n_el
    nnodes: int
    trans_dof: np.ndarray               # (nnodes, 2) all-DOF numbers (0-based)
    rot_dof: dict                       # (node, link) -> all-DOF number
    ndof: int
    fixed: np.ndarray                   # (ndof,) bool
    free_of: np.ndarray                 # (ndof,) free-DOF number 1..nfree, 0 = constrained (Fortran)
    el_link: np.ndarray
    el_dof: np.ndarray                  # (6, nel) 1-based all-DOF numbers
    el_prop: np.ndarray                 # (5, nel)
    lm_link: np.ndarray
    lm_dof: np.ndarray
    lm_prop: np.ndarray
    ri_link: np.ndarray
    ri_dof: np.ndarray
    ri_prop: np.ndarray
    bandwidth: int = 0
    dof_names: list = field(default_factory=list)
    node_frac: list = field(default_factory=list)   # node_frac[link][k]: fraction of the link's length of node k
    last_run: dict | None = field(default=None, repr=False)   # the last run's frames and final state (run())
    parts: dict = field(default_factory=dict)       # rigid link / body name -> slaving.RigidPart
    slides: list = field(default_factory=list)      # slaving.Slide per guided joint
    slaving: object = None                          # slaving.Slaving, None without relations
    uniform: list = field(default_factory=list)     # per link: equal elements

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_case(cls, case: dict) -> "FEModel":
        mech = case.mechanism
        links = case["links"]
        names = [ln["name"] for ln in links]
        joints = mechanism_joints(case)
        fracs = [np.zeros(0) if link.rigid else mesh_fractions(mech, link, ln["elements"])
                 for link, ln in zip(mech.links, links)]
        n_el = [max(f.size - 1, 0) for f in fracs]
        node_of, nnodes = _merge_nodes(joints, fracs)
        rot, trans, ndof, dof_names = _number_dofs(joints, node_of, fracs, nnodes, names)
        fixed = np.zeros(ndof, bool)
        for j in joints:
            if j.inboard is None:
                node = node_of[j.outboard][_node_index(fracs[j.outboard], j.outboard_frac)]
                fixed[trans[node]] = True
                if j.shares_rotation:
                    fixed[rot[(node, j.outboard)]] = True

        def node_dofs(ref):   # a flexible link's point: ((x, y) DOFs of its node, its rotation DOF there)
            li = mech.link_index(ref.body.name)
            node = node_of[li][_node_index(fracs[li], ref.body.fraction(ref.point))]
            return tuple(trans[node]), rot[(node, li)]

        parts, slides, slaving, ndof, fixed, new_names = build_slaving(mech, ndof, fixed, node_dofs)
        dof_names += new_names
        el_link, el_dof, el_prop = _elements(mech, links, fracs, node_of, trans, rot)
        el_dof = np.array(el_dof, dtype=np.int32).T  # (6, nel), 0-based for now

        model = cls(case=case, joints=joints, link_names=names, n_el=n_el, node_of=node_of, nnodes=nnodes,
                    trans_dof=trans, rot_dof=rot, ndof=ndof, fixed=fixed, free_of=np.zeros(ndof, np.int32),
                    el_link=np.array(el_link, np.int32), el_dof=el_dof + 1,
                    el_prop=np.asfortranarray(np.array(el_prop, float).T),
                    lm_link=np.zeros(0, np.int32), lm_dof=np.zeros((2, 0), np.int32), lm_prop=np.zeros((2, 0)),
                    ri_link=np.zeros(0, np.int32), ri_dof=np.zeros(0, np.int32), ri_prop=np.zeros(0),
                    dof_names=dof_names, node_frac=fracs, parts=parts, slides=slides, slaving=slaving,
                    uniform=[uniform_mesh(f) for f in fracs])
        model._lumped(case)
        model._number_free_dofs(el_dof)
        return model

    def _number_free_dofs(self, el_dof0: np.ndarray) -> None:
        sl = self.slaving
        solve = ~self.fixed
        if sl is not None:
            solve[sl.slaves] = False
        if not np.any(solve):
            raise CaseError("joints", "every elastic DOF is constrained: nothing to solve (a superposition model "
                                      "needs a flexible link that the joints leave free to deform)")
        cliques = [el_dof0[:, e] for e in range(el_dof0.shape[1])]
        if sl is not None:   # an item with a slaved DOF couples every DOF its slaves depend on
            masters = {s: [sl.masters[j] for j in p] for s, p in zip(sl.slaves, sl.pattern)}
            items = cliques + [self.lm_dof[:, i] - 1 for i in range(self.lm_dof.shape[1])] + [[d - 1] for d in self.ri_dof]
            cliques = [np.array(sorted({m for d in dofs for m in masters.get(int(d), [int(d)])}), int) for dofs in items]
        self.free_of = rcm_free_numbering(cliques, solve)
        self.bandwidth = int(kernels.api.ked_bandwidth(self.free_of, self.el_dof))
        if sl is not None:
            sl.finalize(self.free_of)
            for c in cliques:
                f = self.free_of[c]
                f = f[f > 0]
                if f.size:
                    self.bandwidth = max(self.bandwidth, int(f.max() - f.min()))

    def node_ref(self, ref: str, where: str) -> tuple[int, int, float]:
        """Resolve a link point ('<link>.<start|mid|end|name|fraction>') to (link index, global node,
        zeta along the link [m]); a CaseError when it is not a mesh node."""
        link, pos = ref.split(".", 1)
        if link in self.parts:
            raise CaseError(where, f"{ref!r} is a point of the rigid {'link' if link in self.link_names else 'body'} "
                                   f"{link!r}, which has no mesh; name a point of a flexible link")
        li = self.link_names.index(link)
        frac = self.case.mechanism.links[li].fraction(pos, where)
        f = self.node_frac[li]
        k = int(np.argmin(np.abs(f - frac)))
        if abs(f[k] - frac) > 1e-9:
            n = self.n_el[li]
            raise CaseError(where, f"{ref!r} is not at a mesh node ({link} has {n} elements: "
                                   f"fractions k/{n}); choose a node, name the point in links.points, "
                                   "or change elements_per_link")
        return li, self.node_of[li][k], k * self.case["links"][li]["length"] / self.n_el[li] \
            if self.uniform[li] else f[k] * self.case["links"][li]["length"]

    def point_ref(self, ref: str, where: str):
        """A body point for outputs: ('node', (link index, node, zeta)) on a flexible link (a mesh node),
        or ('rigid', (RigidPart, PointRef)) on a rigid link or body."""
        link = ref.split(".", 1)[0]
        if link in self.parts:
            return "rigid", (self.parts[link], self.case.mechanism.point(ref, where))
        return "node", self.node_ref(ref, where)

    def _lumped(self, case: dict) -> None:
        """Point masses and rotary inertias of the flexible links (those of rigid links are in their mass
        properties), then every rigid body's mass at its centre and its rotary inertia."""
        rigid_links = {n for n in self.parts if n in self.link_names}
        lm, ri = [], []
        for i, pm in enumerate(case["point_masses"]):
            if pm["at"].split(".")[0] not in rigid_links:
                li, node, z = self.node_ref(pm["at"], f"point_masses[{i}].at")
                lm.append((li + 1, self.trans_dof[node] + 1, pm["mass"], z))
        for i, r in enumerate(case["rotary_inertias"]):
            if r["turns_with"] in rigid_links:
                continue
            _, node, _ = self.node_ref(r["at"], f"rotary_inertias[{i}].at")
            lw = self.link_names.index(r["turns_with"])
            if (node, lw) not in self.rot_dof:
                raise CaseError(f"rotary_inertias[{i}].turns_with", f"link {r['turns_with']!r} does not pass through "
                                f"{r['at']!r}; name a link that meets at that node")
            ri.append((lw + 1, self.rot_dof[(node, lw)] + 1, r["inertia"]))
        for p in self.parts.values():   # classic-translational drops J alpha, as for every rotary inertia
            lm.append((p.col + 1, np.array(p.dofs[:2]) + 1, p.mass, p.zeta))
            if p.inertia > 0.0:
                ri.append((p.col + 1, p.dofs[2] + 1, p.inertia))
        if lm:
            self.lm_link = np.array([c for c, _, _, _ in lm], np.int32)
            self.lm_dof = np.asfortranarray(np.array([d for _, d, _, _ in lm], np.int32).T)
            self.lm_prop = np.asfortranarray(np.array([[m, z] for _, _, m, z in lm], float).T)
        if ri:
            self.ri_link = np.array([a for a, _, _ in ri], np.int32)
            self.ri_dof = np.array([b for _, b, _ in ri], np.int32)
            self.ri_prop = np.array([c for _, _, c in ri], float)

    # ------------------------------------------------------------------ properties
    @cached_property
    def nfree(self) -> int:
        """The number of free DOFs (a mesh is not changed once built: counted once, not per kernel call)."""
        return int(self.free_of.max())

    @property
    def nel(self) -> int:
        return self.el_link.size

    def joint(self, name: str) -> Joint:
        """The joint called ``name``."""
        return next(j for j in self.joints if j.name == name)

    def rotation_dof(self, ref) -> int | None:
        """All-DOF number of the elastic rotation of a point's body there (a PointRef; None: the ground)."""
        if ref.body is None:
            return None
        if ref.body.name in self.parts:
            return self.parts[ref.body.name].dofs[2]
        li = self.link_names.index(ref.body.name)
        node = self.node_of[li][self.node_index(li, ref.body.fraction(ref.point))]
        return self.rot_dof[(node, li)]

    def node_index(self, li: int, frac: float) -> int:
        """Index along link ``li`` of its mesh node at fraction ``frac`` of its length."""
        return _node_index(self.node_frac[li], frac)

    def free_translational(self) -> np.ndarray:
        """All-DOF numbers (0-based) of the free translational DOFs."""
        t = self.trans_dof.ravel()
        return np.sort(t[self.free_of[t] > 0])

    def link_elements(self, li: int) -> np.ndarray:
        """0-based element indices of link ``li`` from its start to its end."""
        return np.flatnonzero(self.el_link == li + 1)

    def link_lengths(self) -> np.ndarray:
        return np.array([ln["length"] for ln in self.case["links"]])

    def _system_args(self):
        return self._kernel_system

    @cached_property
    def _kernel_system(self) -> tuple:
        """The mesh's arrays as every flexmech_ked call takes them, built once (a stepped run calls the
        kernel once per step)."""
        # f2py cannot pass zero-length arrays: an absent kind of lumped inertia is
        # passed as one entry of zero mass (it adds exactly 0 to one diagonal term).
        lm = (self.lm_link, self.lm_dof, self.lm_prop) if self.lm_link.size else (
            np.ones(1, np.int32), np.ones((2, 1), np.int32, order="F"), np.zeros((2, 1), order="F"))
        ri = (self.ri_link, self.ri_dof, self.ri_prop) if self.ri_link.size else (
            np.ones(1, np.int32), np.ones(1, np.int32), np.zeros(1))
        sl = self.slaving
        slv = (sl.slave_of(self.ndof), sl.ptr, sl.col) if sl is not None and sl.nsl else (
            np.zeros(self.ndof, np.int32), np.ones(1, np.int32), np.ones(1, np.int32))
        return (self.free_of, self.el_link, self.el_dof, self.el_prop) + lm + ri + slv

    def slave_values(self, rig: np.ndarray) -> np.ndarray:
        """(3, nnz, N) coefficients [T, T', T''] of the slave rows at rig samples (5, ncols, N) (or one
        sample (5, ncols)); one dummy entry of zeros without slaves."""
        rig = np.asarray(rig, float)
        n = rig.shape[2] if rig.ndim == 3 else 1
        if self.slaving is None or not self.slaving.nsl:
            return np.zeros((3, 1, n), order="F")
        return self.slaving.values(rig)

    def rig_samples(self, rm, gravity, idx=slice(None)) -> np.ndarray:
        """(5, ncols, N) kernel samples of a RigidMotion: the links' columns [phi, omega, alpha, a_O - g]
        (RigidMotion.kernel_samples), then one per rigid body [phi, omega, alpha, a_C - g] (its frame at
        the centre of mass) and one per guided joint [d, d', d'', 0, 0] (flexmech_py/models/superposition/slaving.py)."""
        base = rm.kernel_samples(gravity, idx)
        mech = self.case.mechanism
        if not mech.rigid_bodies and not self.slides:
            return base
        cols = []
        for b in mech.rigid_bodies:
            i = 3 * mech.body_index(b)
            z, zd, zdd = rm.z[idx, i:i + 3], rm.zd[idx, i:i + 3], rm.zdd[idx, i:i + 3]
            cols.append([z[:, 2], zd[:, 2], zdd[:, 2], zdd[:, 0] - gravity[0], zdd[:, 1] - gravity[1]])
        for sl in self.slides:
            jq = rm.joint(sl.joint.name)[idx]
            cols.append([jq[:, 0], jq[:, 1], jq[:, 2], 0.0 * jq[:, 0], 0.0 * jq[:, 0]])
        extra = np.array(cols, float).transpose(1, 0, 2)
        return np.asfortranarray(np.concatenate([base, extra], axis=1))

    def expand(self, x_free: np.ndarray, rig: np.ndarray | None = None) -> np.ndarray:
        """Free-DOF vectors (nfree, ...) -> all-DOF vectors (ndof, ...), zeros at constrained DOFs; the
        slaved DOFs from their masters when the frames' rig samples (5, ncols, N) are given (else 0)."""
        out = np.zeros((self.ndof,) + x_free.shape[1:])
        mask = self.free_of > 0
        out[mask] = x_free[self.free_of[mask] - 1]
        if rig is not None and self.slaving is not None and out.ndim == 2:
            self.slaving.reconstruct(out, rig)
        return out

    def expand_state(self, uf, vf, af, rig):
        """All-DOF (u, v, a) frames from free-DOF ones, slaved DOFs with the derivatives of their rows."""
        u, v, a = self.expand(uf), self.expand(vf), self.expand(af)
        if self.slaving is not None:
            self.slaving.reconstruct(u, rig, (v, a))
        return u, v, a

    def restrict(self, x_all: np.ndarray) -> np.ndarray:
        """All-DOF vectors (ndof, ...) -> free-DOF vectors (nfree, ...)."""
        out = np.zeros((self.nfree,) + x_all.shape[1:])
        mask = self.free_of > 0
        out[self.free_of[mask] - 1] = x_all[mask]
        return out

    # ------------------------------------------------------------------ kernel calls
    def matrices(self, rig: np.ndarray, model: str = STUDY_MODEL, rayleigh=(0.0, 0.0)):
        """Dense (M, C, K) over the free DOFs and the rigid-inertia load over all DOFs at one rigid sample."""
        rig = np.asfortranarray(rig, float)
        mm, cm, km, f, status = kernels.api.ked_matrices(
            self.nfree, *self._system_args(), family(model).load_code, np.asarray(rayleigh, float), rig,
            np.asfortranarray(self.slave_values(rig)[:, :, 0]))
        kernels.check_status(status, "ked_matrices")
        return mm, cm, km, f

    def squared_frequencies(self, rig: np.ndarray, model: str = STUDY_MODEL, nax=None, vectors: bool = False):
        """Ascending w^2 of the frozen configuration at one rigid sample: (K [+ K_sigma(nax)], M) over
        the free DOFs, K the stiffness the model uses there (elastic, centrifugal and angular-
        acceleration terms; gyroscopic and damping terms left out).  See :func:`squared_frequencies`
        (``vectors``: also the mass-normalized mode vectors over the free DOFs)."""
        m, _, k, _ = self.matrices(rig, model)
        if nax is not None:
            k = k + self.geometric_matrix(rig, nax)
        return squared_frequencies(m, k, vectors)

    def geometric_matrix(self, rig: np.ndarray, nax: np.ndarray) -> np.ndarray:
        """Dense geometric stiffness over the free DOFs at one rigid sample for element axial forces
        ``nax`` (nel,) [N], tension > 0 (the term ``solver.geometric_stiffness`` adds to K)."""
        kgm, status = kernels.api.ked_geometric_matrix(self.nfree, *self._system_args(), np.asfortranarray(rig, float),
                                                       np.asfortranarray(self.slave_values(rig)[:, :, 0]),
                                                       np.asarray(nax, float))
        kernels.check_status(status, "ked_geometric_matrix")
        return kgm

    def loads(self, rig: np.ndarray, model: str) -> np.ndarray:
        """Rigid-inertia loads F_rigid over all DOFs, (ndof, ns), at rigid samples rig (5, nlinks, ns)."""
        if model not in SUPERPOSITION_MODELS:
            raise CaseError("model", f"must be one of {', '.join(SUPERPOSITION_MODELS)}, got {model!r}")
        f, status = kernels.api.ked_loads(*self._system_args(), family(model).load_code, np.asfortranarray(rig, float))
        kernels.check_status(status, "ked_loads")
        return f

    def run(self, rig, model, dt, *, beta=0.25, gamma=0.5, alpha_m=0.0, alpha_f=0.0, out_every=1,
            rayleigh=(0.0, 0.0), q_free=None, q_val=None, u0=None, v0=None, a0=None, p0=None, t0=0.0,
            geometric="none", geo_tol=1e-8, geo_maxit=50, div_limit=None, full=False):
        """Generalized-alpha run over rig (5, nlinks, nsteps+1) (``alpha_m = alpha_f = 0``: Newmark
        (beta, gamma); :func:`flexmech_py.case.integrator_coefficients` maps the integrators onto
        these four numbers); returns (uf, vf, af) frames over the free DOFs (with ``full=True``
        also the element axial forces nf (nel, nframes) [N] and the number of axial-force
        iterations).  ``geometric``: none | current | lagged | quasi_static.

        State (free DOFs): ``u0, v0`` (default 0); ``a0`` the true and ``p0`` the pseudo-acceleration
        of a run being continued (``a0=None``: a fresh start, the acceleration from the equations of
        motion and ``p0 = a0``; ``p0=None`` with ``a0`` given: ``p0 = a0``).  ``div_limit`` [m]:
        the divergence guard on the free translations (default DIVERGENCE_FACTOR x the longest
        link length).  After the call ``self.last_run`` holds the frames, the number of valid
        frames ``frames_valid``, the final state ``u, v, a, p``, ``status`` and ``fail_step``
        (also when the run failed).

        Raises SolverError (naming the time) if the compiled loop stops.
        """
        rig = np.asfortranarray(rig, float)
        nsteps = rig.shape[2] - 1
        nf = self.nfree
        u = np.zeros(nf) if u0 is None else np.array(u0, float)
        v = np.zeros(nf) if v0 is None else np.array(v0, float)
        a = np.zeros(nf) if a0 is None else np.array(a0, float)
        p = a.copy() if p0 is None else np.array(p0, float)
        if div_limit is None:
            div_limit = DIVERGENCE_FACTOR * float(self.link_lengths().max())
        if q_free is None:  # no applied elastic loads: one zero entry (f2py cannot pass empty arrays)
            q_free = np.ones(1, np.int32)
            q_val = np.zeros((1, nsteps + 1), order="F")
        uf, vf, af, nf, status, fail, geo_iters, nvalid = kernels.api.ked_run(
            *self._system_args(), family(model).load_code, np.asarray(rayleigh, float), rig,
            self.slave_values(rig),
            np.asarray(q_free, np.int32), np.asfortranarray(q_val, float), dt, alpha_m, alpha_f, beta, gamma,
            out_every, int(a0 is None), GEOMETRIC_CODE[geometric], geo_tol, geo_maxit, float(div_limit), u, v, a, p)
        self.last_run = {"uf": uf, "vf": vf, "af": af, "nf": nf, "frames_valid": int(nvalid), "u": u, "v": v,
                         "a": a, "p": p, "status": int(status), "fail_step": int(fail)}
        kernels.check_status(status, "Newmark integration" if alpha_m == alpha_f == 0.0 else "generalized-alpha integration",
                             time=t0 + fail * dt if fail else t0, iteration="geometric", step=int(fail),
                             data={"uf": uf, "vf": vf, "af": af, "nf": nf, "geo_iters": geo_iters,
                                   "u": u, "v": v, "a": a, "p": p})
        return (uf, vf, af, nf, geo_iters) if full else (uf, vf, af)
