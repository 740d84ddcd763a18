"""Templates: the four-bar (``mechanism.type = "fourbar"``) and the serial chain (``"serial"``) of
the seed paper, written in their short form and expanded into the general tables (links with end
points, joints, drives, initial coordinates).  A template only builds a description; nothing
downstream knows which template, if any, built a mechanism.

Short form (docs/cases.md, "Templates"): ``[mechanism]`` type, ``ground_length`` and ``assembly``
(four-bar) or ``base`` (serial chain); ``[[links]]`` with ``length``; ``[joints]`` a table of
elastic conditions by joint name; ``[drive]`` (``type = "torque"`` with ``[[drive.torques]]``, or
``type = "kinematic"`` with a law); ``[initial]`` ``angles`` and ``speeds`` lists (the crank angle;
the chain's first absolute and then relative joint angles).
"""

from __future__ import annotations

import copy
import math

from ..base import validate as v
from ..base.errors import CaseError, MechanismError
from .schema import link_section

__all__ = ["TEMPLATES", "expand_template", "template_joints"]

TEMPLATES = ("fourbar", "serial")
FOURBAR_LINKS = ["crank", "coupler", "follower"]


def template_joints(kind: str, nlinks: int) -> dict[str, tuple[str, ...]]:
    """Joints of a template: name -> allowed elastic conditions (first = default)."""
    if kind == "fourbar":
        return {"crank_pivot": ("clamp", "pin", "torque"), "crank_coupler": ("pin", "locked", "torque"),
                "coupler_follower": ("pin", "locked", "torque"), "follower_pivot": ("pin", "clamp", "torque")}
    joints = {"base": ("clamp", "pin", "torque")}
    for k in range(2, nlinks + 1):
        joints[f"joint_{k}"] = ("locked", "pin", "torque")
    return joints


def expand_template(raw: dict) -> dict:
    """The general-form case tables of a short-form case (the other tables are kept)."""
    mech = raw["mechanism"]
    kind = v.text(mech, "type", "mechanism", required=True, choices=TEMPLATES)
    links = raw.get("links")
    if not isinstance(links, list) or not links:
        raise CaseError("links", "is missing or empty; add one [[links]] table per link")
    out = copy.deepcopy(raw)
    for i, ln in enumerate(links):
        w = f"links[{i}]"
        v.keys(ln, {"name", "length", "area", "second_moment", "youngs_modulus", "density", "half_depth", "elements",
                    "yield_strain", "rigid", "mass", "inertia", "centre", "points", "section", "material"}, w)
        v.identifier(ln, "name", w, {x["name"] for x in links[:i] if isinstance(x, dict)})
        link_section(ln, w)
        v.num(ln, "length", w, positive=True, required=True)
    if kind == "fourbar":
        lengths, ndof = _fourbar_tables(mech, links), 1
    else:
        lengths, ndof = _serial_tables(mech, links), len(links)
    joints = template_joints(kind, len(links))
    jr = raw.get("joints", {})
    v.keys(jr, set(joints), "joints")
    conditions = {j: v.text(jr, j, "joints", default=allowed[0], choices=allowed) for j, allowed in joints.items()}
    drives = _template_drives(raw.get("drive"), joints, ndof)
    driven = {d["joint"] for d in drives if d["law"] == "force"}
    for j, cond in conditions.items():
        if cond == "torque" and j not in driven:
            raise CaseError(f"joints.{j}", "'torque' leaves a driven joint free in the elastic problem, loaded by its "
                                           "torque; this joint has no [[drive.torques]] entry: add one or use pin/clamp/locked")
    ini = raw.get("initial", {})
    v.keys(ini, {"angles", "speeds"}, "initial")
    if drives and drives[0]["law"] != "force" and "speeds" in ini:
        raise CaseError("initial.speeds", "does not apply to a kinematic drive (the drive law sets the speed); remove it")
    angles = v.vector(ini, "angles", "initial", ndof, default=[0.0] * ndof)
    speeds = v.vector(ini, "speeds", "initial", ndof, default=[0.0] * ndof)
    names = list(joints)
    if kind == "fourbar":
        geometry = _fourbar_geometry(lengths, mech, angles[0])
        coordinates = {"crank_pivot": angles[0]}
    else:
        geometry = _serial_geometry(lengths, [ln["name"] for ln in links], mech, angles)
        coordinates = dict(zip(names, angles))
    for d in drives:
        if d["law"] != "force":
            d["start"] = angles[0]
    out["mechanism"] = {"ground": geometry["ground"], "template": {k: mech[k] for k in mech}}
    for ln, (start, end) in zip(out["links"], geometry["ends"]):
        ln["start"], ln["end"] = start, end       # the given length stays: the link is exactly that long
    out["joints"] = [{"name": name, "type": "revolute", "connects": list(geometry["connects"][name]),
                      "elastic": conditions[name]} for name in names]
    out["drives"] = drives
    out["initial"] = {"coordinates": coordinates}
    if drives[0]["law"] == "force":      # torque-driven: the speeds of the joints that carry the DOFs
        out["initial"]["speeds"] = dict(zip(names[:ndof], speeds))
    out.pop("drive", None)
    if kind == "fourbar" and "outputs" not in raw:
        out["outputs"] = copy.deepcopy(FOURBAR_OUTPUTS)
    if kind == "serial" and "outputs" not in raw:
        raise CaseError("outputs", "is missing; a serial chain needs an [outputs] table naming what to record")
    return out


FOURBAR_OUTPUTS = {
    "crank_angle": {"kind": "joint_angle", "joint": "crank_pivot"},
    "crank_speed": {"kind": "joint_speed", "joint": "crank_pivot"},
    "strain_coupler_mid": {"kind": "strain", "link": "coupler", "at": 0.5},
    "strain_follower_mid": {"kind": "strain", "link": "follower", "at": 0.5},
}


def _fourbar_tables(mech: dict, links: list) -> list:
    v.keys(mech, {"type", "ground_length", "assembly"}, "mechanism")
    if len(links) != 3:
        raise CaseError("links", f"a fourbar needs exactly 3 links (crank, coupler, follower in this order), got {len(links)}")
    if [ln["name"] for ln in links] != FOURBAR_LINKS:
        raise CaseError("links", "a fourbar's links must be named 'crank', 'coupler', 'follower', in this order")
    v.num(mech, "ground_length", "mechanism", positive=True, required=True)
    v.text(mech, "assembly", "mechanism", default="open", choices=("open", "crossed"))
    return [float(ln["length"]) for ln in links]


def _serial_tables(mech: dict, links: list) -> list:
    for key in ("ground_length", "assembly"):
        if key in mech:
            raise CaseError("mechanism", "ground_length and assembly apply to fourbars only")
    v.keys(mech, {"type", "base"}, "mechanism")
    v.vector(mech, "base", "mechanism", 2)
    return [float(ln["length"]) for ln in links]


def _fourbar_geometry(lengths: list, mech: dict, q0: float) -> dict:
    """Ground pivots O2 = (0, 0), O4 = (d, 0); A = O2 + a e(q0); B on the open (higher B_y) or crossed
    (lower B_y) assembly branch."""
    a, b, c = lengths
    d = float(mech["ground_length"])
    ax, ay = a * math.cos(q0), a * math.sin(q0)
    dx, dy = d - ax, -ay
    r = math.hypot(dx, dy)
    if r > b + c or r < abs(b - c) or r == 0.0:
        raise MechanismError(f"four-bar cannot assemble at crank angle {q0:.6g} rad: |A-O4| = {r:.6g} m but the coupler "
                             f"and follower reach only [{abs(b - c):.6g}, {b + c:.6g}] m")
    ell = (b * b - c * c + r * r) / (2 * r)
    hgt = math.sqrt(max(b * b - ell * ell, 0.0))
    cands = [(ax + ell * dx / r - s * hgt * dy / r, ay + ell * dy / r + s * hgt * dx / r) for s in (1.0, -1.0)]
    if abs(cands[0][1] - cands[1][1]) <= 1e-12 * max(a, b, c, d):
        raise MechanismError(f"open assembly is ambiguous at crank angle {q0:.6g} rad: both assembly solutions have "
                             f"B_y = {cands[0][1]:.6g} m")
    cands.sort(key=lambda p: -p[1])
    bx, by = cands[0] if mech.get("assembly", "open") == "open" else cands[1]
    A, B = [ax, ay], [bx, by]
    return {"ground": {"O2": [0.0, 0.0], "O4": [d, 0.0]},
            "ends": [([0.0, 0.0], A), (A, B), ([d, 0.0], B)],
            "connects": {"crank_pivot": ("ground.O2", "crank.start"), "crank_coupler": ("crank.end", "coupler.start"),
                         "coupler_follower": ("coupler.end", "follower.end"),
                         "follower_pivot": ("ground.O4", "follower.start")}}


def _serial_geometry(lengths: list, names: list, mech: dict, angles: list) -> dict:
    """Link 1 from ``base`` at the absolute angle angles[0]; link k from the end of link k-1 at the
    relative angle angles[k-1]."""
    base = [float(x) for x in mech.get("base", [0.0, 0.0])]
    ends, phi, p = [], 0.0, base
    for L, q in zip(lengths, angles):
        phi += q
        e = [p[0] + L * math.cos(phi), p[1] + L * math.sin(phi)]
        ends.append((p, e))
        p = e
    connects = {"base": ("ground.base", f"{names[0]}.start")}
    for k in range(2, len(names) + 1):
        connects[f"joint_{k}"] = (f"{names[k - 2]}.end", f"{names[k - 1]}.start")
    return {"ground": {"base": base}, "ends": ends, "connects": connects}


def _template_drives(raw, joints: dict, ndof: int) -> list:
    if raw is None:
        raise CaseError("drive", "is missing; add a [drive] table (type = 'torque' or 'kinematic')")
    v.keys(raw, {"type", "torques", "law", "speed", "final_speed", "spinup_time"}, "drive")
    kind = v.text(raw, "type", "drive", required=True, choices=("torque", "kinematic"))
    other = {"torques"} if kind == "kinematic" else {"law", "speed", "final_speed", "spinup_time"}
    for key in sorted(other & set(raw)):
        raise CaseError(f"drive.{key}", f"does not apply to a {kind!r} drive; remove it or change drive.type")
    if kind == "torque":
        tq = raw.get("torques")
        if not isinstance(tq, list) or not tq:
            raise CaseError("drive.torques", "is missing; add [[drive.torques]] tables (joint, constant, sin, cos)")
        return [_torque(t, f"drive.torques[{i}]", joints) for i, t in enumerate(tq)]
    if ndof != 1:
        raise CaseError("drive.type", f"'kinematic' drives need a 1-DOF mechanism; this one has {ndof} DOFs: "
                                      "use type = 'torque' or a single-link serial chain")
    law = v.text(raw, "law", "drive", required=True, choices=("constant_speed", "spinup"))
    d = {"joint": next(iter(joints)), "law": law}
    if law == "constant_speed":
        d["speed"] = v.num(raw, "speed", "drive", required=True)
        if "final_speed" in raw or "spinup_time" in raw:
            raise CaseError("drive", "final_speed and spinup_time belong to law = 'spinup'; remove them")
    else:
        if "speed" in raw:
            raise CaseError("drive.speed", "belongs to law = 'constant_speed'; a spin-up uses final_speed and spinup_time")
        d["final_speed"] = v.num(raw, "final_speed", "drive", required=True)
        d["spinup_time"] = v.num(raw, "spinup_time", "drive", required=True, positive=True)
    return [d]


def _torque(t, where: str, joints) -> dict:
    v.keys(t, {"joint", "constant", "sin", "cos"}, where)
    joint = v.text(t, "joint", where, required=True, choices=tuple(joints))
    d = {"joint": joint, "law": "force", "constant": v.num(t, "constant", where, default=0.0)}
    for key in ("sin", "cos"):
        val = t.get(key, [])
        if isinstance(val, (int, float)) and not isinstance(val, bool):
            val = [val]
        if not isinstance(val, list):
            raise CaseError(f"{where}.{key}", f"must be a list of harmonic amplitudes [N m], got {val!r}")
        d[key] = [v.num({"x": x}, "x", f"{where}.{key}") for x in val]
    return d
