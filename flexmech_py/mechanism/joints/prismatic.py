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

from ..rows import CON_ANGLE, CON_PROJECTION
from .base import NO_DIR
from .guide import Guide

__all__ = ["Prismatic"]


@dataclass
class Prismatic(Guide):
    kind: ClassVar[str] = "prismatic"
    rows: ClassVar[int] = 2
    conditions: ClassVar[tuple] = ("free", "locked", "force")
    driven_default: ClassVar[str] = "locked"
    released: ClassVar[tuple] = ("free", "force")
    coupled_rows: ClassVar[tuple] = ("normal", "angle")
    holding: ClassVar[tuple] = ("locked",)
    ties_rotation: ClassVar[bool] = True
    glyph: ClassVar[dict] = {"marker": "square", "size": 7.0, "fill": "#ffffff", "driven_fill": "#ffffff",
                             "edge": "#000000", "legend": "■ slider"}
    case_fields: ClassVar[tuple] = ("axis",)

    def rigid_rows(self, pose) -> tuple:
        return ((CON_PROJECTION, 0, (-pose.axis[1], pose.axis[0]), 0.0), (CON_ANGLE, 0, NO_DIR, pose.ref))
