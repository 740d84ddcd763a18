"""The mechanism's case-file tables (general form), read into a :class:`Mechanism` and written back.

Tables (docs/cases.md, "Mechanisms"): ``[mechanism] ground = {NAME = [x, y]}``, ``[[links]]``,
``[[bodies]]``, ``[[joints]]``, ``[[drives]]``, ``[initial]`` (``coordinates``, ``speeds``), and the
lumped inertias ``[[point_masses]]``, ``[[rotary_inertias]]`` that attach to links.  Every error is
a CaseError naming the field and the fix.
"""

from __future__ import annotations

import copy
import math

import numpy as np

from ..base import validate as v
from ..base.errors import CaseError
from .materials import material_values
from .sections import section_properties
from .drives import LAW_CODES, LAW_PARAMS, Drive
from .joints import JOINT_KINDS, case_fields
from .system import Mechanism

__all__ = ["mechanism_from_spec", "mechanism_spec", "link_section", "derived_keys", "table_samples", "LINK_KEYS",
           "SECTION_KEYS"]

SECTION_KEYS = ("area", "second_moment", "youngs_modulus", "density")
LINK_KEYS = {"name", "start", "end", "length", "angle", "area", "second_moment", "youngs_modulus", "density",
             "half_depth", "elements", "yield_strain", "rigid", "mass", "inertia", "centre", "points", "section",
             "material"}
#: the link keys a ``section`` table gives, and those a ``material`` gives
FROM_SECTION = ("area", "second_moment", "half_depth")
FROM_MATERIAL = ("youngs_modulus", "density")


def _given_by(ln: dict, where: str) -> tuple[dict, dict]:
    """(the link's values given by its section and material, the resolved section and material tables).
    A resolved case holds both a section and the values it gives: they must agree (1e-9), else the
    two are a contradiction named with the fix."""
    derived, tables = {}, {}
    if "section" in ln:
        tables["section"], props = section_properties(ln["section"], f"{where}.section")
        derived.update(area=props.area, second_moment=props.second_moment, half_depth=props.half_depth)
    if "material" in ln:
        mat = material_values(ln["material"], f"{where}.material")
        tables["material"] = copy.deepcopy(ln["material"])   # as given: a name or a table (written back as is)
        derived.update(youngs_modulus=mat["youngs_modulus"], density=mat["density"])
        if "yield_strength" in mat:
            derived["yield_strain"] = mat["yield_strength"] / mat["youngs_modulus"]
    for key, val in derived.items():
        if key in ln and key != "yield_strain":
            given = v.num(ln, key, where, positive=True)
            if abs(given - val) > 1e-9 * abs(val):
                src = "section" if key in FROM_SECTION else "material"
                raise CaseError(f"{where}.{key}", f"({given:g}) disagrees with the link's {src} (which gives "
                                                  f"{val:g}); give one of the two: remove {key} or remove {src}")
    if "yield_strain" in ln:
        derived.pop("yield_strain", None)
    return derived, tables


def derived_keys(ln: dict) -> tuple:
    """The keys of a resolved link table that its section and material give (left out of a written case)."""
    out = (FROM_SECTION if "section" in ln else ()) + (FROM_MATERIAL if "material" in ln else ())
    mat = material_values(ln["material"], "material") if "material" in ln else {}
    if "yield_strength" in mat and "yield_strain" in ln and \
            abs(ln["yield_strain"] - mat["yield_strength"] / mat["youngs_modulus"]) <= 1e-12 * ln["yield_strain"]:
        out += ("yield_strain",)
    return out


def link_section(ln: dict, where: str) -> dict:
    """The validated section and mass entries of a link table (shared by the templates): a ``section``
    table gives area, second moment and half depth, a ``material`` Young's modulus, density and the
    yield strain (docs/cases.md, "Sections and materials")."""
    derived, tables = _given_by(ln, where)
    ln = {**ln, **derived}
    d = _raw_section(ln, where)
    d.update(tables)
    return d


def _raw_section(ln: dict, where: str) -> dict:
    rigid = ln.get("rigid", False)
    if not isinstance(rigid, bool):
        raise CaseError(f"{where}.rigid", f"must be true or false, got {rigid!r}")
    d = {"rigid": rigid}
    if rigid and "mass" in ln:
        d["mass"] = v.num(ln, "mass", where, positive=True)
        d["inertia"] = v.num(ln, "inertia", where, nonneg=True)
        d["centre"] = v.num(ln, "centre", where, default=0.5)
        if not 0.0 <= d["centre"] <= 1.0:
            raise CaseError(f"{where}.centre", f"is a fraction of the length and must lie in [0, 1], got {d['centre']}")
        for key in SECTION_KEYS + ("half_depth", "elements"):
            if key in ln:
                d[key] = v.num(ln, key, where, positive=True)
    else:
        for key in ("mass", "inertia", "centre"):
            if key in ln:
                raise CaseError(f"{where}.{key}", "applies to rigid links only (rigid = true); a flexible link's "
                                                  "mass comes from density x area")
        needed = ("area", "density") if rigid else SECTION_KEYS
        for key in SECTION_KEYS:
            d[key] = v.num(ln, key, where, positive=True, required=key in needed)
        d["half_depth"] = v.num(ln, "half_depth", where, positive=True)
        if d["half_depth"] is None and d.get("second_moment") and d.get("area"):
            d["half_depth"] = 0.5 * math.sqrt(12.0 * d["second_moment"] / d["area"])   # rectangular section
        d["elements"] = v.whole(ln, "elements", where)
    if "yield_strain" in ln:
        d["yield_strain"] = v.num(ln, "yield_strain", where, positive=True)
    return d


def mechanism_from_spec(raw: dict) -> Mechanism:
    """A Mechanism from the general-form tables of a case (raw dict); checks topology too."""
    mech = Mechanism()
    mraw = raw.get("mechanism", {})
    v.keys(mraw, {"ground", "template"}, "mechanism")
    ground = mraw.get("ground", {})
    v.keys(ground, set(ground), "mechanism.ground")
    for name, pos in ground.items():
        if not v.NAME.match(name):
            raise CaseError(f"mechanism.ground.{name}", "ground point names must be identifiers")
        mech.add_ground_point(name, v.vector(ground, name, "mechanism.ground", 2))
    if mraw.get("template") is not None:
        mech.template = dict(mraw["template"])
    _add_bodies(mech, raw.get("links", []), raw.get("bodies", []))
    _joints(mech, raw.get("joints", []))
    _drives(mech, raw.get("drives", []))
    _lumped(mech, raw)
    _initial(mech, raw.get("initial", {}))
    mech.check()
    return mech


def _add_bodies(mech: Mechanism, links, bodies) -> None:
    """Add links and rigid bodies, each after the bodies its point references name (a link may end at a
    plate's point and the plate's point be given on another link); numbered in file order."""
    for key, items in (("links", links), ("bodies", bodies)):
        if not isinstance(items, list):
            raise CaseError(key, f"must be an array of tables [[{key}]]")
    pending = [("links", i, ln) for i, ln in enumerate(links)] + [("bodies", i, b) for i, b in enumerate(bodies)]
    names = {it.get("name") for _, _, it in pending if isinstance(it, dict)}
    while pending:
        left = []
        for key, i, item in pending:
            refs = _references(item, key, i, names)
            if refs <= set(mech.body_names()):
                (_add_link if key == "links" else _add_body)(mech, item, f"{key}[{i}]")
            else:
                left.append((key, i, item))
        if len(left) == len(pending):
            key, i, item = left[0]
            raise CaseError(f"{key}[{i}]", f"its point references form a cycle with "
                                           f"{', '.join(sorted(_references(item, key, i, names)))}; give one of "
                                           "them as coordinates [x, y]")
        pending = left
    order = {it.get("name"): k for k, it in enumerate(list(links) + list(bodies))}
    mech.links.sort(key=lambda b: order[b.name])
    mech.rigid_bodies.sort(key=lambda b: order[b.name])


def _references(item, key: str, i: int, names: set) -> set:
    """Names of the bodies an item's positions refer to (the ground excluded); unknown names are errors."""
    if not isinstance(item, dict):
        raise CaseError(f"{key}[{i}]", "must be a table")
    vals = [(f, item[f]) for f in ("start", "end", "centre") if f in item]
    if key == "bodies" and isinstance(item.get("points"), dict):
        vals += [(f"points.{k}", val) for k, val in item["points"].items()]
    out = set()
    for field_, val in vals:
        if isinstance(val, str) and not val.startswith("ground"):
            body = val.split(".")[0]
            if body not in names:
                raise CaseError(f"{key}[{i}].{field_}", f"unknown body {body!r} in {val!r}; bodies are "
                                                         f"{', '.join(sorted(n for n in names if n))}")
            out.add(body)
    return out


def _add_link(mech: Mechanism, ln: dict, w: str) -> None:
    v.keys(ln, LINK_KEYS, w)
    name = v.identifier(ln, "name", w, set(mech.body_names()))
    props = link_section(ln, w)
    pts = ln.get("points", {})
    v.keys(pts, set(pts), f"{w}.points")
    fr = {}
    for k in pts:
        if not v.NAME.match(k) or k in ("start", "mid", "end"):
            raise CaseError(f"{w}.points.{k}", "point names must be identifiers other than start, mid, end")
        fr[k] = v.num(pts, k, f"{w}.points")
        if not 0.0 <= fr[k] <= 1.0:
            raise CaseError(f"{w}.points.{k}", f"is a fraction of the link's length and must lie in [0, 1], got {fr[k]}")
    if "start" not in ln:
        raise CaseError(f"{w}.start", "is missing; give [x, y] in metres or a point such as 'ground.O2'")
    if "end" in ln:
        if "angle" in ln:
            raise CaseError(f"{w}.angle", "give either 'end', or 'length' and 'angle', not both")
        end, length, angle = _point_or_xy(ln["end"], f"{w}.end"), None, None
    else:
        end = None
        length = v.num(ln, "length", w, positive=True, required=True)
        angle = v.num(ln, "angle", w, required=True)
    link = mech.add_link(name, _point_or_xy(ln["start"], f"{w}.start"), end, length=length, angle=angle,
                         points=fr, where=w, **props)
    if not link.length > 1e-12:
        raise CaseError(f"{w}.end", f"link {name!r} has zero length (start and end coincide); move its end")
    if end is not None and "length" in ln:     # both given (as the resolved input has): they must agree
        given = v.num(ln, "length", w, positive=True)
        if abs(given - link.length) > 1e-9 * link.length:
            raise CaseError(f"{w}.length", f"is {given:g} m but start and end are {link.length:.9g} m apart; "
                                           "give one or make them agree")
        link.nominal_length = given


def _point_or_xy(val, where: str):
    """A point reference (string) or a position [x, y] [m]."""
    if isinstance(val, str):
        return val
    if isinstance(val, list) and len(val) == 2 and all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in val):
        return [float(x) for x in val]
    raise CaseError(where, f"must be [x, y] in metres or a point reference such as 'ground.O2', got {val!r}")


def _add_body(mech: Mechanism, b: dict, w: str) -> None:
    v.keys(b, {"name", "mass", "inertia", "centre", "points"}, w)
    name = v.identifier(b, "name", w, set(mech.body_names()))
    if "centre" not in b:
        raise CaseError(f"{w}.centre", "is missing; give the centre of mass [x, y] in the assembly configuration")
    pts = b.get("points", {})
    v.keys(pts, set(pts), f"{w}.points")
    for k in pts:
        if not v.NAME.match(k) or k == "centre":
            raise CaseError(f"{w}.points.{k}", "point names must be identifiers other than 'centre'")
    mech.add_body(name, v.num(b, "mass", w, positive=True, required=True),
                  v.num(b, "inertia", w, nonneg=True, required=True), _point_or_xy(b["centre"], f"{w}.centre"),
                  {k: _point_or_xy(p, f"{w}.points.{k}") for k, p in pts.items()}, where=w)


def _joints(mech: Mechanism, raw) -> None:
    if not isinstance(raw, list):
        raise CaseError("joints", "must be an array of tables [[joints]] (name, type, connects)")
    for i, j in enumerate(raw):
        w = f"joints[{i}]"
        v.keys(j, {"name", "type", "connects", "elastic"} | set(case_fields()), w)
        name = v.identifier(j, "name", w, {jt.name for jt in mech.joints})
        kind = v.text(j, "type", w, required=True, choices=tuple(JOINT_KINDS))
        con = j.get("connects")
        if not (isinstance(con, list) and len(con) == 2 and all(isinstance(c, str) for c in con)):
            raise CaseError(f"{w}.connects", "must be two point references [a, b], e.g. ['ground', 'crank.start']")
        cls = JOINT_KINDS[kind]
        for key, kinds in case_fields().items():
            if key in j and key not in cls.case_fields:
                raise CaseError(f"{w}.{key}", f"applies to {' and '.join(kinds)} joints only, not to a {kind} joint")
        extra = cls.fields_from_case(j, w)
        elastic = v.text(j, "elastic", w, choices=cls.conditions)
        joint = mech.add_joint(kind, name, con[0], con[1], elastic=elastic, **extra)
        mech.joint_points(joint, f"{w}.connects")


def _drives(mech: Mechanism, raw) -> None:
    if not isinstance(raw, list):
        raise CaseError("drives", "must be an array of tables [[drives]] (joint, law, ...)")
    for i, d in enumerate(raw):
        w = f"drives[{i}]"
        law = v.text(d, "law", w, required=True, choices=tuple(LAW_CODES))
        req, opt = LAW_PARAMS[law]
        v.keys(d, {"joint", "law"} | req | set(opt), w)
        joint = v.text(d, "joint", w, required=True)
        mech.joint(joint, f"{w}.joint")
        for key in sorted(req - set(d)):
            raise CaseError(f"{w}.{key}", f"is missing; a '{law}' law needs {', '.join(sorted(req))}")
        if law == "table":
            params = table_samples({"t": d["t"], "value": d["value"]}, w)
        else:
            params = {key: _law_param(d, key, w, opt.get(key)) for key in sorted(req | set(opt))}
        mech.drives.append(Drive(joint=joint, law=law, params=params))


def _law_param(d: dict, key: str, w: str, default):
    if key not in d:
        return default
    if key in ("sin", "cos"):
        val = d[key]
        val = [val] if isinstance(val, (int, float)) and not isinstance(val, bool) else val
        if not isinstance(val, list):
            raise CaseError(f"{w}.{key}", f"must be a list of harmonic amplitudes, got {val!r}")
        return [v.num({"x": x}, "x", f"{w}.{key}") for x in val]
    if key == "time_harmonics":
        val = d[key]
        if not isinstance(val, list) or not all(isinstance(h, list) and len(h) == 3 for h in val):
            raise CaseError(f"{w}.{key}", "must be a list of [amplitude, angular frequency rad/s, phase rad] triples")
        return [[v.num({"x": x}, "x", f"{w}.{key}") for x in h] for h in val]
    if key == "table":
        return table_samples(d[key], f"{w}.table")
    if key == "profile":
        return v.text(d, key, w, choices=("cycloidal", "quintic"))
    return v.num(d, key, w, positive=key in ("spinup_time", "duration"))


def table_samples(tab, where: str) -> dict:
    """A checked table {t = [...], value = [...]} (increasing times, at least 2 samples)."""
    if not isinstance(tab, dict):
        raise CaseError(where, "must be a table {t = [...], value = [...]}")
    v.keys(tab, {"t", "value"}, where)
    t, y = tab.get("t"), tab.get("value")
    if not isinstance(t, list) or not isinstance(y, list) or len(t) != len(y) or len(t) < 2:
        raise CaseError(where, "needs lists t and value of equal length (at least 2 samples)")
    t = [v.num({"x": x}, "x", f"{where}.t") for x in t]
    y = [v.num({"x": x}, "x", f"{where}.value") for x in y]
    if np.any(np.diff(t) <= 0):
        raise CaseError(f"{where}.t", "the sample times must increase strictly")
    return {"t": t, "value": y}


def _lumped(mech: Mechanism, raw: dict) -> None:
    for key, what in (("point_masses", "mass"), ("rotary_inertias", "inertia")):
        items = raw.get(key, [])
        if not isinstance(items, list):
            raise CaseError(key, f"must be an array of tables [[{key}]] with 'at' and '{what}'")
        for i, it in enumerate(items):
            w = f"{key}[{i}]"
            v.keys(it, {"at", what} | ({"turns_with"} if key == "rotary_inertias" else set()), w)
            if "at" not in it:
                raise CaseError(f"{w}.at", "is missing; give the point as '<link>.end' etc.")
            ref = mech.point(it["at"], f"{w}.at")
            val = v.num(it, what, w, positive=True, required=True)
            if ref.body is None or ref.body.kind != "link":
                raise CaseError(f"{w}.at", "must be a point of a link; add a rigid body's lumped mass to its "
                                           "mass and inertia")
            frac = ref.body.fraction(ref.point, f"{w}.at")
            if key == "point_masses":
                ref.body.lumped.append((frac, val))
                continue
            carrier = ref.body
            if "turns_with" in it:
                carrier = mech.body(v.text(it, "turns_with", w), f"{w}.turns_with")
                at = frac if carrier is ref.body else _fraction_at(carrier, ref.position)
                if carrier.kind != "link" or at is None:
                    raise CaseError(f"{w}.turns_with", f"link {it['turns_with']!r} does not pass through {it['at']!r}; "
                                                       "name a link that meets at that point")
                frac = at
            carrier.hubs.append((frac, val))


def _fraction_at(link, pos):
    """The fraction of the length at which ``link`` passes through the assembly position ``pos`` (a
    named point's own fraction when one is there, else any point of its axis), or None."""
    if link.kind != "link":
        return None
    tol = 1e-9 * max(1.0, link.length)
    for name in link.point_names():
        if np.linalg.norm(link.position(name) - np.asarray(pos)) <= tol:
            return link.fraction(name)
    start, end = np.asarray(link.start, float), np.asarray(link.end, float)
    axis = end - start
    s = float(np.dot(np.asarray(pos, float) - start, axis) / np.dot(axis, axis))
    if 0.0 <= s <= 1.0 and np.linalg.norm(start + s * axis - np.asarray(pos, float)) <= tol:
        return s
    return None


def _initial(mech: Mechanism, ini) -> None:
    v.keys(ini, {"coordinates", "speeds"}, "initial")
    for key, target in (("coordinates", mech.initial_coordinates), ("speeds", mech.initial_speeds)):
        tab = ini.get(key, {})
        if not isinstance(tab, dict):
            raise CaseError(f"initial.{key}", "must be a table {joint = value}")
        for name in tab:
            mech.joint(name, f"initial.{key}.{name}")
            target[name] = v.num(tab, name, f"initial.{key}")
    for name in mech.initial_speeds:
        d = mech.drive_of(name)
        if d is not None and d.kinematic:
            raise CaseError(f"initial.speeds.{name}", "is driven kinematically (its law sets the speed); remove it")


def mechanism_spec(mech: Mechanism) -> dict:
    """The case-file tables of a mechanism (general form)."""
    out = {"mechanism": {"ground": {k: list(p) for k, p in mech.ground.items()}}, "links": [], "bodies": [],
           "joints": [j.spec() for j in mech.joints], "drives": [d.spec() for d in mech.drives],
           "point_masses": [], "rotary_inertias": []}
    for ln in mech.links:
        d = {"name": ln.name, "start": list(ln.start), "end": list(ln.end)}
        if ln.nominal_length is not None:
            d["length"] = ln.nominal_length
        for key in ("area", "second_moment", "youngs_modulus", "density", "half_depth", "elements", "yield_strain",
                    "mass", "inertia", "section", "material"):
            if getattr(ln, key) is not None:
                d[key] = getattr(ln, key)
        if ln.rigid:
            d["rigid"] = True
            if ln.mass is not None:
                d["centre"] = ln.centre
        if ln.points:
            d["points"] = dict(ln.points)
        out["links"].append(d)
        out["point_masses"] += [{"at": f"{ln.name}.{_point_name(ln, f)}", "mass": m} for f, m in ln.lumped]
        out["rotary_inertias"] += [{"at": f"{ln.name}.{_point_name(ln, f)}", "inertia": j, "turns_with": ln.name}
                                   for f, j in ln.hubs]
    for b in mech.rigid_bodies:
        out["bodies"].append({"name": b.name, "mass": b.mass, "inertia": b.inertia, "centre": list(b.centre),
                              "points": {k: list(p) for k, p in b.points.items()}})
    ini = {}
    if mech.initial_coordinates:
        ini["coordinates"] = dict(mech.initial_coordinates)
    if mech.initial_speeds:
        ini["speeds"] = dict(mech.initial_speeds)
    if ini:
        out["initial"] = ini
    return {k: val for k, val in out.items() if val not in ([], {}, {"ground": {}})}


def _point_name(link, frac: float) -> str:
    for name in link.point_names():
        if abs(link.fraction(name) - frac) < 1e-12:
            return name
    return repr(float(frac))

