"""The plan of an accuracy study (:mod:`flexmech_py.studies.accuracy`): its settings checked (one line per bad
option, naming it) and the runs it needs, each a point (model, integrator, steps, mesh) with the roles
it plays: a level of a time or mesh ladder, of the (step, mesh) grid, or of a reference family.

Time grid: the frames are common to every run (the coarsest step's grid, ``n_coarse`` intervals);
the ladder's finest step is dt_0 = t_end / N0 with N0 = n_coarse 2^(levels - 1) (dt_0 <= the case's
dt), the reference's dt_0 / 2^r.  The reference families are the time family at the reference mesh
(steps dt_ref 2^i, i = 0..3) and the mesh family at dt_ref (n_ref / 2^j elements, j = 0..3)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from .accuracy_runs import DEFAULT_KINDS, Integrator, MAX_REPEAT, SHORT_RUN_BUDGET_S, parse_integrators
from ..case import apply_overrides, read_case_file, study_model, validate_case
from ..base.errors import CaseError
from ..base.families import MODELS, family
from ..base.sizes import MAX_STEPS, check_elements, format_count
from ..base.version import __version__

__all__ = ["Settings", "Plan", "settings_of", "plan_runs", "uniform_mesh"]


@dataclass
class Settings:
    """The checked settings of a study and the time grid they give."""

    source: str
    case: dict
    raw_run: dict            # the raw case its runs start from (only the compared outputs)
    models: list
    integrators: list        # [Integrator] of the ladders
    ref_integrator: Integrator
    kmax: int                # the ladder's steps dt_0 2^k, k = 0..kmax
    r: int                   # the reference step dt_0 / 2^r
    elements: list           # the mesh ladder (elements per link)
    n_ref: int               # the reference mesh
    case_mesh: int | None    # the case's own elements per link when uniform
    columns: list
    tolerances: list
    n_coarse: int            # frame intervals (the coarsest step's grid)
    N0: int                  # the ladder's finest step count

    @property
    def t_end(self) -> float:
        return self.case["solver"]["t_end"]

    @property
    def dt_case(self) -> float:
        return self.case["solver"]["dt"]


@dataclass
class Plan:
    """The runs of a study: ``points`` key -> {model, integrator, nsteps, elements, task, roles};
    ``ladders`` (model, integrator label, "time"|"space") -> keys, finest first; ``ref_keys``
    (model, "time"|"space") -> the reference family's keys, finest first; ``keys`` every key, the
    most expensive first."""

    points: dict = field(default_factory=dict)
    ladders: dict = field(default_factory=dict)
    ref_keys: dict = field(default_factory=dict)
    keys: list = field(default_factory=list)


def uniform_mesh(case: dict):
    """The case's elements per flexible link when every link has the same count, else None."""
    ns = {ln["elements"] for ln in case["links"] if not ln.get("rigid")}
    return ns.pop() if len(ns) == 1 else None


def settings_of(case_path, *, overrides, models, integrators, dt_levels, elements, ref_dt_factor, ref_elements,
                columns, tolerances) -> Settings:
    """The study's settings checked against its case (CaseError naming the option otherwise)."""
    source = str(case_path)
    raw = apply_overrides(read_case_file(case_path), list(overrides))
    case = validate_case(raw, source=source)
    models = _models(models, case)
    kmax, r = _steps(dt_levels, ref_dt_factor)
    elements = sorted({int(n) for n in elements})
    if not elements or elements[0] < 1:
        raise CaseError("--elements", f"must be whole numbers >= 1, got {elements}")
    n_ref = _reference_mesh(case, elements, ref_elements)
    tolerances = sorted({float(x) for x in tolerances}, reverse=True)
    if not all(0 < x for x in tolerances):
        raise CaseError("--tolerances", f"must be > 0, got {tolerances}")
    columns = _columns(case, columns)
    raw_run = apply_overrides(raw, [])
    raw_run["outputs"] = {k: v for k, v in raw.get("outputs", {}).items() if k in columns}
    sol = case["solver"]
    n_coarse = max(1, math.ceil(sol["t_end"] / (sol["dt"] * 2 ** kmax) - 1e-9))
    s = Settings(source=source, case=case, raw_run=raw_run, models=models,
                 integrators=parse_integrators(integrators, raw_run),
                 ref_integrator=parse_integrators(None, raw_run)[0], kmax=kmax, r=r, elements=elements, n_ref=n_ref,
                 case_mesh=uniform_mesh(case), columns=columns, tolerances=tolerances, n_coarse=n_coarse,
                 N0=n_coarse * 2 ** kmax)
    _check_ladder_sizes(s, "--dt-levels" if kmax >= r else "--ref-dt-factor")
    return s


def _models(models, case) -> list:
    models = list(models) if models else [study_model(None, case)]
    bad = [m for m in models if m not in MODELS]
    if bad:
        raise CaseError("--models", f"unknown model(s) {', '.join(bad)}; choose from {', '.join(MODELS)}")
    return models


def _steps(dt_levels, ref_dt_factor) -> tuple[int, int]:
    """(kmax, r): the ladder's coarsest step dt_0 2^kmax and the reference's dt_0 / 2^r."""
    if isinstance(dt_levels, bool) or int(dt_levels) < 1:
        raise CaseError("--dt-levels", f"must be >= 1, got {dt_levels}")
    kmax = int(dt_levels) - 1
    r = int(round(math.log2(ref_dt_factor))) if ref_dt_factor >= 1 else -1
    if r < 0 or 2 ** r != ref_dt_factor:
        raise CaseError("--ref-dt-factor", f"must be a power of 2 (1, 2, 4, ...), got {ref_dt_factor}")
    if kmax + r < 3:     # the reference's time family reaches 8 dt_ref, which must not pass the coarsest step
        raise CaseError("--ref-dt-factor", f"the reference runs at dt_ref .. 8 dt_ref must not be coarser than the "
                                           f"coarsest ladder step: needs --dt-levels K and --ref-dt-factor F with K - 1 "
                                           f"+ log2 F >= 3, got K = {kmax + 1}, F = {ref_dt_factor}; e.g. --ref-dt-factor "
                                           f"{2 ** (3 - kmax)}")
    return kmax, r


def _reference_mesh(case, elements: list, ref_elements) -> int:
    if ref_elements:
        n_ref = int(ref_elements)
    else:
        finest = max(elements + [max(ln["elements"] for ln in case["links"] if not ln.get("rigid"))])
        n_ref = 8 * math.ceil(2 * finest / 8)
    if n_ref % 8:
        raise CaseError("--ref-elements", f"must be a multiple of 8 (the reference mesh family is n, n/2, n/4, n/8), "
                                          f"got {n_ref}")
    return n_ref


def _columns(case, columns) -> list:
    if columns:
        missing = [c for c in columns if c not in case["outputs"]]
        if missing:
            raise CaseError("--columns", f"no output named {', '.join(missing)}; the case has {', '.join(case['outputs'])}")
        return list(columns)
    return [n for n, sp in case["outputs"].items() if sp["kind"] in DEFAULT_KINDS] or list(case["outputs"])


def _check_ladder_sizes(s: Settings, dt_field: str) -> None:
    """Refuse a ladder whose finest run has too many steps, or whose meshes would not fit in memory."""
    steps = s.N0 * 2 ** s.r
    if steps > MAX_STEPS:
        raise CaseError(dt_field, f"the reference run would take about {format_count(steps)} steps (dt {s.t_end / steps:.3g} s), "
                                  f"more than the {format_count(MAX_STEPS)} one run can take: lower --dt-levels or "
                                  "--ref-dt-factor")
    links = sum(1 for ln in s.case["links"] if not ln.get("rigid"))
    for fld, n in (("--elements", max(s.elements)), ("--ref-elements", s.n_ref)):
        for m in s.models:
            check_elements(n * links, links, m, fld)


def plan_runs(s: Settings, grid: bool, repeat: int) -> Plan:
    """Every run of the study, each once whatever the roles it plays."""
    plan = Plan()
    add = _adder(s, plan)
    for m in s.models:
        for it in s.integrators:
            plan.ladders[(m, it.label, "time")] = [add("time", m, it, s.N0 // 2 ** k, None, repeat)
                                                   for k in range(s.kmax + 1)]
            plan.ladders[(m, it.label, "space")] = [add("space", m, it, s.N0, n, repeat) for n in reversed(s.elements)]
            if grid:
                for k in range(s.kmax + 1):
                    for n in s.elements:
                        add("grid", m, it, s.N0 // 2 ** k, n, repeat)
    for m in s.models:
        nr, ri = s.N0 * 2 ** s.r, s.ref_integrator
        plan.ref_keys[(m, "time")] = [add("reference", m, ri, nr // 2 ** i, s.n_ref) for i in range(4)]
        plan.ref_keys[(m, "space")] = [plan.ref_keys[(m, "time")][0]] + [
            add("reference", m, ri, nr, s.n_ref // 2 ** j) for j in range(1, 4)]
    # expensive runs first (better load balance): cost ~ steps x elements
    pts = plan.points
    plan.keys = sorted(pts, key=lambda k: -pts[k]["nsteps"] * (pts[k]["elements"] or s.case_mesh or 2)
                       * (8 if family(pts[k]["model"]).constrained else 1))
    return plan


def _adder(s: Settings, plan: Plan):
    """add(role, model, integrator, nsteps, elements, repeats) -> the point's key (made once)."""
    def task(model, it: Integrator, nsteps, n_el, reps):
        return {"raw": s.raw_run, "source": s.source, "overrides": it.overrides, **({"drop": it.drop} if it.drop else {}),
                "model": model, "nsteps": int(nsteps),
                "out_every": int(nsteps // s.n_coarse), "elements": n_el, "repeat": int(reps), "version": __version__,
                "timing": f"wall and cpu, min of >= repeat, short runs up to {MAX_REPEAT} within {SHORT_RUN_BUDGET_S} s",
                "estimate": "once, after the timed runs"}

    def add(role, model, it, nsteps, n_el, reps=1):
        n_el = None if (n_el is not None and n_el == s.case_mesh) else n_el   # the case's own mesh, one run
        key = (model, it.label, int(nsteps), n_el)
        if key not in plan.points:
            plan.points[key] = {"model": model, "integrator": it.label, "nsteps": int(nsteps), "elements": n_el,
                                "task": task(model, it, nsteps, n_el, reps), "roles": []}
        if role not in plan.points[key]["roles"]:
            plan.points[key]["roles"].append(role)
        return key
    return add
