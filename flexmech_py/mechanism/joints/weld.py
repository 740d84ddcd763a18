"""The weld: the two points coincide and the bodies keep their relative angle (``rigid`` only).

It has no coordinate (nothing to drive or measure); its reaction is a force (x, y) and a moment.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ..rows import CON_ANGLE, CON_POINT
from .base import NO_DIR, Joint

__all__ = ["Weld"]


@dataclass
class Weld(Joint):
    kind: ClassVar[str] = "weld"
    rows: ClassVar[int] = 3
    unit: ClassVar[str] = "rad"
    conditions: ClassVar[tuple] = ("rigid",)
    driven_default: ClassVar[str] = "rigid"
    released: ClassVar[tuple] = ()
    coupled_rows: ClassVar[tuple] = ("point", "angle")
    coupled_coordinate: ClassVar[str] = "angle"
    holding: ClassVar[tuple] = ()
    shares_point: ClassVar[bool] = True
    ties_rotation: ClassVar[bool] = True
    has_coordinate: ClassVar[bool] = False

    def rigid_rows(self, pose) -> tuple:
        return ((CON_POINT, 1, NO_DIR, 0.0), (CON_POINT, 2, NO_DIR, 0.0), (CON_ANGLE, 0, NO_DIR, pose.ref))
