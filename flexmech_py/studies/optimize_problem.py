"""A design-optimization problem: the varied keys, the objective and the constraints, and the
quantities one design point yields (its worker, :func:`design_point`).

``--vary KEY.PATH=LO:HI`` names a number of the case file (any ``--set`` key, e.g.
``links.coupler.section.height``) and its bounds; ``--objective`` a quantity to minimize (``life``
is maximized); ``--constraint "QUANTITY <= VALUE"`` (or ``>=``) a limit.  The quantities
(docs/cli.md, "flexmech optimize"): ``mass`` [kg] of the moving parts; ``peak_stress`` [Pa] the
largest |outer-fibre stress| of any flexible link; ``safety_factor`` the smallest against yield;
``life`` [crank cycles] and ``life_hours`` the shortest fatigue life; per link ``LINK.mass``,
``LINK.peak_stress``, ``LINK.safety_factor``, ``LINK.life``; per joint ``JOINT.max_load`` [N]; and
every named output of the case by its name (its largest |value| over the frames analysed).
"""

from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass

from ..case import apply_overrides, validate_case
from ..strength.analysis import DesignAnalysis, parse_window
from ..base.errors import CaseError
from .floquet import PeriodicCase, floquet, steady_state
from ..base.notices import silenced
from ..run.runner import MemorySink, execute
from ..run.simulate import Prepared
from .sweep import point_overrides

__all__ = ["Variable", "Constraint", "Problem", "parse_vary", "parse_constraint", "quantity_names", "design_point",
           "case_mass", "task_of", "FATIGUE_QUANTITIES", "JOINT_LOAD_QUANTITY"]

#: quantities that need the fatigue count (the others do not pay for it)
FATIGUE_QUANTITIES = ("life", "life_hours")
#: the per-joint quantity that needs the joint loads (a reaction solve per frame; the others do not pay for it)
JOINT_LOAD_QUANTITY = "max_load"
#: a life constraint's margin is its decades over this: about 1 / |Basquin exponent|, the decades of life a
#: relative stress change of one decade makes, so that its margin weighs like a stress margin
LIFE_DECADES = 10.0
_LINK_QUANTITIES = ("mass", "peak_stress", "safety_factor", "life")
_CONSTRAINT = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_.]*)\s*(<=|>=)\s*(\S+)\s*$")


@dataclass(frozen=True)
class Variable:
    key: str
    low: float
    high: float


@dataclass(frozen=True)
class Constraint:
    quantity: str
    sense: str          # "<=" or ">="
    limit: float

    def margin(self, value) -> float:
        """Signed margin, >= 0 when met, finite: relative to the limit (lives: decades over LIFE_DECADES,
        a life below one cycle counted as one); a design without the value (a failed run) -1."""
        if value is None or math.isnan(value):
            return -1.0
        if self.quantity.split(".")[-1] in FATIGUE_QUANTITIES:   # decades of life over LIFE_DECADES: a stress
            d = (math.log10(min(max(value, 1.0), 1e300)) - math.log10(self.limit)) / LIFE_DECADES   # margin's size
        else:
            d = (min(value, 1e300) - self.limit) / abs(self.limit)
        d = max(min(d, 1e6), -1e6)
        return d if self.sense == ">=" else -d

    def __str__(self) -> str:
        return f"{self.quantity} {self.sense} {self.limit:g}"


def parse_vary(text: str) -> Variable:
    """``KEY.PATH=LO:HI`` with LO < HI numbers."""
    key, _, spec = text.partition("=")
    parts = spec.split(":")
    try:
        if not key.strip() or len(parts) != 2:
            raise ValueError
        lo, hi = (float(p) for p in parts)
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise ValueError
    except ValueError:
        raise CaseError("--vary", f"{text!r} must be KEY.PATH=LO:HI with numbers, e.g. "
                                  "links.coupler.section.height=0.5e-3:4e-3") from None
    if not lo < hi:
        raise CaseError(f"--vary {key.strip()}", f"the lower bound {lo:g} must be below the upper {hi:g}")
    return Variable(key.strip(), float(lo), float(hi))


def parse_constraint(text: str) -> Constraint:
    """``"QUANTITY <= VALUE"`` or ``>=``."""
    m = _CONSTRAINT.match(text)
    try:
        value = float(m.group(3)) if m else None
    except ValueError:
        value = None
    if value is None or not math.isfinite(value) or value == 0:
        raise CaseError("--constraint", f"{text!r} must be 'QUANTITY <= VALUE' or 'QUANTITY >= VALUE' with a nonzero "
                                        "number, e.g. 'safety_factor >= 2'")
    return Constraint(m.group(1), m.group(2), float(value))


def quantity_names(case) -> list[str]:
    """Every quantity a design point of ``case`` yields (objective and constraint names)."""
    names = ["mass", "peak_stress", "safety_factor", "life", "life_hours"]
    for ln in case["links"]:
        if not ln.get("rigid"):
            names += [f"{ln['name']}.{q}" for q in _LINK_QUANTITIES]
    names += [f"{j['name']}.{JOINT_LOAD_QUANTITY}" for j in case["joints"]]
    return names + list(case["outputs"])


@dataclass
class Problem:
    """What is varied, minimized and limited; ``analysis``: ``steady`` (the periodic steady state) or
    ``run`` (the case's run, over ``window`` = "T0:T1" for the stresses and the fatigue life)."""

    variables: list
    objective: str
    constraints: list
    analysis: str
    window: str | None
    correction: str

    @property
    def needs_fatigue(self) -> bool:
        names = [self.objective] + [c.quantity for c in self.constraints]
        return any(n.split(".")[-1] in FATIGUE_QUANTITIES for n in names)

    @property
    def needs_joint_loads(self) -> bool:
        names = [self.objective] + [c.quantity for c in self.constraints]
        return any(n.split(".")[-1] == JOINT_LOAD_QUANTITY for n in names)

    def check_names(self, case) -> None:
        """CaseError listing what exists when the objective or a constraint names no quantity."""
        have = quantity_names(case)
        for where, name in [("--objective", self.objective)] + [("--constraint", c.quantity) for c in self.constraints]:
            if name not in have:
                raise CaseError(where, f"unknown quantity {name!r}; quantities are {', '.join(have)}")


def case_mass(case) -> dict:
    """{link: mass [kg]} of every link (flexible: density x area x length; rigid: its mass), with
    ``total`` adding the rigid bodies and the point masses."""
    out = {}
    for ln in case["links"]:
        out[ln["name"]] = ln["mass"] if ln.get("mass") is not None else ln["density"] * ln["area"] * ln["length"]
    total = sum(out.values()) + sum(b["mass"] for b in case["bodies"]) + sum(p["mass"] for p in case["point_masses"])
    return {**out, "total": total}


def _run(case, task: dict):
    """(Result, DesignAnalysis) of one design: the periodic steady state, or the case's run."""
    correction = task["correction"] if task["fatigue"] else None
    loads = task["joint_loads"]
    with silenced():
        if task["analysis"] == "steady":
            pc = PeriodicCase(case, task["model"])
            da = DesignAnalysis(pc.case, pc.fe, correction=correction, steady=True, joint_loads=loads)
            res = steady_state(pc, floquet(pc))
        else:
            prep = Prepared(case)
            model = task["model"] or prep.case["solver"]["model"]
            fe = prep.coupled[model].mesh if model in prep.coupled else prep.fe
            window = parse_window(task["window"], prep.case["solver"]["t_end"]) if task["window"] else None
            da = DesignAnalysis(prep.case, fe, window=window, correction=correction, joint_loads=loads)
            res = execute(prep, model, MemorySink(prep.frames), estimate=False)
        da.add(res)
        da.finish(res)
    return res, da


def design_point(task: dict) -> dict:
    """Worker of ``flexmech optimize``: one design.  ``task``: {"raw", "source", "overrides", "model",
    "analysis", "window", "correction", "fatigue"}; returns {"quantities": {...}, "run_s"}."""
    t0 = time.perf_counter()
    case = validate_case(apply_overrides(task["raw"], task["overrides"]), source=task["source"])
    res, da = _run(case, task)
    rep = da.report
    q = {}
    masses = case_mass(res.case)
    q["mass"] = masses["total"]
    for name, s in rep["stress"].items():
        q[f"{name}.mass"] = masses[name]
        q[f"{name}.peak_stress"] = s["peak_abs_stress_Pa"]
        q[f"{name}.safety_factor"] = s["safety_factor"]
    q["peak_stress"] = max((s["peak_abs_stress_Pa"] for s in rep["stress"].values()), default=0.0)
    sfs = [s["safety_factor"] for s in rep["stress"].values() if s["safety_factor"] is not None]
    q["safety_factor"] = min(sfs) if sfs else None
    if "fatigue" in rep:
        lives = rep["fatigue"]["links"]
        for name, f in lives.items():
            q[f"{name}.life"] = f["life_cycles"] if f["life_cycles"] is not None else f["life_histories"]
        q["life"] = min(q[f"{n}.life"] for n in lives)
        q["life_hours"] = min(f["life_hours"] for f in lives.values())
    for name, j in rep["joint_loads"].items():
        q[f"{name}.{JOINT_LOAD_QUANTITY}"] = j["max_N"]
    for name, y in res.columns.items():
        q[name] = float(abs(y).max()) if y.size else 0.0
    return {"quantities": q, "run_s": time.perf_counter() - t0, "warnings": list(res.extra.get("warnings", []))}


def task_of(raw: dict, source: str, values: dict, problem: Problem, model) -> dict:
    """The worker task of the design with ``values`` {key: value}."""
    return {"raw": raw, "source": source, "overrides": point_overrides(values), "model": model,
            "analysis": problem.analysis, "window": problem.window, "correction": problem.correction,
            "fatigue": problem.needs_fatigue, "joint_loads": problem.needs_joint_loads}
