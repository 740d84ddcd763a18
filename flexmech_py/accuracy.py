"""Error against run time: ``flexmech accuracy CASE`` (docs/accuracy.md).

For every model and integrator asked for, a case is run over a ladder of time steps
(dt_k = dt_0 * 2^k, at the case's mesh) and a ladder of meshes (elements per link, at
dt_0), optionally over the whole (step, mesh) grid.  Each run's outputs are compared with
a reference solution of the same model, and the error is set against the measured cost of
the compiled time integration: its CPU time (default, ``clock="cpu"``) or its wall time
(``Result.timing["kernel_s"]``).

Error of a column y: ``max_t |y - y_ref| / max_t |y_ref|`` over the output frames, which
are common to every run (the frame interval is the coarsest step); the worst column is
the largest of these.

Reference (per model, with the case's own integrator): a time family at the reference mesh
(steps dt_ref * 2^i, i = 0..3, dt_ref = dt_0 / ref_dt_factor) and a mesh family at dt_ref
(n_ref / 2^j elements per link, j = 0..3).  For each family and column the orders of the
successive differences, p_i = log2(|Y_{i+1} - Y_{i+2}| / |Y_i - Y_{i+1}|), are checked: if
the two finest agree (within ``consistency``) and exceed 0.5, the finest level is
Richardson-extrapolated, Y_0 + (Y_0 - Y_1) / (2^p - 1); otherwise it is not and the reason
is recorded.  The reference is the finest run plus both corrections.  Its uncertainty is
the spread between the corrections with the two observed orders (applied) or the finest
difference (not applied); errors below it are not resolved.

Runs go through :func:`flexmech_py.parallel.run_tasks` (resumable cache under
``<out>/cache``; a failing run is a data point, not a crash).  Timing: each task measures
its own kernel time, wall (``Result.timing["kernel_s"]``) and CPU (process time spent inside
the kernel entry points ``FEModel.run`` / ``CoupledModel.run``, which excludes the time the
process waits for a core on a busy machine); ``repeat`` runs it several times in the same
process and keeps the minimum, and runs of a few milliseconds are repeated up to
``MAX_REPEAT`` times.  ``jobs = 1`` avoids the runs competing with each other for the cores.
"""

from __future__ import annotations

import csv
import inspect
import io
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .case import apply_overrides, read_case_file, study_model, validate_case
from .errors import CaseError
from .families import MODELS, family
from .notices import silenced
from .outdir import ResultFolder
from .parallel import run_tasks
from .sizes import MAX_STEPS, check_elements, format_count
from .fileio import atomic_write, json_default

__all__ = ["accuracy_study", "run_point", "richardson", "successive_orders", "parse_integrators", "Integrator",
           "Study", "INTEGRATORS", "DEFAULT_KINDS"]

INTEGRATORS = ("newmark", "hht", "generalized-alpha")
MAX_REPEAT = 20              # timing repeats of a short run at most
SHORT_RUN_BUDGET_S = 0.2     # [s] kernel time spent on repeating a short run
DEFAULT_KINDS = ("strain", "displacement", "deflection")   # output kinds compared by default (elastic quantities)


# ----------------------------------------------------------------------------- integrators
@dataclass
class Integrator:
    """One time integrator: a label, the case overrides that select it and the solver keys of the
    other integrators to remove from the case (a case may not carry another integrator's parameters)."""

    label: str
    overrides: list
    drop: list = field(default_factory=list)


# the solver keys of each integrator's parameters
INTEGRATOR_KEYS = {"newmark": ("beta", "gamma"), "hht": ("hht_alpha",), "generalized-alpha": ("rho_inf",)}


def _apply(raw: dict, it) -> dict:
    """The raw case with an integrator's overrides applied and the other integrators' keys removed."""
    out = apply_overrides(raw, it.overrides)
    for key in it.drop:
        out.get("solver", {}).pop(key, None)
    return out


def _has_integrator_key(raw: dict) -> bool:
    """Does this flexmech know ``solver.integrator``?"""
    sol = dict(raw.get("solver", {}))
    if "integrator" not in sol:
        sol = {k: x for k, x in sol.items() if k not in ("beta", "gamma", "hht_alpha", "rho_inf")}
        sol["integrator"] = "newmark"
    try:
        return "integrator" in validate_case(dict(raw, solver=sol))["solver"]
    except CaseError:
        return False


def parse_integrators(spec, raw: dict) -> list[Integrator]:
    """Integrators from a list such as ``["newmark", "hht:-0.1", "generalized-alpha:0.8"]``.

    ``case`` (or an empty spec) is the case's own integrator.  ``hht:A`` sets
    ``solver.hht_alpha = A`` (0 <= A <= 1/3), ``generalized-alpha:R`` sets ``solver.rho_inf = R``,
    ``newmark:B,G`` sets ``solver.beta, solver.gamma``; without a value the case's (or
    --set's) parameter is used.  The labels name the parameters in effect.
    """
    names = [s.strip() for s in (spec or ["case"]) if s and s.strip()] or ["case"]
    known = _has_integrator_key(raw)
    out, seen = [], set()
    for item in names:
        name, _, arg = item.partition(":")
        name = name.strip().lower()
        ov: list[str] = []
        drop: list[str] = []
        if name == "case":
            ov = []
        elif name not in INTEGRATORS:
            raise CaseError("--integrators", f"unknown integrator {name!r}; choose from case, {', '.join(INTEGRATORS)}")
        elif not known and name != "newmark":
            raise CaseError("--integrators", f"{name!r} needs solver.integrator, which this flexmech does not have; "
                                             "only newmark is available")
        else:
            if known:
                ov.append(f"solver.integrator={name}")
                drop = [k for other, keys in INTEGRATOR_KEYS.items() if other != name for k in keys]
            if arg:
                vals = [v.strip() for v in arg.split(",")]
                try:
                    [float(v) for v in vals]
                except ValueError:
                    raise CaseError("--integrators", f"{item!r}: the value after ':' must be a number") from None
                if name == "hht" and len(vals) == 1:
                    ov.append(f"solver.hht_alpha={vals[0]}")
                elif name == "generalized-alpha" and len(vals) == 1:
                    ov.append(f"solver.rho_inf={vals[0]}")
                elif name == "newmark" and len(vals) == 2:
                    ov += [f"solver.beta={vals[0]}", f"solver.gamma={vals[1]}"]
                else:
                    raise CaseError("--integrators", f"{item!r}: use hht:ALPHA, generalized-alpha:RHO_INF or "
                                                     "newmark:BETA,GAMMA")
        it = Integrator("", ov, drop)
        sol = validate_case(_apply(raw, it))["solver"]
        if (ov or drop) and sol == validate_case(raw)["solver"]:
            it = Integrator("", [], [])  # the case's own integrator: the same runs (and cache entries)
        it.label = _integrator_label(sol)
        if it.label not in seen:
            seen.add(it.label)
            out.append(it)
    return out


def _integrator_label(sol: dict) -> str:
    """The integrator a resolved solver table names; ``default`` when it names none (each model then
    runs its family's default, flexmech_py.case.DEFAULT_INTEGRATORS)."""
    kind = sol.get("integrator")
    if kind is None:
        return "default"
    if kind == "hht":
        return f"hht(alpha={sol['hht_alpha']:g})"
    if kind == "generalized-alpha":
        return f"generalized-alpha(rho_inf={sol['rho_inf']:g})"
    if (sol["beta"], sol["gamma"]) == (0.25, 0.5):
        return "newmark"
    return f"newmark(beta={sol['beta']:g},gamma={sol['gamma']:g})"


# ----------------------------------------------------------------------------- one run (a task)
@silenced()      # a point of the study: its error is measured, its warnings are not issued
def run_point(task: dict) -> dict:
    """One run of the study (a :func:`run_tasks` task): the outputs on the common frames and the timings.

    ``task``: ``raw`` (case dict as parsed from TOML), ``source``, ``overrides`` (list),
    ``model``, ``nsteps``, ``out_every``, ``elements`` (per link, or None for the case's
    mesh), ``repeat``.  The kernel is timed ``repeat`` times (same process, same
    prepared case) and the minimum kept; every measurement is returned too.
    """
    from .simulate import Prepared

    case = validate_case(_apply(task["raw"], Integrator("", task["overrides"], task.get("drop", []))),
                         source=task["source"])
    t_end = case["solver"]["t_end"]
    prep = Prepared(case, dt=t_end / task["nsteps"], elements_per_link=task["elements"], out_every=task["out_every"])
    if prep.nsteps != task["nsteps"]:  # pragma: no cover - the grid is chosen so that it cannot happen
        raise RuntimeError(f"time grid mismatch: {prep.nsteps} steps instead of {task['nsteps']}")
    # the CPU time of the compiled time loop: the kernel entry points of this prepared run, wrapped
    kcpu: list = []

    def timed(fn):
        def wrapper(*a, **kw):
            c0 = time.process_time()
            try:
                return fn(*a, **kw)
            finally:
                kcpu.append(time.process_time() - c0)
        return wrapper

    if family(task["model"]).constrained:
        from .coupled import CoupledModel

        cm = CoupledModel.from_case(prep.case, split=family(task["model"]).element_frames)
        cm.run = timed(cm.run)
        prep.coupled[task["model"]] = cm
    else:
        prep.fe.run = timed(prep.fe.run)
    # the per-run error estimate (step doubling, step_doubling.error_estimate) is computed once after the
    # timed runs, not inside them: it is one more run at 2 dt
    no_estimate = {"estimate": False} if "estimate" in inspect.signature(prep.run).parameters else {}
    kernel, total, cpu, kernel_cpu = [], [], [], []
    reps = max(1, int(task.get("repeat", 1)))
    # at least `repeat` timings; short runs (a few ms, where a single preemption by another process
    # multiplies the time) are repeated up to MAX_REPEAT times or SHORT_RUN_BUDGET_S of kernel time
    while len(kernel) < reps or (len(kernel) < MAX_REPEAT and sum(cpu) < SHORT_RUN_BUDGET_S):
        kcpu.clear()
        c0 = time.process_time()
        res = prep.run(task["model"], **no_estimate)
        cpu.append(time.process_time() - c0)
        kernel.append(res.timing["kernel_s"])
        total.append(res.timing["total_s"])
        kernel_cpu.append(sum(kcpu) if kcpu else float("nan"))
    estimate = None
    if no_estimate:
        from . import step_doubling

        est = step_doubling.error_estimate(prep, res)
        if est.get("columns"):
            estimate = {k: est["columns"][k]["relative"] for k in case["outputs"] if k in est["columns"]}
    return {"columns": {k: res.columns[k].tolist() for k in case["outputs"]}, "nsteps": int(res.nsteps),
            "estimate_rel": estimate,
            "dt": float(res.dt), "frames": int(res.t.size), "nfree": int(res.fe.nfree),
            "elements": [int(n) for n in res.fe.n_el if n], "kernel_s": min(kernel), "kernel_s_all": kernel,
            "kernel_cpu_s": min(kernel_cpu), "kernel_cpu_s_all": kernel_cpu,
            "total_s": min(total), "run_cpu_s": min(cpu), "rigid_s": float(res.timing["rigid_s"])}


# ----------------------------------------------------------------------------- orders and Richardson
def _dmax(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))))


def successive_orders(levels, ratio: float = 2.0) -> list:
    """Observed orders from successive differences of ``levels`` (finest first, refinement ``ratio``):
    p_i = log(|Y_{i+1} - Y_{i+2}| / |Y_i - Y_{i+1}|) / log(ratio) (max norm); NaN where undefined."""
    d = [_dmax(levels[i], levels[i + 1]) for i in range(len(levels) - 1)]
    out = []
    for i in range(len(d) - 1):
        out.append(math.log(d[i + 1] / d[i]) / math.log(ratio) if d[i] > 0 and d[i + 1] > 0 else float("nan"))
    return out


def richardson(levels, ratio: float = 2.0, consistency: float = 0.3, min_order: float = 0.5) -> dict:
    """Richardson extrapolation of the finest of ``levels`` (arrays, finest first, each refined by
    ``ratio`` from the next), applied only where the observed order is consistent.

    Needs 4 levels: the orders of the two finest pairs of successive differences must agree
    within ``consistency`` and exceed ``min_order``.  Returns ``applied``, ``orders``, ``order``
    (the finest), ``reason`` (why not, or ''), ``correction`` (array, zero if not applied)
    and ``uncertainty`` (max-norm estimate of the extrapolated or finest level's remaining error).
    """
    levels = [np.asarray(y, float) for y in levels]
    fine = levels[0]
    d0 = _dmax(levels[0], levels[1]) if len(levels) > 1 else float("nan")
    orders = successive_orders(levels, ratio)
    out = {"applied": False, "orders": orders, "order": orders[0] if orders else float("nan"), "reason": "",
           "correction": np.zeros_like(fine), "uncertainty": d0, "finest_difference": d0}
    scale = float(np.max(np.abs(fine))) if fine.size else 0.0
    if len(levels) < 4:
        out["reason"] = f"needs 4 levels to check the order, got {len(levels)}"
    elif not d0 > 1e-13 * scale:
        out["reason"] = "the two finest levels agree to round-off: nothing to extrapolate"
        out["uncertainty"] = 0.0
    elif not all(math.isfinite(p) for p in orders[:2]):
        out["reason"] = "a difference of successive levels is zero: the order is undefined"
    elif orders[0] < min_order:
        out["reason"] = f"observed order {orders[0]:.2f} < {min_order}: not in the asymptotic range"
    elif abs(orders[0] - orders[1]) > consistency:
        out["reason"] = (f"orders of successive differences {orders[1]:.2f} (coarser) and {orders[0]:.2f} (finer) "
                         f"differ by more than {consistency}: not in the asymptotic range")
    else:
        p_f, p_c = orders[0], orders[1]
        diff = levels[0] - levels[1]
        corr = diff / (ratio ** p_f - 1.0)
        out.update(applied=True, correction=corr, uncertainty=float(np.max(np.abs(corr - diff / (ratio ** p_c - 1.0)))))
    return out


# ----------------------------------------------------------------------------- the study
@dataclass
class Study:
    """What :func:`accuracy_study` computed; the files are in ``out_dir``."""

    rows: list                      # one dict per run (accuracy.csv)
    orders: list                    # one dict per observed order (orders.csv)
    reference: dict                 # per model: per column Richardson info (JSON-ready)
    cheapest: list                  # one dict per (model, tolerance, column)
    columns: list
    paths: list = field(default_factory=list)
    batch: dict = field(default_factory=dict)
    settings: dict = field(default_factory=dict)


def _uniform_mesh(case: dict):
    ns = {ln["elements"] for ln in case["links"] if not ln.get("rigid")}
    return ns.pop() if len(ns) == 1 else None


def accuracy_study(case_path, *, overrides=(), models=None, integrators=None, dt_levels: int = 5,
                   elements=(1, 2, 4, 8), grid: bool = False, ref_dt_factor: int = 4, ref_elements: int | None = None,
                   columns=None, tolerances=(0.1, 0.01, 0.001), repeat: int = 1, jobs: int | None = None,
                   out_dir="accuracy", progress: bool = True, consistency: float = 0.3, plots: bool = True,
                   clock: str = "cpu", scheduler=None) -> Study:
    """Run the error-against-time study of one case file and write its files into ``out_dir``
    (through a :class:`~flexmech_py.outdir.ResultFolder`: whole or not at all; the runs cached in
    ``out_dir/cache`` as they finish).

    ``models``: list (default: the case's ``solver.model``); ``integrators``: list for
    :func:`parse_integrators` (default: the case's own); ``dt_levels``: steps dt_0 * 2^k,
    k = 0..dt_levels-1, dt_0 <= the case's ``solver.dt``; ``elements``: the mesh ladder
    (elements per link, at dt_0); ``grid``: also every (step, mesh) pair; reference at
    dt_0 / ``ref_dt_factor`` (a power of 2) and ``ref_elements`` per link (default 2 * the
    finest mesh, a multiple of 8); ``columns``: outputs compared (default: the case's
    ``strain`` and ``displacement`` outputs); ``tolerances``: relative errors for the
    cheapest-run table.  Returns a :class:`Study`.
    """
    kw = dict(locals())
    with ResultFolder(out_dir, "accuracy") as rf:
        study = _study(stage=rf.stage, **kw)
        rf.commit()
    study.paths = [rf.where(p) for p in study.paths]
    return study


def _check_ladder_sizes(case, models, steps: int, t_end: float, elements: list, n_ref: int, dt_field: str) -> None:
    """Refuse a ladder whose finest run has too many steps, or whose meshes would not fit in memory."""
    if steps > MAX_STEPS:
        raise CaseError(dt_field, f"the reference run would take about {format_count(steps)} steps (dt {t_end / steps:.3g} s), "
                                       f"more than the {format_count(MAX_STEPS)} one run can take: lower --dt-levels or "
                                       "--ref-dt-factor")
    links = sum(1 for ln in case["links"] if not ln.get("rigid"))
    for field, n in (("--elements", max(elements)), ("--ref-elements", n_ref)):
        for m in models:
            check_elements(n * links, links, m, field)


def _study(case_path, *, overrides, models, integrators, dt_levels, elements, grid, ref_dt_factor, ref_elements,
           columns, tolerances, repeat, jobs, out_dir, progress, consistency, plots, clock, scheduler, stage) -> Study:
    """The study of :func:`accuracy_study`, its runs cached in ``out_dir/cache`` and its files written
    into ``stage``."""
    if clock not in ("cpu", "wall"):
        raise CaseError("--clock", f"must be cpu or wall, got {clock!r}")
    raw0, source = read_case_file(case_path), str(case_path)
    raw = apply_overrides(raw0, list(overrides))
    case = validate_case(raw, source=source)
    sol = case["solver"]
    models = list(models) if models else [study_model(None, case)]
    bad = [m for m in models if m not in MODELS]
    if bad:
        raise CaseError("--models", f"unknown model(s) {', '.join(bad)}; choose from {', '.join(MODELS)}")
    if isinstance(dt_levels, bool) or int(dt_levels) < 1:
        raise CaseError("--dt-levels", f"must be >= 1, got {dt_levels}")
    kmax = int(dt_levels) - 1
    elements = sorted({int(n) for n in elements})
    if not elements or elements[0] < 1:
        raise CaseError("--elements", f"must be whole numbers >= 1, got {elements}")
    r = int(round(math.log2(ref_dt_factor))) if ref_dt_factor >= 1 else -1
    if r < 0 or 2 ** r != ref_dt_factor:
        raise CaseError("--ref-dt-factor", f"must be a power of 2 (1, 2, 4, ...), got {ref_dt_factor}")
    if kmax + r < 3:     # the reference's time family reaches 8 dt_ref, which must not pass the coarsest step
        raise CaseError("--ref-dt-factor", f"the reference runs at dt_ref .. 8 dt_ref must not be coarser than the "
                                           f"coarsest ladder step: needs --dt-levels K and --ref-dt-factor F with K - 1 "
                                           f"+ log2 F >= 3, got K = {kmax + 1}, F = {ref_dt_factor}; e.g. --ref-dt-factor "
                                           f"{2 ** (3 - kmax)}")
    case_mesh = _uniform_mesh(case)
    n_ref = int(ref_elements) if ref_elements else 2 * max(elements + [max(ln["elements"] for ln in case["links"] if not ln.get("rigid"))])
    n_ref = 8 * math.ceil(n_ref / 8) if not ref_elements else n_ref
    if n_ref % 8:
        raise CaseError("--ref-elements", f"must be a multiple of 8 (the reference mesh family is n, n/2, n/4, n/8), "
                                          f"got {n_ref}")
    tolerances = sorted({float(x) for x in tolerances}, reverse=True)
    if not all(0 < x for x in tolerances):
        raise CaseError("--tolerances", f"must be > 0, got {tolerances}")
    if columns:
        missing = [c for c in columns if c not in case["outputs"]]
        if missing:
            raise CaseError("--columns", f"no output named {', '.join(missing)}; the case has {', '.join(case['outputs'])}")
        columns = list(columns)
    else:
        columns = [n for n, sp in case["outputs"].items() if sp["kind"] in DEFAULT_KINDS] or list(case["outputs"])
    raw_run = apply_overrides(raw, [])
    raw_run["outputs"] = {k: v for k, v in raw.get("outputs", {}).items() if k in columns}
    integ = parse_integrators(integrators, raw_run)
    ref_integ = parse_integrators(None, raw_run)[0]

    # common frames: the coarsest step's grid; every level's step count is a multiple of it
    t_end, dt_case = sol["t_end"], sol["dt"]
    n_coarse = max(1, math.ceil(t_end / (dt_case * 2 ** kmax) - 1e-9))
    N0 = n_coarse * 2 ** kmax                              # dt_0 = t_end / N0 <= dt_case
    _check_ladder_sizes(case, models, N0 * 2 ** r, t_end, elements, n_ref, "--dt-levels" if kmax >= r else "--ref-dt-factor")
    from .version import __version__

    def task(model, it: Integrator, nsteps, n_el, reps=1):
        return {"raw": raw_run, "source": source, "overrides": it.overrides, **({"drop": it.drop} if it.drop else {}),
                "model": model, "nsteps": int(nsteps),
                "out_every": int(nsteps // n_coarse), "elements": n_el, "repeat": int(reps), "version": __version__,
                "timing": f"wall and cpu, min of >= repeat, short runs up to {MAX_REPEAT} within {SHORT_RUN_BUDGET_S} s",
                "estimate": "once, after the timed runs"}

    points: dict = {}     # key -> {"task", "roles": set, ...}

    def add(role, model, it, nsteps, n_el, reps=1):
        n_el = None if (n_el is not None and n_el == case_mesh) else n_el   # the case's own mesh, one run
        key = (model, it.label, int(nsteps), n_el)
        if key not in points:
            points[key] = {"model": model, "integrator": it.label, "nsteps": int(nsteps), "elements": n_el,
                           "task": task(model, it, nsteps, n_el, reps), "roles": []}
        if role not in points[key]["roles"]:
            points[key]["roles"].append(role)
        return key

    ladders = {}          # (model, integrator, "time"|"space") -> list of keys (finest first)
    for m in models:
        for it in integ:
            ladders[(m, it.label, "time")] = [add("time", m, it, N0 // 2 ** k, None, repeat) for k in range(kmax + 1)]
            ladders[(m, it.label, "space")] = [add("space", m, it, N0, n, repeat) for n in reversed(elements)]
            if grid:
                for k in range(kmax + 1):
                    for n in elements:
                        add("grid", m, it, N0 // 2 ** k, n, repeat)
    ref_keys = {}
    for m in models:
        Nr = N0 * 2 ** r
        ref_keys[(m, "time")] = [add("reference", m, ref_integ, Nr // 2 ** i, n_ref) for i in range(4)]
        ref_keys[(m, "space")] = [ref_keys[(m, "time")][0]] + [add("reference", m, ref_integ, Nr, n_ref // 2 ** j)
                                                              for j in range(1, 4)]

    # expensive runs first (better load balance): cost ~ steps x elements
    keys = sorted(points, key=lambda k: -points[k]["nsteps"] * (points[k]["elements"] or case_mesh or 2)
                  * (8 if family(points[k]["model"]).constrained else 1))
    out_dir = Path(out_dir)
    batch = run_tasks(run_point, [points[k]["task"] for k in keys], jobs=jobs, cache_dir=out_dir / "cache",
                      progress=progress, label="accuracy runs", scheduler=scheduler)
    res = dict(zip(keys, batch.results))
    secs = dict(zip(keys, batch.task_s))
    workers = dict(zip(keys, batch.task_worker))

    def ok(k):
        return k in res and isinstance(res[k], dict) and "error" not in res[k]

    def col(k, c):
        return np.asarray(res[k]["columns"][c], float)

    # references
    reference, yref = {}, {}
    for m in models:
        info = {}
        tk, sk = ref_keys[(m, "time")], ref_keys[(m, "space")]
        for c in columns:
            entry = {}
            if not ok(tk[0]):
                entry = {"available": False, "reason": f"the finest reference run failed: {res[tk[0]].get('error')}"}
                info[c] = entry
                continue
            y = col(tk[0], c)
            corr = np.zeros_like(y)
            unc = 0.0
            for direction, fam, ratio_label in (("time", tk, "dt"), ("space", sk, "elements")):
                good = [k for k in fam if ok(k)]
                if len(good) < len(fam):
                    first_bad = next(k for k in fam if not ok(k))
                    levels = [col(k, c) for k in fam[:fam.index(first_bad)]]
                else:
                    levels = [col(k, c) for k in fam]
                rich = richardson(levels, consistency=consistency) if len(levels) >= 2 else {
                    "applied": False, "orders": [], "order": float("nan"), "correction": 0.0,
                    "uncertainty": float("nan"), "finest_difference": float("nan")}
                if len(levels) < len(fam):
                    rich["reason"] = (f"reference run {len(levels)} of the {direction} family failed: "
                                      f"{res[fam[len(levels)]].get('error')}")
                corr = corr + rich["correction"]
                unc += rich["uncertainty"]
                entry[direction] = {"applied": rich["applied"], "orders": rich["orders"], "reason": rich["reason"],
                                    "levels": [_level(points[k], t_end, case_mesh) for k in fam],
                                    "finest_difference_rel": rich["finest_difference"] / max(np.max(np.abs(y)), 1e-300),
                                    "correction_rel": float(np.max(np.abs(rich["correction"])))
                                    / max(np.max(np.abs(y)), 1e-300)}
            yr = y + corr
            scale = float(np.max(np.abs(yr)))
            entry.update(available=scale > 0, peak_abs=scale, uncertainty_rel=unc / scale if scale > 0 else float("nan"),
                         reason="" if scale > 0 else "the reference is zero: relative error undefined")
            info[c] = entry
            if scale > 0:
                yref[(m, c)] = yr
        reference[m] = {"integrator": ref_integ.label, "elements": n_ref,
                        "dt": t_end / (N0 * 2 ** r), "columns": info}

    # one row per run
    rows = []
    for k in keys:
        p = points[k]
        rr = res[k]
        row = {"model": p["model"], "integrator": p["integrator"], "ladders": ";".join(p["roles"]),
               "dt": t_end / p["nsteps"], "dt_over_case_dt": t_end / p["nsteps"] / dt_case, "nsteps": p["nsteps"],
               "elements_per_link": p["elements"] if p["elements"] is not None else (case_mesh or "case"),
               "status": "ok" if ok(k) else "failed", "error_message": "" if ok(k) else rr.get("error", ""),
               "task_s": secs[k], "worker": workers[k]}
        if ok(k):
            row.update(nfree=rr["nfree"], kernel_s=rr["kernel_s"], kernel_cpu_s=rr["kernel_cpu_s"], total_s=rr["total_s"],
                       run_cpu_s=rr["run_cpu_s"], rigid_s=rr["rigid_s"], repeats=len(rr["kernel_s_all"]),
                       kernel_s_all=" ".join(f"{x:.4g}" for x in rr["kernel_s_all"]))
            row["time_s"] = rr["kernel_cpu_s"] if clock == "cpu" and math.isfinite(rr["kernel_cpu_s"]) else rr["kernel_s"]
            errs = {}
            for c in columns:
                if (p["model"], c) in yref:
                    ref = yref[(p["model"], c)]
                    errs[c] = _dmax(col(k, c), ref) / float(np.max(np.abs(ref)))
                else:
                    errs[c] = float("nan")
            for c in columns:
                row[f"err_{c}"] = errs[c]
            est = rr.get("estimate_rel") or {}
            ests = [est[c] for c in columns if c in est and math.isfinite(est[c])]
            row["est_time_worst"] = max(ests) if ests else float("nan")
            finite = {c: e for c, e in errs.items() if math.isfinite(e)}
            row["err_worst"] = max(finite.values()) if finite else float("nan")
            row["worst_column"] = max(finite, key=finite.get) if finite else ""
        rows.append(row)
    row_of = dict(zip(keys, rows))

    # observed orders
    orders = []
    for m in models:
        for it in integ:
            for direction in ("time", "space"):
                lad = ladders[(m, it.label, direction)]
                lv = [_level(points[k], t_end, case_mesh) for k in lad]
                good = []
                for k in lad:
                    if not ok(k):
                        break
                    good.append(k)
                mesh = [points[k]["elements"] or case_mesh for k in lad]
                for c in columns:
                    ys = [col(k, c) for k in good]
                    if direction == "time" or _constant_ratio(mesh):
                        ratio = 2.0 if direction == "time" else mesh[0] / mesh[1]
                        for i, p_ in enumerate(successive_orders(ys, ratio)):
                            orders.append({"model": m, "integrator": it.label, "direction": direction,
                                           "source": "successive differences", "column": c,
                                           "levels": " ".join(lv[i:i + 3]), "order": p_})
                    if direction == "space":   # errors against the reference: space error dominates at dt_0
                        for i in range(len(good) - 1):
                            e1, e2 = row_of[good[i]].get(f"err_{c}"), row_of[good[i + 1]].get(f"err_{c}")
                            n1, n2 = mesh[i], mesh[i + 1]
                            p_ = (math.log(e2 / e1) / math.log(n1 / n2)
                                  if n1 and n2 and e1 and e2 and e1 > 0 and e2 > 0 and math.isfinite(e1 + e2)
                                  else float("nan"))
                            orders.append({"model": m, "integrator": it.label, "direction": direction,
                                           "source": "errors against the reference", "column": c,
                                           "levels": " ".join(lv[i:i + 2]), "order": p_})
        for direction in ("time", "space"):
            fam = ref_keys[(m, direction)]
            for c in columns:
                info = reference[m]["columns"][c].get(direction)
                if not info:
                    continue
                for i, p_ in enumerate(info["orders"]):
                    orders.append({"model": m, "integrator": ref_integ.label, "direction": direction,
                                   "source": "reference family", "column": c,
                                   "levels": " ".join(_level(points[k], t_end, case_mesh) for k in fam[i:i + 3]),
                                   "order": p_})

    # cheapest run per (model, tolerance, column): among the ladder and grid runs
    cheapest = []
    for m in models:
        cand = [row_of[k] for k in keys if points[k]["model"] == m and ok(k)
                and set(points[k]["roles"]) != {"reference"}]
        for tol in tolerances:
            for c in columns + ["worst"]:
                unc = (max((reference[m]["columns"][cc].get("uncertainty_rel", float("nan")) for cc in columns),
                           default=float("nan")) if c == "worst"
                       else reference[m]["columns"][c].get("uncertainty_rel", float("nan")))
                entry = {"model": m, "tolerance": tol, "column": c}
                if not math.isfinite(unc):
                    entry["note"] = "no reference"
                elif unc > tol / 3:
                    entry["note"] = f"not resolved: reference uncertainty {unc:.2g} > tolerance/3"
                else:
                    meet = [rw for rw in cand if rw.get(f"err_{c}", float("nan")) <= tol]
                    if not meet:
                        entry["note"] = "no run reached it"
                    else:
                        best = min(meet, key=lambda rw: rw["time_s"])
                        entry.update(integrator=best["integrator"], dt=best["dt"],
                                     elements_per_link=best["elements_per_link"], time_s=best["time_s"],
                                     kernel_s=best["kernel_s"], kernel_cpu_s=best["kernel_cpu_s"],
                                     total_s=best["total_s"], error=best[f"err_{c}"], note="")
                cheapest.append(entry)

    settings = {"case": source, "overrides": list(overrides), "t_end": t_end, "case_dt": dt_case, "dt0": t_end / N0,
                "dt_levels": kmax + 1, "elements": elements, "case_mesh": case_mesh, "grid": grid,
                "ref_dt": t_end / (N0 * 2 ** r), "ref_elements": n_ref, "frames": n_coarse + 1,
                "frame_interval": t_end / n_coarse, "models": models, "integrators": [i.label for i in integ],
                "columns": columns, "tolerances": tolerances, "repeat": repeat, "consistency": consistency,
                "clock": clock}
    batch_info = {"runs": len(keys), "computed": batch.computed, "cached": batch.cached, "failed": len(batch.failed),
                  "jobs": batch.jobs, "wall_s": batch.wall_s, "retries": batch.retries, "executor": batch.executor}
    study = Study(rows=rows, orders=orders, reference=reference, cheapest=cheapest, columns=columns,
                  batch=batch_info, settings=settings)
    study.paths = _write(study, stage, plots, points, keys, ladders)
    return study


def _level(p: dict, t_end: float, case_mesh) -> str:
    n = p["elements"] if p["elements"] is not None else (case_mesh or "case")
    return f"dt={t_end / p['nsteps']:.3g}/n={n}"


def _constant_ratio(ns) -> bool:
    if len(ns) < 3 or any(n is None for n in ns):
        return False
    ratios = [ns[i] / ns[i + 1] for i in range(len(ns) - 1)]
    return all(abs(x - ratios[0]) < 1e-12 for x in ratios)


# ----------------------------------------------------------------------------- files
def _csv_text(rows: list, fields: list) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=fields, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for rw in rows:
        w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in rw.items()})
    return buf.getvalue()


ROW_FIELDS = ["model", "integrator", "ladders", "dt", "dt_over_case_dt", "nsteps", "elements_per_link", "nfree",
              "status", "time_s", "kernel_s", "kernel_cpu_s", "total_s", "run_cpu_s", "rigid_s", "repeats", "kernel_s_all",
              "task_s", "worker"]


def _write(study: Study, out_dir: Path, plots: bool, points, keys, ladders) -> list:
    cols = study.columns
    fields = ROW_FIELDS + [f"err_{c}" for c in cols] + ["err_worst", "worst_column", "est_time_worst", "error_message"]
    paths = []
    p = out_dir / "accuracy.csv"
    atomic_write(p, _csv_text(study.rows, fields))
    paths.append(p)
    p = out_dir / "orders.csv"
    atomic_write(p, _csv_text(study.orders, ["model", "integrator", "direction", "source", "column", "levels", "order"]))
    paths.append(p)
    p = out_dir / "accuracy.json"
    doc = {"settings": study.settings, "batch": study.batch, "reference": study.reference,
           "orders": study.orders, "cheapest": study.cheapest}
    atomic_write(p, json.dumps(doc, indent=1, default=json_default))
    paths.append(p)
    p = out_dir / "report.md"
    atomic_write(p, report_markdown(study))
    paths.append(p)
    if plots:
        from .plots import work_precision_figure

        png = work_precision_figure(out_dir / "accuracy.png", _plot_panels(study, points, keys, ladders),
                                    title=f"{Path(study.settings['case']).stem}: error against kernel time "
                                          f"(t_end = {study.settings['t_end']:g} s)")
        if png is not None:
            paths.append(png)
    return paths


def _plot_panels(study: Study, points, keys, ladders) -> list:
    row_of = dict(zip(keys, study.rows))
    s = study.settings
    metrics = (["worst"] if len(study.columns) > 1 else []) + study.columns
    metrics = metrics[:4]
    methods = sorted({(k[0], k[1]) for k in ladders},
                     key=lambda mi: (s["models"].index(mi[0]), s["integrators"].index(mi[1])))
    panels = []
    for met in metrics:
        ecol = f"err_{met}"
        lines = []
        for ci, (m, il) in enumerate(methods):
            for direction in ("time", "space"):
                rws = [row_of[k] for k in ladders[(m, il, direction)]]
                okr = [rw for rw in rws if rw["status"] == "ok" and math.isfinite(rw.get(ecol, float("nan")))]
                nfail = sum(rw["status"] != "ok" for rw in rws)
                lab = (f"{m}, {il}: " + (f"dt ladder (n={s['case_mesh'] or 'case'})" if direction == "time"
                                         else f"mesh ladder (dt={s['dt0']:.3g})") + (f", {nfail} failed" if nfail else ""))
                lines.append({"label": lab, "x": [rw["time_s"] for rw in okr], "y": [rw[ecol] for rw in okr],
                              "color": ci, "style": "-" if direction == "time" else "--",
                              "marker": "o" if direction == "time" else "s"})
            if s["grid"]:
                allr = [row_of[k] for k in keys if (points[k]["model"], points[k]["integrator"]) == (m, il)
                        and set(points[k]["roles"]) != {"reference"} and row_of[k]["status"] == "ok"
                        and math.isfinite(row_of[k].get(ecol, float("nan")))]
                front, best = [], float("inf")
                for rw in sorted(allr, key=lambda rw: rw["time_s"]):   # cheapest run for each accuracy
                    if rw[ecol] < best:
                        best = rw[ecol]
                        front.append(rw)
                lines.append({"label": f"{m}, {il}: cheapest for each accuracy (grid)",
                              "x": [rw["time_s"] for rw in front], "y": [rw[ecol] for rw in front],
                              "color": ci, "style": ":", "marker": "", "alpha": 0.9})
                gr = [row_of[k] for k in keys if (points[k]["model"], points[k]["integrator"]) == (m, il)
                      and "grid" in points[k]["roles"] and row_of[k]["status"] == "ok"]
                lines.append({"label": "dots: the other (dt, n) pairs of --grid" if ci == 0 else None,
                              "x": [rw["time_s"] for rw in gr], "y": [rw[ecol] for rw in gr],
                              "color": ci, "style": "", "marker": ".", "alpha": 0.5})
        unc = [study.reference[m]["columns"][c].get("uncertainty_rel", float("nan")) for m in s["models"]
               for c in (study.columns if met == "worst" else [met])]
        unc = [u for u in unc if math.isfinite(u)]
        hl = [(t, f"{t:g}", "tol") for t in s["tolerances"]]
        if unc:
            hl.append((max(max(unc), 1e-16), "reference uncertainty", "ref"))
        panels.append({"title": f"error of {met}" + (" column" if met == "worst" else ""),
                       "xlabel": f"kernel {'CPU' if s['clock'] == 'cpu' else 'wall'} time [s]", "ylabel": "max|y - y_ref| / max|y_ref|",
                       "lines": lines, "hlines": hl})
    return panels


def _fmt(x, spec=".3g") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    return format(x, spec) if isinstance(x, (float, int)) and not isinstance(x, bool) else str(x)


def report_markdown(study: Study) -> str:
    """A Markdown summary: settings, reference, observed orders, cheapest runs, failures."""
    s, b = study.settings, study.batch
    out = [f"# Accuracy study: {Path(s['case']).name}", "",
           f"t_end = {s['t_end']:g} s" + (f" (overrides: {' '.join(s['overrides'])})" if s["overrides"] else "")
           + f"; case dt = {s['case_dt']:g} s, dt_0 = {s['dt0']:.4g} s; dt ladder dt_0 x 2^k, k = 0..{s['dt_levels'] - 1} "
           f"at the case mesh (n = {s['case_mesh'] or 'case'}); mesh ladder n = {', '.join(map(str, s['elements']))} at dt_0"
           + ("; full grid" if s["grid"] else "") + f"; {s['frames']} common frames every {s['frame_interval']:.3g} s.",
           f"Models: {', '.join(s['models'])}; integrators: {', '.join(s['integrators'])}; columns: "
           f"{', '.join(s['columns'])}.",
           f"{b['runs']} runs ({b['computed']} computed, {b['cached']} cached, {b['failed']} failed) in "
           f"{b['wall_s']:.0f} s on {b['jobs']} process(es); kernel times are the minimum of >= {s['repeat']} repeat(s); "
           f"cost = kernel {'CPU' if s['clock'] == 'cpu' else 'wall'} time.",
           "", "## Reference", "",
           f"dt_ref = {s['ref_dt']:.4g} s, n_ref = {s['ref_elements']} elements per link; Richardson per column and "
           f"direction when the orders of successive differences agree within {s['consistency']}.", "",
           "| model | column | time: orders (fine, coarse) | applied | space: orders | applied | correction t / s | "
           "uncertainty |", "|---|---|---|---|---|---|---|---|"]
    notes = []
    for m, ref in study.reference.items():
        for c, e in ref["columns"].items():
            if "time" not in e:
                out.append(f"| {m} | {c} | – | – | – | – | – | {e.get('reason', '')} |")
                continue
            t, sp = e["time"], e["space"]
            out.append(f"| {m} | {c} | {', '.join(_fmt(x, '.2f') for x in t['orders'][:2])} | "
                       f"{'yes' if t['applied'] else 'no'} | {', '.join(_fmt(x, '.2f') for x in sp['orders'][:2])} | "
                       f"{'yes' if sp['applied'] else 'no'} | {_fmt(t['correction_rel'], '.1e')} / "
                       f"{_fmt(sp['correction_rel'], '.1e')} | {_fmt(e.get('uncertainty_rel'), '.1e')} |")
            for d, info in (("time", t), ("space", sp)):
                if not info["applied"] and info["reason"]:
                    notes.append(f"- {m}, {c}, {d}: not extrapolated: {info['reason']}.")
    out += [""] + notes + ["", "## Observed orders", "",
                           "Time: successive differences along the dt ladder (same mesh: time error only), finest "
                           "pair first.  Space: successive differences along the mesh ladder, and the order of the "
                           "errors against the reference.", "",
                           "| model | integrator | direction | source | column | orders (finest first) |",
                           "|---|---|---|---|---|---|"]
    grouped: dict = {}
    for o in study.orders:
        grouped.setdefault((o["model"], o["integrator"], o["direction"], o["source"], o["column"]), []).append(o["order"])
    for (m, il, d, src, c), ps in grouped.items():
        out.append(f"| {m} | {il} | {d} | {src} | {c} | {', '.join(_fmt(p, '.2f') for p in ps)} |")
    out += ["", "## Cheapest run for a required accuracy", "",
            f"Among the runs made, least kernel {'CPU' if s['clock'] == 'cpu' else 'wall'} time; error = "
            "max|y − y_ref| / max|y_ref|.", "",
            "| model | tolerance | column | integrator | dt [s] | elements/link | kernel CPU [s] | kernel wall [s] | "
            "total wall [s] | error | note |",
            "|---|---|---|---|---|---|---|---|---|---|---|"]
    for e in study.cheapest:
        out.append(f"| {e['model']} | {e['tolerance']:g} | {e['column']} | {e.get('integrator', '–')} | "
                   f"{_fmt(e.get('dt'))} | {e.get('elements_per_link', '–')} | {_fmt(e.get('kernel_cpu_s'), '.3g')} | "
                   f"{_fmt(e.get('kernel_s'), '.3g')} | {_fmt(e.get('total_s'), '.3g')} | {_fmt(e.get('error'), '.2g')} | "
                   f"{e.get('note', '')} |")
    failed = [rw for rw in study.rows if rw["status"] != "ok"]
    if failed:
        out += ["", "## Failed runs", "", "| model | integrator | dt [s] | elements/link | error |", "|---|---|---|---|---|"]
        for rw in failed:
            out.append(f"| {rw['model']} | {rw['integrator']} | {rw['dt']:.3g} | {rw['elements_per_link']} | "
                       f"{rw['error_message']} |")
    out += ["", "## Runs", "", "| model | integrator | ladders | dt [s] | n | kernel CPU [s] | kernel wall [s] | "
            "worst error | worst column |", "|---|---|---|---|---|---|---|---|---|"]
    for rw in study.rows:
        out.append(f"| {rw['model']} | {rw['integrator']} | {rw['ladders']} | {rw['dt']:.3g} | {rw['elements_per_link']} | "
                   f"{_fmt(rw.get('kernel_cpu_s'), '.3g')} | {_fmt(rw.get('kernel_s'), '.3g')} | "
                   f"{_fmt(rw.get('err_worst'), '.2g')} | {rw.get('worst_column', '')} |")
    return "\n".join(out) + "\n"
