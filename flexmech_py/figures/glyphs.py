"""How a drawn mechanism looks: the glyph of every joint kind, of the ground and of every body kind,
and the joints' places among the drawn points.  One table for every drawing: the PNG panels and GIF
of :mod:`flexmech_py.figures.drawing` (matplotlib) and the page of :mod:`flexmech_py.view` (a canvas) both
read it.  A joint kind's glyph is declared by its module (``Joint.glyph``,
:mod:`flexmech_py.mechanism.joints`): the table below is read from the kinds, so a new kind brings its
glyph with it.  Colours are CSS hex strings (matplotlib
takes them too), sizes in points (1/72 in).  Nothing here draws or computes physics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..mechanism.joints import JOINT_KINDS, Joint

__all__ = ["JOINT_GLYPHS", "GROUND_PIVOT", "GROUND_GUIDE", "BODY_STYLES", "BODY_COLOURS", "RIGID_GHOST",
           "JointMark", "joint_marks", "glyph_of", "legend_words", "shape_lines", "table"]

#: joint kind -> its mark at the joint's point (``Joint.glyph`` of the kind's module): ``marker`` circle |
#: square, ``size`` [pt], ``fill`` of an undriven joint, ``driven_fill`` of a joint with a drive, ``edge``
#: colour; ``legend`` its word
JOINT_GLYPHS = {kind: dict(cls.glyph) for kind, cls in JOINT_KINDS.items()}
#: a joint to the ground other than a guided one: a triangle under the ground point
GROUND_PIVOT = {"marker": "triangle", "size": 11.0, "fill": "#d9d9d9", "edge": "#000000", "legend": "▲ ground pivot"}
#: a guided joint's guide on the ground (Joint.guided): a line through the ground point along the joint's axis
GROUND_GUIDE = {"colour": "#595959", "width": 1.0, "legend": "(grey line: its guide on the ground)"}
#: body kind (flexmech_py.models.shapes.KINDS) -> its deformed line: ``width`` [pt], ``fill`` opacity of a
#: rigid body's outline (0: none)
BODY_STYLES = {"flexible": {"width": 2.4, "fill": 0.0}, "rigid_link": {"width": 3.2, "fill": 0.0},
               "body": {"width": 3.2, "fill": 0.25}}
#: the bodies' colours, in the order of the drawn bodies (matplotlib's C0, C2, C3, C4, C5, C1, C6, C8, C9)
BODY_COLOURS = ("#1f77b4", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#ff7f0e", "#e377c2", "#bcbd22", "#17becf")
#: the rigid configuration under the deformed one: thin, grey, dashed (``dash`` on, off [pt])
RIGID_GHOST = {"colour": "#8c8c8c", "width": 1.0, "dash": (4.0, 3.0)}


def glyph_of(kind: str) -> dict:
    """The glyph of a joint kind (an unknown kind is drawn with the protocol's default glyph)."""
    return JOINT_GLYPHS.get(kind, Joint.glyph)


@dataclass
class JointMark:
    """Where a joint is drawn: ``point`` the index of its non-ground side's point among the drawn
    points (None when that point is not drawn), ``ground`` the ground point [m] when one side is the
    ground (else None), ``axis`` the unit direction of a guided joint's guide on the ground; ``ends`` its
    two sides a and b: a point index among the drawn points, the ground point [m], or None (not drawn),
    for the kind's own outline (``Joint.glyph_shapes``, :func:`shape_lines`)."""

    name: str
    kind: str
    point: int | None
    ground: np.ndarray | None
    axis: np.ndarray | None
    driven: bool
    joint: object = None
    ends: tuple = (None, None)


def joint_marks(mech, sf) -> list[JointMark]:
    """The marks of every joint of ``mech`` in the point layout of ``sf`` (a ShapeFrames): the point of
    its side b (of a if b is the ground)."""
    driven = {d.joint for d in mech.drives}
    out = []
    for j in mech.joints:
        a, b = mech.joint_points(j)
        side = b if b.body is not None else a
        grounded = a.body is None or b.body is None
        ground = np.asarray((a if a.body is None else b).position, float) if grounded else None
        axis = np.asarray(j.unit_axis(), float) if grounded and j.guided else None
        ends = tuple(np.asarray(p.position, float) if p.body is None else _drawn_point(sf, p) for p in (a, b))
        out.append(JointMark(j.name, j.kind, _drawn_point(sf, side), ground, axis, j.name in driven, j, ends))
    return out


def _drawn_point(sf, p) -> int | None:
    """The index of point reference ``p`` (on a body) among sf's drawn points (None: not drawn)."""
    label = f"{p.body.fraction(p.point):.12g}" if p.body.kind == "link" and not p.body.rigid else p.point
    return sf.point(p.body.name, label)


def legend_words(marks) -> list[str]:
    """The legend of the joint glyphs drawn (only those present)."""
    words = [Joint.glyph["legend"]]
    if any(m.driven for m in marks):
        words.append("● driven joint")
    if any(m.ground is not None and m.axis is None for m in marks):
        words.append(GROUND_PIVOT["legend"])
    for kind in sorted({m.kind for m in marks}):
        legend = glyph_of(kind)["legend"]
        if legend in words:
            continue
        guides = any(m.axis is not None and m.kind == kind for m in marks)
        words.append(legend + (" " + GROUND_GUIDE["legend"] if guides else ""))
    return words


def shape_lines(shapes: list, pa, pb) -> list:
    """Polylines ((n, 2) arrays [m]) of a joint kind's outline (``Joint.glyph_shapes``) at its two points'
    drawn positions pa, pb.  The page's ``shapeLines`` (view_mechanism.js) draws the same shapes."""
    pa, pb = np.asarray(pa, float), np.asarray(pb, float)
    ring = _ring(73)
    out = []
    for sh in shapes:
        if sh["shape"] == "circle":
            out.append((pa, pb)[sh["at"]] + sh["radius"] * ring)
        elif sh["shape"] == "segment":
            out.append(np.array([pa, pb]))
        elif sh["shape"] == "slot":
            out.extend(_slot_lines(sh, pa, pb))
    return out


def _ring(n: int) -> np.ndarray:
    t = np.linspace(0.0, 2.0 * np.pi, n)[:, None]
    return np.hstack([np.cos(t), np.sin(t)])


def _slot_lines(sh: dict, pa, pb) -> list:
    """A slot's stadium centred on pa along the line to the pin pb (its axis when pb is on pa), half
    length ``half`` or 1.15 |pb - pa|, width a tenth of it; the pin's circle about pb."""
    d = pb - pa
    dist = float(np.hypot(*d))
    u = d / dist if dist > 1e-9 else np.asarray(sh["axis"], float)
    half = sh["half"] if sh["half"] is not None else 1.15 * dist
    w = 0.05 * max(half, 1e-3)
    n = np.array([-u[1], u[0]])
    t = np.linspace(-0.5 * np.pi, 0.5 * np.pi, 13)[:, None]
    cap = np.cos(t) * u + np.sin(t) * n
    outline = np.vstack([pa + half * u + w * cap, pa - half * u - w * cap])
    return [np.vstack([outline, outline[:1]]), pb + 0.8 * w * _ring(25)]


def table() -> dict:
    """The whole description as plain data (what the page of :mod:`flexmech_py.view` draws with)."""
    return {"joints": JOINT_GLYPHS, "ground_pivot": GROUND_PIVOT, "ground_guide": GROUND_GUIDE,
            "bodies": BODY_STYLES, "colours": list(BODY_COLOURS),
            "ghost": dict(RIGID_GHOST, dash=list(RIGID_GHOST["dash"]))}
