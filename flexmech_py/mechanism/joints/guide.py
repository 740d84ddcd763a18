"""What the guided joint kinds share (a straight guide fixed to body a through point a, along ``axis``,
a global direction in the drawn configuration): the case field, its check, the unit direction and the
coordinate (the slide of point b along the guide [m], a CON_PROJECTION on the guide direction)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ...base import validate as v
from ...base.errors import CaseError
from ..rows import CON_PROJECTION
from .base import Joint

__all__ = ["Guide"]


@dataclass
class Guide(Joint):
    axis: tuple = (1.0, 0.0)

    unit: ClassVar[str] = "m"
    coupled_coordinate: ClassVar[str] = "slide"
    guided: ClassVar[bool] = True

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

    def coordinate_row(self, axis) -> tuple:
        return (CON_PROJECTION, 0, (axis[0], axis[1]))
