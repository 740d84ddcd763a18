"""Joint kinds, one module each (the protocol: :mod:`.base`), and their registry :data:`JOINT_KINDS`.

A new kind is one module here with one :class:`~.base.Joint` subclass, one entry in ``_KINDS`` below
and one row routine in the Fortran constraint vocabulary (docs/architecture.md)."""

from __future__ import annotations

from .base import Joint
from .gear import Gear
from .prismatic import Prismatic
from .revolute import Revolute
from .slot import Slot
from .weld import Weld

__all__ = ["Joint", "Revolute", "Prismatic", "Weld", "Gear", "Slot", "JOINT_KINDS", "case_fields"]

_KINDS = (Revolute, Prismatic, Weld, Gear, Slot)
#: the joint kinds by their case-file ``type``
JOINT_KINDS = {cls.kind: cls for cls in _KINDS}


def case_fields() -> dict:
    """{key: the kinds that take it} of every kind's own case-file keys."""
    out = {}
    for cls in _KINDS:
        for f in cls.case_fields:
            out.setdefault(f, []).append(cls.kind)
    return out
