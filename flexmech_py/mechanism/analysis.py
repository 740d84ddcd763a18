"""Making a mechanism ready to move: closing its loops, counting its degrees of freedom, checking its
drives and initial speeds (docs/theory.md section 17.2).

:func:`prepare_motion` returns a :class:`MotionSetup`: the assembled coordinates and velocities at
t = 0, the degrees of freedom, whether the motion is kinematic (every DOF driven) or dynamic, and the
*primary* joints whose coordinates are the mechanism's generalized coordinates q in results (the
kinematically driven joints, then those chosen for the free degrees of freedom).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..base import kernels
from ..base.errors import CaseError, MechanismError
from .packing import Packed, coordinate_drive, drawn_coordinates, joint_coordinates, marker_position, pack, row_scales
from .system import Mechanism

__all__ = ["MotionSetup", "prepare_motion", "constraint_matrices", "scaled_jacobian", "RANK_TOL"]

RANK_TOL = 1e-9          # singular values below RANK_TOL x the largest count as zero (scaled Jacobian)
ASSEMBLY_TOL = 1e-12     # the loops close to RANK_TOL x the mechanism's length [m]
ASSEMBLY_MAXIT = 50


@dataclass
class MotionSetup:
    """A mechanism at t = 0, ready for flexmech_py.mechanism.motion."""

    mech: Mechanism
    gravity: tuple
    packed: Packed            # joints, kinematic and force drives
    z0: np.ndarray            # assembled coordinates
    zd0: np.ndarray           # initial velocities
    dof: int
    mode: str                 # "kinematic" (every DOF driven) or "dynamic"
    primary: list             # joints whose coordinates make q
    moved: dict               # assembly: point label -> distance moved [m]
    warnings: list = field(default_factory=list)

    @property
    def max_moved(self) -> tuple[str, float]:
        if not self.moved:
            return "", 0.0
        k = max(self.moved, key=self.moved.get)
        return k, self.moved[k]


def constraint_matrices(packed: Packed, z, zd=None, t: float = 0.0):
    """(phi, jac, gam, nu, q) of a packed description at (z, zd, t) (flexmech_mbs: mbs_constraints)."""
    zd = np.zeros(packed.n) if zd is None else np.asarray(zd, float)
    phi, jac, gam, nu, q, status = kernels.mbs.mbs_eval(packed.nrow, packed.ispec, packed.rspec,
                                                        np.asarray(z, float), zd, float(t))
    kernels.check_status(status, "mbs_eval")
    return phi, jac, gam, nu, q


def scaled_jacobian(mech: Mechanism, packed: Packed, jac: np.ndarray) -> np.ndarray:
    """The Jacobian in length units: rows in radians times lref, rotation columns times lref."""
    out = jac * row_scales(mech, packed)[:, None]
    out[:, 2::3] *= packed.lref
    return out


def _rank(a: np.ndarray) -> int:
    if a.size == 0:
        return 0
    s = np.linalg.svd(a, compute_uv=False)
    return int(np.sum(s > RANK_TOL * s[0])) if s[0] > 0 else 0


def _dependent_rows(a: np.ndarray) -> list[int]:
    """Rows that take part in the combinations a^T y = 0 (the left null space), largest first."""
    u, s, _ = np.linalg.svd(a)
    null = u[:, int(np.sum(s > RANK_TOL * s[0])):]
    w = np.sqrt(np.sum(null ** 2, axis=1))
    return [int(i) for i in np.argsort(-w) if w[i] > 0.3 * w.max()]


def _row_joint(mech: Mechanism, packed: Packed, row: int) -> str:
    for j, (r0, nr) in zip(mech.joints, packed.joint_rows):
        if r0 <= row < r0 + nr:
            return j.name
    return next(f"drive on {name}" for name, r in packed.drive_rows.items() if r == row)


def prepare_motion(mech: Mechanism, gravity=(0.0, 0.0)) -> MotionSetup:
    """Close the loops, check constraints, drives and initial speeds; the state at t = 0."""
    z_drawn = drawn_coordinates(mech)
    joints_only = pack(mech, gravity, kinematic_only=True)
    nj_rows = sum(nr for _, nr in joints_only.joint_rows)
    _, jac, _, _, _ = constraint_matrices(joints_only, z_drawn)
    jj = scaled_jacobian(mech, joints_only, jac)[:nj_rows]
    rank_j = _rank(jj)
    if rank_j < nj_rows:
        names = sorted({_row_joint(mech, joints_only, r) for r in _dependent_rows(jj)})
        raise CaseError("joints", f"the mechanism is over-constrained: its {nj_rows} joint equations have rank {rank_j}; "
                                  f"joints {', '.join(names)} constrain the same motion (a loop that cannot move, or a "
                                  "doubled constraint); remove or change one (e.g. a revolute into a pin-in-slot)")
    dof = len(z_drawn) - rank_j
    _check_drive_count(mech, dof)
    z0, moved = _assemble(mech, gravity, z_drawn)
    starts = joint_coordinates(mech, z0)
    packed = pack(mech, gravity, starts)
    nkin = sum(1 for d in mech.drives if d.kinematic)
    mode = "kinematic" if nkin == dof else "dynamic"
    if mode == "kinematic":
        zd0, primary = np.zeros(len(z0)), [d.joint for d in mech.drives if d.kinematic]
    else:
        zd0, primary = _initial_velocities(mech, packed, z0, starts)
    warnings = []
    nforce = sum(1 for d in mech.drives if not d.kinematic)
    if dof - nkin - nforce > 0 and not np.any(np.asarray(gravity, float)):
        free = [p for p in primary if mech.drive_of(p) is None]
        warnings.append(f"{dof - nkin - nforce} free degree(s) of freedom ({', '.join(free)}) with no drive and no "
                        "gravity: they move only by their initial speeds and the coupling to the rest")
    return MotionSetup(mech=mech, gravity=tuple(float(g) for g in gravity), packed=packed, z0=z0, zd0=zd0, dof=dof,
                       mode=mode, primary=primary, moved=moved, warnings=warnings)


def _check_drive_count(mech: Mechanism, dof: int) -> None:
    nkin = sum(1 for d in mech.drives if d.kinematic)
    if nkin > dof:
        raise CaseError("drives", f"{nkin} kinematic drives on a mechanism with {dof} degree(s) of freedom: a drive "
                                  "would fight the joints; remove drives or release a joint")
    if len(mech.drives) > dof:
        raise CaseError("drives", f"{len(mech.drives)} drives on a mechanism with {dof} degree(s) of freedom: "
                                  "give at most one drive per degree of freedom")


def _assemble(mech: Mechanism, gravity, z_drawn: np.ndarray) -> tuple[np.ndarray, dict]:
    """Close the loops from the drawn configuration: joints, kinematic drives at t = 0 and
    initial.coordinates; returns the coordinates and how far each joint point moved."""
    starts = joint_coordinates(mech, z_drawn)
    starts.update(mech.initial_coordinates)
    fixed = [coordinate_drive(j, val) for j, val in mech.initial_coordinates.items()
             if not (mech.drive_of(j) and mech.drive_of(j).kinematic)]
    packed = pack(mech, gravity, starts, extra_drives=fixed, kinematic_only=True)
    _, jac, _, _, _ = constraint_matrices(packed, z_drawn)
    sj = scaled_jacobian(mech, packed, jac)
    if _rank(sj) < packed.nrow:
        rows = _dependent_rows(sj)
        names = sorted({_row_joint(mech, packed, r) for r in rows})
        raise CaseError("drives", f"the kinematic drives and initial.coordinates fix coordinates that depend on each "
                                  f"other ({', '.join(names)}); drive independent joints")
    z = z_drawn.copy()
    status, iters, resid = kernels.mbs.mbs_assemble(packed.ispec, packed.rspec, z, 0.0,
                                                    ASSEMBLY_TOL * packed.lref, ASSEMBLY_MAXIT)
    if status != 0:
        raise MechanismError(f"the mechanism cannot assemble: closing its loops from the drawn configuration left a "
                             f"violation of {resid:.3g} m after {iters} Newton iterations; check the link lengths and "
                             "the joints' points (the drawn configuration need only be close, but a loop must close)")
    moved = {}
    for j in mech.joints:
        for ref, m in zip(mech.joint_points(j), packed.markers[2 * mech.joints.index(j):2 * mech.joints.index(j) + 2]):
            if m[0] is not None:
                moved[ref.label] = float(np.linalg.norm(marker_position(z, m) - marker_position(z_drawn, m)))
    return z, moved


def _coordinate_rows(mech: Mechanism, z0: np.ndarray, starts: dict):
    """Jacobian rows of every joint coordinate (weld joints excluded) at z0: {joint: row}."""
    names = [j.name for j in mech.joints if j.has_coordinate]
    extra = pack(mech, (0.0, 0.0), starts, kinematic_only=True,
                 extra_drives=[coordinate_drive(n, starts[n]) for n in names])
    _, jac, _, _, _ = constraint_matrices(extra, z0)
    return {n: jac[extra.nrow - len(names) + i] for i, n in enumerate(names)}


def _initial_velocities(mech: Mechanism, packed: Packed, z0: np.ndarray, starts: dict):
    """Velocities at t = 0: joint constraints, kinematic drive rates, the given initial.speeds and zero
    speed for as many further joint coordinates as there are still free DOFs (force-driven joints
    first, then the rest in order).  Returns (zd0, primary joints)."""
    _, jac, _, nu, _ = constraint_matrices(packed, z0)
    rows, rhs = list(jac), list(nu)
    crow = _coordinate_rows(mech, z0, starts)
    n = len(z0)
    primary = [d.joint for d in mech.drives if d.kinematic]

    def scaled(rs):      # rotation columns in length units, every row of unit length (rank only)
        a = np.array(rs, float)
        a[:, 2::3] *= packed.lref
        norms = np.linalg.norm(a, axis=1)
        return a / np.where(norms > 0, norms, 1.0)[:, None]

    for name, speed in mech.initial_speeds.items():
        if name not in crow:
            raise CaseError(f"initial.speeds.{name}", "a weld has no coordinate to move")
        if _rank(scaled(rows + [crow[name]])) <= _rank(scaled(rows)):
            raise CaseError(f"initial.speeds.{name}", "depends on the other given speeds and the drives (the mechanism "
                                                      "has fewer free degrees of freedom): remove it")
        rows.append(crow[name])
        rhs.append(speed)
        primary.append(name)
    forced = [d.joint for d in mech.drives if not d.kinematic]
    others = [j.name for j in mech.joints if j.name in crow]
    for name in forced + others:
        if len(rows) >= n or _rank(scaled(rows)) >= n:
            break
        if name in primary:
            continue
        if _rank(scaled(rows + [crow[name]])) > _rank(scaled(rows)):
            rows.append(crow[name])
            rhs.append(0.0)
            primary.append(name)
    a = np.array(rows)
    zd0 = np.linalg.lstsq(a, np.array(rhs), rcond=None)[0]
    return zd0, primary
