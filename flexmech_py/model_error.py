"""The model part of the error budget (docs/theory.md section 21.3): the difference between the run's
model and the exact (``nonlinear``, co-rotational) model, both on the budget's model grid (the coarser of its probe mesh
and the run's, 16 times the step).  Both carry nearly the same discretization error there, so their
difference measures the model error of the run's model (docs/validation.md "Error budget": estimate
against the true error; a superposition model against the same with geometric stiffness misses the
rigid-elastic coupling and every output the superposition models take from the rigid-body solution).

Also: the ladder of models ``model = "auto"`` climbs (:mod:`flexmech_py.auto_model`), their labels,
and which outputs can be compared between the model families at all.
"""

from __future__ import annotations

from .case import SUPERPOSITION_MODELS

__all__ = ["EXACT", "GEOMETRIC", "LADDER", "label", "comparable", "is_reference"]

#: the exact model: the reference of every model-error estimate (its own model error is taken as 0)
EXACT = ("nonlinear", None)
#: a superposition model with the geometric stiffness of its axial forces (those of the previous step:
#: as close to the exact model as "current" on the cases measured, at a third of its cost)
GEOMETRIC = ("classic", "lagged")
#: (model, geometric stiffness) from the cheapest to the exact one, as ``model = "auto"`` tries them
LADDER = (("hac", "none"), GEOMETRIC, EXACT)


def label(model: str, geometric: str | None = None) -> str:
    """How a configuration is named in tables and warnings."""
    if model in SUPERPOSITION_MODELS and geometric not in (None, "none"):
        return f"{model} + geometric stiffness ({geometric})"
    return model


def is_reference(model: str) -> bool:
    """Is ``model`` the exact one (no model error of its own)?"""
    return model == EXACT[0]


def comparable(spec: dict | None, case: dict, model: str) -> str:
    """'' when an output of ``model`` can be compared with the exact model's, else why not: a rigid-
    inertia load is a model's definition, a kinematically driven joint's coordinate is prescribed, and
    a superposition model's ``displacement`` is the elastic deflection where the coupled models give
    the deviation from the rigid-body solution.  ``spec`` None: an extra column of the coupled models
    (energies, drive torques), comparable between them."""
    if spec is None:
        return ""
    kind = spec["kind"]
    if kind == "inertia_load":
        return "a rigid-inertia load is a model's own definition"
    if kind.startswith("joint_"):
        drive = case.mechanism.drive_of(spec["joint"])
        if drive is not None and drive.kinematic:
            return "the coordinate of a kinematically driven joint is prescribed"
    if kind == "displacement" and model in SUPERPOSITION_MODELS:
        return ("a superposition model's displacement is the elastic deflection, the exact model's the deviation "
                "from the rigid-body solution")
    return ""
