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


def output_unit(spec: dict) -> str:
    kind = spec["kind"]
    if kind in UNITS:
        return UNITS[kind]
    comp = spec["component"]
    if kind == "displacement":
        return "rad" if comp == "rotation" else "m"
    return "N m" if comp == "rotation" else "N"  # inertia_load


def _joint_rigid(fe, motion, name, attr):
    j = fe.joint(name)
    val = getattr(motion, attr)[:, j.outboard]
    if j.inboard is not None:
        val = val - getattr(motion, attr)[:, j.inboard]
    return np.unwrap(val) if attr == "phi" else val  # angles continuous in time (no 2 pi jumps)


def link_curvature(fe, u_all: np.ndarray, phi: np.ndarray, li: int, frac: float) -> np.ndarray:
    """Curvature v'' [1/m] of link ``li`` at ``frac`` of its length over the frames.

    u_all (ndof, nf) elastic DOFs; phi (nf,) rigid link angle.
    """
    els = fe.link_elements(li)
    n = len(els)
    s = frac * n
    k = int(round(s))
    if abs(s - k) < 1e-9:   # at a node: average the elements that meet there
        parts = []
        if k > 0:
            parts.append((els[k - 1], 1.0))
        if k < n:
            parts.append((els[k], 0.0))
    else:
        e = min(int(np.floor(s)), n - 1)
        parts = [(els[e], s - e)]
    kap = 0.0
    for e, xi in parts:
        dglob = u_all[fe.el_dof[:, e] - 1]
        kap = kap + kernels.element_curvatures(dglob, phi, fe.el_prop[0, e], xi)
    return kap / len(parts)


def evaluate_outputs(fe, specs: dict, u_all: np.ndarray, motion, q, qd, qdd, rig_frames, run_model: str,
                     load_cache: dict | None = None, joint_motion=None, curvature=None,
                     axial=None) -> dict[str, np.ndarray]:
    """Evaluate every named output over the frames.

    u_all (ndof, nf) elastic DOFs (displacements from the rigid motion ``motion``);
    rig_frames (5, nlinks, nf) the kernel rigid samples (for inertia loads).
    joint_motion: LinkMotion for joint and link angles (default ``motion``; the coupled model
    passes its own rigid motion); curvature: callable(link, fraction) -> kappa (default: from u_all);
    axial: (nel, nf) element axial forces [N] for ``axial_force`` outputs.
    """
    joint_motion = motion if joint_motion is None else joint_motion
    out = {}
    loads = {} if load_cache is None else load_cache
    links = fe.case["links"]
    for name, sp in specs.items():
        kind = sp["kind"]
        if kind in ("joint_angle", "joint_speed", "joint_acceleration"):
            attr = {"joint_angle": "phi", "joint_speed": "omega", "joint_acceleration": "alpha"}[kind]
            out[name] = _joint_rigid(fe, joint_motion, sp["joint"], attr)
        elif kind == "link_angle":
            out[name] = np.unwrap(joint_motion.phi[:, fe.link_names.index(sp["link"])])
        elif kind in ("strain", "curvature"):
            li = fe.link_names.index(sp["link"])
            kap = (link_curvature(fe, u_all, motion.phi[:, li], li, sp["at"]) if curvature is None
                   else curvature(li, sp["at"]))
            out[name] = kap * links[li]["half_depth"] if kind == "strain" else kap
        elif kind == "axial_force":
            if axial is None:
                raise CaseError(f"outputs.{name}", "axial forces are not available for this model")
            li = fe.link_names.index(sp["link"])
            els = fe.link_elements(li)
            n = len(els)
            s = sp["at"] * n
            k = int(round(s))
            if abs(s - k) < 1e-9 and 0 < k < n:
                out[name] = 0.5 * (axial[els[k - 1]] + axial[els[k]])
            else:
                out[name] = axial[els[min(int(np.floor(s)), n - 1)]]
        elif kind in ("displacement", "position"):
            li, node, zeta = fe.node_ref(sp["at"], f"outputs.{name}.at")
            comp = sp["component"]
            ux, uy = u_all[fe.trans_dof[node, 0]], u_all[fe.trans_dof[node, 1]]
            phi = motion.phi[:, li]
            c, s = np.cos(phi), np.sin(phi)
            if kind == "position":
                rigid = (motion.ox[:, li] + zeta * c) if comp == "x" else (motion.oy[:, li] + zeta * s)
                out[name] = rigid + (ux if comp == "x" else uy)
            else:
                out[name] = {"x": ux, "y": uy, "axial": c * ux + s * uy, "transverse": -s * ux + c * uy,
                             "rotation": u_all[fe.rot_dof[(node, li)]] if comp == "rotation" else None}[comp]
        elif kind == "inertia_load":
            model = run_model if sp["model"] == "run" else sp["model"]
            if model not in loads:
                loads[model] = fe.loads(rig_frames, model)
            f = loads[model]
            comp = sp["component"]
            if comp == "norm":  # forces only: the translational free DOFs [N]
                out[name] = np.linalg.norm(f[fe.free_translational()], axis=0)
            else:
                li, node, _ = fe.node_ref(sp["at"], f"outputs.{name}.at")
                dof = fe.rot_dof[(node, li)] if comp == "rotation" else fe.trans_dof[node, "xy".index(comp)]
                out[name] = f[dof].copy()
        else:  # pragma: no cover - the case validator only admits the kinds above
            raise AssertionError(kind)
    return out
