"""Named outputs of a run, evaluated from the elastic frames and the rigid motion.

Every output kind is documented in ``docs/cases.md``; docs/theory.md section 8.1 says what each
means in each model family: a kinematically driven joint reads its law, other joints the model's
rigid coordinates (here the rigid-body solution's frames), a link angle is its chord's,
``displacement`` is measured from the rigid-body solution and ``deflection`` from the rigid
mechanism at the model's own joint coordinates.  The coupled and nonlinear models evaluate the same
kinds on their frames (flexmech_py.models.constrained.outputs).
Strains are the
bending strain ``eps = c * kappa`` with ``kappa = v''`` the curvature of the
element's Hermite field in the link frame and ``c`` the link's half depth
(the strain of the fibre at ``eta = -c``); at an interior mesh node the
curvature is averaged over the two elements that meet there.
"""

from __future__ import annotations

import copy

import numpy as np

from ...base import kernels
from ...case import UNITS
from ...base.errors import CaseError
from ...mechanism.placement import Placement, point_state

__all__ = ["evaluate_outputs", "output_unit", "point_components", "wrap_angle", "joint_at_joint",
           "DeflectionReference"]


def output_unit(spec: dict, case: dict) -> str:
    """The unit of an output (a joint's outputs take its coordinate's unit: rad or m)."""
    kind = spec["kind"]
    if kind in UNITS:
        return UNITS[kind]
    if kind in ("joint_speed", "joint_acceleration", "drive_force"):
        angular = case.mechanism.joint(spec["joint"]).angular
        return {"joint_speed": ("rad/s", "m/s"), "joint_acceleration": ("rad/s^2", "m/s^2"),
                "drive_force": ("N m", "N")}[kind][0 if angular else 1]
    comp = spec["component"]
    if kind in ("displacement", "deflection"):
        return "rad" if comp == "rotation" else "m"
    if kind == "reaction":
        return "N m" if comp == "moment" else "N"
    return "N m" if comp == "rotation" else "N"  # inertia_load


class DeflectionReference:
    """A run's reference configuration of its ``deflection`` outputs, block after block: the rigid
    mechanism at the model's own generalized coordinates (the primary joints' coordinates measured at
    the joints; flexmech_py.mechanism.placement).  None (the rigid-body solution is that configuration)
    when the case has no deflection output or every degree of freedom is driven kinematically."""

    def __init__(self, case, setup):
        needed = setup.mode == "dynamic" and any(sp["kind"] == "deflection" for sp in case["outputs"].values())
        self.placement = Placement(setup) if needed else None
        self.primary = setup.primary

    def fresh(self) -> "DeflectionReference":
        """The reference of a new run (its placement started again), without building it again."""
        other = copy.copy(self)
        other.placement = None if self.placement is None else self.placement.restarted()
        return other

    def __call__(self, t, coordinate):
        """z (nf, n) at the frames t; ``coordinate(joint)`` the model's (nf,) coordinate of a primary joint."""
        if self.placement is None:
            return None
        return self.placement(t, np.column_stack([coordinate(p) for p in self.primary]))


def link_curvature(fe, u_all: np.ndarray, phi: np.ndarray, li: int, frac: float) -> np.ndarray:
    """Curvature v'' [1/m] of link ``li`` at ``frac`` of its length over the frames.

    u_all (ndof, nf) elastic DOFs; phi (nf,) rigid link angle.
    """
    els = fe.link_elements(li)
    parts = [(els[e], xi) for e, xi in _element_at(fe, li, frac)]
    kap = 0.0
    for e, xi in parts:
        dglob = u_all[fe.el_dof[:, e] - 1]
        kap = kap + kernels.element_curvatures(dglob, phi, fe.el_prop[0, e], xi)
    return kap / len(parts)


def link_node_curvatures(fe, u_all: np.ndarray, phi: np.ndarray, li: int) -> np.ndarray:
    """(n+1, nf) curvature v'' [1/m] at every mesh node of link ``li`` (n elements) over the frames:
    what :func:`link_curvature` gives node by node (the mean of the two elements at an interior
    node), with one kernel call per distinct element length."""
    els = fe.link_elements(li)
    n, nf = els.size, u_all.shape[1]
    d = u_all[fe.el_dof[:, els] - 1]                       # (6, n, nf)
    ends = np.empty((2, n, nf))                            # curvature at xi = 0 and xi = 1 of each element
    lengths = fe.el_prop[0, els]
    for length in np.unique(lengths):
        idx = np.flatnonzero(lengths == length)
        sub = d[:, idx, :].reshape(6, idx.size * nf)
        ph = np.tile(phi, idx.size)
        for j, xi in enumerate((0.0, 1.0)):
            ends[j, idx] = kernels.element_curvatures(sub, ph, float(length), xi).reshape(idx.size, nf)
    out = np.empty((n + 1, nf))
    out[0], out[n] = ends[0, 0], ends[1, n - 1]
    out[1:n] = 0.5 * (ends[1, :n - 1] + ends[0, 1:])
    return out


def _element_at(fe, li: int, frac: float) -> list[tuple[int, float]]:
    """[(element index along link li, xi)] at fraction ``frac``: both elements at an interior node (xi 1 and
    0), else the element containing it."""
    f = fe.node_frac[li]
    n = f.size - 1
    if fe.uniform[li]:
        s = frac * n
        k = int(round(s))
        at_node = abs(s - k) < 1e-9
    else:
        k = int(np.argmin(np.abs(f - frac)))
        at_node = abs(f[k] - frac) < 1e-9
    if at_node:   # at a node: the elements that meet there
        return [(e, xi) for e, xi in ((k - 1, 1.0), (k, 0.0)) if 0 <= e < n]
    if fe.uniform[li]:
        e = min(int(np.floor(s)), n - 1)
        return [(e, s - e)]
    e = int(np.clip(np.searchsorted(f, frac) - 1, 0, n - 1))
    return [(e, (frac - f[e]) / (f[e + 1] - f[e]))]


def evaluate_outputs(fe, specs: dict, u_all: np.ndarray, motion, rig_frames, run_model: str, rm=None,
                     load_cache: dict | None = None, axial=None, rates=None, reactions=None,
                     z_ref=None) -> dict[str, np.ndarray]:
    """Evaluate every named output over the frames.

    u_all (ndof, nf) elastic DOFs (displacements from the rigid motion ``motion``, a LinkMotion);
    rig_frames (5, nlinks, nf) the kernel rigid samples (for inertia loads); rm the RigidMotion at the
    frames (joint coordinates, reactions, drive forces of the rigid-body solution);
    axial: (nel, nf) element axial forces [N] for ``axial_force`` outputs; rates: (v_all, a_all) the
    elastic velocities and accelerations (a guided joint's elastic slide adds to its rigid one);
    reactions: callable(joint) -> (nf, 3) the model's joint reactions (``source = "model"``; without
    it the rigid-body reactions); z_ref (nf, n): the rigid mechanism at the model's coordinates (the
    reference of ``deflection``; None: the rigid-body solution rm, every degree of freedom driven).
    """
    out = {}
    loads = {} if load_cache is None else load_cache
    links = fe.case["links"]
    for name, sp in specs.items():
        kind = sp["kind"]
        if kind in ("joint_angle", "joint_displacement", "joint_speed", "joint_acceleration"):
            k = {"joint_angle": 0, "joint_displacement": 0, "joint_speed": 1, "joint_acceleration": 2}[kind]
            if sp.get("measure", "frames") == "joint":
                out[name] = joint_at_joint(fe, rm, sp["joint"], k, u_all, rates)
            else:
                out[name] = rm.joint(sp["joint"])[:, k] + _elastic_slide(fe, sp["joint"], k, u_all, rates)
        elif kind == "link_angle":
            out[name] = np.unwrap(_chord_angle(fe, u_all, motion, fe.link_names.index(sp["link"])))
        elif kind in ("strain", "curvature"):
            li = fe.link_names.index(sp["link"])
            kap = link_curvature(fe, u_all, motion.phi[:, li], li, sp["at"])
            out[name] = kap * links[li]["half_depth"] if kind == "strain" else kap
        elif kind == "axial_force":
            out[name] = axial_output(fe, axial, sp, name)
        elif kind in ("displacement", "deflection", "position"):
            out[name] = _point_output(fe, u_all, motion, sp, name, rm, z_ref)
        elif kind == "inertia_load":
            model = run_model if sp["model"] == "run" else sp["model"]
            if model not in loads:
                loads[model] = fe.loads(rig_frames, model)
            out[name] = load_output(fe, loads[model], sp, name)
        elif kind == "reaction":
            model_source = sp.get("source", "model") == "model" and reactions is not None
            r = reactions(sp["joint"]) if model_source else rm.reaction(sp["joint"])
            out[name] = {"x": r[:, 0], "y": r[:, 1], "moment": r[:, 2],
                         "magnitude": np.hypot(r[:, 0], r[:, 1])}[sp["component"]].copy()
        elif kind == "drive_force":
            out[name] = rm.drive_force(sp["joint"]).copy()
        else:  # pragma: no cover - the case validator only admits the kinds above
            raise AssertionError(kind)
    return out


def axial_output(fe, axial, sp: dict, name: str) -> np.ndarray:
    if axial is None:
        raise CaseError(f"outputs.{name}", "axial forces are not available for this model")
    li = fe.link_names.index(sp["link"])
    els = fe.link_elements(li)
    at = _element_at(fe, li, sp["at"])
    return sum(axial[els[e]] for e, _ in at) / len(at)


def _elastic_slide(fe, joint: str, k: int, u_all, rates) -> np.ndarray | float:
    """A guided joint's elastic slide (k = 0), its rate (1) or acceleration (2): the along DOF; 0 for
    other joints."""
    dof = next((sl.dof for sl in getattr(fe, "slides", ()) if sl.joint.name == joint), None)
    if dof is None:
        return 0.0
    x = u_all if k == 0 else (None if rates is None else rates[k - 1])
    return 0.0 if x is None else x[dof]


def joint_at_joint(fe, rm, name: str, k: int, u_all, rates=None) -> np.ndarray:
    """A joint's coordinate (k = 0), rate (1) or acceleration (2) measured at the joint (the reference of
    ``deflection``): the rigid-body solution's plus the elastic part there (the relative elastic rotation
    of the two bodies at a revolute or weld joint, zero where they share it; a guided joint's
    elastic slide)."""
    mech = fe.case.mechanism
    j = mech.joint(name)
    if j.guided:
        return rm.joint(name)[:, k] + _elastic_slide(fe, name, k, u_all, rates)
    x = u_all if k == 0 else (None if rates is None else rates[k - 1])
    ra, rb = (fe.rotation_dof(p) for p in mech.joint_points(j))
    if x is None:
        return rm.joint(name)[:, k].copy()
    return rm.joint(name)[:, k] + (0.0 if rb is None else x[rb]) - (0.0 if ra is None else x[ra])


def _chord_angle(fe, u_all, motion, li: int) -> np.ndarray:
    """(nf,) angle [rad] of link li's chord, the line through its end points (a rigid link: its frame,
    turned by its small elastic rotation)."""
    phi = motion.phi[:, li]
    name = fe.link_names[li]
    if name in getattr(fe, "parts", {}):
        return phi + u_all[fe.parts[name].dofs[2]]
    du = u_all[fe.trans_dof[fe.node_of[li][-1]]] - u_all[fe.trans_dof[fe.node_of[li][0]]]
    c, s = np.cos(phi), np.sin(phi)
    return phi + np.arctan2(-s * du[0] + c * du[1], fe.case["links"][li]["length"] + c * du[0] + s * du[1])


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles [rad] in (-pi, pi]."""
    return np.arctan2(np.sin(a), np.cos(a))


def point_components(d: np.ndarray, rot: np.ndarray, phi: np.ndarray, comp: str) -> np.ndarray:
    """One component of a point's displacement d (2, nf) and rotation rot (nf,): ``x``, ``y``, ``axial``
    and ``transverse`` along and across the frame angle phi (nf,), ``rotation``."""
    if comp == "rotation":
        return np.array(rot, float)
    c, s = np.cos(phi), np.sin(phi)
    return {"x": d[0], "y": d[1], "axial": c * d[0] + s * d[1], "transverse": -s * d[0] + c * d[1]}[comp].copy()


def _rigid_point_motion(fe, u_all, rm, part, ref):
    """Rigid position (2, nf), small displacement d + dtheta z x s (2, nf), rotation dtheta and frame angle
    of a point of a rigid link or body."""
    mech = fe.case.mechanism
    pos, phi = point_state(mech, rm.z, ref)
    i = 3 * mech.body_index(part.body)
    sx, sy = pos[0] - rm.z[:, i], pos[1] - rm.z[:, i + 1]
    dx, dy, dth = (u_all[d] for d in part.dofs)
    frame = phi if part.body.kind == "link" else np.zeros_like(phi)
    return pos, np.array([dx - sy * dth, dy + sx * dth]), dth, frame


def _point_output(fe, u_all, motion, sp: dict, name: str, rm=None, z_ref=None) -> np.ndarray:
    """Position, displacement or deflection of a node or of a rigid link's or body's point."""
    kind, where = fe.point_ref(sp["at"], f"outputs.{name}.at")
    if kind == "rigid":
        pos, d, rot, phi = _rigid_point_motion(fe, u_all, rm, *where)
    else:
        li, node, zeta = where
        phi = motion.phi[:, li]
        pos = np.array([motion.ox[:, li] + zeta * np.cos(phi), motion.oy[:, li] + zeta * np.sin(phi)])
        d, rot = u_all[fe.trans_dof[node]], u_all[fe.rot_dof[(node, li)]]
    if sp["kind"] == "position":
        return (pos + d)["xy".index(sp["component"])]
    if sp["kind"] == "deflection" and z_ref is not None:   # from the rigid mechanism at the model's coordinates
        ref = fe.case.mechanism.point(sp["at"])
        p_rs, phi_rs = point_state(fe.case.mechanism, rm.z, ref)
        p_ref, phi = point_state(fe.case.mechanism, z_ref, ref)
        d, rot = d + (p_rs - p_ref), rot + wrap_angle(phi_rs - phi)
    return point_components(d, rot, phi, sp["component"])


def load_output(fe, f: np.ndarray, sp: dict, name: str) -> np.ndarray:
    comp = sp["component"]
    if comp == "norm":  # forces only: the translational free DOFs [N]
        return np.linalg.norm(f[fe.free_translational()], axis=0)
    li, node, _ = fe.node_ref(sp["at"], f"outputs.{name}.at")
    dof = fe.rot_dof[(node, li)] if comp == "rotation" else fe.trans_dof[node, "xy".index(comp)]
    return f[dof].copy()
