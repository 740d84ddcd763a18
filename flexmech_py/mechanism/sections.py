"""Cross-sections of flexible links given by shape: area, second moment and outer-fibre distance.

A link's ``section`` table names a ``shape`` and its dimensions [m] (docs/cases.md, "Sections and
materials"; the formulas are docs/theory.md section 22.1).  Every shape here is symmetric about the
bending axis (the link's axis in the plane of the mechanism), so both outer fibres lie at the same
distance ``c`` = ``half_depth`` from it.  The dimension that lies in the plane of motion is
``height`` (or ``diameter``); ``width`` is out of the plane.

- ``rectangle``: ``width``, ``height``
- ``circle``: ``diameter``
- ``tube``: ``outer_diameter``, ``wall``
- ``hollow_rectangle``: ``width``, ``height``, ``wall``
- ``i_section``: ``width`` (flanges), ``height`` (overall), ``flange`` (flange thickness), ``web`` (web thickness)

Every error is a CaseError naming the field and the fix.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..base import validate as v
from ..base.errors import CaseError

__all__ = ["SectionProperties", "SHAPES", "section_properties"]

#: each shape's dimensions, in the order the formulas take them
SHAPES = {
    "rectangle": ("width", "height"),
    "circle": ("diameter",),
    "tube": ("outer_diameter", "wall"),
    "hollow_rectangle": ("width", "height", "wall"),
    "i_section": ("width", "height", "flange", "web"),
}


@dataclass(frozen=True)
class SectionProperties:
    """Area A [m^2], second moment I [m^4] about the bending axis and outer-fibre distance c [m]."""

    area: float
    second_moment: float
    half_depth: float

    @property
    def section_modulus(self) -> float:
        """Z = I / c [m^3]: the bending moment per unit outer-fibre stress."""
        return self.second_moment / self.half_depth


def _rectangle(b, h):
    return b * h, b * h ** 3 / 12.0, 0.5 * h


def _circle(d):
    return math.pi * d ** 2 / 4.0, math.pi * d ** 4 / 64.0, 0.5 * d


def _tube(d, t):
    di = d - 2.0 * t
    return math.pi * (d ** 2 - di ** 2) / 4.0, math.pi * (d ** 4 - di ** 4) / 64.0, 0.5 * d


def _hollow_rectangle(b, h, t):
    bi, hi = b - 2.0 * t, h - 2.0 * t
    return b * h - bi * hi, (b * h ** 3 - bi * hi ** 3) / 12.0, 0.5 * h


def _i_section(b, h, tf, tw):
    hw = h - 2.0 * tf
    return 2.0 * b * tf + hw * tw, (b * h ** 3 - (b - tw) * hw ** 3) / 12.0, 0.5 * h


_FORMULAS = {"rectangle": _rectangle, "circle": _circle, "tube": _tube, "hollow_rectangle": _hollow_rectangle,
             "i_section": _i_section}


def _check_consistent(shape: str, d: dict, where: str) -> None:
    """Dimensions that leave no section: a wall as thick as the radius, flanges taller than the height."""
    if shape == "tube" and d["wall"] >= 0.5 * d["outer_diameter"]:
        raise CaseError(f"{where}.wall", f"({d['wall']:g} m) is at least the outer radius "
                                         f"({0.5 * d['outer_diameter']:g} m): a tube's wall must be thinner than "
                                         "its radius; use shape = 'circle' for a solid bar, or a thinner wall")
    if shape == "hollow_rectangle" and 2.0 * d["wall"] >= min(d["width"], d["height"]):
        raise CaseError(f"{where}.wall", f"({d['wall']:g} m) leaves no hollow: two walls must be thinner than "
                                         f"the width and the height ({min(d['width'], d['height']):g} m); use "
                                         "shape = 'rectangle' for a solid bar, or a thinner wall")
    if shape == "i_section":
        if 2.0 * d["flange"] >= d["height"]:
            raise CaseError(f"{where}.flange", f"({d['flange']:g} m): two flanges must be thinner than the "
                                               f"height ({d['height']:g} m); give a thinner flange or a taller section")
        if d["web"] > d["width"]:
            raise CaseError(f"{where}.web", f"({d['web']:g} m) is wider than the flanges ({d['width']:g} m); "
                                            "give web <= width")


def section_properties(spec, where: str) -> tuple[dict, SectionProperties]:
    """(resolved section table, its properties) of a link's ``section`` table at ``where``
    (e.g. ``links[1].section``)."""
    if not isinstance(spec, dict):
        raise CaseError(where, f"must be a table, e.g. {{shape = 'rectangle', width = 0.0254, height = 0.0016}}; "
                               f"got {spec!r}")
    shape = v.text(spec, "shape", where, required=True, choices=tuple(SHAPES))
    v.keys(spec, {"shape", *SHAPES[shape]}, where)
    dims = {k: v.num(spec, k, where, positive=True, required=True) for k in SHAPES[shape]}
    _check_consistent(shape, dims, where)
    area, inertia, c = _FORMULAS[shape](*(dims[k] for k in SHAPES[shape]))
    return {"shape": shape, **dims}, SectionProperties(area, inertia, c)
