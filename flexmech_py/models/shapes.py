"""The mechanism's drawn points: rigid positions and elastic displacements per instant (per mode
shape), and the CSV file that holds them (``mode_shapes.csv`` of ``flexmech modes``; docs/cli.md).

Points, body by body (:func:`body_points`): every flexible link's mesh nodes in order from its start
(labelled by their fraction of the link's length), a rigid link's start, end, named points and joint
points, a rigid body's centre of mass, named points and joint points.  Per point: its position in the
rigid-body solution ``x`` [m], its elastic displacement ``d`` [m] from there (global components) and
the elastic rotation ``rot`` [rad] of its body there (a flexible link: the slope of the deflection
relative to the rigid link axis) and, for a run's frames, the curvature ``kappa`` [1/m] of a flexible
link at its nodes as the model computes it (what its ``strain`` outputs are made of; empty at the
points of rigid parts).  Nothing here draws (flexmech_py/figures/drawing.py does).
"""

from __future__ import annotations

import csv
import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..base.errors import FlexmechError
from ..base.families import family
from ..base.fileio import atomic_write

__all__ = ["Body", "ShapeFrames", "body_points", "rigid_positions", "superposition_displacements",
           "coupled_displacements", "node_curvatures", "write_shape_csv", "read_shape_csv", "ShapeCollector",
           "spread"]

KINDS = ("flexible", "rigid_link", "body")


@dataclass
class Body:
    """A body's drawn points: ``kind`` flexible | rigid_link | body, ``labels`` (a fraction of a link's
    length or a point name), ``sl`` its slice of the point arrays, ``fracs`` the fractions of a
    flexible link's nodes (None otherwise)."""

    name: str
    kind: str
    labels: list
    sl: slice
    fracs: np.ndarray | None = None

    def index(self, label: str) -> int | None:
        """Index (into the point arrays) of a point: a name, or the node nearest to a fraction."""
        if self.fracs is not None:
            try:
                f = float(label)
            except ValueError:
                return None
            return self.sl.start + int(np.argmin(np.abs(self.fracs - f)))
        return self.sl.start + self.labels.index(label) if label in self.labels else None


@dataclass
class ShapeFrames:
    """Drawn points at several instants (a run's frames) or of several mode shapes: ``key`` (n,) the
    time [s] or the frequency [Hz] of each, ``x`` (n, npts, 2) rigid positions [m], ``d`` (n, npts, 2)
    elastic displacements, ``rot`` (n, npts) elastic rotations [rad]; ``bodies`` the point layout;
    ``kappa`` (n, npts) the curvature [1/m] at a flexible link's nodes (NaN elsewhere), or None."""

    bodies: list
    key: np.ndarray
    x: np.ndarray
    d: np.ndarray
    rot: np.ndarray
    kappa: np.ndarray | None = None

    def select(self, idx) -> "ShapeFrames":
        return ShapeFrames(self.bodies, self.key[idx], self.x[idx], self.d[idx], self.rot[idx],
                           None if self.kappa is None else self.kappa[idx])

    def point(self, body: str, label: str) -> int | None:
        b = next((b for b in self.bodies if b.name == body), None)
        return None if b is None else b.index(label)


def _joint_labels(mech, body) -> list[str]:
    out = []
    for j in mech.joints:
        for ref in mech.joint_points(j):
            if ref.body is body and ref.point not in out:
                out.append(ref.point)
    return out


def body_points(mech, node_frac) -> list[Body]:
    """The point layout of a mechanism whose flexible links are meshed at ``node_frac[link]`` (the
    fractions of the FE model's or the coupled model's nodes)."""
    out, n = [], 0
    for li, ln in enumerate(mech.links):
        if ln.rigid:
            labels = list(dict.fromkeys(["start", "end"] + list(ln.points) + _joint_labels(mech, ln)))
            out.append(Body(ln.name, "rigid_link", labels, slice(n, n + len(labels))))
        else:
            f = np.asarray(node_frac[li], float)
            out.append(Body(ln.name, "flexible", [f"{x:.12g}" for x in f], slice(n, n + f.size), f))
        n = out[-1].sl.stop
    for b in mech.rigid_bodies:
        labels = list(dict.fromkeys(["centre"] + list(b.points) + _joint_labels(mech, b)))
        out.append(Body(b.name, "body", labels, slice(n, n + len(labels))))
        n = out[-1].sl.stop
    return out


def _rotate(c, s, v):
    """R(phi) v for arrays c, s (n,) and a constant 2-vector v: (n, 2)."""
    return np.stack([c * v[0] - s * v[1], s * v[0] + c * v[1]], axis=-1)


def _marker(body, label: str) -> np.ndarray:
    return body.marker(label)


def rigid_positions(mech, bodies: list, rm) -> np.ndarray:
    """(N, npts, 2) positions [m] of the points in the rigid-body solution rm (a RigidMotion)."""
    x = np.zeros((rm.t.size, bodies[-1].sl.stop, 2))
    for b in bodies:
        body = mech.body(b.name)
        bi = mech.body_index(body)
        zc, phi = rm.z[:, 3 * bi:3 * bi + 2], rm.z[:, 3 * bi + 2]
        c, s = np.cos(phi), np.sin(phi)
        if b.kind == "flexible":
            km = rm.motion
            li = mech.link_index(b.name)
            e = np.stack([np.cos(km.phi[:, li]), np.sin(km.phi[:, li])], axis=-1)
            o = np.stack([km.ox[:, li], km.oy[:, li]], axis=-1)
            x[:, b.sl] = o[:, None, :] + (b.fracs[None, :, None] * body.length) * e[:, None, :]
        else:
            for k, lab in enumerate(b.labels):
                x[:, b.sl.start + k] = zc + _rotate(c, s, _marker(body, lab))
    return x


def _empty(bodies: list, n: int) -> tuple[np.ndarray, np.ndarray]:
    npts = bodies[-1].sl.stop
    return np.zeros((n, npts, 2)), np.zeros((n, npts))


def _node_displacements(mesh, b, u: np.ndarray, d: np.ndarray, rot: np.ndarray) -> None:
    """Fill d, rot of flexible link b's nodes from the all-DOF displacements u of a mesh layout
    (FEModel or LinkMesh: ``link_names``, ``node_of``, ``trans_dof``, ``rot_dof``)."""
    li = mesh.link_names.index(b.name)
    for k, node in enumerate(mesh.node_of[li]):
        d[:, b.sl.start + k] = u[mesh.trans_dof[node]].T
        rot[:, b.sl.start + k] = u[mesh.rot_dof[(node, li)]]


def superposition_displacements(fe, bodies: list, u: np.ndarray, rm) -> tuple[np.ndarray, np.ndarray]:
    """(d (N, npts, 2), rot (N, npts)) of the superposition models' all-DOF displacements u (ndof, N):
    a flexible link's nodes from their translations and rotations, a rigid part's points from its
    (dx, dy, dtheta) at the centre of mass, d = (dx, dy) + dtheta k x s(t)."""
    mech = fe.case.mechanism
    d, rot = _empty(bodies, u.shape[1])
    for b in bodies:
        if b.kind == "flexible":
            _node_displacements(fe, b, u, d, rot)
            continue
        part = fe.parts[b.name]
        body = mech.body(b.name)
        phi = rm.z[:, 3 * mech.body_index(body) + 2]
        c, s = np.cos(phi), np.sin(phi)
        dth = u[part.dofs[2]]
        for k, lab in enumerate(b.labels):
            sp = _rotate(c, s, _marker(body, lab))
            d[:, b.sl.start + k] = u[list(part.dofs[:2])].T + dth[:, None] * np.stack([-sp[:, 1], sp[:, 0]], axis=-1)
            rot[:, b.sl.start + k] = dth
    return d, rot


def coupled_displacements(cm, bodies: list, u_dev: np.ndarray, qf: np.ndarray, rm) -> tuple[np.ndarray, np.ndarray]:
    """(d, rot) of the coupled and nonlinear models: a flexible link's nodes from the deviation u_dev
    (flexmech_py.models.constrained.outputs.deviation, the layout of cm.mesh), a rigid part's points from its
    coordinates in the model's states qf (ndof, N) minus those of the rigid-body solution rm."""
    mech = cm.case.mechanism
    d, rot = _empty(bodies, qf.shape[1])
    for b in bodies:
        if b.kind == "flexible":
            _node_displacements(cm.mesh, b, u_dev, d, rot)
            continue
        body = mech.body(b.name)
        bi = mech.body_index(body)
        dofs = cm.body_of(bi)[1]
        z_ref = rm.z[:, 3 * bi:3 * bi + 3]
        c0, s0 = np.cos(z_ref[:, 2]), np.sin(z_ref[:, 2])
        c1, s1 = np.cos(qf[dofs[2]]), np.sin(qf[dofs[2]])
        dphi = qf[dofs[2]] - z_ref[:, 2]
        for k, lab in enumerate(b.labels):
            m = _marker(body, lab)
            d[:, b.sl.start + k] = (qf[dofs[:2]].T - z_ref[:, :2]) + _rotate(c1, s1, m) - _rotate(c0, s0, m)
            rot[:, b.sl.start + k] = np.arctan2(np.sin(dphi), np.cos(dphi))
    return d, rot


def node_curvatures(block, idx: np.ndarray, bodies: list) -> np.ndarray:
    """(n, npts) the curvature [1/m] of every flexible link at its nodes at the frames ``idx`` of a
    run's block (a Result), as the model computes its strain outputs; NaN at the points of rigid parts."""
    sub = dataclasses.replace(block, t=block.t[idx], u=block.u[:, idx],
                              state=None if block.state is None else block.state[:, idx],
                              motion=None if block.motion is None else block.motion.select(idx))
    names = [ln["name"] for ln in block.case["links"]]
    out = np.full((idx.size, bodies[-1].sl.stop), np.nan)
    for b in bodies:
        if b.kind == "flexible":
            out[:, b.sl] = sub.node_curvatures(names.index(b.name)).T
    return out


#: the columns of a shape file; KAPPA_COLUMN follows them when the file holds curvatures
SHAPE_COLUMNS = "body,kind,point,x,y,dx,dy,rot"
KAPPA_COLUMN = "kappa"


def write_shape_csv(path, sf: ShapeFrames, head: list[str], key: str = "t") -> Path:
    """Write ShapeFrames as CSV: ``#`` comment lines ``head``, a header
    ``index,<key>,body,kind,point,x,y,dx,dy,rot[,kappa]`` and one row per instant and point
    (atomically); ``kappa`` when sf has curvatures, empty at the points of rigid parts."""

    with_k = sf.kappa is not None
    lines = [f"# {h}" for h in head] + [f"index,{key},{SHAPE_COLUMNS}" + (f",{KAPPA_COLUMN}" if with_k else "")]
    for i in range(sf.key.size):
        for b in sf.bodies:
            for k, lab in enumerate(b.labels):
                p = b.sl.start + k
                row = (f"{i},{sf.key[i]:.10g},{b.name},{b.kind},{lab},{sf.x[i, p, 0]:.10g},{sf.x[i, p, 1]:.10g},"
                       f"{sf.d[i, p, 0]:.6e},{sf.d[i, p, 1]:.6e},{sf.rot[i, p]:.6e}")
                if with_k:
                    row += "," if np.isnan(sf.kappa[i, p]) else f",{sf.kappa[i, p]:.6e}"
                lines.append(row)
    atomic_write(Path(path), "\n".join(lines) + "\n")
    return Path(path)


def read_shape_csv(path) -> tuple[ShapeFrames, str, list[str]]:
    """(ShapeFrames, the name of the key column, the comment lines) of a file written by
    :func:`write_shape_csv`; FlexmechError naming the file when it is not one."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise FlexmechError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    head = [ln[1:].strip() for ln in text if ln.startswith("#")]
    rows = list(csv.reader(ln for ln in text if ln and not ln.startswith("#")))
    if not rows or len(rows[0]) < 2 or ",".join(rows[0][2:]) not in (SHAPE_COLUMNS, f"{SHAPE_COLUMNS},{KAPPA_COLUMN}"):
        raise FlexmechError(f"{path}: not a shape file written by flexmech (header index,t,{SHAPE_COLUMNS}[,kappa])")
    key_name, body_rows, width = rows[0][1], rows[1:], len(rows[0])
    try:
        idx = np.array([int(r[0]) for r in body_rows])
        vals = np.array([[float(x) if x else np.nan for x in (r[1], *r[5:width])] for r in body_rows])
        vals = vals.reshape(-1, width - 4)
    except (ValueError, IndexError):
        raise FlexmechError(f"{path}: a row is not index,{key_name},{','.join(rows[0][2:])} numbers") from None
    n = int(idx.max()) + 1 if idx.size else 0
    first = body_rows[:int(np.sum(idx == 0))]
    bodies, start = [], 0
    for r in first:
        if not bodies or bodies[-1][0] != r[2]:
            bodies.append((r[2], r[3], []))
        bodies[-1][2].append(r[4])
    out = []
    for name, kind, labels in bodies:
        if kind not in KINDS:
            raise FlexmechError(f"{path}: unknown body kind {kind!r} (expected {', '.join(KINDS)})")
        fr = np.array([float(x) for x in labels]) if kind == "flexible" else None
        out.append(Body(name, kind, labels, slice(start, start + len(labels)), fr))
        start += len(labels)
    if n == 0 or idx.size != n * start:
        raise FlexmechError(f"{path}: every instant must list the same {start} points")
    vals = vals.reshape(n, start, width - 4)
    kappa = vals[:, :, 6] if width == 11 else None
    return ShapeFrames(out, vals[:, 0, 0], vals[:, :, 1:3], vals[:, :, 3:5], vals[:, :, 5], kappa), key_name, head


def spread(n: int, count: int) -> np.ndarray:
    """Indices of ``count`` (at most n) of n frames spread evenly, the first and the last included."""
    return np.unique(np.linspace(0, n - 1, min(int(count), n)).round().astype(int))


class ShapeCollector:
    """The drawn points of a run at ``count`` frames spread evenly over it (the first and the last
    included), gathered block by block as the run goes (an observer of
    :func:`flexmech_py.run.runner.execute`; a Result kept in memory is one block): what
    ``flexmech run --draw`` writes to shape.csv.  ``frames``: the run's output frames; ``coupled``:
    {model: its CoupledModel} as the run fills it (``Prepared.coupled``; superposition runs need none)."""

    def __init__(self, mech, frames: int, count: int, coupled=None):
        self.mech, self.coupled = mech, {} if coupled is None else coupled
        self.want = spread(frames, max(2, int(count)))
        self.seen = 0
        self.parts: list[ShapeFrames] = []

    def add(self, block) -> None:
        n = block.t.size
        idx = self.want[(self.want >= self.seen) & (self.want < self.seen + n)] - self.seen
        self.seen += n
        if idx.size:
            self.parts.append(self._points(block, idx))

    def _points(self, block, idx: np.ndarray) -> ShapeFrames:
        rm = block.rigid.select(idx)
        if family(block.model).constrained:      # the block's own: "auto" chooses the model in the run
            cm = self.coupled[block.model]
            bodies = body_points(self.mech, cm.mesh.node_frac)
            d, rot = coupled_displacements(cm, bodies, block.u[:, idx], block.state[:, idx], rm)
        else:
            bodies = body_points(self.mech, block.fe.node_frac)
            d, rot = superposition_displacements(block.fe, bodies, block.u[:, idx], rm)
        return ShapeFrames(bodies, block.t[idx], rigid_positions(self.mech, bodies, rm), d, rot,
                           node_curvatures(block, idx, bodies))

    def result(self) -> ShapeFrames | None:
        """The frames gathered (None before the first)."""
        if not self.parts:
            return None
        p = self.parts
        return ShapeFrames(p[0].bodies, np.concatenate([s.key for s in p]), np.concatenate([s.x for s in p]),
                           np.concatenate([s.d for s in p]), np.concatenate([s.rot for s in p]),
                           np.concatenate([s.kappa for s in p]))
