"""Case files: TOML schema, defaults, validation and ``--set`` overrides.

A case is read into a plain nested ``dict`` (the *resolved input*: every
default filled in, every value checked), which is what ``summary.json``
records.  The schema is documented in ``docs/cases.md``; every error is a
:class:`~flexmech_py.errors.CaseError` naming the field and the fix.
"""

from __future__ import annotations

import copy
import math
import re
from pathlib import Path

from .errors import CaseError

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = ["load_case", "validate_case", "apply_overrides", "MODELS", "SUPERPOSITION_MODELS", "JOINTS_OF", "OUTPUT_KINDS",
           "INTEGRATORS", "integrator_coefficients", "DIVERGENCE_FACTOR"]

SUPERPOSITION_MODELS = ("hac", "classic", "classic-translational")
MODELS = SUPERPOSITION_MODELS + ("coupled", "nonlinear")
MECHANISMS = ("fourbar", "serial")
INTEGRATORS = ("newmark", "hht", "generalized-alpha")
# the parameter key of each integrator (solver.<key>), its default and its range
INTEGRATOR_PARAMS = {"newmark": ("beta", "gamma"), "hht": ("hht_alpha",), "generalized-alpha": ("rho_inf",)}
HHT_ALPHA_DEFAULT, HHT_ALPHA_MAX = 0.05, 1.0 / 3.0
RHO_INF_DEFAULT = 0.8
DIVERGENCE_FACTOR = 1.0   # default solver.divergence_limit = DIVERGENCE_FACTOR x the longest link length
OUTPUT_KINDS = {
    # kind: (required keys, optional keys with defaults)
    "joint_angle": ({"joint"}, {}),
    "joint_speed": ({"joint"}, {}),
    "joint_acceleration": ({"joint"}, {}),
    "link_angle": ({"link"}, {}),
    "strain": ({"link"}, {"at": 0.5}),
    "curvature": ({"link"}, {"at": 0.5}),
    "displacement": ({"at", "component"}, {}),
    "position": ({"at", "component"}, {}),
    "inertia_load": ({"component"}, {"at": None, "model": "run"}),
    "axial_force": ({"link"}, {"at": 0.5}),
}
COMPONENTS = {
    "displacement": ("x", "y", "rotation", "axial", "transverse"),
    "position": ("x", "y"),
    "inertia_load": ("x", "y", "rotation", "norm"),
}
UNITS = {
    "joint_angle": "rad", "joint_speed": "rad/s", "joint_acceleration": "rad/s^2", "link_angle": "rad",
    "strain": "1", "curvature": "1/m", "position": "m", "axial_force": "N",
}
ERROR_ESTIMATES = ("time", "none")   # step doubling (one more run at 2 dt), or nothing (guards.py)
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def JOINTS_OF(mech_type: str, nlinks: int) -> dict[str, tuple[str, ...]]:
    """Joints of a mechanism type: name -> allowed elastic conditions (first = default)."""
    if mech_type == "fourbar":
        return {
            "crank_pivot": ("clamp", "pin", "torque"),
            "crank_coupler": ("pin", "locked", "torque"),
            "coupler_follower": ("pin", "locked", "torque"),
            "follower_pivot": ("pin", "clamp", "torque"),
        }
    joints = {"base": ("clamp", "pin", "torque")}
    for k in range(2, nlinks + 1):
        joints[f"joint_{k}"] = ("locked", "pin", "torque")
    return joints


# ----------------------------------------------------------------------------- scalar checks
def _num(d: dict, key: str, where: str, *, default=None, positive=False, nonneg=False, required=False):
    if key not in d:
        if required:
            raise CaseError(f"{where}.{key}", "is missing; add it (a number in SI units)")
        return default
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise CaseError(f"{where}.{key}", f"must be a number, got {v!r}")
    v = float(v)
    if not math.isfinite(v):
        raise CaseError(f"{where}.{key}", f"must be finite, got {v!r}")
    if positive and v <= 0:
        raise CaseError(f"{where}.{key}", f"must be > 0, got {v!r}")
    if nonneg and v < 0:
        raise CaseError(f"{where}.{key}", f"must be >= 0, got {v!r}")
    return v


def _int(d: dict, key: str, where: str, *, default=None, minimum=1):
    if key not in d:
        return default
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, int) and not (isinstance(v, float) and v.is_integer()):
        raise CaseError(f"{where}.{key}", f"must be a whole number, got {v!r}")
    v = int(v)
    if v < minimum:
        raise CaseError(f"{where}.{key}", f"must be >= {minimum}, got {v}")
    return v


def _str(d: dict, key: str, where: str, *, default=None, choices=None, required=False):
    if key not in d:
        if required:
            hint = f" (one of {', '.join(map(repr, choices))})" if choices else ""
            raise CaseError(f"{where}.{key}", f"is missing; add it{hint}")
        return default
    v = d[key]
    if not isinstance(v, str):
        raise CaseError(f"{where}.{key}", f"must be a string, got {v!r}")
    if choices is not None and v not in choices:
        raise CaseError(f"{where}.{key}", f"must be one of {', '.join(map(repr, choices))}, got {v!r}")
    return v


def _vec(d: dict, key: str, where: str, n: int, *, default=None, nonneg=False):
    if key not in d:
        return default
    v = d[key]
    if not isinstance(v, list) or len(v) != n:
        raise CaseError(f"{where}.{key}", f"must be a list of {n} numbers, got {v!r}")
    return [_num({"x": x}, "x", f"{where}.{key}", nonneg=nonneg) for x in v]


def _keys(d, allowed, where: str):
    if not isinstance(d, dict):
        raise CaseError(where, f"must be a table, got {d!r}")
    for k in d:
        if k not in allowed:
            raise CaseError(f"{where}.{k}", f"unknown key; allowed keys here: {', '.join(sorted(allowed))}")


# ----------------------------------------------------------------------------- integrators
def integrator_coefficients(integrator: str, params: dict | None = None) -> tuple[float, float, float, float]:
    """(alpha_m, alpha_f, beta, gamma) of the generalized-alpha time loop (docs/theory.md section 15).

    ``integrator``: ``newmark`` (params ``beta`` 0.25, ``gamma`` 0.5: alpha_m = alpha_f = 0),
    ``hht`` (``hht_alpha`` in [0, 1/3], default 0.05: alpha_m = 0, alpha_f = alpha,
    gamma = 1/2 + alpha, beta = (1 + alpha)^2 / 4) or ``generalized-alpha`` (Chung-Hulbert,
    ``rho_inf`` in [0, 1], default 0.8: alpha_m = (2 rho - 1)/(rho + 1), alpha_f = rho/(rho + 1),
    gamma = 1/2 - alpha_m + alpha_f, beta = (1 - alpha_m + alpha_f)^2 / 4).  ``params`` is any
    mapping holding those keys (e.g. a resolved ``case["solver"]``); missing ones take the defaults.
    The one place the integrators are mapped onto the kernels' parameters, for every model.
    """
    params = {} if params is None else params
    if integrator == "newmark":
        return 0.0, 0.0, float(params.get("beta", 0.25)), float(params.get("gamma", 0.5))
    if integrator == "hht":
        al = float(params.get("hht_alpha", HHT_ALPHA_DEFAULT))
        if not 0.0 <= al <= HHT_ALPHA_MAX + 1e-15:
            raise CaseError("solver.hht_alpha", f"must lie in [0, 1/3], got {al}")
        return 0.0, al, 0.25 * (1.0 + al) ** 2, 0.5 + al
    if integrator == "generalized-alpha":
        rho = float(params.get("rho_inf", RHO_INF_DEFAULT))
        if not 0.0 <= rho <= 1.0:
            raise CaseError("solver.rho_inf", f"must lie in [0, 1], got {rho}")
        am, af = (2.0 * rho - 1.0) / (rho + 1.0), rho / (rho + 1.0)
        return am, af, 0.25 * (1.0 - am + af) ** 2, 0.5 - am + af
    raise CaseError("solver.integrator", f"must be one of {', '.join(map(repr, INTEGRATORS))}, got {integrator!r}")


def _integrator(sol: dict) -> dict:
    """Validate solver.integrator and its parameters; the resolved entries (only the keys that apply)."""
    name = _str(sol, "integrator", "solver", default="newmark", choices=INTEGRATORS)
    for other, keys in INTEGRATOR_PARAMS.items():
        if other == name:
            continue
        for key in keys:
            if key in sol:
                raise CaseError(f"solver.{key}", f"applies to integrator = {other!r}, not {name!r}; remove it, or "
                                                 f"set solver.integrator = {other!r}")
    if name == "newmark":
        beta = _num(sol, "beta", "solver", default=0.25, positive=True)
        gamma = _num(sol, "gamma", "solver", default=0.5)
        if gamma < 0.5:
            raise CaseError("solver.gamma", f"must be >= 0.5 (gamma < 1/2 adds negative damping), got {gamma}")
        if beta < 0.25 * (gamma + 0.5) ** 2 - 1e-15:
            raise CaseError("solver.beta", f"beta = {beta} with gamma = {gamma} is only conditionally stable; "
                                           f"use beta >= (gamma + 1/2)^2 / 4 = {0.25 * (gamma + 0.5) ** 2:g}")
        return {"integrator": name, "beta": beta, "gamma": gamma}
    if name == "hht":
        al = _num(sol, "hht_alpha", "solver", default=HHT_ALPHA_DEFAULT)
        if not 0.0 <= al <= HHT_ALPHA_MAX + 1e-15:
            raise CaseError("solver.hht_alpha", f"must lie in [0, 1/3] (0: average acceleration, 1/3: the most "
                                                f"numerical damping), got {al}; use e.g. 0.05")
        return {"integrator": name, "hht_alpha": al}
    rho = _num(sol, "rho_inf", "solver", default=RHO_INF_DEFAULT)
    if not 0.0 <= rho <= 1.0:
        raise CaseError("solver.rho_inf", f"must lie in [0, 1] (1: no numerical damping, 0: the most), got {rho}; "
                                          "use e.g. 0.8")
    return {"integrator": name, "rho_inf": rho}


# ----------------------------------------------------------------------------- sections
def _links(raw) -> list[dict]:
    if not isinstance(raw, list) or not raw:
        raise CaseError("links", "is missing or empty; add one [[links]] table per link")
    out, names = [], set()
    allowed = {"name", "length", "area", "second_moment", "youngs_modulus", "density", "half_depth", "elements",
               "yield_strain"}
    for i, ln in enumerate(raw):
        w = f"links[{i}]"
        _keys(ln, allowed, w)
        name = _str(ln, "name", w, required=True)
        if not _NAME.match(name):
            raise CaseError(f"{w}.name", f"must be an identifier (letters, digits, _), got {name!r}")
        if name in names:
            raise CaseError(f"{w}.name", f"duplicate link name {name!r}; give each link its own name")
        names.add(name)
        d = {"name": name}
        for key in ("length", "area", "second_moment", "youngs_modulus", "density"):
            d[key] = _num(ln, key, w, positive=True, required=True)
        d["half_depth"] = _num(ln, "half_depth", w, positive=True)
        if d["half_depth"] is None:  # rectangular section: h = sqrt(12 I / A)
            d["half_depth"] = 0.5 * math.sqrt(12.0 * d["second_moment"] / d["area"])
        d["elements"] = _int(ln, "elements", w)
        if "yield_strain" in ln:   # absent: no yield check (guards.py)
            d["yield_strain"] = _num(ln, "yield_strain", w, positive=True)
        out.append(d)
    return out


def _torque(t, where: str, joints) -> dict:
    _keys(t, {"joint", "constant", "sin", "cos"}, where)
    joint = _str(t, "joint", where, required=True, choices=tuple(joints))
    d = {"joint": joint, "constant": _num(t, "constant", where, default=0.0)}
    for key in ("sin", "cos"):
        v = t.get(key, [])
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            v = [v]
        if not isinstance(v, list):
            raise CaseError(f"{where}.{key}", f"must be a list of harmonic amplitudes [N m], got {v!r}")
        d[key] = [_num({"x": x}, "x", f"{where}.{key}") for x in v]
    return d


def _drive(raw, mech: dict, joints, ndof: int) -> dict:
    if raw is None:
        raise CaseError("drive", "is missing; add a [drive] table (type = 'torque' or 'kinematic')")
    _keys(raw, {"type", "torques", "law", "speed", "final_speed", "spinup_time"}, "drive")
    kind = _str(raw, "type", "drive", required=True, choices=("torque", "kinematic"))
    other = {"torques"} if kind == "kinematic" else {"law", "speed", "final_speed", "spinup_time"}
    for key in sorted(other & set(raw)):
        raise CaseError(f"drive.{key}", f"does not apply to a {kind!r} drive; remove it or change drive.type")
    if kind == "torque":
        tq = raw.get("torques")
        if not isinstance(tq, list) or not tq:
            raise CaseError("drive.torques", "is missing; add [[drive.torques]] tables (joint, constant, sin, cos)")
        return {"type": "torque", "torques": [_torque(t, f"drive.torques[{i}]", joints) for i, t in enumerate(tq)]}
    if ndof != 1:
        raise CaseError("drive.type", f"'kinematic' drives need a 1-DOF mechanism; this one has {ndof} DOFs: "
                                      "use type = 'torque' or a single-link serial chain")
    law = _str(raw, "law", "drive", required=True, choices=("constant_speed", "spinup"))
    d = {"type": "kinematic", "law": law}
    if law == "constant_speed":
        d["speed"] = _num(raw, "speed", "drive", required=True)
        if "final_speed" in raw or "spinup_time" in raw:
            raise CaseError("drive", "final_speed and spinup_time belong to law = 'spinup'; remove them")
    else:
        if "speed" in raw:
            raise CaseError("drive.speed", "belongs to law = 'constant_speed'; a spin-up uses final_speed and spinup_time")
        d["final_speed"] = _num(raw, "final_speed", "drive", required=True)
        d["spinup_time"] = _num(raw, "spinup_time", "drive", required=True, positive=True)
    return d


def _node_ref(ref, where: str, links: dict) -> str:
    if not isinstance(ref, str) or "." not in ref:
        raise CaseError(where, f"must be '<link>.start', '<link>.mid', '<link>.end' or '<link>.<fraction>', got {ref!r}")
    link, pos = ref.split(".", 1)
    if link not in links:
        raise CaseError(where, f"unknown link {link!r}; links are {', '.join(links)}")
    if pos not in ("start", "mid", "end"):
        try:
            f = float(pos)
        except ValueError:
            raise CaseError(where, f"position {pos!r} must be start, mid, end or a fraction 0..1") from None
        if not 0.0 <= f <= 1.0:
            raise CaseError(where, f"fraction {f} must lie in [0, 1]")
    return ref


def _outputs(raw, joints, links: dict, mech_type: str) -> dict:
    if raw is None:
        raw = DEFAULT_OUTPUTS[mech_type]
    if not isinstance(raw, dict) or not raw:
        raise CaseError("outputs", "must be a table of named outputs, e.g. tip_x = {kind = 'position', at = 'l2.end', component = 'x'}")
    out = {}
    for name, spec in raw.items():
        w = f"outputs.{name}"
        if not _NAME.match(name) or name == "t":
            raise CaseError(w, "output names must be identifiers other than 't'")
        if not isinstance(spec, dict) or "kind" not in spec:
            raise CaseError(w, f"must be a table with a 'kind' (one of {', '.join(OUTPUT_KINDS)})")
        kind = _str(spec, "kind", w, choices=tuple(OUTPUT_KINDS))
        req, opt = OUTPUT_KINDS[kind]
        _keys(spec, {"kind"} | req | set(opt), w)
        d = {"kind": kind}
        for key in sorted(req - set(spec)):
            raise CaseError(f"{w}.{key}", f"is missing; a '{kind}' output needs {', '.join(sorted(req))}")
        if "joint" in req:
            d["joint"] = _str(spec, "joint", w, choices=tuple(joints))
        if "link" in req:
            d["link"] = _str(spec, "link", w, choices=tuple(links))
            d["at"] = _num(spec, "at", w, default=opt.get("at"))
            if not 0.0 <= d["at"] <= 1.0:
                raise CaseError(f"{w}.at", f"is a fraction of the link length and must lie in [0, 1], got {d['at']}")
        if kind in COMPONENTS:
            d["component"] = _str(spec, "component", w, choices=COMPONENTS[kind])
            if d["component"] == "norm":  # the norm of the whole load over the free DOFs
                if "at" in spec:
                    raise CaseError(f"{w}.at", "does not apply to component = 'norm' (the norm over all free DOFs); remove it")
            elif "at" not in spec:
                raise CaseError(f"{w}.at", f"is missing; a '{kind}' output needs the node, e.g. at = 'coupler.mid'")
            else:
                d["at"] = _node_ref(spec["at"], f"{w}.at", links)
        if kind == "inertia_load":
            d["model"] = _str(spec, "model", w, default="run", choices=("run",) + SUPERPOSITION_MODELS)
        out[name] = d
    return out


DEFAULT_OUTPUTS = {
    "fourbar": {
        "crank_angle": {"kind": "joint_angle", "joint": "crank_pivot"},
        "crank_speed": {"kind": "joint_speed", "joint": "crank_pivot"},
        "strain_coupler_mid": {"kind": "strain", "link": "coupler", "at": 0.5},
        "strain_follower_mid": {"kind": "strain", "link": "follower", "at": 0.5},
    },
}


def validate_case(raw: dict, source: str = "<case>") -> dict:
    """Check a raw case dict and return the resolved case (defaults filled in)."""
    if not isinstance(raw, dict):
        raise CaseError("case", "the case must be a TOML table")
    _keys(raw, {"case", "mechanism", "links", "mesh", "joints", "drive", "initial", "point_masses",
                "rotary_inertias", "loads", "solver", "outputs"}, "case file")
    r = {}
    meta = raw.get("case", {})
    _keys(meta, {"title", "description", "source"}, "case")
    r["case"] = {"title": _str(meta, "title", "case", default=Path(source).stem),
                 "description": _str(meta, "description", "case", default=""),
                 "source": _str(meta, "source", "case", default="")}

    mech = raw.get("mechanism")
    if mech is None:
        raise CaseError("mechanism", "is missing; add [mechanism] with type = 'fourbar' or 'serial'")
    _keys(mech, {"type", "ground_length", "assembly", "base"}, "mechanism")
    mtype = _str(mech, "type", "mechanism", required=True, choices=MECHANISMS)
    links = _links(raw.get("links"))
    r["links"] = links
    lnames = {ln["name"]: ln for ln in links}
    if mtype == "fourbar":
        if len(links) != 3:
            raise CaseError("links", f"a fourbar needs exactly 3 links (crank, coupler, follower in this order), got {len(links)}")
        if [ln["name"] for ln in links] != ["crank", "coupler", "follower"]:
            raise CaseError("links", "a fourbar's links must be named 'crank', 'coupler', 'follower', in this order")
        r["mechanism"] = {"type": mtype,
                          "ground_length": _num(mech, "ground_length", "mechanism", positive=True, required=True),
                          "assembly": _str(mech, "assembly", "mechanism", default="open", choices=("open", "crossed"))}
        if "base" in mech:
            raise CaseError("mechanism.base", "applies to serial chains only; a fourbar's ground pivots are (0,0) and (ground_length,0)")
        ndof = 1
    else:
        if "ground_length" in mech or "assembly" in mech:
            raise CaseError("mechanism", "ground_length and assembly apply to fourbars only")
        r["mechanism"] = {"type": mtype, "base": _vec(mech, "base", "mechanism", 2, default=[0.0, 0.0])}
        ndof = len(links)

    mesh = raw.get("mesh", {})
    _keys(mesh, {"elements_per_link"}, "mesh")
    r["mesh"] = {"elements_per_link": _int(mesh, "elements_per_link", "mesh", default=2)}
    for ln in links:
        if ln["elements"] is None:
            ln["elements"] = r["mesh"]["elements_per_link"]

    joints = JOINTS_OF(mtype, len(links))
    jr = raw.get("joints", {})
    _keys(jr, set(joints), "joints")
    r["joints"] = {j: _str(jr, j, "joints", default=allowed[0], choices=allowed) for j, allowed in joints.items()}

    r["drive"] = _drive(raw.get("drive"), r["mechanism"], joints, ndof)
    driven = {t["joint"] for t in r["drive"].get("torques", [])}
    for j, cond in r["joints"].items():
        if cond == "torque" and j not in driven:
            raise CaseError(f"joints.{j}", "'torque' leaves a driven joint free in the elastic problem, loaded by its "
                                           "torque; this joint has no [[drive.torques]] entry: add one or use pin/clamp/locked")

    ini = raw.get("initial", {})
    _keys(ini, {"angles", "speeds"}, "initial")
    if r["drive"]["type"] == "kinematic" and "speeds" in ini:
        raise CaseError("initial.speeds", "does not apply to a kinematic drive (the drive law sets the speed); remove it")
    r["initial"] = {"angles": _vec(ini, "angles", "initial", ndof, default=[0.0] * ndof),
                    "speeds": _vec(ini, "speeds", "initial", ndof, default=[0.0] * ndof)}

    pms = raw.get("point_masses", [])
    if not isinstance(pms, list):
        raise CaseError("point_masses", "must be an array of tables [[point_masses]] with 'at' and 'mass'")
    r["point_masses"] = []
    for i, pm in enumerate(pms):
        w = f"point_masses[{i}]"
        _keys(pm, {"at", "mass"}, w)
        if "at" not in pm:
            raise CaseError(f"{w}.at", "is missing; give the node as '<link>.end' etc.")
        r["point_masses"].append({"at": _node_ref(pm["at"], f"{w}.at", lnames),
                                  "mass": _num(pm, "mass", w, positive=True, required=True)})
    ris = raw.get("rotary_inertias", [])
    if not isinstance(ris, list):
        raise CaseError("rotary_inertias", "must be an array of tables [[rotary_inertias]] with 'at', 'inertia', 'turns_with'")
    r["rotary_inertias"] = []
    for i, ri in enumerate(ris):
        w = f"rotary_inertias[{i}]"
        _keys(ri, {"at", "inertia", "turns_with"}, w)
        if "at" not in ri:
            raise CaseError(f"{w}.at", "is missing; give the node as '<link>.end' etc.")
        at = _node_ref(ri["at"], f"{w}.at", lnames)
        r["rotary_inertias"].append({"at": at, "inertia": _num(ri, "inertia", w, positive=True, required=True),
                                     "turns_with": _str(ri, "turns_with", w, default=at.split(".")[0], choices=tuple(lnames))})

    loads = raw.get("loads", {})
    _keys(loads, {"gravity"}, "loads")
    r["loads"] = {"gravity": _vec(loads, "gravity", "loads", 2, default=[0.0, 0.0])}

    sol = raw.get("solver", {})
    _keys(sol, {"t_end", "dt", "output_every", "integrator", "beta", "gamma", "hht_alpha", "rho_inf", "divergence_limit",
                "rayleigh", "model", "rigid_rtol", "rigid_atol", "newton_tol", "newton_maxit",
                "geometric_stiffness", "geometric_tol", "geometric_maxit", "error_estimate"}, "solver")
    t_end = _num(sol, "t_end", "solver", positive=True, required=True)
    dt = _num(sol, "dt", "solver", positive=True, required=True)
    if dt > t_end:
        raise CaseError("solver.dt", f"({dt} s) is longer than the run (t_end = {t_end} s); choose dt <= t_end")
    integ = _integrator(sol)
    div_limit = _num(sol, "divergence_limit", "solver", positive=True,
                     default=DIVERGENCE_FACTOR * max(ln["length"] for ln in links))
    r["solver"] = {"t_end": t_end, "dt": dt,
                   "output_every": _int(sol, "output_every", "solver", default=1),
                   **integ, "divergence_limit": div_limit,
                   "rayleigh": _vec(sol, "rayleigh", "solver", 2, default=[0.0, 0.0], nonneg=True),
                   "model": _str(sol, "model", "solver", default="hac", choices=MODELS),
                   "rigid_rtol": _num(sol, "rigid_rtol", "solver", default=1e-10, positive=True),
                   "rigid_atol": _num(sol, "rigid_atol", "solver", default=1e-12, positive=True),
                   "newton_tol": _num(sol, "newton_tol", "solver", default=1e-8, positive=True),
                   "newton_maxit": _int(sol, "newton_maxit", "solver", default=25),
                   "geometric_stiffness": _str(sol, "geometric_stiffness", "solver", default="none",
                                               choices=("none", "current", "lagged", "quasi_static")),
                   "geometric_tol": _num(sol, "geometric_tol", "solver", default=1e-8, positive=True),
                   "geometric_maxit": _int(sol, "geometric_maxit", "solver", default=50),
                   "error_estimate": _str(sol, "error_estimate", "solver", default="time", choices=ERROR_ESTIMATES)}
    if mtype == "serial" and "outputs" not in raw:
        raise CaseError("outputs", "is missing; a serial chain needs an [outputs] table naming what to record")
    r["outputs"] = _outputs(raw.get("outputs"), joints, lnames, mtype)
    return r


def read_case_file(path) -> dict:
    """The raw (unvalidated) table of a TOML case file; CaseError when it is missing or not TOML."""
    path = Path(path)
    if not path.is_file():
        raise CaseError("case file", f"{str(path)!r} does not exist; give the path of a .toml case file")
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise CaseError("case file", f"{path}: not valid TOML ({exc}); fix the syntax") from None


def load_case(path, overrides: list[str] | None = None) -> dict:
    """Read, override (``KEY.PATH=VALUE`` strings) and validate a TOML case file."""
    path = Path(path)
    raw = read_case_file(path)
    if overrides:
        raw = apply_overrides(raw, overrides)
    case = validate_case(raw, source=str(path))
    case["case"]["path"] = str(path)
    return case


def _parse_value(text: str):
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text  # a bare string


def apply_overrides(raw: dict, overrides: list[str]) -> dict:
    """Return a copy of ``raw`` with ``KEY.PATH=VALUE`` overrides applied.

    Path elements index tables by key, arrays by position (``links.0.length``)
    or, for arrays of named tables, by name (``links.coupler.length``).
    Values are TOML values (``2e-5``, ``"pin"``, ``[0, -9.81]``); bare words are strings.
    """
    raw = copy.deepcopy(raw)
    for ov in overrides:
        if "=" not in ov:
            raise CaseError("--set", f"{ov!r} must look like KEY.PATH=VALUE, e.g. solver.dt=2e-5")
        key, text = ov.split("=", 1)
        parts = [p for p in key.strip().split(".") if p]
        if not parts:
            raise CaseError("--set", f"{ov!r} has an empty key")
        node = raw
        for depth, p in enumerate(parts[:-1]):
            where = ".".join(parts[: depth + 1])
            if isinstance(node, list):
                node = _list_item(node, p, where)
            elif isinstance(node, dict):
                node = node.setdefault(p, {})
            else:
                raise CaseError(f"--set {key}", f"{where} is a value, not a table")
        last = parts[-1]
        if isinstance(node, list):
            raise CaseError(f"--set {key}", "cannot replace a whole array element; set one of its keys")
        if not isinstance(node, dict):
            raise CaseError(f"--set {key}", f"{'.'.join(parts[:-1])} is a value, not a table")
        node[last] = _parse_value(text.strip())
    return raw


def _list_item(lst: list, p: str, where: str):
    if p.isdigit():
        i = int(p)
        if i >= len(lst):
            raise CaseError(f"--set {where}", f"index {i} out of range (the array has {len(lst)} entries)")
        return lst[i]
    for item in lst:
        if isinstance(item, dict) and item.get("name") == p:
            return item
    names = [str(item.get("name")) for item in lst if isinstance(item, dict)]
    raise CaseError(f"--set {where}", f"no entry named {p!r}; names are {', '.join(names)}")
