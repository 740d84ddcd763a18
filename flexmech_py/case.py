"""Case files: TOML schema, defaults, validation and ``--set`` overrides.

A case is read into a :class:`Case`: a plain nested ``dict`` (the *resolved input*: every default
filled in, every value checked; what ``summary.json`` records) whose ``mechanism`` property is the
:class:`~flexmech_py.mechanism.Mechanism` it describes.  The schema is documented in
``docs/cases.md``: the mechanism's tables (links, bodies, joints, drives; or a template in its short
form, expanded by :mod:`flexmech_py.mechanism.templates`), the mesh, lumped inertias, loads, the
solver and the outputs.  Every error is a :class:`~flexmech_py.base.errors.CaseError` naming the field
and the fix.
"""

from __future__ import annotations

import copy
import json
import math
import numbers
from pathlib import Path

from .base import validate as v
from .base.bundled import resolve_case_path
from .base.errors import CaseError
from .base.families import (AUTO, DEFAULT_INTEGRATORS, MODEL_CHOICES, MODELS, RHO_INF_DEFAULT, STUDY_MODEL,
                            SUPERPOSITION_MODELS, family)
from .base.inputs import read_text
from .mechanism import mechanism_from_spec
from .mechanism.control import check_controllers
from .mechanism.feedforward import resolve_feedforward
from .mechanism.schema import derived_keys, mechanism_spec
from .mechanism.templates import expand_template
from .base.sizes import check_elements, check_mesh
from .base.tomlfile import dumps_toml

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = ["Case", "load_case", "validate_case", "apply_overrides", "MODELS", "MODEL_CHOICES", "SUPERPOSITION_MODELS",
           "STUDY_MODEL", "study_model", "OUTPUT_KINDS", "INTEGRATORS", "integrator_coefficients", "integrator_of",
           "DEFAULT_INTEGRATORS", "DIVERGENCE_FACTOR", "with_elements"]


def study_model(model: str | None, case: dict) -> str:
    """The model a study of one model uses: ``model``, else the case's, with "auto" taken as STUDY_MODEL
    (auto chooses per run; a study of one model's discretization or frozen dynamics names it)."""
    model = case["solver"]["model"] if model is None else model
    return STUDY_MODEL if model == AUTO else model


INTEGRATORS = ("newmark", "hht", "generalized-alpha")
# the parameter key of each integrator (solver.<key>), its default and its range
#: the nonlinear model's node angles (docs/theory.md 12.1): each element's end rotations from its
#: chord, welded at interior nodes ("relative", the default), or one absolute angle per node shared by
#: its two elements ("shared": no weld rows, time per step linear in the elements)
NODE_ANGLES = ("relative", "shared")
INTEGRATOR_PARAMS = {"newmark": ("beta", "gamma"), "hht": ("hht_alpha",), "generalized-alpha": ("rho_inf",)}
HHT_ALPHA_DEFAULT, HHT_ALPHA_MAX = 0.05, 1.0 / 3.0
DIVERGENCE_FACTOR = 1.0   # default solver.divergence_limit = DIVERGENCE_FACTOR x the longest link length
OUTPUT_KINDS = {
    # kind: (required keys, optional keys with defaults)
    "joint_angle": ({"joint"}, {"measure": "frames"}),
    "joint_displacement": ({"joint"}, {"measure": "frames"}),
    "joint_speed": ({"joint"}, {"measure": "frames"}),
    "joint_acceleration": ({"joint"}, {"measure": "frames"}),
    "link_angle": ({"link"}, {}),
    "strain": ({"link"}, {"at": 0.5}),
    "curvature": ({"link"}, {"at": 0.5}),
    "displacement": ({"at", "component"}, {}),
    "deflection": ({"at", "component"}, {}),
    "position": ({"at", "component"}, {}),
    "inertia_load": ({"component"}, {"at": None, "model": "run"}),
    "axial_force": ({"link"}, {"at": 0.5}),
    "reaction": ({"joint", "component"}, {"source": "model"}),
    "drive_force": ({"joint"}, {}),
}
COMPONENTS = {
    "displacement": ("x", "y", "rotation", "axial", "transverse"),
    "deflection": ("x", "y", "rotation", "axial", "transverse"),
    "position": ("x", "y"),
    "inertia_load": ("x", "y", "rotation", "norm"),
    "reaction": ("x", "y", "magnitude", "moment"),
}
UNITS = {
    "joint_angle": "rad", "joint_displacement": "m", "link_angle": "rad", "strain": "1", "curvature": "1/m",
    "position": "m", "axial_force": "N",
}
REACTION_SOURCES = ("model", "rigid")   # reaction outputs: the run model's, or the rigid-body solution's
#: joint_* outputs: the model's rigid coordinate between the bodies' frames (chords), or the coordinate measured
#: at the joint (the bodies' tangents there: a hub, what an encoder and a collocated controller read)
JOINT_MEASURES = ("frames", "joint")
#: solver.error_estimate: the parts of the error budget (budget.py), "all" of them, "none", or parts joined
#: by "+" (e.g. "time+mesh")
ERROR_PARTS = ("time", "mesh", "model")
TOLERANCE_DEFAULT = 0.05       # solver.tolerance: a fraction of each output's peak (budget.TOLERANCE)
ELEMENTS_DEFAULT = 8           # mesh.elements_per_link of a case that gives none
TOP_KEYS = {"case", "mechanism", "links", "bodies", "mesh", "joints", "drive", "drives", "initial", "point_masses",
            "rotary_inertias", "loads", "solver", "outputs", "controllers"}


#: the tables a case's Mechanism is built from (Case.mechanism is rebuilt when one of them changes)
MECHANISM_TABLES = ("mechanism", "links", "bodies", "joints", "drives", "initial", "point_masses", "rotary_inertias")


def _same_tables(kept: list, tables: list) -> bool:
    """Whether the tables are those a Mechanism was built from: a deep comparison of values (cheaper
    than serializing them at every access), then, where it says no or cannot say (NaN, arrays in the
    tables), the comparison of their JSON text."""
    try:
        if kept == tables:
            return True
    except ValueError:          # (an array somewhere in the tables: its == is elementwise)
        pass
    return json.dumps(kept, sort_keys=True, default=str) == json.dumps(tables, sort_keys=True, default=str)


class Case(dict):
    """A resolved case (a dict: the case-file tables, checked and with every default) whose
    :attr:`mechanism` is the Mechanism it describes.  Build one with :func:`load_case`,
    :func:`validate_case` (a raw dict) or :meth:`from_mechanism`; write it with :meth:`write`."""

    @property
    def mechanism(self):
        """The :class:`~flexmech_py.mechanism.Mechanism` of the case's current tables (rebuilt when the
        tables change, e.g. after a study edits a copy)."""
        tables = [self.get(k) for k in MECHANISM_TABLES]
        cached = self.__dict__.get("_mechanism")
        if cached is None or not _same_tables(cached[0], tables):
            cached = (copy.deepcopy(tables), mechanism_from_spec(self))
            self.__dict__["_mechanism"] = cached
        return cached[1]

    @classmethod
    def from_mechanism(cls, mech, *, solver: dict, outputs: dict, loads: dict | None = None,
                       mesh: dict | None = None, title: str = "mechanism", description: str = "") -> "Case":
        """A case from a Mechanism built in Python and the other tables (validated like a file)."""
        raw = mechanism_spec(mech)
        raw.update(case={"title": title, "description": description}, solver=dict(solver), outputs=dict(outputs))
        for key, val in (("loads", loads), ("mesh", mesh)):
            if val is not None:
                raw[key] = val
        return validate_case(raw, source=title)

    def write(self, path) -> Path:
        """Write the case as a TOML file (general form; derived entries left out); returns the path."""
        path = Path(path)
        path.write_text(dumps_toml(case_file_tables(self)), encoding="utf-8")
        return path


def case_file_tables(case: dict) -> dict:
    """The tables of a resolved case as a case file holds them."""
    out = copy.deepcopy(dict(case))
    out["case"] = {k: val for k, val in out["case"].items() if k != "path" and val != ""}
    for ln in out.get("links", []):   # what a section or material gives is written as the section or material
        for key in derived_keys(ln):
            ln.pop(key, None)
    return {k: val for k, val in out.items() if val not in ([], {})}


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


def integrator_of(sol: dict, model: str) -> dict:
    """The integrator entries (``integrator`` and its parameters) a run of ``model`` uses: the case's
    (a resolved ``case["solver"]``) or, when it names none, DEFAULT_INTEGRATORS of the model's family."""
    if "integrator" in sol:
        return {k: sol[k] for k in ("integrator",) + INTEGRATOR_PARAMS[sol["integrator"]] if k in sol}
    return family(model).default_integrator


def _integrator(sol: dict) -> dict:
    """Validate solver.integrator and its parameters; the resolved entries (only the keys that apply).
    A case that names no integrator but gives one integrator's parameters names that integrator; one
    that gives neither resolves to no entries (the model family's default, :func:`integrator_of`)."""
    given = [name for name, keys in INTEGRATOR_PARAMS.items() if any(k in sol for k in keys)]
    if "integrator" not in sol and not given:
        return {}
    name = v.text(sol, "integrator", "solver", default=(given or ["newmark"])[0], choices=INTEGRATORS)
    for other, keys in INTEGRATOR_PARAMS.items():
        if other == name:
            continue
        for key in keys:
            if key in sol:
                raise CaseError(f"solver.{key}", f"applies to integrator = {other!r}, not {name!r}; remove it, or "
                                                 f"set solver.integrator = {other!r}")
    if name == "newmark":
        beta = v.num(sol, "beta", "solver", default=0.25, positive=True)
        gamma = v.num(sol, "gamma", "solver", default=0.5)
        if gamma < 0.5:
            raise CaseError("solver.gamma", f"must be >= 0.5 (gamma < 1/2 adds negative damping), got {gamma}")
        if beta < 0.25 * (gamma + 0.5) ** 2 - 1e-15:
            raise CaseError("solver.beta", f"beta = {beta} with gamma = {gamma} is only conditionally stable; "
                                           f"use beta >= (gamma + 1/2)^2 / 4 = {0.25 * (gamma + 0.5) ** 2:g}")
        return {"integrator": name, "beta": beta, "gamma": gamma}
    if name == "hht":
        al = v.num(sol, "hht_alpha", "solver", default=HHT_ALPHA_DEFAULT)
        if not 0.0 <= al <= HHT_ALPHA_MAX + 1e-15:
            raise CaseError("solver.hht_alpha", f"must lie in [0, 1/3] (0: average acceleration, 1/3: the most "
                                                f"numerical damping), got {al}; use e.g. 0.05")
        return {"integrator": name, "hht_alpha": al}
    rho = v.num(sol, "rho_inf", "solver", default=RHO_INF_DEFAULT)
    if not 0.0 <= rho <= 1.0:
        raise CaseError("solver.rho_inf", f"must lie in [0, 1] (1: no numerical damping, 0: the most), got {rho}; "
                                          "use e.g. 0.8")
    return {"integrator": name, "rho_inf": rho}


# ----------------------------------------------------------------------------- the case
def _general_tables(raw: dict) -> dict:
    """The mechanism's tables in general form: a template's short form expanded, or the general
    tables checked for short-form keys that do not belong there."""
    mech = raw.get("mechanism", {})
    if isinstance(mech, dict) and "type" in mech:
        return expand_template(raw)
    for key, what in (("drive", "[[drives]] tables (joint, law, ...)"), ("joints", "[[joints]] tables")):
        if key in raw and not (key == "joints" and isinstance(raw[key], list)):
            raise CaseError(key, f"is the short form of the templates (mechanism.type = 'fourbar' or 'serial'); "
                                 f"describe a general mechanism with {what}")
    ini = raw.get("initial", {})
    for key in ("angles",):
        if isinstance(ini, dict) and key in ini:
            raise CaseError(f"initial.{key}", "belongs to the templates; give initial.coordinates = {joint = value}")
    if not raw.get("links") and not raw.get("bodies"):
        raise CaseError("mechanism", "is missing; add [mechanism] with type = 'fourbar' or 'serial', or describe "
                                     "the mechanism with [[links]], [[joints]] and [[drives]] tables (docs/cases.md)")
    return raw


def validate_case(raw: dict, source: str = "<case>") -> Case:
    """Check a raw case dict and return the resolved :class:`Case` (defaults filled in)."""
    if not isinstance(raw, dict):
        raise CaseError("case", "the case must be a TOML table")
    v.keys(raw, TOP_KEYS, "case file")
    r = Case()
    meta = raw.get("case", {})
    v.keys(meta, {"title", "description", "source"}, "case")
    r["case"] = {"title": v.text(meta, "title", "case", default=Path(source).stem),
                 "description": v.text(meta, "description", "case", default=""),
                 "source": v.text(meta, "source", "case", default="")}
    general = _general_tables(raw)
    mech = mechanism_from_spec(general)
    mesh = general.get("mesh", {})
    v.keys(mesh, {"elements_per_link"}, "mesh")
    r["mesh"] = {"elements_per_link": v.whole(mesh, "elements_per_link", "mesh", default=ELEMENTS_DEFAULT)}
    spec = mechanism_spec(mech)
    r["mechanism"] = spec.get("mechanism", {"ground": {}})
    if mech.template is not None:
        r["mechanism"]["template"] = mech.template
    r["links"] = spec.get("links", [])
    for ln, link in zip(r["links"], mech.links):
        ln["length"] = link.length
        if not link.rigid and ln.get("elements") is None:
            ln["elements"] = r["mesh"]["elements_per_link"]
    check_mesh(r)      # before any array of the mesh exists (docs/cli.md, sizes)
    r["bodies"] = spec.get("bodies", [])
    r["joints"] = spec.get("joints", [])
    for j, joint in zip(r["joints"], mech.joints):
        j["elastic"] = mech.condition(joint)
    r["drives"] = spec.get("drives", [])
    r["initial"] = {"coordinates": dict(mech.initial_coordinates), "speeds": dict(mech.initial_speeds)}
    r["point_masses"] = spec.get("point_masses", [])
    r["rotary_inertias"] = spec.get("rotary_inertias", [])
    loads = general.get("loads", {})
    v.keys(loads, {"gravity"}, "loads")
    r["loads"] = {"gravity": v.vector(loads, "gravity", "loads", 2, default=[0.0, 0.0])}
    r["solver"] = _solver(general.get("solver", {}), mech)
    _check_tables_cover_run(mech, r["solver"]["t_end"])
    controllers = check_controllers(general.get("controllers"), mech, r["solver"])
    resolve_feedforward(controllers, mech, r["loads"]["gravity"], r["solver"])
    if controllers:
        r["controllers"] = controllers
        if r["solver"]["model"] == "auto":      # (a one-way model misses the loop's action on the deflection)
            r["solver"]["model"] = "nonlinear"
    if "outputs" not in general:
        raise CaseError("outputs", "is missing; add an [outputs] table naming what to record, e.g. "
                                   "tip_x = {kind = 'position', at = 'arm.end', component = 'x'}")
    r["outputs"] = _outputs(general["outputs"], mech)
    return r


def _solver(sol: dict, mech) -> dict:
    v.keys(sol, {"t_end", "dt", "output_every", "integrator", "beta", "gamma", "hht_alpha", "rho_inf", "divergence_limit",
                 "rayleigh", "model", "rigid_rtol", "rigid_atol", "newton_tol", "newton_maxit",
                 "geometric_stiffness", "geometric_tol", "geometric_maxit", "error_estimate", "tolerance", "node_angles"},
           "solver")
    t_end = v.num(sol, "t_end", "solver", positive=True, required=True)
    dt = v.num(sol, "dt", "solver", positive=True, required=True)
    if dt > t_end:
        raise CaseError("solver.dt", f"({dt} s) is longer than the run (t_end = {t_end} s); choose dt <= t_end")
    out_every = v.whole(sol, "output_every", "solver", default=1)
    steps = max(1, math.ceil(t_end / dt - 1e-9))
    if out_every > steps:       # the grid would be refined to out_every steps: dt silently shrunk
        raise CaseError("solver.output_every", f"({out_every}) is more than the run's {steps} steps "
                        f"(t_end / dt); choose at most {steps}, or a longer t_end")
    longest = max([ln.length for ln in mech.links] + [mech.characteristic_length() if not mech.links else 0.0])
    return {"t_end": t_end, "dt": dt,
            "output_every": out_every,
            **_integrator(sol),
            "divergence_limit": v.num(sol, "divergence_limit", "solver", positive=True,
                                      default=DIVERGENCE_FACTOR * longest),
            "rayleigh": v.vector(sol, "rayleigh", "solver", 2, default=[0.0, 0.0], nonneg=True),
            "model": v.text(sol, "model", "solver", default=AUTO, choices=MODEL_CHOICES),
            "rigid_rtol": v.num(sol, "rigid_rtol", "solver", default=1e-10, positive=True),
            "rigid_atol": v.num(sol, "rigid_atol", "solver", default=1e-12, positive=True),
            "newton_tol": v.num(sol, "newton_tol", "solver", default=1e-8, positive=True),
            "newton_maxit": v.whole(sol, "newton_maxit", "solver", default=25),
            "geometric_stiffness": v.text(sol, "geometric_stiffness", "solver", default="none",
                                          choices=("none", "current", "lagged", "quasi_static")),
            "geometric_tol": v.num(sol, "geometric_tol", "solver", default=1e-8, positive=True),
            "geometric_maxit": v.whole(sol, "geometric_maxit", "solver", default=50),
            "error_estimate": _error_estimate(sol),
            "tolerance": _tolerance(sol),
            "node_angles": v.text(sol, "node_angles", "solver", default="relative", choices=NODE_ANGLES)}


def _error_estimate(sol: dict) -> str:
    """solver.error_estimate: "all" (default), "none", or parts of ERROR_PARTS joined by "+"."""
    text = v.text(sol, "error_estimate", "solver", default="all")
    if text in ("all", "none"):
        return text
    parts = [p.strip() for p in text.split("+")]
    bad = [p for p in parts if p not in ERROR_PARTS]
    if bad or not parts:
        raise CaseError("solver.error_estimate", f"must be 'all', 'none' or parts of {', '.join(ERROR_PARTS)} joined by "
                                                 f"'+' (e.g. 'time+mesh'), got {text!r}")
    return "+".join(p for p in ERROR_PARTS if p in parts)


def _tolerance(sol: dict) -> float:
    tol = v.num(sol, "tolerance", "solver", default=TOLERANCE_DEFAULT, positive=True)
    if tol >= 1.0:
        raise CaseError("solver.tolerance", f"is a fraction of each output's peak and must be below 1, got {tol}; "
                                            "e.g. 0.05 for 5 %")
    return tol


def _check_tables_cover_run(mech, t_end: float) -> None:
    """A law's table must span [0, t_end] (its spline is not extrapolated)."""
    for i, d in enumerate(mech.drives):
        tab = d.params if d.law == "table" else d.params.get("table")
        if tab is None:
            continue
        where = f"drives[{i}]" + ("" if d.law == "table" else ".table")
        if tab["t"][0] > 0.0 or tab["t"][-1] < t_end:
            raise CaseError(f"{where}.t", f"the table spans [{tab['t'][0]:g}, {tab['t'][-1]:g}] s but the run needs "
                                          f"[0, {t_end:g}] s; extend the table or shorten solver.t_end")


def _outputs(raw, mech) -> dict:
    if not isinstance(raw, dict) or not raw:
        raise CaseError("outputs", "must be a table of named outputs, e.g. tip_x = {kind = 'position', at = 'l2.end', component = 'x'}")
    out = {}
    for name, spec in raw.items():
        w = f"outputs.{name}"
        if not v.NAME.match(name) or name == "t":
            raise CaseError(w, "output names must be identifiers other than 't'")
        if not isinstance(spec, dict) or "kind" not in spec:
            raise CaseError(w, f"must be a table with a 'kind' (one of {', '.join(OUTPUT_KINDS)})")
        kind = v.text(spec, "kind", w, choices=tuple(OUTPUT_KINDS))
        req, opt = OUTPUT_KINDS[kind]
        v.keys(spec, {"kind"} | req | set(opt), w)
        for key in sorted(req - set(spec)):
            raise CaseError(f"{w}.{key}", f"is missing; a '{kind}' output needs {', '.join(sorted(req))}")
        d = {"kind": kind}
        if "joint" in req:
            d["joint"] = _output_joint(spec, kind, w, mech)
        if "measure" in opt:
            d["measure"] = v.text(spec, "measure", w, default="frames", choices=JOINT_MEASURES)
        if "link" in req:
            d["link"] = v.text(spec, "link", w, choices=tuple(ln.name for ln in mech.links))
            if kind != "link_angle":
                if mech.links[mech.link_index(d["link"])].rigid:
                    raise CaseError(f"{w}.link", f"link {d['link']!r} is rigid: it has no {kind.replace('_', ' ')}")
                d["at"] = v.num(spec, "at", w, default=opt.get("at"))
                if not 0.0 <= d["at"] <= 1.0:
                    raise CaseError(f"{w}.at", f"is a fraction of the link length and must lie in [0, 1], got {d['at']}")
        if kind in COMPONENTS:
            d["component"] = v.text(spec, "component", w, choices=COMPONENTS[kind])
        if kind in ("displacement", "deflection", "position", "inertia_load"):
            _output_point(spec, d, kind, w, mech)
        if kind == "inertia_load":
            d["model"] = v.text(spec, "model", w, default="run", choices=("run",) + SUPERPOSITION_MODELS)
        if kind == "reaction":   # the run model's joint reaction, or the rigid-body solution's
            d["source"] = v.text(spec, "source", w, default="model", choices=REACTION_SOURCES)
        out[name] = d
    return out


def _output_joint(spec: dict, kind: str, w: str, mech) -> str:
    name = v.text(spec, "joint", w, choices=tuple(j.name for j in mech.joints))
    joint = mech.joint(name)
    if kind == "joint_angle" and not joint.angular:
        raise CaseError(f"{w}.kind", f"{name!r} is a {joint.kind} joint: its coordinate is a displacement; use "
                                     "kind = 'joint_displacement'")
    if kind == "joint_displacement" and joint.angular:
        raise CaseError(f"{w}.kind", f"{name!r} is a {joint.kind} joint: its coordinate is an angle; use "
                                     "kind = 'joint_angle'")
    if kind == "drive_force" and mech.drive_of(name) is None:
        raise CaseError(f"{w}.joint", f"{name!r} has no drive; name a joint with a [[drives]] entry")
    return name


def _output_point(spec: dict, d: dict, kind: str, w: str, mech) -> None:
    if d.get("component") == "norm":   # the norm of the whole load over the free DOFs
        if "at" in spec:
            raise CaseError(f"{w}.at", "does not apply to component = 'norm' (the norm over all free DOFs); remove it")
        return
    if "at" not in spec:
        raise CaseError(f"{w}.at", f"is missing; a '{kind}' output needs the point, e.g. at = 'coupler.mid'")
    ref = mech.point(v.text(spec, "at", w), f"{w}.at")
    if ref.body is None:
        raise CaseError(f"{w}.at", "names a ground point, which does not move; name a point of a body")
    if kind == "inertia_load" and (ref.body.kind != "link" or ref.body.rigid):
        raise CaseError(f"{w}.at", "inertia loads are given at the points of flexible links (the mesh nodes)")
    link_only = d.get("component") in ("rotation", "axial", "transverse")
    if kind in ("displacement", "deflection") and link_only and ref.body.kind != "link":
        raise CaseError(f"{w}.component", f"{d['component']!r} is defined for link points; use x or y")
    d["at"] = spec["at"]


#: tables and arrays inside each other, at most (a case file needs four)
MAX_NESTING = 32


def read_case_file(path) -> dict:
    """The raw (unvalidated) table of a TOML case file; CaseError when it is missing, not a readable
    file, not UTF-8, not TOML, or nested past MAX_NESTING levels."""
    path = resolve_case_path(path)
    text = read_text(path, "case file", "case file", "give the path of a .toml case file or the name of a "
                                                     "bundled one (flexmech_py.case_names())")
    try:
        return _shallow(tomllib.loads(text), f"case file {path}")
    except tomllib.TOMLDecodeError as exc:
        raise CaseError("case file", f"{path}: not valid TOML ({exc}); fix the syntax") from None
    except RecursionError:
        raise CaseError("case file", f"{path}: arrays or tables nested past what flexmech reads ({MAX_NESTING} "
                                     "levels); flatten them") from None


def _shallow(value, where: str):
    """``value`` when no array or table in it lies more than MAX_NESTING levels deep; CaseError otherwise
    (deeper values would exhaust the recursion of the code that copies and validates them)."""
    level = [value]
    for _ in range(MAX_NESTING + 1):
        level = [x for v in level for x in (v.values() if isinstance(v, dict) else v if isinstance(v, list) else ())]
        if not level:
            return value
    raise CaseError(where.split(" ")[0] if where.startswith("--set") else "case file",
                    f"{where}: arrays or tables nested more than {MAX_NESTING} levels deep; flatten them")


def load_case(path, overrides: list[str] | None = None) -> dict:
    """Read, override (``KEY.PATH=VALUE`` strings) and validate a TOML case file (a path, or the name of
    a bundled case when no such file exists here: :func:`flexmech_py.base.bundled.resolve_case_path`)."""
    path = resolve_case_path(path)
    raw = read_case_file(path)
    if overrides:
        raw = apply_overrides(raw, overrides)
    case = validate_case(raw, source=str(path))
    case["case"]["path"] = str(path)
    return case


def parse_value(text: str):
    try:
        return _shallow(tomllib.loads(f"v = {text}")["v"], "--set value")
    except tomllib.TOMLDecodeError:
        return text  # a bare string
    except RecursionError:
        raise CaseError("--set", f"a value nested more than {MAX_NESTING} levels deep; flatten it") from None


def apply_overrides(raw: dict, overrides: list[str]) -> dict:
    """Return a copy of ``raw`` with ``KEY.PATH=VALUE`` overrides applied.

    Path elements index tables by key, arrays by position (``links.0.length``)
    or, for arrays of named tables, by name (``links.coupler.length``).
    Values are TOML values (``2e-5``, ``"pin"``, ``[0, -9.81]``); bare words are strings.
    An empty value (``KEY.PATH=``) removes the key (``drives.0.final_speed=`` when a drive changes
    its law); an empty string is ``KEY.PATH=""``.
    """
    raw = copy.deepcopy(raw)
    for ov in overrides:
        if "=" not in ov:
            raise CaseError("--set", f"{ov!r} must look like KEY.PATH=VALUE, e.g. solver.dt=2e-5")
        key, text = ov.split("=", 1)
        parts = [p for p in key.strip().split(".") if p]
        if not parts:
            raise CaseError("--set", f"{ov!r} has an empty key")
        if len(parts) != len(key.strip().split(".")):
            raise CaseError("--set", f"{key.strip()!r} has an empty part (two dots in a row, or a dot at an end); "
                                     "write the key as e.g. solver.dt or links.coupler.area")
        remove = not text.strip()
        node = _override_parent(raw, parts, key, create=not remove)
        if remove:
            if parts[-1] not in node:
                have = ", ".join(sorted(node)) or "none"
                raise CaseError(f"--set {key}", f"nothing to remove: {'.'.join(parts[:-1]) or 'the case'} has no key "
                                                f"{parts[-1]!r} (its keys: {have})")
            del node[parts[-1]]
        else:
            node[parts[-1]] = parse_value(text.strip())
    return raw


def _override_parent(raw: dict, parts: list[str], key: str, create: bool) -> dict:
    """The table an override's last key lives in (missing tables created when ``create``)."""
    node = raw
    for depth, p in enumerate(parts[:-1]):
        where = ".".join(parts[: depth + 1])
        if isinstance(node, list):
            node = _list_item(node, p, where)
        elif isinstance(node, dict):
            if p not in node and not create:
                raise CaseError(f"--set {key}", f"nothing to remove: {where} is not in the case")
            node = node.setdefault(p, {})
        else:
            raise CaseError(f"--set {key}", f"{where} is a value, not a table")
    if isinstance(node, list):
        what = "replace" if create else "remove"
        raise CaseError(f"--set {key}", f"cannot {what} a whole array element; {'set' if create else 'remove'} one of "
                                        "its keys")
    if not isinstance(node, dict):
        raise CaseError(f"--set {key}", f"{'.'.join(parts[:-1])} is a value, not a table")
    return node


def _list_item(lst: list, p: str, where: str):
    """An array's entry by position, by its ``name``, or (``[[drives]]``, which have none) by its ``joint``."""
    if p.isdigit():
        i = int(p)
        if i >= len(lst):
            raise CaseError(f"--set {where}", f"index {i} out of range (the array has {len(lst)} entries)")
        return lst[i]
    for item in lst:
        if isinstance(item, dict) and item.get("name", item.get("joint")) == p:
            return item
    names = [str(item.get("name", item.get("joint"))) for item in lst if isinstance(item, dict)]
    raise CaseError(f"--set {where}", f"no entry named {p!r}; names are {', '.join(names)}")


def with_elements(case: dict, n: int) -> dict:
    """A copy of a resolved case with ``n`` elements on every flexible link (checked: a whole number >= 1,
    a mesh that fits)."""
    if isinstance(n, bool) or not isinstance(n, numbers.Integral) or n < 1:
        raise CaseError("elements_per_link", f"must be a whole number >= 1, got {n!r}")
    links = sum(1 for ln in case["links"] if not ln.get("rigid"))
    check_elements(int(n) * links, links, field="--elements-per-link")   # before the mesh is made
    c = copy.deepcopy(case)
    c["mesh"]["elements_per_link"] = int(n)
    for ln in c["links"]:
        if not ln.get("rigid"):
            ln["elements"] = int(n)
    return c
