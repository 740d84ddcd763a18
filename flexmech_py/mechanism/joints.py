"""Joint kinds.  A joint connects point ``a`` (on body a, or the ground) to point ``b`` (on body b);
its coordinate is measured from a to b.  Each kind knows its constraint rows and its coordinate as
rows of the one Fortran constraint vocabulary (:mod:`flexmech_py.mechanism.rows`: the index of the
row routine in flexmech_markers, its parameters), and the elastic conditions it admits in the
superposition models.

Elastic condition (what the joint transmits in the elastic problem of the superposition models;
the first of ``conditions`` is the default of an undriven joint, ``driven_default`` of a driven one):

- revolute: ``pin`` (relative elastic rotation free), ``locked`` (one shared elastic rotation;
  ``clamp`` is the same and the usual word at a ground pivot), ``torque`` (free, loaded by the
  joint's force drive).
- prismatic: ``free`` (relative elastic sliding free), ``locked`` (none), ``force`` (free, loaded
  by the joint's force drive).
- weld: ``rigid`` only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .rows import CON_ANGLE, CON_POINT, CON_PROJECTION

_NO_DIR = (0.0, 0.0)

__all__ = ["Joint", "Revolute", "Prismatic", "Weld", "JOINT_KINDS"]


@dataclass
class Joint:
    """Base class: ``name``, point references ``a`` and ``b`` ("body.point", "ground" or
    "ground.<name>"), ``elastic`` condition (None: the default, see the module docstring)."""

    name: str
    a: str
    b: str
    elastic: str | None = None

    kind: ClassVar[str] = ""
    rows: ClassVar[int] = 0
    unit: ClassVar[str] = "rad"
    conditions: ClassVar[tuple] = ()
    driven_default: ClassVar[str] = ""
    released: ClassVar[tuple] = ()     # conditions that leave the joint coordinate free elastically

    def spec(self) -> dict:
        """The joint as a case-file table."""
        d = {"name": self.name, "type": self.kind, "connects": [self.a, self.b]}
        if self.elastic is not None:
            d["elastic"] = self.elastic
        return d

    def default_condition(self, driven: bool) -> str:
        return self.driven_default if driven else self.conditions[0]

    def rigid_rows(self, axis, ref: float) -> tuple:
        """The joint's constraint rows in the rigid-body solver (flexmech_mbs), each ``(kind, aux, d,
        value)`` with g - value = 0 (``kind`` an index of :mod:`.rows`); ``axis``: the guide direction
        in body a's frame, ``ref``: phi_b - phi_a as assembled [rad]."""
        raise NotImplementedError

    def coordinate_row(self, axis) -> tuple:
        """``(kind, aux, d)`` of the joint coordinate (what drives act on)."""
        return (CON_ANGLE, 0, _NO_DIR)

    @property
    def angular(self) -> bool:
        """The joint coordinate is an angle (rad), not a displacement (m)."""
        return self.unit == "rad"


@dataclass
class Revolute(Joint):
    kind: ClassVar[str] = "revolute"
    rows: ClassVar[int] = 2
    unit: ClassVar[str] = "rad"
    conditions: ClassVar[tuple] = ("pin", "locked", "clamp", "torque")
    driven_default: ClassVar[str] = "clamp"
    released: ClassVar[tuple] = ("pin", "torque")

    def rigid_rows(self, axis, ref: float) -> tuple:
        return ((CON_POINT, 1, _NO_DIR, 0.0), (CON_POINT, 2, _NO_DIR, 0.0))


@dataclass
class Prismatic(Joint):
    """A guide fixed to body a through point a, along ``axis`` (a global direction in the assembly
    configuration); point b slides along it, body b keeps its angle to body a."""

    axis: tuple = (1.0, 0.0)

    kind: ClassVar[str] = "prismatic"
    rows: ClassVar[int] = 2
    unit: ClassVar[str] = "m"
    conditions: ClassVar[tuple] = ("free", "locked", "force")
    driven_default: ClassVar[str] = "locked"
    released: ClassVar[tuple] = ("free", "force")

    def spec(self) -> dict:
        return {**super().spec(), "axis": [float(x) for x in self.axis]}

    def rigid_rows(self, axis, ref: float) -> tuple:
        return ((CON_PROJECTION, 0, (-axis[1], axis[0]), 0.0), (CON_ANGLE, 0, _NO_DIR, ref))

    def coordinate_row(self, axis) -> tuple:
        return (CON_PROJECTION, 0, (axis[0], axis[1]))

    def unit_axis(self) -> np.ndarray:
        u = np.asarray(self.axis, float)
        return u / np.linalg.norm(u)


@dataclass
class Weld(Joint):
    kind: ClassVar[str] = "weld"
    rows: ClassVar[int] = 3
    unit: ClassVar[str] = "rad"
    conditions: ClassVar[tuple] = ("rigid",)
    driven_default: ClassVar[str] = "rigid"
    released: ClassVar[tuple] = ()

    def rigid_rows(self, axis, ref: float) -> tuple:
        return ((CON_POINT, 1, _NO_DIR, 0.0), (CON_POINT, 2, _NO_DIR, 0.0), (CON_ANGLE, 0, _NO_DIR, ref))


JOINT_KINDS = {cls.kind: cls for cls in (Revolute, Prismatic, Weld)}
