"""The prismatic joint: a guide fixed to body a through point a, along ``axis`` (a global direction in
the assembly configuration); point b slides along it, body b keeps its angle to body a.

Elastic conditions (superposition models): ``free`` (relative elastic sliding free), ``locked``
(none), ``force`` (free, loaded by the joint's force drive).  Its coordinate is the slide of b along
the guide [m]; its reaction a force normal to the guide and a moment (and, when locked, a force
along it).  The superposition models take a guide only on the ground or a rigid body (flexmech_py.
slaving); the coupled and nonlinear models also on a flexible link (Family.guides_on_flexible_links).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ... import validate as v
from ...errors import CaseError
from ..rows import CON_ANGLE, CON_PROJECTION
from .base import NO_DIR, Joint

__all__ = ["Prismatic"]


@dataclass
class Prismatic(Joint):
    axis: tuple = (1.0, 0.0)

    kind: ClassVar[str] = "prismatic"
    rows: ClassVar[int] = 2
    unit: ClassVar[str] = "m"
    conditions: ClassVar[tuple] = ("free", "locked", "force")
    driven_default: ClassVar[str] = "locked"
    released: ClassVar[tuple] = ("free", "force")
    coupled_rows: ClassVar[tuple] = ("normal", "angle")
    coupled_coordinate: ClassVar[str] = "slide"
    holding: ClassVar[tuple] = ("locked",)
    ties_rotation: ClassVar[bool] = True
    guided: ClassVar[bool] = True
    glyph: ClassVar[dict] = {"marker": "square", "size": 7.0, "fill": "#ffffff", "driven_fill": "#ffffff",
                             "edge": "#000000", "legend": "■ slider"}
    case_fields: ClassVar[tuple] = ("axis",)

    @classmethod
    def fields_from_case(cls, table: dict, where: str) -> dict:
        axis = v.vector(table, "axis", where, 2)
        if axis is None:
            raise CaseError(f"{where}.axis", "is missing; give the guide direction, e.g. [1, 0]")
        return {"axis": tuple(axis)}

    def spec(self) -> dict:
        return {**super().spec(), "axis": [float(x) for x in self.axis]}

    def check(self) -> None:
        if not np.linalg.norm(np.asarray(self.axis, float)) > 0:
            raise CaseError(f"joints.{self.name}.axis", "the guide direction has zero length; give e.g. axis = [1, 0]")

    def unit_axis(self) -> np.ndarray:
        u = np.asarray(self.axis, float)
        return u / np.linalg.norm(u)

    def rigid_rows(self, pose) -> tuple:
        return ((CON_PROJECTION, 0, (-pose.axis[1], pose.axis[0]), 0.0), (CON_ANGLE, 0, NO_DIR, pose.ref))

    def coordinate_row(self, axis) -> tuple:
        return (CON_PROJECTION, 0, (axis[0], axis[1]))
