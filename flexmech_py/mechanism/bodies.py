"""Bodies of a planar mechanism: straight links (flexible or rigid beams) and rigid bodies.

Every body has a frame: a link's frame has its origin at the link *start* and its x axis along the
link (start to end), so its angle is the link angle; a rigid body's frame is parallel to the global
frame in the assembly configuration, with its origin at the centre of mass.  Points on a body are
named: a link has ``start``, ``mid``, ``end``, named fractions of its length and plain fractions
(``"0.25"``); a rigid body has ``centre`` and named points given by their global position in the
assembly configuration.  The rigid-body layer (flexmech_py/mechanism/packing.py, the Fortran
flexmech_mbs) places every body's coordinates at its centre of mass; ``marker`` gives a point's
position relative to it in the body frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..base.errors import CaseError

__all__ = ["Link", "RigidBody", "LINK_POINTS"]

LINK_POINTS = {"start": 0.0, "mid": 0.5, "end": 1.0}


@dataclass
class Link:
    """A straight beam from ``start`` to ``end`` (assembly positions [m]).

    Section: ``area`` [m^2], ``second_moment`` [m^4], ``youngs_modulus`` [Pa], ``density``
    [kg/m^3], ``half_depth`` [m] (distance of the outer fibre from the axis, for strains).
    ``rigid``: no elastic DOFs; a rigid link's mass is its bar's (density x area) or ``mass`` with
    ``inertia`` about its centre at fraction ``centre``.  ``points``: named fractions of the length.
    ``lumped``: point masses [(fraction, kg)], ``hubs``: rotary inertias turning with the link
    [(fraction, kg m^2)] (from the case's point_masses and rotary_inertias)."""

    name: str
    start: tuple
    end: tuple
    area: float | None = None
    second_moment: float | None = None
    youngs_modulus: float | None = None
    density: float | None = None
    half_depth: float | None = None
    elements: int | None = None
    rigid: bool = False
    mass: float | None = None
    inertia: float | None = None
    centre: float = 0.5
    yield_strain: float | None = None
    section: dict | None = None       # the section table it was given by (flexmech_py.mechanism.sections), if any
    material: dict | None = None      # its resolved material (flexmech_py.mechanism.materials), if given
    points: dict = field(default_factory=dict)
    lumped: list = field(default_factory=list)
    hubs: list = field(default_factory=list)
    nominal_length: float | None = None    # the length as given (equal to |end - start| within 1e-9)

    kind = "link"

    @property
    def length(self) -> float:
        if self.nominal_length is not None:
            return self.nominal_length
        return math.hypot(self.end[0] - self.start[0], self.end[1] - self.start[1])

    @property
    def angle(self) -> float:
        """Axis angle in the assembly configuration [rad]."""
        return math.atan2(self.end[1] - self.start[1], self.end[0] - self.start[0])

    @property
    def flexible(self) -> bool:
        return not self.rigid

    def point_names(self) -> list[str]:
        return list(LINK_POINTS) + list(self.points)

    def fraction(self, point: str, where: str = "point") -> float:
        """The fraction of the length [0, 1] of a named point or a plain fraction ``"0.25"``."""
        if point in LINK_POINTS:
            return LINK_POINTS[point]
        if point in self.points:
            return float(self.points[point])
        try:
            f = float(point)
        except ValueError:
            raise CaseError(where, f"link {self.name!r} has no point {point!r}; its points are "
                                   f"{', '.join(self.point_names())} or a fraction 0..1") from None
        if not 0.0 <= f <= 1.0:
            raise CaseError(where, f"fraction {f} of link {self.name!r} must lie in [0, 1]")
        return f

    def position(self, point: str, where: str = "point") -> np.ndarray:
        """Assembly position of a point [m]."""
        w = self.fraction(point, where)
        return (1.0 - w) * np.asarray(self.start, float) + w * np.asarray(self.end, float)

    def mass_properties(self) -> tuple[float, float, float]:
        """(mass [kg], centre of mass along the axis from the start [m], rotary inertia about the
        centre of mass [kg m^2]): the bar (or the given mass and inertia), the point masses and hubs."""
        L = self.length
        if self.mass is not None:
            m, xc = self.mass, self.centre * L
            j_c = self.inertia if self.inertia is not None else self.mass * L * L / 12.0
            s, j0 = m * xc, j_c + m * xc * xc                  # first and second moments about the start
        else:
            m = self.density * self.area * L
            s, j0 = m * L / 2.0, m * L * L / 3.0
        for frac, mass in self.lumped:
            m, s, j0 = m + mass, s + mass * frac * L, j0 + mass * (frac * L) ** 2
        j0 += sum(j for _, j in self.hubs)
        xc = s / m
        return m, xc, j0 - m * xc * xc

    def marker(self, point: str, where: str = "point") -> np.ndarray:
        """Position of a point relative to the centre of mass in the link frame [m]."""
        _, xc, _ = self.mass_properties()
        return np.array([self.fraction(point, where) * self.length - xc, 0.0])

    def centre_of_mass(self) -> np.ndarray:
        """Assembly position of the centre of mass [m]."""
        _, xc, _ = self.mass_properties()
        return np.asarray(self.start, float) + xc * np.array([math.cos(self.angle), math.sin(self.angle)])


@dataclass
class RigidBody:
    """A rigid body that is not a beam: ``mass`` [kg], rotary ``inertia`` about its centre of mass
    [kg m^2], its ``centre`` of mass and named ``points`` at their assembly positions [m]."""

    name: str
    mass: float
    inertia: float
    centre: tuple
    points: dict = field(default_factory=dict)

    kind = "body"
    angle = 0.0            # its frame is parallel to the global frame in the assembly configuration
    flexible = False
    rigid = True

    def point_names(self) -> list[str]:
        return ["centre"] + list(self.points)

    def position(self, point: str, where: str = "point") -> np.ndarray:
        if point == "centre":
            return np.asarray(self.centre, float)
        if point not in self.points:
            raise CaseError(where, f"body {self.name!r} has no point {point!r}; its points are "
                                   f"{', '.join(self.point_names())}")
        return np.asarray(self.points[point], float)

    def mass_properties(self) -> tuple[float, float, float]:
        return self.mass, 0.0, self.inertia

    def marker(self, point: str, where: str = "point") -> np.ndarray:
        return self.position(point, where) - np.asarray(self.centre, float)

    def centre_of_mass(self) -> np.ndarray:
        return np.asarray(self.centre, float)
