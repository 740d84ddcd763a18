"""Which outputs mean the same quantity in two models (docs/theory.md section 8.1): every output kind
has one definition in every model family, except where the families' premises make two values of it
different things.  Used by ``flexmech compare --models`` (its marks) and by the error budget's model
part (:mod:`flexmech_py.checks.model_error`: a difference of unlike quantities is no model error).
"""

from __future__ import annotations

from .base.families import family

__all__ = ["definition_notes", "rigid_in_superposition", "JOINT_OUTPUT_KINDS"]

#: the output kinds of a joint's coordinate
JOINT_OUTPUT_KINDS = ("joint_angle", "joint_speed", "joint_acceleration")


def definition_notes(case: dict, model: str, reference_model: str, free_motion: bool) -> dict[str, str]:
    """{output: why model's and reference_model's values of it are not the same quantity} (docs/theory.md
    section 8.1): across the model families, ``displacement`` when the mechanism has a degree of freedom
    no kinematic drive fixes (``free_motion``: the coupled and nonlinear models' own rigid motion drifts
    from the rigid-body solution the displacement is measured from; the superposition models' does not,
    by their premise) and the ``joint_*`` outputs of a revolute or weld joint on a flexible link that no
    kinematic drive moves (the rigid-body solution's frames against the chords; measured at the joint,
    ``measure = "joint"``, they are one quantity); ``inertia_load`` with
    ``model = "run"`` between different load models.  Every other kind means the same in every model."""
    coupled = [m for m in (model, reference_model) if family(m).constrained]
    own = {m: family(m).inertia_loads for m in (model, reference_model)}  # a "run" load's model
    out = {}
    for name, sp in case["outputs"].items():
        if sp["kind"] == "displacement" and len(coupled) == 1 and free_motion:
            out[name] = (f"not the same quantity: the {coupled[0]} model's displacement includes the drift of its own "
                         "rigid motion from the rigid-body solution (this mechanism has degrees of freedom no "
                         "kinematic drive fixes), which the superposition models leave out by their premise; compare "
                         "deflection outputs (kind = \"deflection\", the same at and component) for the bending "
                         "alone")
        elif (sp["kind"] in JOINT_OUTPUT_KINDS and sp.get("measure", "frames") == "frames" and len(coupled) == 1
              and _frames_differ(case.mechanism, sp["joint"])):
            out[name] = (f"not the same quantity: the superposition models give the rigid-body solution's angle "
                         f"between the bodies' frames (no elastic part), the {coupled[0]} model the angle between "
                         "their chords (the links' elastic rotation and the model's drift included); compare "
                         "link_angle outputs (the chord in every model), or measure = \"joint\" (the tangents at the "
                         "joint in every model), for like with like")
        elif sp["kind"] == "inertia_load" and sp["model"] == "run" and own[model] != own[reference_model]:
            load = {m: (f"{m}: the classic load of its own rigid motion (it has no load model)" if m in coupled
                        else f"{m}: its {m} load") for m in (model, reference_model)}
            out[name] = (f"not the same quantity: model = \"run\" is each run's rigid-inertia load ({load[model]}; "
                         f"{load[reference_model]}); name one load model in the output (e.g. model = \"classic\") "
                         "to compare like with like")
    return out


def rigid_in_superposition(case, name: str) -> bool:
    """Is output ``name`` the rigid-body solution's value in the superposition models: a kinematic drive's
    ``drive_force`` (docs/theory.md section 18.5)?  No superposition model, with or without geometric
    stiffness, has an elastic part in it; the coupled and nonlinear models do (their multipliers)."""
    sp = case["outputs"].get(name)
    if sp is None or sp["kind"] != "drive_force":
        return False
    drive = case.mechanism.drive_of(sp["joint"])
    return drive is not None and drive.kinematic


def _frames_differ(mech, joint: str) -> bool:
    """A revolute or weld joint on a flexible link that no kinematic drive moves: its coordinate is the
    rigid-body solution's frames in the superposition models, the chords in the coupled ones."""
    j = mech.joint(joint)
    drive = mech.drive_of(joint)
    if j.guided or (drive is not None and drive.kinematic):
        return False
    return any(p.body is not None and p.body.kind == "link" and not p.body.rigid for p in mech.joint_points(j))
