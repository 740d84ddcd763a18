"""The joint protocol: what every joint kind declares (docs/architecture.md, "Adding a joint kind").

A joint connects point ``a`` (on body a, or the ground) to point ``b`` (on body b); its coordinate is
measured from a to b.  A kind is one module of this package holding one subclass of :class:`Joint`:
its case fields (:meth:`Joint.fields_from_case`, :meth:`Joint.spec`) and their validation
(:meth:`Joint.check`), its rigid-body constraint rows and coordinate as rows of the one Fortran
constraint vocabulary (:meth:`Joint.rigid_rows`, :meth:`Joint.coordinate_row`: indices of
:mod:`flexmech_py.mechanism.rows`, the row routines of flexmech_markers), its rows in
the coupled and nonlinear models (``coupled_rows``, ``coupled_coordinate``, ``holding``), its joint
coordinate (``unit``), what its reaction transmits (``shares_point``, ``ties_rotation``, ``guided``)
and its glyph in drawings.  Solvers, outputs, reactions, drawings and templates read these
attributes; none asks which kind a joint is.

Elastic condition (what the joint transmits in the elastic problem of the superposition models; the
first of ``conditions`` is the default of an undriven joint, ``driven_default`` of a driven one).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ..rows import CON_ANGLE

__all__ = ["Joint", "NO_DIR"]

#: the direction parameter of a row that takes none
NO_DIR = (0.0, 0.0)


@dataclass
class Joint:
    """Base class: ``name``, point references ``a`` and ``b`` ("body.point", "ground" or
    "ground.<name>"), ``elastic`` condition (None: the default, see the module docstring)."""

    name: str
    a: str
    b: str
    elastic: str | None = None

    #: the case file's ``type``
    kind: ClassVar[str] = ""
    #: the number of rigid-body constraint rows (:meth:`rigid_rows`)
    rows: ClassVar[int] = 0
    #: the joint coordinate's unit: "rad" (an angle) or "m" (a slide)
    unit: ClassVar[str] = "rad"
    conditions: ClassVar[tuple] = ()
    driven_default: ClassVar[str] = ""
    #: conditions that leave the joint coordinate free elastically
    released: ClassVar[tuple] = ()
    #: the coupled and nonlinear models' rows (roles of flexmech_markers rows: "point" = 2 rows or
    #: shared position DOFs, "normal" = the guide's normal projection, "angle" = the relative angle
    #: held) and the measure of the joint coordinate a drive acts on ("angle" or "slide")
    coupled_rows: ClassVar[tuple] = ()
    coupled_coordinate: ClassVar[str] = "angle"
    #: elastic conditions that hold the joint coordinate at its initial value in those models
    holding: ClassVar[tuple] = ()
    #: the two points coincide (the joint's force has x and y components; shared position DOFs)
    shares_point: ClassVar[bool] = False
    #: the rows always tie the relative rotation of the two bodies (a moment in the reaction)
    ties_rotation: ClassVar[bool] = False
    #: point b slides along a guide fixed to body a (its reaction is normal to the guide)
    guided: ClassVar[bool] = False
    #: the joint leaves a relative motion free: a coordinate to drive and measure
    has_coordinate: ClassVar[bool] = True
    #: the joint's mark at its point in every drawing (flexmech_py.figures.glyphs: the PNGs of flexmech_py.figures.drawing
    #: and the page of flexmech_py.view): ``marker`` circle | square | triangle, ``size`` [pt], ``fill``
    #: of an undriven joint, ``driven_fill`` of a driven one, ``edge`` colour (CSS hex), ``legend`` its
    #: words in a legend
    glyph: ClassVar[dict] = {"marker": "circle", "size": 5.5, "fill": "#ffffff", "driven_fill": "#000000",
                             "edge": "#000000", "legend": "o joint"}

    #: the kind's own keys in a case file's joint table (beside name, type, connects, elastic)
    case_fields: ClassVar[tuple] = ()

    @classmethod
    def fields_from_case(cls, table: dict, where: str) -> dict:
        """The kind's own fields of a case file's joint table (validated; CaseError naming the field)."""
        return {}

    def spec(self) -> dict:
        """The joint as a case-file table."""
        d = {"name": self.name, "type": self.kind, "connects": [self.a, self.b]}
        if self.elastic is not None:
            d["elastic"] = self.elastic
        return d

    def check(self) -> None:
        """CaseError when the kind's own fields are unusable (the mechanism's check calls it)."""

    def rigid_rows(self, pose) -> tuple:
        """The joint's constraint rows in the rigid-body solver (flexmech_mbs), each ``(kind, aux, d,
        value)`` with g - value = 0 (``kind`` an index of :mod:`flexmech_py.mechanism.rows`); ``pose``:
        the joint's markers as assembled (:class:`flexmech_py.mechanism.packing.Pose`: angles,
        positions, a guided kind's guide direction in body a's frame)."""
        raise NotImplementedError(f"joint kind {self.kind!r} declares no rigid rows")

    def coordinate_row(self, axis) -> tuple:
        """``(kind, aux, d)`` of the joint coordinate (what drives act on and outputs measure)."""
        return (CON_ANGLE, 0, NO_DIR)

    def rotation_weights(self) -> tuple:
        """(w_a, w_b) of the elastic rotation relation w_a rot_a + w_b rot_b = 0 the superposition
        models hold when the rotation is tied (flexmech_py.models.superposition.slaving): (-1, 1), the same rotation."""
        return (-1.0, 1.0)

    def check_placed(self, a, b) -> None:
        """CaseError when the joint's drawn points (PointRefs a, b) do not fit the kind (e.g. a centre
        distance its radii fix); the mechanism's check calls it after :meth:`check`."""

    def own_rows(self, pose) -> list:
        """A kind whose coupled rows include the role ``own``: its rows ``(role, kind, aux, d)`` in the
        coupled and nonlinear models, each held at :meth:`held_values` on the rigid motion."""
        return []

    def held_values(self, role: str, ang_a, ang_b, pa, pb):
        """(N,) the value of the own row ``role`` given the markers' frame angles (N,) as the model
        takes them and positions (N, 2) over the rigid motion (see :meth:`own_rows`)."""
        raise NotImplementedError(f"joint kind {self.kind!r} has no own rows")

    def reaction_from(self, lam, pa, pb):
        """(N, 3) [F_x, F_y, M] body a exerts on body b at b's point, from the multipliers ``lam`` (N,
        rows) of the kind's own rows and the two points' positions pa, pb (N, 2); None for a kind whose
        reaction follows from ``shares_point``/``ties_rotation``/``guided`` alone."""
        return None

    def reaction_units(self, pa, pb):
        """For a kind with :meth:`reaction_from`: ((force (N, 2), moment (N,)) on b at its point, the same
        on a at its point) of a unit multiplier of its own row, given the points' positions (the
        superposition models' reaction equations take them as its unknown's columns); None otherwise."""
        return None

    def glyph_shapes(self) -> list:
        """The kind's own outline beside its marker, as plain data that every drawing evaluates at the
        two points' drawn positions (flexmech_py.figures.glyphs.shape_lines for the PNGs, the page's
        shapeLines for the browser view): a list of ``{"shape": "circle", "at": 0 | 1, "radius": r}``
        (a circle about point a or b), ``{"shape": "segment"}`` (a to b) and ``{"shape": "slot",
        "half": h | None, "axis": [x, y]}`` (a slot's outline centred on a along the line from a to the
        pin b, ``h`` its half length or None: 1.15 |b - a|, ``axis`` the line when b is on a, and the
        pin's circle); none for most kinds."""
        return []

    def default_condition(self, driven: bool) -> str:
        return self.driven_default if driven else self.conditions[0]

    @property
    def angular(self) -> bool:
        """The joint coordinate is an angle (rad), not a displacement (m)."""
        return self.unit == "rad"

