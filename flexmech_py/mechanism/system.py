"""The mechanism: bodies, ground points, typed joints and drives: the hub every model starts from.

Nothing here knows a mechanism type: a four-bar or a serial chain is a Mechanism built by
:mod:`flexmech_py.mechanism.templates`.  Build one from Python with the ``add_*`` methods or from a
plain dict (:func:`flexmech_py.mechanism.schema.mechanism_from_spec`, the case-file tables); write it
back with :func:`flexmech_py.mechanism.schema.mechanism_spec`.  Rigid-body analysis lives in ``analysis`` and ``motion``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..base.errors import CaseError
from .bodies import Link, RigidBody
from .drives import Drive
from .joints import JOINT_KINDS, Joint

__all__ = ["Mechanism", "PointRef", "GROUND"]

GROUND = "ground"


@dataclass(frozen=True)
class PointRef:
    """A resolved point: ``body`` (None: the ground), ``point`` name, ``position`` in the assembly [m]."""

    body: object
    point: str
    position: tuple

    @property
    def on_ground(self) -> bool:
        return self.body is None

    @property
    def label(self) -> str:
        return f"{GROUND}.{self.point}" if self.body is None else f"{self.body.name}.{self.point}"


class Mechanism:
    """Bodies (links first, then rigid bodies: their order is the body numbering), named ground
    points, joints in order, drives, and the initial state (``initial_coordinates`` moves joints from
    the drawn configuration, ``initial_speeds`` gives the speed of free coordinates)."""

    def __init__(self):
        self.links: list[Link] = []
        self.rigid_bodies: list[RigidBody] = []
        self.ground: dict[str, tuple] = {}
        self.joints: list[Joint] = []
        self.drives: list[Drive] = []
        self.initial_coordinates: dict[str, float] = {}
        self.initial_speeds: dict[str, float] = {}
        self.template: dict | None = None          # how a template built it (provenance only)

    # ------------------------------------------------------------------ building
    def add_link(self, name: str, start, end=None, *, length=None, angle=None, where: str | None = None,
                 **props) -> Link:
        """A link from ``start`` to ``end`` (positions [m] or point references such as "ground.O2"),
        or from ``start`` with ``length`` [m] and ``angle`` [rad]; ``props``: the Link fields;
        ``where``: the field prefix of error messages (default ``links.<name>``)."""
        where = where or f"links.{name}"
        p0 = self._at(start, f"{where}.start")
        if end is None:
            if length is None or angle is None:
                raise CaseError(where, "give 'end', or 'length' and 'angle'")
            p1 = p0 + length * np.array([math.cos(angle), math.sin(angle)])
        else:
            p1 = self._at(end, f"{where}.end")
        link = Link(name=name, start=tuple(map(float, p0)), end=tuple(map(float, p1)),
                    nominal_length=None if length is None else float(length), **props)
        self._new_body(link)
        self.links.append(link)
        return link

    def add_body(self, name: str, mass: float, inertia: float, centre, points=None, where: str | None = None) -> RigidBody:
        """A rigid body with ``mass`` [kg], ``inertia`` about its centre of mass [kg m^2], its
        ``centre`` and named ``points`` (positions [m] or point references)."""
        where = where or f"bodies.{name}"
        c = self._at(centre, f"{where}.centre")
        pts = {k: tuple(map(float, self._at(v, f"{where}.points.{k}"))) for k, v in (points or {}).items()}
        body = RigidBody(name=name, mass=float(mass), inertia=float(inertia), centre=tuple(map(float, c)), points=pts)
        self._new_body(body)
        self.rigid_bodies.append(body)
        return body

    def add_ground_point(self, name: str, position) -> None:
        self.ground[name] = tuple(map(float, position))

    def add_joint(self, kind: str, name: str, a: str, b: str, elastic: str | None = None, **extra) -> Joint:
        """A joint of ``kind`` (a key of mechanism.joints.JOINT_KINDS) from point ``a`` to point ``b``."""
        if kind not in JOINT_KINDS:
            raise CaseError(f"joints.{name}.type", f"must be one of {', '.join(map(repr, JOINT_KINDS))}, got {kind!r}")
        if any(j.name == name for j in self.joints):
            raise CaseError(f"joints.{name}", "duplicate joint name; give each joint its own name")
        joint = JOINT_KINDS[kind](name=name, a=a, b=b, elastic=elastic, **extra)
        self.joints.append(joint)
        return joint

    def add_drive(self, joint: str, law: str, **params) -> Drive:
        drive = Drive(joint=joint, law=law, params=params)
        self.drives.append(drive)
        return drive

    def _new_body(self, body) -> None:
        if body.name == GROUND or body.name in self.body_names():
            raise CaseError(f"{body.kind}s.{body.name}", f"the name {body.name!r} is taken; give each body its own name")

    def _at(self, where_or_point, where: str) -> np.ndarray:
        if isinstance(where_or_point, str):
            return np.asarray(self.point(where_or_point, where).position, float)
        v = np.asarray(where_or_point, float)
        if v.shape != (2,) or not np.all(np.isfinite(v)):
            raise CaseError(where, f"must be [x, y] in metres or a point reference, got {where_or_point!r}")
        return v

    # ------------------------------------------------------------------ lookup
    @property
    def bodies(self) -> list:
        """Every body in numbering order: the links, then the rigid bodies."""
        return self.links + self.rigid_bodies

    def body_names(self) -> list[str]:
        return [b.name for b in self.bodies]

    def body(self, name: str, where: str = "body"):
        for b in self.bodies:
            if b.name == name:
                return b
        raise CaseError(where, f"unknown body {name!r}; bodies are {', '.join(self.body_names()) or 'none'}")

    def body_index(self, body) -> int:
        """0-based body number (None for the ground), by name: ``body`` may be the same body of a copy of
        this mechanism (a probe's remeshed case reads the rigid motion of the run's)."""
        return None if body is None else next(i for i, b in enumerate(self.bodies) if b.name == body.name)

    def link_index(self, name: str) -> int:
        return next(i for i, ln in enumerate(self.links) if ln.name == name)

    def joint(self, name: str, where: str = "joint") -> Joint:
        for j in self.joints:
            if j.name == name:
                return j
        raise CaseError(where, f"unknown joint {name!r}; joints are {', '.join(j.name for j in self.joints) or 'none'}")

    def point(self, ref: str, where: str = "point", other: str | None = None) -> PointRef:
        """Resolve "body.point", "ground.<name>" or "ground" (then at the position of ``other``)."""
        if not isinstance(ref, str) or not ref:
            raise CaseError(where, f"must be a point reference such as 'crank.end' or 'ground.O2', got {ref!r}")
        name, _, pt = ref.partition(".")
        if name == GROUND:
            if not pt:
                if other is None:
                    raise CaseError(where, "a bare 'ground' needs the joint's other point to locate it")
                return PointRef(None, f"@{other}", tuple(self.point(other, where).position))
            if pt not in self.ground:
                raise CaseError(where, f"unknown ground point {pt!r}; ground points are "
                                       f"{', '.join(self.ground) or 'none'} (mechanism.ground)")
            return PointRef(None, pt, self.ground[pt])
        if not pt:
            raise CaseError(where, f"{ref!r} must name a point of body {name!r}, e.g. '{name}.end'")
        body = self.body(name, where)
        return PointRef(body, pt, tuple(body.position(pt, where)))

    def joint_points(self, joint: Joint, where: str | None = None) -> tuple[PointRef, PointRef]:
        where = where or f"joints.{joint.name}.connects"
        a = self.point(joint.a, where, other=joint.b)
        b = self.point(joint.b, where, other=joint.a)
        return a, b

    def drive_of(self, joint_name: str) -> Drive | None:
        return next((d for d in self.drives if d.joint == joint_name), None)

    def condition(self, joint: Joint) -> str:
        """The joint's elastic condition (its own, or the default: see joints.py)."""
        if joint.elastic is not None:
            return joint.elastic
        return joint.default_condition(self.drive_of(joint.name) is not None)

    def characteristic_length(self) -> float:
        """The mechanism's length scale [m]: the largest distance between its points (at least the
        longest link)."""
        pts = [np.asarray(p, float) for b in self.bodies for p in (b.position(n) for n in b.point_names())]
        pts += [np.asarray(p, float) for p in self.ground.values()]
        P = np.array(pts)
        span = float(np.max(np.ptp(P, axis=0))) if len(P) > 1 else 0.0
        return max([span] + [ln.length for ln in self.links] + [1e-3])

    # ------------------------------------------------------------------ checks
    def check(self) -> None:
        """Topology checks (each failure: one CaseError naming the field): points exist, a joint joins
        two different bodies, guides have a direction, drives name joints (one each) with a
        law that fits the coordinate, and every body is connected to the ground."""
        if not self.bodies:
            raise CaseError("links", "the mechanism has no bodies; add [[links]] or [[bodies]]")
        if not self.joints:
            raise CaseError("joints", "the mechanism has no joints; add [[joints]] connecting it to the ground")
        for j in self.joints:
            a, b = self.joint_points(j)
            if a.body is b.body:
                raise CaseError(f"joints.{j.name}.connects", "connects a body to itself (or the ground to the ground); "
                                                              "name points on two different bodies")
            cond = self.condition(j)
            if cond not in j.conditions:
                raise CaseError(f"joints.{j.name}.elastic", f"must be one of {', '.join(map(repr, j.conditions))} "
                                                           f"for a {j.kind} joint, got {cond!r}")
            j.check()
            j.check_placed(a, b)
        seen = set()
        for i, d in enumerate(self.drives):
            joint = self.joint(d.joint, f"drives[{i}].joint")
            if d.joint in seen:
                raise CaseError(f"drives[{i}].joint", f"joint {d.joint!r} has two drives; give each joint at most one")
            seen.add(d.joint)
            if not joint.has_coordinate:
                raise CaseError(f"drives[{i}].joint", f"{d.joint!r} is a {joint.kind}: it has no free coordinate to drive")
            if d.law == "force" and not joint.angular and (d.params.get("sin") or d.params.get("cos")):
                raise CaseError(f"drives[{i}].sin", f"harmonics of the joint coordinate need an angle; {d.joint!r} "
                                                    f"is {joint.kind}: use time_harmonics or a table")
        for j in self.joints:
            if self.condition(j) in ("torque", "force") and (self.drive_of(j.name) is None
                                                              or self.drive_of(j.name).kinematic):
                raise CaseError(f"joints.{j.name}.elastic", f"{self.condition(j)!r} leaves the joint free in the "
                                "elastic problem, loaded by its force drive; this joint has no force drive: add one "
                                "([[drives]] law = 'force') or use another condition")
        self._check_connected()

    def _check_connected(self) -> None:
        reach = {None}                     # body names reached from the ground (None)
        edges = []
        for j in self.joints:
            a, b = self.joint_points(j)
            edges.append((a.body and a.body.name, b.body and b.body.name))
        changed = True
        while changed:
            changed = False
            for ba, bb in edges:
                for x, y in ((ba, bb), (bb, ba)):
                    if x in reach and y not in reach:
                        reach.add(y)
                        changed = True
        floating = [b.name for b in self.bodies if b.name not in reach]
        if floating:
            raise CaseError("joints", f"{', '.join(map(repr, floating))} {'is' if len(floating) == 1 else 'are'} not "
                                      "connected to the ground through any chain of joints (a floating body); add a joint")
