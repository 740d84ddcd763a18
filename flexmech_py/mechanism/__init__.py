"""The mechanism: bodies, points, typed joints, drives, and their rigid-body mechanics.

The hub of flexmech: the case schema builds a :class:`Mechanism` (templates expand into one), the
finite-element models and every study take one.  See docs/cases.md ("Mechanisms") and
docs/theory.md section 17.
"""

from .analysis import MotionSetup, prepare_motion
from .bodies import Link, RigidBody
from .drives import Drive
from .joints import JOINT_KINDS, Joint, Prismatic, Revolute, Weld
from .motion import LinkMotion, MotionSource, RigidMotion
from .schema import mechanism_from_spec, mechanism_spec
from .system import GROUND, Mechanism, PointRef

__all__ = ["Mechanism", "Link", "RigidBody", "Joint", "Revolute", "Prismatic", "Weld", "JOINT_KINDS", "Drive",
           "PointRef", "GROUND", "MotionSetup", "prepare_motion", "MotionSource", "RigidMotion", "LinkMotion",
           "mechanism_from_spec", "mechanism_spec"]
