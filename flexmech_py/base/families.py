"""Model families: the one registry of the elastic models a run can use (docs/architecture.md).

A family is an object, not a name: its label, what it is (superposition of an elastic deflection on a
rigid-body motion computed first, or one pass with the constraints in the loop; small or large
deflections), what it supports (joint kinds, output kinds) and its defaults (integrator).  The run,
the checks and the studies ask a family for these properties; no other module compares a model name
with a literal (tests/test_architecture.py checks it).  A new family is one entry here and one
implementation behind the run's block protocol (:meth:`flexmech_py.run.simulate.Prepared.blocks`).

This module is a leaf: it imports nothing of the package.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["Family", "FAMILIES", "MODELS", "SUPERPOSITION_MODELS", "family", "names", "superposition_names",
           "large_deflection_reference", "DEFAULT_INTEGRATORS", "AUTO", "AUTO_LADDER", "MODEL_CHOICES", "STUDY_MODEL"]

#: the integrator of a run whose case names none, by kind of family (docs/theory.md section 15.4): the
#: superposition models keep average acceleration (no multipliers in their loop; their golden
#: numbers); the coupled and nonlinear models' constraint multipliers need numerical dissipation
#: (under average acceleration their period-2 dt error grows without bound, whatever the step)
RHO_INF_DEFAULT = 0.8
DEFAULT_INTEGRATORS = {"superposition": {"integrator": "newmark", "beta": 0.25, "gamma": 0.5},
                       "constrained": {"integrator": "generalized-alpha", "rho_inf": RHO_INF_DEFAULT}}


@dataclass(frozen=True)
class Family:
    """One model family.

    ``superposition``: the elastic deflection is superposed on the rigid-body motion (the rigid
    inertia loads drive a linear elastic problem; the Fortran ked kernels); otherwise the family
    integrates the flexible mechanism in one pass with its constraint rows (the coupled kernels).
    ``large_deflection``: follows large rotations of every element and buckling (co-rotational).
    ``element_frames``: one chord frame per element (else one per flexible link); constrained families.
    ``load_code``: the Fortran ked kernels' rigid-inertia load model (superposition families).
    ``load_mass``: the element mass matrix the rigid inertia loads are formed with: "translational"
    (Hac, Eq. 15) or "consistent" (Eq. 14).  ``rotary_loads``: the rigid angular acceleration loads
    the elements' and lumped inertias' rotations.
    ``guides_on_flexible_links``: a guide (Joint.guided: a slider's, a slot's) may be carried by a flexible link.
    ``dof2_bytes``: memory per squared DOF count of the family's set-up and run (flexmech_py.base.sizes; the
    coupled model's condensed solve holds columns per constraint row: measured 17-31 B per ndof^2 at
    9 000-72 000 DOFs).  ``element_bytes``: memory per element when the family's own (0: the
    superposition models' ELEMENT_BYTES of flexmech_py.base.sizes; the nonlinear model's Newton step keeps
    the constraint gradients on their patterns and the bordered saddle band, linear in the mesh:
    measured peak resident memory above the interpreter's 7.7-8.7 kB per element at 3 000-6 000
    elements on the seed four-bar and both six-bars, 3-5 steps; about a factor of two kept as margin).
    """

    name: str
    label: str
    superposition: bool
    large_deflection: bool = False
    element_frames: bool = False
    load_code: int | None = None
    load_mass: str | None = None
    rotary_loads: bool = True
    guides_on_flexible_links: bool = False
    dof2_bytes: int = 0
    element_bytes: int = 0
    outputs_excluded: frozenset = field(default_factory=frozenset)
    #: the superposition family whose rigid-inertia loads an ``inertia_load`` output with model "run"
    #: means in a constrained family (a superposition family means its own)
    run_loads: str | None = None

    @property
    def constrained(self) -> bool:
        """The constraint rows are in the family's time loop (with their multipliers)."""
        return not self.superposition

    @property
    def default_integrator(self) -> dict:
        """The integrator entries of a run of this family whose case names none."""
        return dict(DEFAULT_INTEGRATORS["superposition" if self.superposition else "constrained"])

    @property
    def inertia_loads(self) -> str:
        """The superposition family whose rigid-inertia loads this family's ``inertia_load`` outputs
        with model "run" report."""
        return self.name if self.superposition else self.run_loads

    def supports_output(self, kind: str) -> bool:
        return kind not in self.outputs_excluded


FAMILIES: dict[str, Family] = {f.name: f for f in (
    Family("hac", "case I (hac, Eq. 15)", superposition=True, load_code=1, load_mass="translational"),
    Family("classic", "case II (classic, Eq. 14)", superposition=True, load_code=2, load_mass="consistent"),
    Family("classic-translational", "Eq. 14 translational (classic-translational)", superposition=True,
           load_code=3, load_mass="consistent", rotary_loads=False),
    Family("coupled", "coupled (one-pass, Sec. 3)", superposition=False, guides_on_flexible_links=True,
           dof2_bytes=32, run_loads="classic"),
    Family("nonlinear", "nonlinear (co-rotational)", superposition=False, large_deflection=True,
           element_frames=True, guides_on_flexible_links=True, element_bytes=16_000, run_loads="classic"),
)}

#: every family's name, in the registry's order
MODELS = tuple(FAMILIES)
#: the superposition families' names
SUPERPOSITION_MODELS = tuple(n for n, f in FAMILIES.items() if f.superposition)
#: the choice that is no family: the cheapest family whose estimated model error is within
#: solver.tolerance (flexmech_py.checks.auto_model), the default of a case that names none
AUTO = "auto"
#: what solver.model and --model accept: a family's name, or AUTO
MODEL_CHOICES = MODELS + (AUTO,)
#: (family, geometric stiffness) from the cheapest to the exact one, as AUTO climbs them
#: (flexmech_py.checks.auto_model): hac, then classic with the geometric stiffness of the previous step's
#: axial forces (as close to the exact model as "current" on the cases measured, at a third of its
#: cost), then the large-deflection reference
AUTO_LADDER = (("hac", "none"), ("classic", "lagged"), ("nonlinear", None))
#: the family of the studies of one model (accuracy, modes, steady, stability) when the case says AUTO
STUDY_MODEL = "hac"


def names(**capabilities) -> tuple:
    """The names of the families whose attributes equal ``capabilities`` (all families without)."""
    return tuple(n for n, f in FAMILIES.items() if all(getattr(f, k) == v for k, v in capabilities.items()))


def superposition_names() -> tuple:
    return SUPERPOSITION_MODELS


def family(name) -> Family:
    """The family of a model name (a Family passes through); KeyError naming the choices otherwise."""
    if isinstance(name, Family):
        return name
    try:
        return FAMILIES[name]
    except (KeyError, TypeError):
        raise KeyError(f"unknown model {name!r}; choose from {', '.join(MODELS)}") from None


def large_deflection_reference() -> Family:
    """The family that judges the others: large deflections, every element in its own frame."""
    return next(f for f in FAMILIES.values() if f.large_deflection)
