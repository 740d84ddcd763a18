"""The runs of an accuracy study (:mod:`flexmech_py.studies.accuracy`): the time integrators it compares
(labels, the case overrides that select each) and one timed run of a point of the study (a task of
:func:`flexmech_py.run.parallel.run_tasks`: the outputs on the common frames and the kernel's CPU and
wall time, the minimum of several repeats for short runs)."""

from __future__ import annotations

import inspect
import time
from dataclasses import dataclass, field

from ..checks import step_doubling
from ..case import apply_overrides, validate_case
from ..models.constrained.coupled import CoupledModel
from ..base.errors import CaseError
from ..base.families import family
from ..base.notices import silenced
from ..run.simulate import Prepared

__all__ = ["INTEGRATORS", "INTEGRATOR_KEYS", "DEFAULT_KINDS", "MAX_REPEAT", "SHORT_RUN_BUDGET_S", "Integrator",
           "apply_integrator", "has_integrator_key", "parse_integrators", "integrator_label", "run_point"]

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


def apply_integrator(raw: dict, it) -> dict:
    """The raw case with an integrator's overrides applied and the other integrators' keys removed."""
    out = apply_overrides(raw, it.overrides)
    for key in it.drop:
        out.get("solver", {}).pop(key, None)
    return out


def has_integrator_key(raw: dict) -> bool:
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
    known = has_integrator_key(raw)
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
        sol = validate_case(apply_integrator(raw, it))["solver"]
        if (ov or drop) and sol == validate_case(raw)["solver"]:
            it = Integrator("", [], [])  # the case's own integrator: the same runs (and cache entries)
        it.label = integrator_label(sol)
        if it.label not in seen:
            seen.add(it.label)
            out.append(it)
    return out


def integrator_label(sol: dict) -> str:
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
    case = validate_case(apply_integrator(task["raw"], Integrator("", task["overrides"], task.get("drop", []))),
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
        est = step_doubling.error_estimate(prep, res)
        if est.get("columns"):
            estimate = {k: est["columns"][k]["relative"] for k in case["outputs"] if k in est["columns"]}
    return {"columns": {k: res.columns[k].tolist() for k in case["outputs"]}, "nsteps": int(res.nsteps),
            "estimate_rel": estimate,
            "dt": float(res.dt), "frames": int(res.t.size), "nfree": int(res.fe.nfree),
            "elements": [int(n) for n in res.fe.n_el if n], "kernel_s": min(kernel), "kernel_s_all": kernel,
            "kernel_cpu_s": min(kernel_cpu), "kernel_cpu_s_all": kernel_cpu,
            "total_s": min(total), "run_cpu_s": min(cpu), "rigid_s": float(res.timing["rigid_s"])}
