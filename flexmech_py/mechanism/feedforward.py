"""A controller's feedforward from the rigid-body inverse dynamics along its reference
(``feedforward = "inverse_dynamics"`` in a ``[[controllers]]`` table; docs/cases.md, docs/theory.md
section 23.2).

The effort ff(t) that, added to the joint's own force law, makes the *rigid* mechanism follow the
references exactly: each such controller's force drive is replaced by a kinematic drive along its
reference, the rigid-body solver's kinematic mode gives every drive's generalized force along that
motion (flexmech_mbs: a kinematic drive applies -lambda), and ff = that force less the joint's own
constant force law (which keeps acting in the run).  The references must then prescribe the whole
motion (every degree of freedom followed by such a controller or by a kinematic drive of the case);
a shaped reference (``shaper``) is the sum of the law's shifted copies, sampled on the table's grid
and followed as a table.  The result is stored as the controller's ``feedforward`` table in time,
on ``FF_SAMPLES`` points over the run (a cubic spline in the time loop).
"""

from __future__ import annotations

import copy

import numpy as np

from ..base.errors import CaseError
from ..base.shaping import design
from .analysis import prepare_motion
from .drives import Drive
from .motion import MotionSource

__all__ = ["resolve_feedforward", "INVERSE_DYNAMICS", "FF_SAMPLES"]

INVERSE_DYNAMICS = "inverse_dynamics"
FF_SAMPLES = 1001            # at most: the table's points over the run (fewer when the run has fewer steps)


def resolve_feedforward(controllers: list, mech, gravity, solver: dict) -> None:
    """Replace every ``feedforward = "inverse_dynamics"`` of ``controllers`` (checked dicts, in place)
    by its table {t, value} [s, N m or N]; a controller that cannot have one raises CaseError naming
    its field and the fix."""
    wanted = [(i, c) for i, c in enumerate(controllers) if c.get("feedforward") == INVERSE_DYNAMICS]
    if not wanted:
        return
    n = int(min(FF_SAMPLES, np.ceil(solver["t_end"] / solver["dt"]) + 1))
    t = np.linspace(0.0, solver["t_end"], max(n, 3))
    laws = {c["joint"]: _law_drive(mech, c, f"controllers[{i}]") for i, c in wanted}
    drives = dict(laws)
    drives.update(_shaped_drives(mech, [c for _, c in wanted], laws, gravity, t,
                                 f"controllers[{wanted[0][0]}].feedforward"))
    effort = _drive_efforts(mech, drives, gravity, t, f"controllers[{wanted[0][0]}].feedforward")
    for _, c in wanted:
        own = mech.drive_of(c["joint"]).params.get("constant") or 0.0
        c["feedforward"] = {"t": [float(x) for x in t], "value": [float(x) for x in effort[c["joint"]] - own]}


def _law_drive(mech, c: dict, w: str) -> Drive:
    """The kinematic drive along controller c's reference law (unshaped)."""
    if c.get("measure", "joint") != "joint":
        raise CaseError(f"{w}.feedforward", "inverse_dynamics follows a joint's reference; this controller "
                                            "measures a point: give the feedforward as a table {t, value}")
    own = mech.drive_of(c["joint"]).params
    if any(own.get(k) for k in ("sin", "cos", "time_harmonics", "table")):
        raise CaseError(f"{w}.feedforward", f"inverse_dynamics subtracts the joint's own force law, which must be "
                                            f"a constant; {c['joint']!r}'s depends on its angle or time: give the "
                                            "feedforward as a table {t, value}")
    ref = c["reference"]
    return Drive(joint=c["joint"], law=ref["law"], params={k: x for k, x in ref.items() if k != "law"})


def _shaped_drives(mech, controllers: list, laws: dict, gravity, t: np.ndarray, w: str) -> dict:
    """{joint: its reference drive as a table on t} of the controllers with a shaper: the sum of their
    law's shifted copies, the law's values at every t - t_i read from one motion the unshaped laws
    prescribe (sampled on the union of those times)."""
    shifts = {}
    for c in controllers:
        if c.get("shaper"):
            sh = c["shaper"]
            shaper = design(sh["kind"], sh["frequency_hz"], sh["damping"], sh["tolerance"])
            shifts[c["joint"]] = [(a, np.clip(t - ti, 0.0, None)) for a, ti in zip(shaper.amplitudes, shaper.times)]
    if not shifts:
        return {}
    grid = np.unique(np.concatenate([s for pairs in shifts.values() for _, s in pairs]))
    values = _joint_values(mech, laws, gravity, grid, w)
    out = {}
    for j, pairs in shifts.items():
        shaped = sum(a * np.interp(s, grid, values[j]) for a, s in pairs)
        out[j] = Drive(joint=j, law="table", params={"t": [float(x) for x in t], "value": [float(x) for x in shaped]})
    return out


def _prescribed(mech, drives: dict, gravity, w: str):
    """The rigid motion's set-up with the joints of ``drives`` driven by them instead of their force
    drives; CaseError when that leaves the motion free."""
    mech = copy.deepcopy(mech)
    mech.drives = [drives.get(d.joint, d) for d in mech.drives]
    mech.initial_speeds = {}           # a prescribed motion's speeds are its laws'

    setup = prepare_motion(mech, gravity)
    if setup.mode != "kinematic":
        free = setup.dof - sum(1 for d in mech.drives if d.kinematic)
        raise CaseError(w, f"inverse_dynamics needs the references to prescribe the whole motion; with them the "
                           f"mechanism keeps {free} free degree(s) of freedom: put a controller with this "
                           "feedforward (or a kinematic drive) on every free joint, or give the feedforward as a "
                           "table {t, value}")
    return setup


def _joint_values(mech, drives: dict, gravity, t: np.ndarray, w: str) -> dict:
    """The coordinates of the joints of ``drives`` on the grid t along their prescribed motion."""
    setup = _prescribed(mech, drives, gravity, w)
    rm = MotionSource(setup)(t)
    names = [j.name for j in setup.mech.joints]
    return {j: rm.jq[:, names.index(j), 0] for j in drives}


def _drive_efforts(mech, drives: dict, gravity, t: np.ndarray, w: str) -> dict:
    """The generalized force [N m or N] each drive of ``drives`` applies along the prescribed motion."""
    setup = _prescribed(mech, drives, gravity, w)
    rm = MotionSource(setup)(t)
    order = [d.joint for d in setup.packed.drives]
    return {j: rm.dv[:, order.index(j)] for j in drives}
