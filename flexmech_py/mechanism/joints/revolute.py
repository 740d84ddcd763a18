"""The revolute joint: the two points coincide, the bodies turn freely about them.

Elastic conditions (superposition models): ``pin`` (relative elastic rotation free), ``locked`` (one
shared elastic rotation; ``clamp`` is the same and the usual word at a ground pivot), ``torque``
(free, loaded by the joint's force drive).  Its coordinate is the angle of body b from body a [rad];
its reaction a force (x, y), and a moment when held (``locked``/``clamp``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ..rows import CON_POINT
from .base import NO_DIR, Joint

__all__ = ["Revolute"]


@dataclass
class Revolute(Joint):
    kind: ClassVar[str] = "revolute"
    rows: ClassVar[int] = 2
    unit: ClassVar[str] = "rad"
    conditions: ClassVar[tuple] = ("pin", "locked", "clamp", "torque")
    driven_default: ClassVar[str] = "clamp"
    released: ClassVar[tuple] = ("pin", "torque")
    coupled_rows: ClassVar[tuple] = ("point",)
    coupled_coordinate: ClassVar[str] = "angle"
    holding: ClassVar[tuple] = ("locked", "clamp")
    shares_point: ClassVar[bool] = True

    def rigid_rows(self, pose) -> tuple:
        return ((CON_POINT, 1, NO_DIR, 0.0), (CON_POINT, 2, NO_DIR, 0.0))
