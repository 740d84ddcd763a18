"""The gear pair: two gears, of pitch radii ``radii = [r_a, r_b]``, on bodies a and b, centred on the
joint's points a and b, mesh externally (``mesh = "external"``: they turn opposite ways) or internally
(``"internal"``: gear b is the ring, r_b > r_a, or a the ring, r_a > r_b; they turn the same way).

Its one row (the Fortran row routine ``row_gear``, kind CON_GEAR): the pitch circles roll on each other
without slip, ``r_a (psi_a - theta) + s r_b (psi_b - theta)`` held at its assembled value, theta the
angle of the line of centres, s = +1 external, -1 internal; with fixed centres ``r_a dpsi_a = -s r_b
dpsi_b`` (ratio -s r_a / r_b).  psi is the frame angle at the centre: a rigid body's angle, or on a
flexible link the node's angle (its elastic rotation included: the mesh is elastic through the link).
The centres must be ``r_a + s r_b`` apart as drawn (the pitch circles touch).  Pressure angle 0: the
line of action is the common tangent at the pitch point.

Reaction (the row's multiplier lambda is the tooth force along the line of action [N]): gear a exerts
on gear b the force ``lambda t`` (t the unit tangent, Omega times the unit line of centres from a to
b) at the pitch point, i.e. at b's centre the same force and the moment ``-s r_b lambda``; the tooth
force is the torque on a gear divided by its pitch radius.  No coordinate: nothing to drive.

Elastic condition: ``meshed`` only.  The superposition models hold the same row on the elastic
rotations as a relation (flexmech_py.models.superposition.slaving) when the line of centres does not move elastically (both
centres on rigid bodies or at ground pivots); otherwise they refuse the joint, naming the coupled and
nonlinear models, which take it anywhere.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ...base import validate as v
from ...base.errors import CaseError
from ..rows import CON_GEAR, gear_branch, gear_theta
from .base import Joint

__all__ = ["Gear"]

_MESH_SIGN = {"external": 1.0, "internal": -1.0}
_CENTRE_TOL = 1e-6       # relative mismatch of the centre distance allowed


@dataclass
class Gear(Joint):
    radii: tuple = (1.0, 1.0)
    mesh: str = "external"

    kind: ClassVar[str] = "gear"
    rows: ClassVar[int] = 1
    unit: ClassVar[str] = "rad"
    conditions: ClassVar[tuple] = ("meshed",)
    driven_default: ClassVar[str] = "meshed"
    released: ClassVar[tuple] = ()
    coupled_rows: ClassVar[tuple] = ("own",)
    coupled_coordinate: ClassVar[str] = "angle"
    holding: ClassVar[tuple] = ()
    ties_rotation: ClassVar[bool] = True
    has_coordinate: ClassVar[bool] = False
    glyph: ClassVar[dict] = {**Joint.glyph, "legend": "◎ gear pair (pitch circles)"}
    case_fields: ClassVar[tuple] = ("radii", "mesh")

    @classmethod
    def fields_from_case(cls, table: dict, where: str) -> dict:
        radii = v.vector(table, "radii", where, 2)
        if radii is None:
            raise CaseError(f"{where}.radii", "is missing; give the two pitch radii [m], e.g. radii = [0.05, 0.1]")
        mesh = v.text(table, "mesh", where, choices=tuple(_MESH_SIGN)) or "external"
        return {"radii": tuple(float(r) for r in radii), "mesh": mesh}

    def spec(self) -> dict:
        return {**super().spec(), "radii": [float(r) for r in self.radii], "mesh": self.mesh}

    @property
    def sign(self) -> float:
        """s: +1 external mesh, -1 internal."""
        return _MESH_SIGN[self.mesh]

    @property
    def centre_distance(self) -> float:
        """r_a + s r_b [m] (signed: negative when gear b is the ring of an internal mesh)."""
        return self.radii[0] + self.sign * self.radii[1]

    @property
    def ratio(self) -> float:
        """dpsi_b / dpsi_a with fixed centres: -s r_a / r_b."""
        return -self.sign * self.radii[0] / self.radii[1]

    def check(self) -> None:
        where = f"joints.{self.name}"
        if not all(math.isfinite(r) and r > 0 for r in self.radii):
            raise CaseError(f"{where}.radii", f"pitch radii must be positive lengths [m], got {list(self.radii)}")
        if self.mesh == "internal" and self.radii[0] == self.radii[1]:
            raise CaseError(f"{where}.radii", "an internal mesh needs a ring larger than its pinion; the radii are equal")

    def rotation_weights(self) -> tuple:
        """The mesh row on elastic rotations about fixed centres: r_a rot_a + s r_b rot_b = 0."""
        return (float(self.radii[0]), float(self.sign * self.radii[1]))

    def check_placed(self, a, b) -> None:
        where = f"joints.{self.name}"
        dist = float(np.linalg.norm(np.asarray(b.position, float) - np.asarray(a.position, float)))
        want = abs(self.centre_distance)
        if abs(dist - want) > _CENTRE_TOL * max(want, dist):
            rule = "r_a + r_b" if self.mesh == "external" else "|r_a - r_b|"
            raise CaseError(f"{where}.radii", f"the gear centres are drawn {dist:.6g} m apart; an {self.mesh} mesh "
                                              f"of these radii needs {rule} = {want:.6g} m: move a centre or change radii")

    def rigid_rows(self, pose) -> tuple:
        c = np.asarray(pose.pb, float) - np.asarray(pose.pa, float)
        d = (float(self.radii[0]), float(self.sign * self.radii[1]))
        return ((CON_GEAR, gear_branch(c), d, self.row_value(pose, gear_branch(c))),)

    def row_value(self, pose, branch: int) -> float:
        """The row's value g at ``pose`` (what it holds)."""
        c = np.asarray(pose.pb, float) - np.asarray(pose.pa, float)
        return (self.radii[0] * pose.ang_a + self.sign * self.radii[1] * pose.ang_b
                - self.centre_distance * gear_theta(c, branch))

    def own_rows(self, pose) -> list:
        """The coupled and nonlinear models' rows: ``(role, kind, aux, d)``, each held at its value at
        the start (:meth:`row_value`); here the one mesh row, role ``tooth``."""
        (kind, aux, d, _), = self.rigid_rows(pose)
        return [("tooth", kind, aux, d)]

    def held_values(self, role: str, ang_a, ang_b, pa, pb) -> np.ndarray:
        """The mesh row's value over the rigid motion, on the branch of the assembled line of centres."""
        branch = gear_branch(pb[0] - pa[0])
        theta = np.array([gear_theta(c, branch) for c in pb - pa])
        return self.radii[0] * ang_a + self.sign * self.radii[1] * ang_b - self.centre_distance * theta

    def reaction_from(self, lam, pa, pb) -> np.ndarray:
        """(N, 3) [F_x, F_y, M] gear a exerts on gear b, at b's centre, from the row's multiplier (N, 1)
        and the centres pa, pb (N, 2)."""
        (fb, mb), _ = self.reaction_units(pa, pb)
        lam = np.asarray(lam, float).reshape(-1)
        return np.column_stack([fb * lam[:, None], mb * lam])

    def reaction_units(self, pa, pb) -> tuple:
        """((force (N, 2), moment (N,)) on b at its centre, the same on a at its centre) of a unit
        multiplier: the generalized force -G^T of the row, k h on b's centre and -k h on a's
        (h = Omega c / |c|^2, k = r_a + s r_b: the tooth force along the common tangent, k/|c| = 1),
        the moments -s r_b on b and -r_a on a."""
        c = pb - pa
        h = np.stack([-c[:, 1], c[:, 0]], axis=1) / np.sum(c * c, axis=1)[:, None]
        n = c.shape[0]
        return ((self.centre_distance * h, np.full(n, -self.sign * self.radii[1])),
                (-self.centre_distance * h, np.full(n, -float(self.radii[0]))))

    def glyph_shapes(self) -> list:
        """The two pitch circles about the drawn centres, and the line of centres."""
        return [{"shape": "circle", "at": 0, "radius": float(self.radii[0])},
                {"shape": "circle", "at": 1, "radius": float(self.radii[1])}, {"shape": "segment"}]

    def tooth_force(self, lam: np.ndarray) -> np.ndarray:
        """The tooth force along the line of action [N] (signed: positive pushes b's pitch point along +t)."""
        return np.asarray(lam, float)
