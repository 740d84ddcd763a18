"""The pin in a slot: point b (the pin, on body b) slides along a straight slot of body a, the line
through point a along ``axis`` (a global direction as drawn, turning with body a); the pin turns freely
in the slot.  Two relative freedoms: the slide along the slot and the rotation.

Its one row is the existing projection row (CON_PROJECTION, d = the slot normal in a's frame: the pin
stays on the slot's line); its coordinate the slide along the slot [m] (CON_PROJECTION, d = the slot
direction), which drives act on.  No new Fortran: a prismatic joint without its angle row.

Reaction: the force normal to the slot that body a exerts on the pin (no moment: the pin turns
freely; no force along the slot unless its slide is held).

Elastic conditions (superposition models): ``free`` (elastic slide free), ``locked`` (no elastic
slide), ``force`` (free, loaded by the joint's force drive); the relative elastic rotation is free.
The superposition models take a slot only on the ground or a rigid body (flexmech_py.models.superposition.slaving refuses
one on a flexible link, naming the joint); in the coupled and nonlinear models the slot may be cut
in a flexible link: its point a is then a mesh node and the slot is the straight line through that
node turning with the node's frame, so the slot moves with the link's deflection there (its
translation and elastic rotation; not its bending between nodes).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ...base import validate as v
from ..rows import CON_PROJECTION
from .base import Joint
from .guide import Guide

__all__ = ["Slot"]


@dataclass
class Slot(Guide):
    #: the slot's drawn length [m] (the outline only; the row is the whole line)
    slot_length: float | None = None

    kind: ClassVar[str] = "slot"
    rows: ClassVar[int] = 1
    conditions: ClassVar[tuple] = ("free", "locked", "force")
    driven_default: ClassVar[str] = "locked"
    released: ClassVar[tuple] = ("free", "force")
    coupled_rows: ClassVar[tuple] = ("normal",)
    holding: ClassVar[tuple] = ("locked",)
    glyph: ClassVar[dict] = {**Joint.glyph, "legend": "⊂⊃ pin in a slot (slot outline)"}
    case_fields: ClassVar[tuple] = ("axis", "slot_length")

    @classmethod
    def fields_from_case(cls, table: dict, where: str) -> dict:
        length = v.num(table, "slot_length", where, positive=True)
        return {**super().fields_from_case(table, where), "slot_length": length}

    def spec(self) -> dict:
        out = super().spec()
        if self.slot_length is not None:
            out["slot_length"] = float(self.slot_length)
        return out

    def rigid_rows(self, pose) -> tuple:
        return ((CON_PROJECTION, 0, (-pose.axis[1], pose.axis[0]), 0.0),)

    def glyph_shapes(self) -> list:
        """The slot's outline (``slot_length`` long, or reaching past the pin) and the pin's circle."""
        half = None if self.slot_length is None else 0.5 * float(self.slot_length)
        return [{"shape": "slot", "half": half, "axis": [float(x) for x in self.unit_axis()]}]
