"""Finite-element model of a mechanism: nodes, DOFs, joints, elements, lumped inertias.

Conventions (docs/theory.md):

- Every link is meshed with ``n`` equal beam elements from its *start* (its
  rigid reference point O) to its *end*; element axes follow the rigid link angle.
- Each mesh node has two elastic translational DOFs (global X, Y components),
  shared by the links that meet at a joint.  Rotational DOFs belong to a
  (node, link) pair; links joined by a ``locked`` joint share one.
- Ground joints fix the node's translations; ``clamp`` also fixes the rotation
  of the attached link.  Constrained DOFs are kept in the numbering ("all
  DOFs") and dropped from the solved system ("free DOFs").
- Free DOFs are numbered by reverse Cuthill-McKee to keep the band narrow.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import kernels
from .case import JOINTS_OF, SUPERPOSITION_MODELS
from .errors import CaseError

__all__ = ["FEModel", "Joint", "LOAD_MODEL_CODE"]

LOAD_MODEL_CODE = {"hac": 1, "classic": 2, "classic-translational": 3}
GEOMETRIC_CODE = {"none": 0, "current": 1, "lagged": 2, "quasi_static": 3}


@dataclass
class Joint:
    """A joint: ``inboard`` link index (None = ground) and ``outboard`` link index, each at an end."""

    name: str
    inboard: int | None
    inboard_end: str | None
    outboard: int
    outboard_end: str
    elastic: str


def mechanism_joints(case: dict) -> list[Joint]:
    """The joints of the case's mechanism type, with their elastic conditions."""
    mtype = case["mechanism"]["type"]
    el = case["joints"]
    if mtype == "fourbar":
        return [Joint("crank_pivot", None, None, 0, "start", el["crank_pivot"]),
                Joint("crank_coupler", 0, "end", 1, "start", el["crank_coupler"]),
                Joint("coupler_follower", 1, "end", 2, "end", el["coupler_follower"]),
                Joint("follower_pivot", None, None, 2, "start", el["follower_pivot"])]
    n = len(case["links"])
    joints = [Joint("base", None, None, 0, "start", el["base"])]
    joints += [Joint(f"joint_{k}", k - 2, "end", k - 1, "start", el[f"joint_{k}"]) for k in range(2, n + 1)]
    assert [j.name for j in joints] == list(JOINTS_OF(mtype, n))
    return joints


def squared_frequencies(m: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Ascending eigenvalues w^2 [rad^2/s^2] of K x = w^2 M x (K and M symmetrized), via the Cholesky
    factor of M (NumPy only).  Negative values: the frozen system is unstable in that mode.  Raises
    numpy.linalg.LinAlgError when M is not positive definite."""
    lc = np.linalg.cholesky(0.5 * (m + m.T))
    a = np.linalg.solve(lc, np.linalg.solve(lc, 0.5 * (k + k.T)).T)
    return np.linalg.eigvalsh(0.5 * (a + a.T))


def reverse_cuthill_mckee(neighbours: list) -> np.ndarray:
    """Reverse Cuthill-McKee order of a graph given as sorted neighbour arrays (self included).

    The algorithm of scipy.sparse.csgraph.reverse_cuthill_mckee (each component from its
    lowest-degree node, breadth first, each level's new nodes by increasing degree, reversed),
    written out so that a run does not import scipy.sparse (about 0.2 s of start-up)."""
    n = len(neighbours)
    degree = np.array([len(nb) for nb in neighbours])
    inds = np.argsort(degree)
    order = np.zeros(n, dtype=np.intp)
    visited = np.zeros(n, bool)
    N = 0
    for zz in range(n):
        seed = inds[zz]
        if visited[seed]:
            continue
        order[N] = seed
        N += 1
        visited[seed] = True
        level_start, level_end = N - 1, N
        while level_start < level_end:
            for ii in range(level_start, level_end):
                n_old = N
                for j in neighbours[order[ii]]:
                    if not visited[j]:
                        visited[j] = True
                        order[N] = j
                        N += 1
                new = order[n_old:N]
                order[n_old:N] = new[np.argsort(degree[new], kind="stable")]   # the insertion sort
            level_start, level_end = level_end, N
        if N == n:
            break
    return order[::-1]


def rcm_free_numbering(cliques, free_mask: np.ndarray) -> np.ndarray:
    """Free-DOF numbers (1-based; 0 = not free) by reverse Cuthill-McKee.

    cliques: 0-based DOF index arrays whose DOFs are all coupled (an element, a link);
    free_mask (ndof,) marks the DOFs to number.
    """
    free = np.flatnonzero(free_mask)
    pos = -np.ones(free_mask.size, int)
    pos[free] = np.arange(free.size)
    nbs = [set() for _ in range(free.size)]
    for dofs in cliques:
        f = pos[np.asarray(dofs)]
        f = [int(x) for x in f[f >= 0]]
        for a in f:
            nbs[a].update(f)
    perm = reverse_cuthill_mckee([np.array(sorted(nb), dtype=np.intp) for nb in nbs])
    order = np.empty(free.size, int)
    order[perm] = np.arange(free.size)
    out = np.zeros(free_mask.size, np.int32)
    out[free] = order + 1
    return out


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
    last_run: dict | None = field(default=None, repr=False)   # the last run's frames and final state (run())

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_case(cls, case: dict) -> "FEModel":
        links = case["links"]
        names = [ln["name"] for ln in links]
        n_el = [ln["elements"] for ln in links]
        joints = mechanism_joints(case)
        # global nodes: one per (link, k), merged at joints
        nodes = _UnionFind()
        for j in joints:
            if j.inboard is not None:
                nodes.union((j.inboard, 0 if j.inboard_end == "start" else n_el[j.inboard]),
                            (j.outboard, 0 if j.outboard_end == "start" else n_el[j.outboard]))
        ids, node_of = {}, []
        for li, n in enumerate(n_el):
            row = []
            for k in range(n + 1):
                root = nodes.find((li, k))
                ids.setdefault(root, len(ids))
                row.append(ids[root])
            node_of.append(row)
        nnodes = len(ids)

        # rotational DOF groups: (node, link) pairs, merged by locked joints
        rots = _UnionFind()
        for j in joints:
            if j.inboard is not None and j.elastic == "locked":   # "torque" and "pin": separate rotations
                na = node_of[j.inboard][0 if j.inboard_end == "start" else -1]
                rots.union((na, j.inboard), (na, j.outboard))
        # DOF numbering (before bandwidth reduction): node translations, then rotations
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
        ndof = 2 * nnodes + len(rot_groups)
        fixed = np.zeros(ndof, bool)
        for j in joints:
            if j.inboard is None:
                node = node_of[j.outboard][0 if j.outboard_end == "start" else -1]
                fixed[trans[node]] = True
                if j.elastic == "clamp":
                    fixed[rot[(node, j.outboard)]] = True

        el_link, el_dof, el_prop = [], [], []
        for li, ln in enumerate(links):
            le = ln["length"] / n_el[li]
            ra, ea, ei = ln["density"] * ln["area"], ln["youngs_modulus"] * ln["area"], ln["youngs_modulus"] * ln["second_moment"]
            for k in range(n_el[li]):
                n1, n2 = node_of[li][k], node_of[li][k + 1]
                el_link.append(li + 1)
                el_dof.append([trans[n1, 0], trans[n1, 1], rot[(n1, li)], trans[n2, 0], trans[n2, 1], rot[(n2, li)]])
                el_prop.append([le, k * le, ra, ea, ei])
        el_dof = np.array(el_dof, dtype=np.int32).T  # (6, nel), 0-based for now

        model = cls(case=case, joints=joints, link_names=names, n_el=n_el, node_of=node_of, nnodes=nnodes,
                    trans_dof=trans, rot_dof=rot, ndof=ndof, fixed=fixed, free_of=np.zeros(ndof, np.int32),
                    el_link=np.array(el_link, np.int32), el_dof=el_dof + 1,
                    el_prop=np.asfortranarray(np.array(el_prop, float).T),
                    lm_link=np.zeros(0, np.int32), lm_dof=np.zeros((2, 0), np.int32), lm_prop=np.zeros((2, 0)),
                    ri_link=np.zeros(0, np.int32), ri_dof=np.zeros(0, np.int32), ri_prop=np.zeros(0),
                    dof_names=dof_names)
        model._number_free_dofs(el_dof)
        model._lumped(case)
        return model

    def _number_free_dofs(self, el_dof0: np.ndarray) -> None:
        if not np.any(~self.fixed):
            raise CaseError("joints", "every elastic DOF is constrained: nothing to solve")
        self.free_of = rcm_free_numbering([el_dof0[:, e] for e in range(el_dof0.shape[1])], ~self.fixed)
        self.bandwidth = int(kernels.api.ked_bandwidth(self.free_of, self.el_dof))

    def node_ref(self, ref: str, where: str) -> tuple[int, int, float]:
        """Resolve '<link>.<start|mid|end|fraction>' to (link index, global node, zeta along the link)."""
        link, pos = ref.split(".", 1)
        li = self.link_names.index(link)
        frac = {"start": 0.0, "mid": 0.5, "end": 1.0}.get(pos)
        frac = float(pos) if frac is None else frac
        n = self.n_el[li]
        k = int(round(frac * n))
        if abs(frac * n - k) > 1e-9:
            raise CaseError(where, f"{ref!r} is not at a mesh node ({link} has {n} elements: "
                                   f"fractions k/{n}); choose a node or change elements_per_link")
        return li, self.node_of[li][k], k * self.case["links"][li]["length"] / n

    def _lumped(self, case: dict) -> None:
        lm = [self.node_ref(pm["at"], f"point_masses[{i}].at") + (pm["mass"],)
              for i, pm in enumerate(case["point_masses"])]
        if lm:
            self.lm_link = np.array([li + 1 for li, _, _, _ in lm], np.int32)
            self.lm_dof = np.asfortranarray(np.array([self.trans_dof[node] + 1 for _, node, _, _ in lm], np.int32).T)
            self.lm_prop = np.asfortranarray(np.array([[m, z] for _, _, z, m in lm], float).T)
        ri = []
        for i, r in enumerate(case["rotary_inertias"]):
            _, node, _ = self.node_ref(r["at"], f"rotary_inertias[{i}].at")
            lw = self.link_names.index(r["turns_with"])
            if (node, lw) not in self.rot_dof:
                raise CaseError(f"rotary_inertias[{i}].turns_with", f"link {r['turns_with']!r} does not pass through "
                                f"{r['at']!r}; name a link that meets at that node")
            ri.append((lw + 1, self.rot_dof[(node, lw)] + 1, r["inertia"]))
        if ri:
            self.ri_link = np.array([a for a, _, _ in ri], np.int32)
            self.ri_dof = np.array([b for _, b, _ in ri], np.int32)
            self.ri_prop = np.array([c for _, _, c in ri], float)

    # ------------------------------------------------------------------ properties
    @property
    def nfree(self) -> int:
        return int(self.free_of.max())

    @property
    def nel(self) -> int:
        return self.el_link.size

    def joint(self, name: str) -> Joint:
        """The joint called ``name``."""
        return next(j for j in self.joints if j.name == name)

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
        # f2py cannot pass zero-length arrays: an absent kind of lumped inertia is
        # passed as one entry of zero mass (it adds exactly 0 to one diagonal term).
        lm = (self.lm_link, self.lm_dof, self.lm_prop) if self.lm_link.size else (
            np.ones(1, np.int32), np.ones((2, 1), np.int32, order="F"), np.zeros((2, 1), order="F"))
        ri = (self.ri_link, self.ri_dof, self.ri_prop) if self.ri_link.size else (
            np.ones(1, np.int32), np.ones(1, np.int32), np.zeros(1))
        return (self.free_of, self.el_link, self.el_dof, self.el_prop) + lm + ri

    def expand(self, x_free: np.ndarray) -> np.ndarray:
        """Free-DOF vectors (nfree, ...) -> all-DOF vectors (ndof, ...), zeros at constrained DOFs."""
        out = np.zeros((self.ndof,) + x_free.shape[1:])
        mask = self.free_of > 0
        out[mask] = x_free[self.free_of[mask] - 1]
        return out

    def restrict(self, x_all: np.ndarray) -> np.ndarray:
        """All-DOF vectors (ndof, ...) -> free-DOF vectors (nfree, ...)."""
        out = np.zeros((self.nfree,) + x_all.shape[1:])
        mask = self.free_of > 0
        out[self.free_of[mask] - 1] = x_all[mask]
        return out

    # ------------------------------------------------------------------ kernel calls
    def matrices(self, rig: np.ndarray, model: str = "hac", rayleigh=(0.0, 0.0)):
        """Dense (M, C, K) over the free DOFs and the rigid-inertia load over all DOFs at one rigid sample."""
        rig = np.asfortranarray(rig, float)
        mm, cm, km, f, status = kernels.api.ked_matrices(
            self.nfree, *self._system_args(), LOAD_MODEL_CODE[model], np.asarray(rayleigh, float), rig)
        kernels.check_status(status, "ked_matrices")
        return mm, cm, km, f

    def squared_frequencies(self, rig: np.ndarray, model: str = "hac", nax=None) -> np.ndarray:
        """Ascending w^2 of the frozen configuration at one rigid sample: (K [+ K_sigma(nax)], M) over
        the free DOFs, K the stiffness the model uses there (elastic, centrifugal and angular-
        acceleration terms; gyroscopic and damping terms left out).  See :func:`squared_frequencies`."""
        m, _, k, _ = self.matrices(rig, model)
        if nax is not None:
            k = k + self.geometric_matrix(rig, nax)
        return squared_frequencies(m, k)

    def geometric_matrix(self, rig: np.ndarray, nax: np.ndarray) -> np.ndarray:
        """Dense geometric stiffness over the free DOFs at one rigid sample for element axial forces
        ``nax`` (nel,) [N], tension > 0 (the term ``solver.geometric_stiffness`` adds to K)."""
        kgm, status = kernels.api.ked_geometric_matrix(self.nfree, *self._system_args(), np.asfortranarray(rig, float),
                                                       np.asarray(nax, float))
        kernels.check_status(status, "ked_geometric_matrix")
        return kgm

    def loads(self, rig: np.ndarray, model: str) -> np.ndarray:
        """Rigid-inertia loads F_rigid over all DOFs, (ndof, ns), at rigid samples rig (5, nlinks, ns)."""
        if model not in SUPERPOSITION_MODELS:
            raise CaseError("model", f"must be one of {', '.join(SUPERPOSITION_MODELS)}, got {model!r}")
        f, status = kernels.api.ked_loads(*self._system_args(), LOAD_MODEL_CODE[model], np.asfortranarray(rig, float))
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
        from .case import DIVERGENCE_FACTOR

        rig = np.asfortranarray(rig, float)
        nsteps = rig.shape[2] - 1
        nframes = nsteps // out_every + 1
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
            nframes, *self._system_args(), LOAD_MODEL_CODE[model], np.asarray(rayleigh, float), rig,
            np.asarray(q_free, np.int32), np.asfortranarray(q_val, float), dt, alpha_m, alpha_f, beta, gamma,
            out_every, int(a0 is None), GEOMETRIC_CODE[geometric], geo_tol, geo_maxit, float(div_limit), u, v, a, p)
        self.last_run = {"uf": uf, "vf": vf, "af": af, "nf": nf, "frames_valid": int(nvalid), "u": u, "v": v,
                         "a": a, "p": p, "status": int(status), "fail_step": int(fail)}
        kernels.check_status(status, "Newmark integration" if alpha_m == alpha_f == 0.0 else "generalized-alpha integration",
                             time=t0 + fail * dt if fail else t0, iteration="geometric", step=int(fail),
                             data={"uf": uf, "vf": vf, "af": af, "nf": nf, "geo_iters": geo_iters,
                                   "u": u, "v": v, "a": a, "p": p})
        return (uf, vf, af, nf, geo_iters) if full else (uf, vf, af)
