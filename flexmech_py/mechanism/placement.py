"""The rigid mechanism placed at given values of its generalized coordinates (docs/theory.md section
8.1): the reference configuration of the ``deflection`` outputs.

A model's own motion may drift from the rigid-body solution (the coupled and nonlinear models: the
elasticity acts back on the rigid motion of a mechanism with free degrees of freedom).  The
deflection of a point is measured from where the *rigid* mechanism would hold it at the model's own
coordinates q (the primary joints' coordinates measured at the joints), so that the drift does not
count as deflection.  :class:`Placement` closes the loops with those coordinates held (kinematic drives
at their laws), frame after frame, each from the previous solution (Gauss-Newton with the smallest
changes, flexmech_mbs: mbs_assemble).
"""

from __future__ import annotations

import copy

import numpy as np

from ..base import kernels
from .analysis import ASSEMBLY_MAXIT, ASSEMBLY_TOL, MotionSetup
from .packing import coordinate_drive, joint_coordinates, pack

__all__ = ["Placement", "point_state"]


class Placement:
    """``placement(t, q)`` -> z (nf, n): the body coordinates of the rigid mechanism with the primary
    joints of ``setup`` at q (nf, nprimary) at the times t (nf,) (kinematically driven primaries follow
    their laws; their columns of q are not read).  Frames are solved in order, each from the previous
    one (the first from ``z_start``, default the assembled configuration at t = 0); call it block after
    block of a run.  Where the loops cannot close at the model's coordinates (a model's motion the rigid
    mechanism cannot reach: it diverged, or passed a limit position), that frame and the later ones are
    NaN and ``failed_at`` is its time."""

    def __init__(self, setup: MotionSetup, z_start=None):
        mech = setup.mech
        self.setup = setup
        self.held = [i for i, p in enumerate(setup.primary) if not (mech.drive_of(p) and mech.drive_of(p).kinematic)]
        starts = joint_coordinates(mech, setup.z0)      # the kinematic laws' default starts, as for the run
        names = [setup.primary[i] for i in self.held]
        zero = pack(mech, setup.gravity, starts, kinematic_only=True,
                    extra_drives=[coordinate_drive(n, 0.0) for n in names])
        self.ispec, self.rspec = zero.ispec, zero.rspec
        self.slots = []                   # rspec index of each held coordinate's value
        for k, n in enumerate(names):
            one = pack(mech, setup.gravity, starts, kinematic_only=True,
                       extra_drives=[coordinate_drive(m, 1.0 if m == n else 0.0) for m in names])
            self.slots.append(int(np.flatnonzero(one.rspec != zero.rspec)[0]))
        self.tol = ASSEMBLY_TOL * zero.lref
        self.z_start = np.array(setup.z0 if z_start is None else z_start, float)
        self.z = self.z_start.copy()
        self.failed_at = None

    def restarted(self) -> "Placement":
        """A placement of the same set-up for a new run (from ``z_start`` again), without packing the
        mechanism again."""
        other = copy.copy(self)
        other.z, other.failed_at = self.z_start.copy(), None
        return other

    def __call__(self, t, q) -> np.ndarray:
        t = np.asarray(t, float)
        q = np.asarray(q, float).reshape(t.size, -1)
        out = np.full((t.size, self.z.size), np.nan)
        if self.failed_at is not None:
            return out
        rspec = self.rspec.copy()
        for i in range(t.size):
            for k, slot in zip(self.held, self.slots):
                rspec[slot] = q[i, k]
            z = self.z.copy()
            status, iters, resid = kernels.mbs.mbs_assemble(self.ispec, rspec, z, float(t[i]), self.tol,
                                                            ASSEMBLY_MAXIT)
            if status != 0:
                self.failed_at = float(t[i])
                return out
            out[i] = self.z = z
        return out


def point_state(mech, z: np.ndarray, ref) -> tuple[np.ndarray, np.ndarray]:
    """((2, nf) position [m], (nf,) frame angle [rad]) of a body's point (a PointRef) in the
    configurations z (nf, n): the body's centre and frame carried to the point."""
    bi = mech.body_index(ref.body)
    s = ref.body.marker(ref.point)
    phi = z[:, 3 * bi + 2]
    c, sn = np.cos(phi), np.sin(phi)
    return z[:, 3 * bi:3 * bi + 2].T + np.array([c * s[0] - sn * s[1], sn * s[0] + c * s[1]]), phi
