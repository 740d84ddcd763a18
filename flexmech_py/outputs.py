"""Named outputs of a run, evaluated from the elastic frames and the rigid motion.

Every output kind is documented in ``docs/cases.md``.  Strains are the
bending strain ``eps = c * kappa`` with ``kappa = v''`` the curvature of the
element's Hermite field in the link frame and ``c`` the link's half depth
(the strain of the fibre at ``eta = -c``); at an interior mesh node the
curvature is averaged over the two elements that meet there.
"""

from __future__ import annotations

import numpy as np

from . import kernels
from .case import UNITS
from .errors import CaseError

__all__ = ["evaluate_outputs", "output_unit"]


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
    if kind == "displacement":
        return "rad" if comp == "rotation" else "m"
    if kind == "reaction":
        return "N m" if comp == "moment" else "N"
    return "N m" if comp == "rotation" else "N"  # inertia_load


def _joint_from_links(fe, motion, name, k):
    """A revolute joint's angle (k = 0), speed (1) or acceleration (2) from link motion: phi_b - phi_a
    of its FE joint, in the mechanism's orientation."""
    j = fe.joint(name)
    attr = ("phi", "omega", "alpha")[k]
    val = getattr(motion, attr)[:, j.outboard]
    if j.inboard is not None:
        val = val - getattr(motion, attr)[:, j.inboard]
    val = j.sign * val
    return np.unwrap(val) if k == 0 else val


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
                     load_cache: dict | None = None, joint_motion=None, curvature=None,
                     axial=None, rates=None, reactions=None) -> dict[str, np.ndarray]:
    """Evaluate every named output over the frames.

    u_all (ndof, nf) elastic DOFs (displacements from the rigid motion ``motion``, a LinkMotion);
    rig_frames (5, nlinks, nf) the kernel rigid samples (for inertia loads); rm the RigidMotion at the
    frames (joint coordinates, reactions, drive forces of the rigid-body solution).
    joint_motion: LinkMotion the joint and link angles come from instead (the coupled models pass
    their own chord motion); curvature: callable(link, fraction) -> kappa (default: from u_all);
    axial: (nel, nf) element axial forces [N] for ``axial_force`` outputs; rates: (v_all, a_all) the
    elastic velocities and accelerations (a prismatic joint's elastic slide adds to its rigid one);
    reactions: callable(joint) -> (nf, 3) the model's joint reactions (``source = "model"``; without
    it the rigid-body reactions).
    """
    out = {}
    loads = {} if load_cache is None else load_cache
    links = fe.case["links"]
    for name, sp in specs.items():
        kind = sp["kind"]
        if kind in ("joint_angle", "joint_displacement", "joint_speed", "joint_acceleration"):
            k = {"joint_angle": 0, "joint_displacement": 0, "joint_speed": 1, "joint_acceleration": 2}[kind]
            out[name] = (_joint_from_links(fe, joint_motion, sp["joint"], k) if joint_motion is not None
                         else rm.joint(sp["joint"])[:, k] + _elastic_slide(fe, sp["joint"], k, u_all, rates))
        elif kind == "link_angle":
            lm = motion if joint_motion is None else joint_motion
            out[name] = np.unwrap(lm.phi[:, fe.link_names.index(sp["link"])])
        elif kind in ("strain", "curvature"):
            li = fe.link_names.index(sp["link"])
            kap = (link_curvature(fe, u_all, motion.phi[:, li], li, sp["at"]) if curvature is None
                   else curvature(li, sp["at"]))
            out[name] = kap * links[li]["half_depth"] if kind == "strain" else kap
        elif kind == "axial_force":
            out[name] = _axial_output(fe, axial, sp, name)
        elif kind in ("displacement", "position"):
            out[name] = _point_output(fe, u_all, motion, sp, name, rm)
        elif kind == "inertia_load":
            model = run_model if sp["model"] == "run" else sp["model"]
            if model not in loads:
                loads[model] = fe.loads(rig_frames, model)
            out[name] = _load_output(fe, loads[model], sp, name)
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


def _axial_output(fe, axial, sp: dict, name: str) -> np.ndarray:
    if axial is None:
        raise CaseError(f"outputs.{name}", "axial forces are not available for this model")
    li = fe.link_names.index(sp["link"])
    els = fe.link_elements(li)
    at = _element_at(fe, li, sp["at"])
    return sum(axial[els[e]] for e, _ in at) / len(at)


def _elastic_slide(fe, joint: str, k: int, u_all, rates) -> np.ndarray | float:
    """A prismatic joint's elastic slide (k = 0), its rate (1) or acceleration (2): the along DOF; 0 for
    other joints."""
    dof = next((sl.dof for sl in getattr(fe, "slides", ()) if sl.joint.name == joint), None)
    if dof is None:
        return 0.0
    x = u_all if k == 0 else (None if rates is None else rates[k - 1])
    return 0.0 if x is None else x[dof]


def _rigid_point_output(fe, u_all, rm, part, ref, sp: dict) -> np.ndarray:
    """Position or displacement of a point of a rigid link or body: rigid + d + dtheta z x s (linearized)."""
    mech = fe.case.mechanism
    i = 3 * mech.body_index(part.body)
    phi = rm.z[:, i + 2]
    c, s = np.cos(phi), np.sin(phi)
    m = part.body.marker(ref.point)
    sx, sy = c * m[0] - s * m[1], s * m[0] + c * m[1]
    dx, dy, dth = (u_all[d] for d in part.dofs)
    ux, uy = dx - sy * dth, dy + sx * dth
    comp = sp["component"]
    if sp["kind"] == "position":
        return (rm.z[:, i] + sx + ux) if comp == "x" else (rm.z[:, i + 1] + sy + uy)
    if comp == "rotation":
        return dth.copy()
    ca, sa = (c, s) if part.body.kind == "link" else (np.ones_like(c), np.zeros_like(s))
    return {"x": ux, "y": uy, "axial": ca * ux + sa * uy, "transverse": -sa * ux + ca * uy}[comp]


def _point_output(fe, u_all, motion, sp: dict, name: str, rm=None) -> np.ndarray:
    kind, where = fe.point_ref(sp["at"], f"outputs.{name}.at")
    if kind == "rigid":
        return _rigid_point_output(fe, u_all, rm, *where, sp)
    li, node, zeta = where
    comp = sp["component"]
    ux, uy = u_all[fe.trans_dof[node, 0]], u_all[fe.trans_dof[node, 1]]
    phi = motion.phi[:, li]
    c, s = np.cos(phi), np.sin(phi)
    if sp["kind"] == "position":
        rigid = (motion.ox[:, li] + zeta * c) if comp == "x" else (motion.oy[:, li] + zeta * s)
        return rigid + (ux if comp == "x" else uy)
    if comp == "rotation":
        return u_all[fe.rot_dof[(node, li)]]
    return {"x": ux, "y": uy, "axial": c * ux + s * uy, "transverse": -s * ux + c * uy}[comp]


def _load_output(fe, f: np.ndarray, sp: dict, name: str) -> np.ndarray:
    comp = sp["component"]
    if comp == "norm":  # forces only: the translational free DOFs [N]
        return np.linalg.norm(f[fe.free_translational()], axis=0)
    li, node, _ = fe.node_ref(sp["at"], f"outputs.{name}.at")
    dof = fe.rot_dof[(node, li)] if comp == "rotation" else fe.trans_dof[node, "xy".index(comp)]
    return f[dof].copy()
