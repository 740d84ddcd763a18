"""Outputs and diagnostics of the coupled and nonlinear models (flexmech_py.models.constrained.coupled), evaluated on
the model's own frames: its chord and body motion, the deviation from the rigid-body solution,
curvatures and axial forces, joint coordinates, joint reactions and drive forces from the
multipliers (docs/theory.md section 11.6), energy balance and constraint satisfaction."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...base import kernels
from .coupled import CON_ANGLE, CON_POINT, CON_PROJECTION, CoupledModel
from ...mechanism.motion import LinkMotion
from ...mechanism.placement import point_state
from ...mechanism.rows import ROW_KINDS, residual
from ..superposition.outputs import axial_output, load_output, point_components, wrap_angle

__all__ = ["ModelFrames", "model_frames", "chord_motion", "body_angles", "node_state", "deviation", "curvature",
           "axial_forces", "joint_angles", "joint_coordinate", "joint_at_joint", "joint_output", "evaluate", "reaction",
           "drive_force", "Diagnostics", "multiplier_alternation", "FrameReactions"]


@dataclass
class ModelFrames:
    """A run's frames and what the outputs need of them: qf, vf, af (ndof, nf), lf (nc, nf), t (nf,);
    ``post`` (CoupledModel.post over ``measures``: the constraint rows, then one coordinate row per
    joint), ``chord`` (LinkMotion of the links), ``angles`` {body: (3, nf)} frame angle, rate,
    acceleration of every body."""

    qf: np.ndarray
    vf: np.ndarray
    af: np.ndarray
    lf: np.ndarray
    t: np.ndarray
    post: dict
    measures: list
    chord: LinkMotion
    angles: dict

    def measure(self, row) -> np.ndarray:
        """(3, nf) [value, rate, acceleration] of a measure row."""
        return self.post["measures"][:, self.measures.index(row)]


def model_frames(cm: CoupledModel, qf, vf, af, lf, t, gravity=(0.0, 0.0), rayleigh=(0.0, 0.0)) -> ModelFrames:
    measures = list(cm.rows) + [jm.coordinate for jm in cm.joints.values()]
    post = cm.post(qf, vf, af, lf, t, measures, gravity, rayleigh)
    chord = chord_motion(cm, qf, vf, af)
    return ModelFrames(qf, vf, af, lf, np.asarray(t, float), post, measures, chord, body_angles(cm, qf, vf, af, chord))


# ----------------------------------------------------------------------------- motion of the bodies
def chord_motion(cm: CoupledModel, qf, vf, af) -> LinkMotion:
    """Rigid motion of every link over the frames: the chord (start node to end node) of a flexible
    link, the frame of a rigid link (its start from the centre of mass); the rigid motion the
    coupled and nonlinear models compute."""
    mech = cm.case.mechanism
    nl = len(mech.links)
    out = {k: np.empty((qf.shape[1], nl)) for k in LinkMotion.__dataclass_fields__}
    for li, link in enumerate(mech.links):
        if link.rigid:
            _, dofs, *_ = cm.body_of(mech.body_index(link))
            xc = link.mass_properties()[1]
            phi, om, al = qf[dofs[2]], vf[dofs[2]], af[dofs[2]]
            c, s = np.cos(phi), np.sin(phi)
            out["phi"][:, li], out["omega"][:, li], out["alpha"][:, li] = np.unwrap(phi), om, al
            out["ox"][:, li], out["oy"][:, li] = qf[dofs[0]] - xc * c, qf[dofs[1]] - xc * s
            out["vx"][:, li], out["vy"][:, li] = vf[dofs[0]] + xc * om * s, vf[dofs[1]] - xc * om * c
            out["ax"][:, li] = af[dofs[0]] + xc * (al * s + om * om * c)
            out["ay"][:, li] = af[dofs[1]] - xc * (al * c - om * om * s)
            continue
        ds, de = cm.link_ends(li)
        c, cd, cdd = qf[de] - qf[ds], vf[de] - vf[ds], af[de] - af[ds]
        l2 = (c ** 2).sum(0)
        g = np.array([-c[1], c[0]]) / l2
        om = (g * cd).sum(0)
        out["phi"][:, li] = np.unwrap(np.arctan2(c[1], c[0]))
        out["omega"][:, li] = om
        out["alpha"][:, li] = (g * cdd).sum(0) - 2 * (c * cd).sum(0) * om / l2
        out["ox"][:, li], out["oy"][:, li] = qf[ds]
        out["vx"][:, li], out["vy"][:, li] = vf[ds]
        out["ax"][:, li], out["ay"][:, li] = af[ds]
    return LinkMotion(**out)


def body_angles(cm: CoupledModel, qf, vf, af, chord: LinkMotion) -> dict:
    """{body name: (3, nf)} frame angle (unwrapped), rate and acceleration of every body: a link's
    chord (flexible) or frame (rigid), a rigid body's frame."""
    mech = cm.case.mechanism
    out = {}
    for bi, body in enumerate(mech.bodies):
        if body.kind == "link":
            li = mech.link_index(body.name)
            out[body.name] = np.array([chord.phi[:, li], chord.omega[:, li], chord.alpha[:, li]])
        else:
            d = cm.body_of(bi)[1][2]
            out[body.name] = np.array([np.unwrap(qf[d]), vf[d], af[d]])
    return out


def _th(d, n: int, k: int) -> int:
    """All-DOF number of the rotation of node k (0..n) in a segment's local vector d (0-based layout
    [xs ys xe ye th_0 (p_k v_k th_k)_{k=1..n-1} th_n])."""
    return d[3 * n + 2] if k == n else d[3 * k + 4]


def node_state(cm: CoupledModel, qf, li: int, k: int):
    """Total position (2, nf) and tangent angle (nf,) of mesh node k of flexible link li."""
    si, kk = cm.node_segment(li, k)
    d, n = cm.seg_slice(si), int(cm.n_el[si])
    c = qf[d[2:4]] - qf[d[0:2]]
    phi = np.arctan2(c[1], c[0])
    _, k0, k1 = cm.segments[si]
    f = cm.fracs[li]
    w = (f[k] - f[k0]) / (f[k1] - f[k0])
    p, v = (qf[d[3 * kk + 2]], qf[d[3 * kk + 3]]) if 0 < kk < n else (0.0, 0.0)
    cs, sn = np.cos(phi), np.sin(phi)
    pos = (1 - w) * qf[d[0:2]] + w * qf[d[2:4]] + np.array([cs * p - sn * v, sn * p + cs * v])
    return pos, phi + qf[_th(d, n, kk)]


def deviation(cm: CoupledModel, qf, ref: LinkMotion) -> np.ndarray:
    """Displacement from the rigid-body solution in the layout of ``cm.mesh`` (ndof, nf): node
    translations = total position - rigid-body-solution position; rotations = total tangent angle -
    rigid-body-solution link angle (principal value)."""
    mesh = cm.mesh
    u = np.zeros((mesh.ndof, qf.shape[1]))
    for li, ln in enumerate(cm.case["links"]):
        if cm.fracs[li] is None:
            continue
        L = ln["length"]
        cr, sr = np.cos(ref.phi[:, li]), np.sin(ref.phi[:, li])
        for k, f in enumerate(cm.fracs[li]):
            pos, psi = node_state(cm, qf, li, k)
            node = mesh.node_of[li][k]
            u[mesh.trans_dof[node]] = pos - np.array([ref.ox[:, li] + f * L * cr, ref.oy[:, li] + f * L * sr])
            dphi = psi - ref.phi[:, li]
            u[mesh.rot_dof[(node, li)]] = np.arctan2(np.sin(dphi), np.cos(dphi))
    return u


# ----------------------------------------------------------------------------- elastic fields
def _element_parts(cm: CoupledModel, li: int, frac: float) -> list:
    """(segment, element within it, xi) of the element(s) at fraction frac of link li (both elements at
    an interior mesh node)."""
    f = cm.fracs[li]
    n_link = f.size - 1
    k = int(np.argmin(np.abs(f - frac)))
    if abs(f[k] - frac) < 1e-9:
        parts = [(kk, xi) for kk, xi in ((k - 1, 1.0), (k, 0.0)) if 0 <= kk < n_link]
    else:
        e = min(int(np.searchsorted(f, frac, side="right")) - 1, n_link - 1)
        parts = [(e, (frac - f[e]) / (f[e + 1] - f[e]))]
    out = []
    for e, xi in parts:
        out.append((*cm.element_segment(li, e), xi))
    return out


def curvature(cm: CoupledModel, qf, li: int, frac: float) -> np.ndarray:
    """Curvature [1/m] of flexible link li at frac of its length, from the chord-frame elastic DOFs
    (the mean of the two elements at an interior mesh node)."""
    out = 0.0
    parts = _element_parts(cm, li, frac)
    for si, e, xi in parts:
        d, n = cm.seg_slice(si), int(cm.n_el[si])
        loc = np.zeros((6, qf.shape[1]))
        for j, kk in enumerate((e, e + 1)):
            if 0 < kk < n:
                loc[3 * j], loc[3 * j + 1] = qf[d[3 * kk + 2]], qf[d[3 * kk + 3]]
            loc[3 * j + 2] = qf[_th(d, n, kk)]
        _, k0, _ = cm.segments[si]
        le = cm.case["links"][li]["length"] * (cm.fracs[li][k0 + e + 1] - cm.fracs[li][k0 + e])
        out = out + kernels.element_curvatures(loc, np.zeros(qf.shape[1]), le, xi)
    return out / len(parts)


def axial_forces(cm: CoupledModel, qf) -> np.ndarray:
    """(nel, nf) axial force [N] of every element of the mesh (flexible links in order): EA times the
    chord stretch of its segment plus its elastic axial strain; in the nonlinear model (one element
    per segment) plus the element's mean w'^2/2 from its end angles th (docs/theory.md 12.4)."""
    out = np.empty((cm.mesh.nel, qf.shape[1]))
    for si, (li, k0, k1) in enumerate(cm.segments):
        d, n = cm.seg_slice(si), int(cm.n_el[si])
        L = cm.case["links"][li]["length"]
        f = cm.fracs[li]
        ls = L * (f[k1] - f[k0])
        ea = cm.case["links"][li]["youngs_modulus"] * cm.case["links"][li]["area"]
        eps_c = np.hypot(*(qf[d[2:4]] - qf[d[0:2]])) / ls - 1.0
        if cm.split:
            t0, t1 = qf[_th(d, n, 0)], qf[_th(d, n, 1)]
            eps_c = eps_c + (4.0 * t0 * t0 - 2.0 * t0 * t1 + 4.0 * t1 * t1) / 60.0
        els = cm.mesh.link_elements(li)
        for e in range(n):
            p1 = qf[d[3 * e + 2]] if 0 < e < n else 0.0
            p2 = qf[d[3 * (e + 1) + 2]] if 0 < e + 1 < n else 0.0
            out[els[k0 + e]] = ea * (eps_c + (p2 - p1) / (L * (f[k0 + e + 1] - f[k0 + e])))
    return out


# ----------------------------------------------------------------------------- joints
def joint_angles(cm: CoupledModel, qf) -> dict:
    """{joint: coordinate (nf,)} measured at the joint's markers (the tangent angles of flexible links
    there; a guided joint's slide), angles unwrapped in time."""
    zeros = np.zeros_like(qf)
    rows = [jm.coordinate for jm in cm.joints.values()]
    mv = cm.post(qf, zeros, zeros, np.zeros((max(1, len(cm.rows)), qf.shape[1])), np.zeros(qf.shape[1]),
                 rows)["measures"]
    return {name: (np.unwrap(mv[0, i]) if jm.coordinate.kind == CON_ANGLE else mv[0, i])
            for i, (name, jm) in enumerate(cm.joints.items())}


def joint_coordinate(cm: CoupledModel, fr: ModelFrames, name: str) -> np.ndarray:
    """(3, nf) [coordinate, rate, acceleration] of a joint in the model: the relative frame angle of its
    bodies (a flexible link's chord), unwrapped, or a guided joint's slide along its guide."""
    jm = cm.joints[name]
    if jm.guided:
        return fr.measure(jm.coordinate)
    mech = cm.case.mechanism
    a, b = mech.joint_points(mech.joint(name))
    val = np.zeros((3, fr.t.size))
    for p, sign in ((b, 1.0), (a, -1.0)):
        if p.body is not None:
            val = val + sign * fr.angles[p.body.name]
    return val


def joint_at_joint(cm: CoupledModel, fr: ModelFrames, rm, name: str) -> np.ndarray:
    """(3, nf) [coordinate, rate, acceleration] of a joint measured at the joint, as its constraint rows
    and drive measure it: the relative angle of the two bodies' tangents there (a flexible link's, a
    rigid body's frame), unwrapped and on the rigid-body solution's turn at the first frame, or a
    guided joint's slide.  A kinematic drive's law, exactly, for a driven joint."""
    jm = cm.joints[name]
    val = np.array(fr.measure(jm.coordinate), float)
    if not jm.guided:
        val[0] = np.unwrap(val[0])
        val[0] += 2 * np.pi * np.round((rm.joint(name)[0, 0] - val[0, 0]) / (2 * np.pi))
    return val


def joint_output(cm: CoupledModel, fr: ModelFrames, rm, name: str) -> np.ndarray:
    """(3, nf) a joint's ``joint_*`` outputs: a kinematically driven joint at the joint (its law), any
    other the model's rigid coordinate (:func:`joint_coordinate`: its bodies' chords and frames; a
    guided joint's slide), the turn aligned with the rigid-body solution's at the first frame."""
    drive = cm.case.mechanism.drive_of(name)
    if drive is not None and drive.kinematic:
        return joint_at_joint(cm, fr, rm, name)
    val = np.array(joint_coordinate(cm, fr, name), float)
    if not cm.joints[name].guided:
        val[0] = np.unwrap(val[0])
        val[0] += 2 * np.pi * np.round((rm.joint(name)[0, 0] - val[0, 0]) / (2 * np.pi))
    return val


def _lam(fr: ModelFrames, jm, role: str) -> np.ndarray:
    return fr.lf[jm.rows[role]] if role in jm.rows else np.zeros(fr.t.size)


def reaction(cm: CoupledModel, fr: ModelFrames, name: str) -> np.ndarray:
    """(nf, 3) [F_x, F_y, M] that body a exerts on body b at the joint in the model (global components
    [N], moment [N m]): from the multipliers of its rows, or, where the joint shares its position DOFs,
    from the residual of the bodies on b's side at the shared node."""
    jm = cm.joints[name]
    out = np.zeros((fr.t.size, 3))
    if jm.own:
        pos = [fr.post["markers"][:2, m].T for m in jm.markers]
        own = cm.case.mechanism.joint(name).reaction_from(np.stack([_lam(fr, jm, r) for r in jm.own], 1), *pos)
        if own is not None:
            return own
    if jm.guided:
        psi = fr.post["markers"][2, jm.markers[0]]
        c, s = np.cos(psi), np.sin(psi)
        u = np.array([c * jm.axis[0] - s * jm.axis[1], s * jm.axis[0] + c * jm.axis[1]])
        n = np.array([-u[1], u[0]])
        out[:, :2] = (-_lam(fr, jm, "normal") * n - _lam(fr, jm, "hold") * u).T
        out[:, 2] = -_lam(fr, jm, "angle")
        return out
    if jm.shared is not None:
        out[:, :2] = _shared_force(cm, fr, jm).T
    else:
        out[:, 0], out[:, 1] = _lam(fr, jm, "x"), _lam(fr, jm, "y")
    out[:, 2] = -_lam(fr, jm, "angle") - _lam(fr, jm, "hold")
    return out


class FrameReactions:
    """The model's joint reactions over one block's frames (``Result.reactions`` of a coupled block):
    ``self(joint)`` (nf, 3) as :func:`reaction`.  A part of the block (:meth:`over` with ``sel``) keeps
    them; a join of blocks has none (the multipliers of the frames are not kept)."""

    def __init__(self, cm: CoupledModel, fr: ModelFrames | None, arrays: dict | None = None):
        self.cm, self.fr, self.arrays = cm, fr, {} if arrays is None else arrays

    def __call__(self, name: str) -> np.ndarray:
        if name not in self.arrays:
            self.arrays[name] = reaction(self.cm, self.fr, name)
        return self.arrays[name]

    def over(self, res, sel=None):
        if sel is None:
            return None
        return FrameReactions(self.cm, None, {name: self(name)[sel] for name in self.cm.joints})


def _shared_force(cm: CoupledModel, fr: ModelFrames, jm) -> np.ndarray:
    """(2, nf) force on b's side at a shared node: the sum of the segment-end residuals of the links
    that joints at this node connect to b without this joint (or minus a's side when b's reaches the
    ground)."""
    mech = cm.case.mechanism
    edges = []
    for other in cm.joints.values():
        if other.shared == jm.shared and other.name != jm.name:
            a, b = mech.joint_points(mech.joint(other.name))
            edges.append((_side(mech, a), _side(mech, b)))
    a, b = mech.joint_points(mech.joint(jm.name))
    sign, side = 1.0, _component(_side(mech, b), edges)
    if None in side:
        sign, side = -1.0, _component(_side(mech, a), edges)
    tot = np.zeros((2, fr.t.size))
    for si, end in cm.node_ends[jm.shared]:
        if cm.segments[si][0] in side:
            tot += fr.post["ends"][2 * end:2 * end + 2, si]
    return sign * tot


def _side(mech, p):
    return None if p.body is None else mech.link_index(p.body.name)


def _component(start, edges) -> set:
    seen, todo = {start}, [start]
    while todo:
        x = todo.pop()
        for a, b in edges:
            for y, z in ((a, b), (b, a)):
                if y == x and z not in seen:
                    seen.add(z)
                    todo.append(z)
    return seen


def drive_force(cm: CoupledModel, fr: ModelFrames, name: str) -> np.ndarray:
    """(nf,) the torque [N m] or force [N] the drive of joint ``name`` applies on its coordinate: a
    kinematic drive's constraint force (-lambda), a force drive's law at the model's coordinate plus the
    outputs of the controllers acting through it."""
    jm = cm.joints[name]
    if jm.force is not None:      # (with the outputs of the controllers acting through it)
        return fr.post["forces"][jm.force] + cm.control_effort(name, fr.t.size)
    return -fr.lf[jm.rows["drive"]]


# ----------------------------------------------------------------------------- outputs
def evaluate(cm: CoupledModel, specs: dict, fr: ModelFrames, rm, ref: LinkMotion, u_dev, axial,
             superposition_fe=None, z_ref=None, run_loads=None) -> dict:
    """Every named output over the model's frames; rm the rigid-body solution at the frames (its
    reactions for ``source = "rigid"``, its positions for displacements), ref its LinkMotion;
    superposition_fe: callable giving the FE model (inertia loads only); run_loads: the superposition
    family an inertia load of model "run" means (the run's Family.inertia_loads); z_ref (nf, n) the rigid
    mechanism at the model's own coordinates (deflections; None: rm, every degree of freedom driven)."""
    out = {}
    for name, sp in specs.items():
        kind = sp["kind"]
        if kind in ("joint_angle", "joint_displacement", "joint_speed", "joint_acceleration"):
            k = {"joint_angle": 0, "joint_displacement": 0, "joint_speed": 1, "joint_acceleration": 2}[kind]
            at_joint = sp.get("measure", "frames") == "joint"
            out[name] = (joint_at_joint if at_joint else joint_output)(cm, fr, rm, sp["joint"])[k].copy()
        elif kind == "link_angle":
            out[name] = np.unwrap(fr.chord.phi[:, cm.mesh.link_names.index(sp["link"])])
        elif kind in ("strain", "curvature"):
            li = cm.mesh.link_names.index(sp["link"])
            kap = curvature(cm, fr.qf, li, sp["at"])
            out[name] = kap * cm.case["links"][li]["half_depth"] if kind == "strain" else kap
        elif kind == "axial_force":
            out[name] = axial_output(cm.mesh, axial, sp, name)
        elif kind in ("displacement", "deflection", "position"):
            out[name] = _point_output(cm, fr, rm, sp, name, z_ref)
        elif kind == "inertia_load":
            fe = superposition_fe()
            model = run_loads if sp["model"] == "run" else sp["model"]
            rig = np.asfortranarray(np.stack([fr.chord.phi, fr.chord.omega, fr.chord.alpha,
                                              fr.chord.ax - cm.case["loads"]["gravity"][0],
                                              fr.chord.ay - cm.case["loads"]["gravity"][1]]).transpose(0, 2, 1))
            out[name] = load_output(fe, fe.loads(rig, model), sp, name)
        elif kind == "reaction":
            r = rm.reaction(sp["joint"]) if sp.get("source", "model") == "rigid" else reaction(cm, fr, sp["joint"])
            out[name] = {"x": r[:, 0], "y": r[:, 1], "moment": r[:, 2],
                         "magnitude": np.hypot(r[:, 0], r[:, 1])}[sp["component"]].copy()
        elif kind == "drive_force":
            out[name] = drive_force(cm, fr, sp["joint"])
        else:  # pragma: no cover - the case validator only admits the kinds above
            raise AssertionError(kind)
    return out


def _point_output(cm: CoupledModel, fr: ModelFrames, rm, sp: dict, name: str, z_ref=None) -> np.ndarray:
    """Position of a named point of a body in the model, or its displacement from the rigid-body
    solution (``displacement``) or from the rigid mechanism at the model's coordinates z_ref
    (``deflection``): x, y; axial, transverse in that configuration's link frame; rotation of a link's
    tangent from its angle there."""
    mk = cm.output_marker(sp["at"], f"outputs.{name}.at")
    if mk >= fr.post["markers"].shape[1]:
        raise AssertionError("output markers are added before the run")
    st = fr.post["markers"][:, mk]
    if sp["kind"] == "position":
        return st["xy".index(sp["component"])].copy()
    z = z_ref if sp["kind"] == "deflection" and z_ref is not None else rm.z
    pos, phi = point_state(cm.case.mechanism, z, cm.case.mechanism.point(sp["at"]))
    return point_components(st[0:2] - pos, wrap_angle(st[2] - phi), phi, sp["component"])


# ----------------------------------------------------------------------------- diagnostics
class _Continuous:
    """Angle series that continue from block to block: each new piece is unwrapped from the end of
    the previous one (a piece may start with the previous piece's last sample again)."""

    def __init__(self):
        self._last = {}      # key -> (last sample as given, last continuous value)

    def __call__(self, key, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float)
        if key in self._last:
            raw, cont = self._last[key]
            y = np.unwrap(np.r_[raw, x])
            y = y[1:] - y[0] + cont
        else:
            y = np.unwrap(x)
        self._last[key] = (float(x[-1]), float(y[-1]))
        return y


class Diagnostics:
    """Energy balance, Newton statistics, link-length drift, constraint satisfaction and the drift of
    the joint coordinates from the rigid-body solution, accumulated over a run's blocks of frames
    (:meth:`add` per block, in order; :meth:`summary` for summary.json's ``coupled`` entry)."""

    def __init__(self, cm: CoupledModel):
        self.cm = cm
        self.e0 = None
        self.energy_drift, self.scale = 0.0, 1e-300
        self.final_kinetic = self.final_work = 0.0
        self.iterations, self.max_iterations, self.factorizations = 0, 0, 0
        self.stretch = 0.0
        self.violation = {"point_m": 0.0, "guide_normal_m": 0.0, "angle_rad": 0.0, "slide_m": 0.0}
        self.drift: dict[str, dict] = {}
        self._turns = {}                  # joint -> whole turns removed from its drift (set at the first frame)
        self._cont = _Continuous()

    def add(self, fr: ModelFrames, ef, rm, iters: int, cval) -> None:
        """One block: its frames fr, energies ef (4, nf), rigid motion rm and constraint values cval
        (3, nc, nf) at those frames, and the Newton iterations of its steps."""
        cm = self.cm
        e = ef[0] + ef[1] - ef[2]
        if self.e0 is None:
            self.e0 = float(e[0])
        self.energy_drift = max(self.energy_drift, float(np.max(np.abs(e - self.e0))))
        self.scale = max(self.scale, float(np.max(np.abs(ef[0]))), float(np.max(np.abs(ef[2]))))
        self.final_kinetic, self.final_work = float(ef[0, -1]), float(ef[2, -1])
        self.iterations += int(iters)
        self.factorizations += int((cm.last_run or {}).get("factorizations", 0))
        self.max_iterations = max(self.max_iterations, int(np.max(ef[3])))
        for si, (li, k0, k1) in enumerate(cm.segments):
            d = cm.seg_slice(si)
            ls = cm.case["links"][li]["length"] * (cm.fracs[li][k1] - cm.fracs[li][k0])
            self.stretch = max(self.stretch, float(np.max(np.abs(np.hypot(*(fr.qf[d[2:4]] - fr.qf[d[0:2]])) / ls - 1.0))))
        for k, v in constraint_violation(cm, fr, cval).items():
            self.violation[k] = max(self.violation.get(k, 0.0), v)
        self._add_drift(fr, rm)

    def _add_drift(self, fr: ModelFrames, rm) -> None:
        cm = self.cm
        tangents = joint_angles(cm, fr.qf)
        for name, jm in cm.joints.items():
            mod = joint_coordinate(cm, fr, name)[0]
            rig = rm.joint(name)[:, 0]
            d = self.drift.setdefault(name, {})
            if jm.guided:
                d["max_abs_m"] = max(d.get("max_abs_m", 0.0), float(np.max(np.abs(mod - rig))))
                d["final_m"] = float(mod[-1] - rig[-1])
                continue
            rig_c = self._cont(("rigid", name), rig)
            dth = self._cont(("model", name), mod) - rig_c
            dhub = self._cont(("tangent", name), tangents[name]) - rig_c
            if name not in self._turns:
                self._turns[name] = (2 * np.pi * np.round(dth[0] / (2 * np.pi)), 2 * np.pi * np.round(dhub[0] / (2 * np.pi)))
            dth, dhub = dth - self._turns[name][0], dhub - self._turns[name][1]
            d["max_abs_rad"] = max(d.get("max_abs_rad", 0.0), float(np.max(np.abs(dth))))
            d["final_rad"] = float(dth[-1])
            d["at_joint_tangents_max_abs_rad"] = max(d.get("at_joint_tangents_max_abs_rad", 0.0),
                                                     float(np.max(np.abs(dhub))))

    def summary(self, nsteps: int) -> dict:
        viol = dict(self.violation)
        return {"energy_balance": {"max_abs_drift_J": self.energy_drift, "relative_drift": self.energy_drift / self.scale,
                                   "final_kinetic_J": self.final_kinetic, "final_work_J": self.final_work},
                "newton": {"iterations": self.iterations, "mean_per_step": self.iterations / max(nsteps, 1),
                           "max_per_step": self.max_iterations, "factorizations": self.factorizations,
                           "factorizations_per_step": self.factorizations / max(nsteps, 1)},
                "solver": self.cm.solver,
                "link_length_drift": {"max_relative": self.stretch, "bound": 1e-3, "within_bound": self.stretch < 1e-3},
                "joint_closure_error_m": max(viol["point_m"], viol["guide_normal_m"]),
                "constraint_violation": viol,
                "rigid_drift_from_rigid_body_solution": {k: dict(v) for k, v in self.drift.items()}}


def constraint_violation(cm: CoupledModel, fr: ModelFrames, cval) -> dict:
    """Largest |g - value| over the frames of the constraint rows by kind: point coincidence and guide
    normal [m], angles [rad] (welds, held joints, kinematic drives, a nonlinear link's interior
    nodes), slides [m] (kinematic drives and locked guided joints), and any other row kind under its
    name and unit (mechanism.rows: e.g. ``<name>_m``)."""
    out = {"point_m": 0.0, "guide_normal_m": 0.0, "angle_rad": 0.0, "slide_m": 0.0}
    for i, r in enumerate(cm.rows):
        err = residual(r.kind, r.d, fr.post["measures"][0, i] - cval[0, i])
        key = {CON_POINT: "point_m", CON_ANGLE: "angle_rad"}.get(r.kind,
                                                                  "guide_normal_m" if r.role == "normal" else "slide_m")
        if r.kind not in (CON_POINT, CON_ANGLE, CON_PROJECTION):     # another row kind: its name and unit
            name, unit, _ = ROW_KINDS[r.kind]
            key = f"{name}_{unit}"
        out[key] = max(out.get(key, 0.0), float(np.max(np.abs(err))))
    return out


def multiplier_alternation(cm: CoupledModel, la, lf, t, columns: dict) -> dict:
    """The step-to-step alternation of a block's multipliers (the kernel's ``la``: per row and frame
    the largest alternating part since the last frame, fortran/flexmech_alternation.f90) for the run's
    alternation check (flexmech_py/checks/alternation.py): per joint row ``"joint.role"`` its unit, largest
    alternating part, the frame time of it and the row's largest |multiplier| at the frames; and, per
    output column built on a joint's multipliers (a kinematic drive's force, a joint reaction from its
    rows), that joint.  ``columns``: the block's column names of the automatic drive columns, by joint."""
    rows = {}
    for i, r in enumerate(cm.rows):
        if r.joint is None or la.shape[1] == 0:
            continue
        k = int(np.argmax(la[i]))
        rows[f"{r.joint}.{r.role}"] = {"joint": r.joint, "unit": "N m" if r.kind == CON_ANGLE else "N",
                                       "amplitude": float(la[i, k]), "t": float(t[k]),
                                       "peak": float(np.max(np.abs(lf[i])))}
    built = dict(columns)
    for name, sp in cm.case["outputs"].items():
        if sp["kind"] == "drive_force" or (sp["kind"] == "reaction" and sp.get("source", "model") == "model"
                                           and cm.joints[sp["joint"]].shared is None):
            built[name] = sp["joint"]
    return {"rows": rows, "columns": built}
