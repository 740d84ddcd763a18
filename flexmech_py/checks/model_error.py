"""The model part of the error budget (docs/theory.md section 21.3): the difference between the run's
model and the exact (``nonlinear``, co-rotational) model, both on the budget's model grid (the coarser of its probe mesh
and the run's, 16 times the step).  Both carry nearly the same discretization error there, so their
difference measures the model error of the run's model (docs/validation.md "Error budget": estimate
against the true error; a superposition model against the same with geometric stiffness misses the
rigid-elastic coupling and every output the superposition models take from the rigid-body solution).

Also: the ladder of models ``model = "auto"`` climbs (:mod:`flexmech_py.checks.auto_model`), their labels,
and which outputs can be compared between the model families at all.
"""

from __future__ import annotations

from ..definitions import definition_notes
from ..base.families import AUTO_LADDER, SUPERPOSITION_MODELS

__all__ = ["EXACT", "GEOMETRIC", "LADDER", "label", "comparable", "is_reference"]

#: (model, geometric stiffness) from the cheapest to the exact one, as ``model = "auto"`` tries them
#: (the registry's families.AUTO_LADDER)
LADDER = AUTO_LADDER
#: the exact model: the reference of every model-error estimate (its own model error is taken as 0)
EXACT = LADDER[-1]
#: a superposition model with the geometric stiffness of its axial forces (those of the previous step:
#: as close to the exact model as "current" on the cases measured, at a third of its cost)
GEOMETRIC = LADDER[1]


def label(model: str, geometric: str | None = None) -> str:
    """How a configuration is named in tables and warnings."""
    if model in SUPERPOSITION_MODELS and geometric not in (None, "none"):
        return f"{model} + geometric stiffness ({geometric})"
    return model


def is_reference(model: str) -> bool:
    """Is ``model`` the exact one (no model error of its own)?"""
    return model == EXACT[0]


def comparable(name: str, case, model: str, free_motion: bool) -> str:
    """'' when output ``name`` of ``model`` and of the exact model are the same quantity, else why not:
    :func:`flexmech_py.definitions.definition_notes` (a displacement that holds the coupled models' drift
    on a mechanism with a free degree of freedom, an undriven joint's coordinate: frames against chords),
    and a rigid-inertia load (a model's own definition, with no mesh limit: the probes leave it out).
    ``free_motion``: the mechanism has a degree of freedom no kinematic drive fixes.  An extra column
    of the coupled models (energies, drive torques) compares between them."""
    spec = case["outputs"].get(name)
    if spec is None:
        return ""
    if spec["kind"] == "inertia_load":
        return "a rigid-inertia load is a model's own definition"
    return definition_notes(case, model, EXACT[0], free_motion).get(name, "")
