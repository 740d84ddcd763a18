"""The superposition family's loads and checks of its elastic problem: the force drives' torques and
forces as generalized forces on the elastic DOFs, the elastic problem checked for zero-stiffness
modes, and the element quantities its blocks report (axial stretch, curvature)."""

from __future__ import annotations

import numpy as np

from ...base.errors import CaseError
from ...mechanism.motion import RigidMotion
from .model import FEModel
from .outputs import link_curvature, link_node_curvatures

__all__ = ["elastic_torque_loads", "drive_loads", "check_elastic_problem", "axial_stretch", "superposition_curvature",
           "superposition_node_curvatures"]


def elastic_torque_loads(case: dict, fe: FEModel, rm: RigidMotion, rig: np.ndarray | None = None):
    """The force drives' torques and forces as generalized forces on the free elastic DOFs: (q_free,
    q_val) or (None, None); ``rig`` the samples of rm (fe.rig_samples) when the model has slave relations.

    A torque on a revolute joint acts on the elastic rotation of its body b at the joint, its reaction
    on body a's; a force on a guided joint acts on the joint's along DOF (the elastic slide: the
    force on b and its reaction on a at the contact point do the work F ds).  Assembled over all DOFs
    (constrained ones included), projected onto the masters of slaved DOFs and restricted to the free
    DOFs; rows that vanish identically (torques on clamped DOFs, or action and reaction on one locked
    rotation) are dropped, so they cost nothing.
    """
    mech = case.mechanism
    forced = [d.joint for d in mech.drives if not d.kinematic]
    if not forced:
        return None, None
    q_all = drive_loads(fe, rm, forced)
    if fe.slaving is not None:
        q_all = fe.slaving.project(q_all, fe.rig_samples(rm, case["loads"]["gravity"]) if rig is None else rig)
    qf = fe.restrict(q_all)
    rows = np.flatnonzero(np.any(qf != 0.0, axis=1))
    if rows.size == 0:
        return None, None
    return (rows + 1).astype(np.int32), np.asfortranarray(qf[rows])


def drive_loads(fe: FEModel, rm: RigidMotion, joints) -> np.ndarray:
    """(ndof, N) the generalized forces of the drives of ``joints`` over all DOFs: a torque on the
    elastic rotations of its joint's bodies (+ on b, - on a), a force on its joint's along DOF."""
    mech = fe.case.mechanism
    slides = {sl.joint.name: sl for sl in fe.slides}
    q_all = np.zeros((fe.ndof, rm.t.size))
    for name in joints:
        f = rm.drive_force(name)
        if name in slides:
            q_all[slides[name].dof] += f
            continue
        a, b = mech.joint_points(mech.joint(name))
        db, da = fe.rotation_dof(b), fe.rotation_dof(a)
        if db is not None:
            q_all[db] += f
        if da is not None:
            q_all[da] -= f
    return q_all


def check_elastic_problem(fe: FEModel, rig0: np.ndarray, dof: int | None = None) -> None:
    """Reject an elastic problem with zero-stiffness modes (an unconstrained mechanism motion);
    ``dof`` the mechanism's degrees of freedom (at most that many joints can be left free with
    'torque' on purpose)."""
    if fe.nfree > 1500:  # a dense eigenvalue check would cost more than the run; skipped
        return
    # squared natural frequencies of M and the elastic K alone (the rigid sample's angle only): a
    # zero-stiffness mode sits at round-off (~1e-16 of the largest), a real mode above (w_1/w_max)^2
    # ~ 1e-10 even at 256 elements per link; K's own eigenvalues spread far more (axial vs bending)
    try:
        ev = fe.squared_frequencies(rig0[:, :, 0] * np.array([1, 0, 0, 0, 0])[:, None])
    except np.linalg.LinAlgError:
        turning = [p.name for p in fe.parts.values() if p.inertia == 0.0 and fe.free_of[p.dofs[2]] > 0]
        if turning:
            raise CaseError(f"bodies.{turning[0]}.inertia", "is 0 but the body can turn in the elastic problem of "
                                                           "the superposition models (its joints leave its rotation "
                                                           "free): give its rotary inertia about its centre of mass") from None
        raise CaseError("links", "the mass matrix is not positive definite: every link needs density > 0 and area > 0") from None
    scale = np.max(np.abs(ev))
    nzero = int(np.sum(np.abs(ev) < 1e-13 * scale))
    # a joint left free with 'torque' (a guided one with 'force') turns the mechanism's own degree of
    # freedom into a zero-stiffness mode of the elastic problem, on purpose (theory.md section 14)
    mech = fe.case.mechanism
    released = sum(1 for j in mech.joints if mech.condition(j) in ("torque", "force"))
    allowed = min(released, released if dof is None else dof)
    if nzero > allowed:
        raise CaseError("joints", f"the elastic problem has {nzero - allowed} unintended zero-stiffness mode(s): the joints leave the "
                                  "mechanism free to move elastically; clamp the driven ground joint "
                                  "(crank_pivot/base = 'clamp') or lock a joint")


def superposition_curvature(res, li: int, frac: float) -> np.ndarray:
    return link_curvature(res.fe, res.u, res.motion.phi[:, li], li, frac)


def superposition_node_curvatures(res, li: int) -> np.ndarray:
    return link_node_curvatures(res.fe, res.u, res.motion.phi[:, li], li)


def axial_stretch(fe, u_all, motion) -> np.ndarray:
    """(nel, nf) elongation p2 - p1 [m] of every element in its link frame."""
    out = np.empty((fe.nel, u_all.shape[1]))
    for li in np.unique(fe.el_link) - 1:
        els = fe.link_elements(li)
        c, s = np.cos(motion.phi[:, li]), np.sin(motion.phi[:, li])
        d = u_all[fe.el_dof[:, els] - 1]                   # (6, n, nf)
        out[els] = (c * d[3] + s * d[4]) - (c * d[0] + s * d[1])
    return out
