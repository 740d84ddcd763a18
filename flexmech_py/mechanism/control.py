"""Feedback controllers on force-driven joints: the ``[[controllers]]`` tables of a case, checked, and
packed into the flat layout of the Fortran module flexmech_control (docs/cases.md, controllers;
docs/theory.md section 23).

A controller adds a PID effort to the force drive of its joint (that drive's own law keeps acting:
a disturbance, or a feedforward of its own):

    u = sat(ff(t) + kp e + ki I + kd e'),   e = r(t) - y,  e' = r'(t) - y'

r is any kinematic law of the drives (``reference``), y the joint coordinate (collocated), ff an
optional table in time (``feedforward``), sat the output limits, and I the error's integral, held while
the output is saturated in the direction the error pushes (anti-windup by clamping).
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from ..base import validate as v
from ..base.errors import CaseError, ValidityWarning
from ..base.shaping import SHAPERS, design
from .drives import KINEMATIC_LAWS, LAW_PARAMS, Drive, cubic_spline
from .feedforward import INVERSE_DYNAMICS
from .schema import table_samples

__all__ = ["check_controllers", "refuse_superposition", "closes_in_rigid_motion", "rigid_pack", "loop_suspect", "ControlPack", "pack_controllers", "CONTROL_NST", "MAX_DELAY_STEPS"]

KEYS = {"shaper", "name", "joint", "kp", "ki", "kd", "limit", "limits", "reference", "feedforward", "sample_time", "delay",
        "measure"}
MAX_DELAY_STEPS = 2000                      # flexmech_control: CTL_MAXDELAY
CONTROL_NST = 5 + 2 * (MAX_DELAY_STEPS + 1)  # flexmech_control: CTL_NST
CONSTRAINED = ("coupled", "nonlinear")


def check_controllers(raw, mech, solver: dict) -> list:
    """The checked controllers of a case (resolved dicts) from its ``[[controllers]]`` tables; a bad
    one raises CaseError naming the field and the fix."""
    if raw is None or raw == []:
        return []
    if not isinstance(raw, list):
        raise CaseError("controllers", "must be an array of tables [[controllers]] (joint, kp, ki, kd, reference)")
    out, names = [], set()
    for i, c in enumerate(raw):
        w = f"controllers[{i}]"
        if not isinstance(c, dict):
            raise CaseError(w, "must be a table with joint, kp, ki, kd, reference")
        v.keys(c, KEYS, w)
        joint = v.text(c, "joint", w, required=True)
        _force_driven(mech, joint, f"{w}.joint")
        measure = _measure(c, w)
        _check_measured(mech, measure, f"{w}.measure")
        name = v.text(c, "name", w, default=f"{joint}_pid")
        if name in names:
            raise CaseError(f"{w}.name", f"{name!r} names two controllers; give each its own name")
        names.add(name)
        gains = {k: v.num(c, k, w, default=0.0, nonneg=True) for k in ("kp", "ki", "kd")}
        if not any(gains.values()):
            raise CaseError(f"{w}.kp", "kp, ki and kd are all zero; give at least one positive gain")
        resolved = {"name": name, "joint": joint, **gains, "limits": _limits(c, w),
                    "reference": _reference(c.get("reference"), f"{w}.reference"),
                    "feedforward": _feedforward(c.get("feedforward"), f"{w}.feedforward"),
                    **_timing(c, w, solver["dt"]), "measure": measure, **_shaper(c, w)}
        out.append({k: x for k, x in resolved.items() if x is not None})   # (written back as TOML)
    if solver["model"] != "auto":
        refuse_superposition({"controllers": out}, solver["model"])
    return out


def refuse_superposition(case: dict, model: str) -> None:
    """CaseError when a controller of the case cannot close its loop in ``model`` (docs/theory.md 23.3): a
    superposition model integrates the rigid-body motion first and the elastic motion after it, one way,
    so it closes a collocated, continuous loop (the joint's own coordinate and rate) inside the rigid-body
    integration, and refuses a loop on a measured point (the deflection never reaches the rigid motion)
    and a sampled or delayed one (its rigid-body integration has no sample instants)."""
    if model in CONSTRAINED:
        return
    for i, c in enumerate(case.get("controllers") or []):
        why = _rigid_refusal(c, model)
        if why is not None:
            raise CaseError(f"controllers[{i}].{why[0]}", why[1])


def closes_in_rigid_motion(case: dict) -> bool:
    """Whether the case has controllers and every one closes inside the rigid-body integration (collocated,
    continuous): then the rigid-body motion of the case is the controlled one (flexmech_mbs_control)."""
    ctl = case.get("controllers") or []
    return bool(ctl) and all(_rigid_refusal(c, "hac") is None for c in ctl)


def _rigid_refusal(c: dict, model: str):
    """(field, reason) why controller c cannot close in the rigid-body integration of ``model``, or None."""
    m = c.get("measure", "joint")
    if m != "joint":
        what = (m.get("point") or f"the strain of {m.get('strain')}") if isinstance(m, dict) else m
        return "measure", (f"controller {_name(c)!r} measures {what!r} (non-collocated); {model!r} integrates the "
                           "rigid-body motion before the elastic motion, one way, so the deflection it would feed back "
                           "never reaches the rigid motion the controller drives: use model = \"coupled\" or "
                           "\"nonlinear\" (or measure = \"joint\")")
    for key in ("sample_time", "delay"):
        x = c.get(key, 0.0)
        if isinstance(x, (int, float)) and not isinstance(x, bool) and x > 0:
            return key, (f"controller {_name(c)!r} has {key} = {x} s; {model!r} closes a continuous loop inside "
                         f"its rigid-body integration (no sample instants there): remove {key} (the loop then acts "
                         "continuously) or use model = \"coupled\" or \"nonlinear\"")
    return None


def rigid_pack(case: dict, packed, dt: float):
    """The case's controllers packed for the rigid-body integration of ``packed`` (its force drives in
    their packed order), or None when they do not all close there (:func:`closes_in_rigid_motion`)."""
    if not closes_in_rigid_motion(case):
        return None
    mech = case.mechanism
    revolute = {j.name for j in mech.joints if j.angular}
    forces = [d.joint for d in packed.drives if not d.kinematic]
    return pack_controllers(case["controllers"], forces, revolute, dt, {})


def loop_suspect(case: dict, columns: dict) -> str | None:
    """For a run that failed: the controller whose output grew most over its frames (the last quarter
    against the first), named with its growth, when it grew tenfold or more; None otherwise."""
    best = None
    for c in case.get("controllers", []):
        u = np.abs(np.asarray(columns.get(f"control_{c['name']}", []), float))
        if u.size < 8:
            continue
        q = u.size // 4
        growth = u[-q:].max() / max(u[:q].max(), 1e-300)
        if growth >= 10.0 and (best is None or growth > best[1]):
            best = (c["name"], growth, u[:q].max(), u[-q:].max())
    if best is None:
        return None
    return (f"feedback controller {best[0]!r}: its output grew {best[1]:.3g}-fold before the stop ({best[2]:.3g} -> "
            f"{best[3]:.3g}): an unstable closed loop; lower its gains, shorten its sample_time or its delay")


def _name(c) -> str:
    return c.get("name") or f"{c.get('joint')}_pid"


def _force_driven(mech, joint: str, where: str) -> None:
    mech.joint(joint, where)
    drives = [d for d in mech.drives if d.joint == joint]
    if any(d.kinematic for d in drives):
        raise CaseError(where, f"joint {joint!r} is prescribed by a kinematic drive (law {drives[0].law!r}); a "
                               f"controller acts through a force drive: make its drive law = \"force\" (a template "
                               f"case: [drive] type = \"torque\")")
    if not drives:
        raise CaseError(where, f"joint {joint!r} has no force drive; add one (the controller's effort adds to it): "
                               f"[[drives]] joint = \"{joint}\", law = \"force\", or in a template case (type = "
                               f"\"fourbar\", ...) [drive] type = \"torque\" with [[drive.torques]] joint = \"{joint}\"")


def _limits(c: dict, w: str):
    if "limit" in c and "limits" in c:
        raise CaseError(f"{w}.limits", "give either limit (symmetric) or limits = [lo, hi], not both")
    if "limit" in c:
        u = v.num(c, "limit", w, positive=True)
        return [-u, u]
    if "limits" in c:
        lo, hi = v.vector(c, "limits", w, 2)
        if not lo < hi:
            raise CaseError(f"{w}.limits", f"must be [lo, hi] with lo < hi, got [{lo}, {hi}]")
        return [lo, hi]
    return None


def _reference(ref, w: str) -> dict:
    if ref is None:
        raise CaseError(w, "is missing; give the reference as a motion law, e.g. {law = \"rest_to_rest\", "
                           "travel = 0.5, duration = 0.2}")
    if not isinstance(ref, dict):
        raise CaseError(w, "must be a table {law = ..., ...} of a kinematic law")
    law = v.text(ref, "law", w, required=True, choices=KINEMATIC_LAWS)
    req, opt = LAW_PARAMS[law]
    v.keys(ref, {"law"} | req | set(opt), w)
    for key in sorted(req - set(ref)):
        raise CaseError(f"{w}.{key}", f"is missing; a '{law}' law needs {', '.join(sorted(req))}")
    if law == "table":
        return {"law": law, **table_samples({"t": ref.get("t"), "value": ref.get("value")}, w)}
    out = {"law": law}
    for key in sorted(req | set(opt)):
        if key == "profile":
            out[key] = v.text(ref, key, w, default="cycloidal", choices=("cycloidal", "quintic"))
        else:
            out[key] = v.num(ref, key, w, default=opt.get(key),
                             positive=key in ("duration", "spinup_time"))
    return {k: x for k, x in out.items() if x is not None}


def _feedforward(ff, w: str):
    """A table {t, value} in time, or "inverse_dynamics" (resolved into a table by
    flexmech_py.mechanism.feedforward once the case's loads are known)."""
    if ff is None or ff == INVERSE_DYNAMICS:
        return ff
    if not isinstance(ff, dict):
        raise CaseError(w, "must be a table {t = [...], value = [...]} (the effort in time, N m or N) or "
                           f"\"{INVERSE_DYNAMICS}\" (the rigid-body inverse dynamics along the reference)")
    return table_samples(ff, w)


def _shaper(c: dict, w: str) -> dict:
    """``shaper = {kind = "zv" | "zvd" | "ei", frequency_hz, damping = 0, tolerance = 0.05}``: the
    reference convolved with its impulses (flexmech_py.base.shaping: the design)."""
    sh = c.get("shaper")
    if sh is None:
        return {}
    where = f"{w}.shaper"
    if not isinstance(sh, dict):
        raise CaseError(where, "must be a table {kind = \"zv\", frequency_hz = ...}")
    v.keys(sh, {"kind", "frequency_hz", "damping", "tolerance"}, where)
    kind = v.text(sh, "kind", where, required=True, choices=SHAPERS)
    f = v.num(sh, "frequency_hz", where, required=True, positive=True)
    zeta = v.num(sh, "damping", where, default=0.0, nonneg=True)
    tol = v.num(sh, "tolerance", where, default=0.05, positive=True)
    try:
        design(kind, f, zeta, tol)
        return {"shaper": {"kind": kind, "frequency_hz": f, "damping": zeta, "tolerance": tol}}
    except CaseError as exc:
        raise CaseError(f"{w}.{exc.field}", str(exc).split(": ", 1)[1]) from None


def _timing(c: dict, w: str, dt: float) -> dict:
    """sample_time and delay [s], each a whole number of steps (rounded, with a warning, when not)."""
    ts = v.num(c, "sample_time", w, default=0.0, nonneg=True)
    delay = v.num(c, "delay", w, default=0.0, nonneg=True)
    out = {"sample_time": _whole_steps(ts, dt, f"{w}.sample_time", minimum=1) if ts > 0 else 0.0}
    period = out["sample_time"] or dt
    out["delay"] = _whole_steps(delay, period, f"{w}.delay", minimum=0) if delay > 0 else 0.0
    steps = round(out["delay"] / dt)
    if steps > MAX_DELAY_STEPS:
        raise CaseError(f"{w}.delay", f"({delay} s) is {steps} steps of solver.dt; at most {MAX_DELAY_STEPS}: "
                                      "shorten it or lengthen the sample time")
    return out


def _whole_steps(x: float, unit: float, where: str, minimum: int) -> float:
    k = max(minimum, round(x / unit))
    if abs(k * unit - x) > 1e-9 * max(x, unit):
        warnings.warn(f"{where}: {x} s is not a whole number of {unit} s periods; taken as {k * unit:.6g} s",
                      ValidityWarning, stacklevel=3)
    return k * unit


def _measure(c: dict, w: str):
    """``"joint"`` (the joint's coordinate and rate, collocated), ``{point = "<link>.<point>", direction
    = [x, y]}``: the point's position along the unit direction (fixed in the frame of the joint's body
    a) from the joint's point a, and its rate (non-collocated; the reference then in m), or ``{strain =
    "<link>", at = f}``: the bending strain at the outer fibre of a flexible link at fraction f of its
    length, the mean over the element holding f (over the two elements around f when f is a mesh node:
    flexmech_py.models.constrained.layout), like a strain gauge of that length (the reference then in
    strain, the gains in effort per unit strain)."""
    m = c.get("measure", "joint")
    where = f"{w}.measure"
    if m == "joint":
        return m
    if not isinstance(m, dict):
        raise CaseError(where, f"must be \"joint\", {{point = \"<link>.end\", direction = [0, 1]}} or "
                               f"{{strain = \"<link>\", at = 0.5}}, got {m!r}")
    if "strain" in m:
        v.keys(m, {"strain", "at"}, where)
        return {"strain": v.text(m, "strain", where, required=True),
                "at": v.num(m, "at", where, required=True, nonneg=True)}
    v.keys(m, {"point", "direction"}, where)
    point = v.text(m, "point", where, required=True)
    d = np.asarray(v.vector(m, "direction", where, 2, default=[0.0, 1.0]), float)
    if not np.linalg.norm(d) > 0:
        raise CaseError(f"{where}.direction", "must be a nonzero vector [x, y]")
    return {"point": point, "direction": [float(x) for x in d / np.linalg.norm(d)]}


def _check_measured(mech, m, where: str) -> None:
    """The measured point is the mechanism's; a strain gauge's link is flexible, with a half depth."""
    if m == "joint":
        return
    if "point" in m:
        mech.point(m["point"], f"{where}.point")
        return
    link = next((ln for ln in mech.links if ln.name == m["strain"]), None)
    if link is None or link.rigid:
        names = ", ".join(ln.name for ln in mech.links if not ln.rigid)
        raise CaseError(f"{where}.strain", f"{m['strain']!r} is not a flexible link (flexible links: {names})")
    if not link.half_depth:
        raise CaseError(f"{where}.strain", f"link {link.name!r} has no half_depth (the outer fibre's distance "
                                           "from the axis, m): give links.half_depth or a section")
    if m["at"] > 1.0:
        raise CaseError(f"{where}.at", f"is a fraction of the link's length, 0..1; got {m['at']}")


def _scaled_reference(ref: dict, s: float) -> dict:
    """A reference law in units of its measured signal divided by s (a strain reference as the
    relative node rotation the model measures): every value-like parameter divided by s."""
    out = dict(ref)
    for key in ("start", "travel", "speed", "final_speed", "amplitude", "mean"):
        if out.get(key) is not None:
            out[key] = out[key] / s
    if "value" in out:
        out["value"] = [x / s for x in out["value"]]
    return out


class ControlPack:
    """The flat layout of flexmech_control: cint (9, n), cpar (9, n), the tables' splines ctab_t,
    ctab_c and a fresh state cst (NST, n) (n >= 1: a padding controller with drive 0 when none)."""

    def __init__(self, controllers: list, force_joints: list, revolute: set, dt: float, rows: dict,
                 scales: dict | None = None):
        n = max(1, len(controllers))
        self.dt = dt
        self.names = [c["name"] for c in controllers]
        self.joints = [c["joint"] for c in controllers]
        self.cint = np.zeros((12, n), np.int32, order="F")
        self.cpar = np.zeros((17, n), order="F")
        tab_t, tab_c = [], []
        for k, c in enumerate(controllers):
            sc = (scales or {}).get(c["name"], 1.0)      # measured = sc x row: law and gains in row units
            ref_law = _scaled_reference(c["reference"], sc) if sc != 1.0 else c["reference"]
            ref = Drive(joint=c["joint"], law=ref_law["law"], params={p: x for p, x in ref_law.items() if p != "law"})
            law = ref.packed(math.nan)     # a start left out: the coordinate measured at the run's start
            rt = _append(tab_t, tab_c, law["table"])
            ft = _append(tab_t, tab_c, None if c.get("feedforward") is None else
                         (np.asarray(c["feedforward"]["t"], float),
                          cubic_spline(c["feedforward"]["t"], c["feedforward"]["value"])))
            lo, hi = c.get("limits") or (-np.inf, np.inf)
            s = round(c["sample_time"] / dt) if c["sample_time"] else 0
            m = round(c["delay"] / dt)
            kind, ma, mb, d = rows.get(c["name"], (0, -1, -1, (0.0, 0.0)))
            self.cint[:, k] = [force_joints.index(c["joint"]) + 1, ref.code, *rt, *ft, max(s, 1 if m else 0), m,
                               int(c["joint"] in revolute and kind == 0), kind, ma + 1, mb + 1]
            amps, times = _impulses(c.get("shaper"))
            self.cpar[:, k] = [c["kp"] * sc, c["ki"] * sc, c["kd"] * sc, lo, hi, *law["par"], *amps, *times, *d]
        self.ctab_t = np.asarray(tab_t or [0.0], float)
        self.ctab_c = np.asfortranarray(np.array(tab_c, float).T if tab_c else np.zeros((4, 1)))
        self.cst = np.zeros((CONTROL_NST, n), order="F")


def _impulses(shaper):
    """The shaper's amplitudes and times, 3 of each (padded with zeros); none: one unit impulse at 0."""
    if shaper is None:
        return [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]
    sh = design(shaper["kind"], shaper["frequency_hz"], shaper["damping"], shaper["tolerance"])
    a, t = [float(x) for x in sh.amplitudes], [float(x) for x in sh.times]
    return a + [0.0] * (3 - len(a)), t + [0.0] * (3 - len(t))


def _append(tab_t: list, tab_c: list, table) -> list:
    if table is None:
        return [0, 0]
    first = len(tab_t) + 1
    tab_t += list(table[0])
    tab_c += list(table[1].T)
    return [first, len(table[0])]


def pack_controllers(controllers: list, force_joints: list, revolute: set, dt: float, rows: dict,
                     scales: dict | None = None) -> ControlPack:
    """The controllers for a run with step dt whose force drives act on ``force_joints`` (in the order
    of the model's force drives); ``revolute``: the joints whose coordinate is an angle; ``rows``:
    {controller: (row kind, marker a, marker b (0-based), direction)} of the non-collocated ones,
    ``scales`` {controller: s} their measured signal per unit of the row (a strain: c / span)."""
    return ControlPack(controllers, force_joints, revolute, dt, rows, scales)
