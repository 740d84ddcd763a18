"""Joint kinds.  A joint connects point ``a`` (on body a, or the ground) to point ``b`` (on body b);
its coordinate is measured from a to b.  Each kind knows its constraint rows (the Fortran
flexmech_mbs constraint kind ``code``), its coordinate and the elastic conditions it admits in the
superposition models.  A new joint kind is one class here and one constraint kind in flexmech_mbs.

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
    code: ClassVar[int] = 0
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

    @property
    def angular(self) -> bool:
        """The joint coordinate is an angle (rad), not a displacement (m)."""
        return self.unit == "rad"


@dataclass
class Revolute(Joint):
    kind: ClassVar[str] = "revolute"
    code: ClassVar[int] = 1
    rows: ClassVar[int] = 2
    unit: ClassVar[str] = "rad"
    conditions: ClassVar[tuple] = ("pin", "locked", "clamp", "torque")
    driven_default: ClassVar[str] = "clamp"
    released: ClassVar[tuple] = ("pin", "torque")


@dataclass
class Prismatic(Joint):
    """A guide fixed to body a through point a, along ``axis`` (a global direction in the assembly
    configuration); point b slides along it, body b keeps its angle to body a."""

    axis: tuple = (1.0, 0.0)

    kind: ClassVar[str] = "prismatic"
    code: ClassVar[int] = 2
    rows: ClassVar[int] = 2
    unit: ClassVar[str] = "m"
    conditions: ClassVar[tuple] = ("free", "locked", "force")
    driven_default: ClassVar[str] = "locked"
    released: ClassVar[tuple] = ("free", "force")

    def spec(self) -> dict:
        return {**super().spec(), "axis": [float(x) for x in self.axis]}

    def unit_axis(self) -> np.ndarray:
        u = np.asarray(self.axis, float)
        return u / np.linalg.norm(u)


@dataclass
class Weld(Joint):
    kind: ClassVar[str] = "weld"
    code: ClassVar[int] = 3
    rows: ClassVar[int] = 3
    unit: ClassVar[str] = "rad"
    conditions: ClassVar[tuple] = ("rigid",)
    driven_default: ClassVar[str] = "rigid"
    released: ClassVar[tuple] = ()


JOINT_KINDS = {cls.kind: cls for cls in (Revolute, Prismatic, Weld)}
