"""``flexmech optimize``: the best design within bounds, by SciPy, its runs on the executor.

The problem (:mod:`flexmech_py.studies.optimize_problem`) is solved in the unit box (each variable scaled
to [0, 1] between its bounds):

- ``slsqp`` (default): SciPy's SLSQP with forward-difference gradients; the n + 1 designs of each
  gradient are one batch on the executor (the local process pool or Dask), so they run in parallel;
- ``differential-evolution``: SciPy's global search for rough landscapes, each generation one
  batch; an infeasible design ranks behind every feasible one by its violation (Deb's rule as a
  penalty); its best design is then polished by SLSQP.

Every design is a cached task of :func:`flexmech_py.run.parallel.run_tasks` (``OUT/cache``, as sweep
points): an interrupted optimization resumes, a repeated one costs nothing.  Written: the optimum
as a case file (``optimum.toml``), every evaluation (``evaluations.csv``), the optimizer's iterates
(``iterations.csv``), ``optimize.json`` (problem, optimum, constraint activity, cost) and
``convergence.png``.  When no design within the bounds meets the constraints, the least
infeasible one is written, marked, and the command exits with :data:`EXIT_INFEASIBLE`.
"""

from __future__ import annotations

import json
import math
import time

import numpy as np
import scipy.optimize as so

from ..base.errors import CaseError
from .optimize_problem import design_point, task_of
from ..run.parallel import run_tasks
from ..base.tomlfile import dumps_toml
from ..case import apply_overrides

__all__ = ["Evaluator", "optimize", "METHODS", "EXIT_INFEASIBLE", "FD_STEP", "ACTIVE_MARGIN"]

METHODS = ("slsqp", "differential-evolution")
#: exit code of an optimization that found no feasible design (docs/cli.md, exit codes)
EXIT_INFEASIBLE = 4
#: forward-difference step in the unit box (1e-3 of each variable's range)
FD_STEP = 1e-3
#: a constraint whose margin at the optimum is below this (relative; lives: decades) is active
ACTIVE_MARGIN = 1e-3
#: the penalty of an infeasible design in differential evolution: behind every feasible one
_INFEASIBLE_BASE = 1e6


class Evaluator:
    """Designs evaluated on an executor, each once (memory, then the task cache on disk); every
    evaluation recorded as a row (objective, constraint margins, feasibility, the design)."""

    def __init__(self, problem, raw: dict, source: str, model, executor, cache_dir, progress: bool = False):
        self.problem, self.raw, self.source, self.model = problem, raw, source, model
        self.executor, self.cache_dir, self.progress = executor, cache_dir, progress
        self.memo: dict = {}
        self.rows: list[dict] = []
        self.computed = self.cached = 0
        self.f_scale = None

    def values(self, u) -> dict:
        """{key: value} of the unit-box point u."""
        return {v.key: v.low + float(np.clip(x, 0.0, 1.0)) * (v.high - v.low) for v, x in zip(self.problem.variables, u)}

    def _key(self, u) -> tuple:
        return tuple(np.round(np.clip(np.asarray(u, float), 0.0, 1.0), 12))

    def batch(self, us) -> None:
        """Evaluate the unit-box points ``us`` not yet known, as one batch on the executor."""
        todo = list({self._key(u): u for u in us if self._key(u) not in self.memo}.items())
        if not todo:
            return
        tasks = [task_of(self.raw, self.source, self.values(u), self.problem, self.model) for _, u in todo]
        b = run_tasks(design_point, tasks, cache_dir=self.cache_dir, progress=self.progress, label="designs",
                      scheduler=self.executor)
        self.computed += b.computed
        self.cached += b.cached
        for (key, u), r, sec in zip(todo, b.results, b.task_s):
            self._record(key, u, r, sec)

    def _record(self, key, u, r: dict, sec: float) -> None:
        q = r.get("quantities", {})
        f = q.get(self.problem.objective)
        if self.f_scale is None and f is not None and math.isfinite(f) and f != 0:
            self.f_scale = abs(f)
        margins = [c.margin(q.get(c.quantity)) for c in self.problem.constraints]
        row = {"evaluation": len(self.rows) + 1, **self.values(u), "objective": _objective(self.problem, f),
               "feasible": "error" not in r and all(m >= 0 for m in margins),
               "violation": max([0.0] + [-m for m in margins]), "error": r.get("error", ""), "task_s": sec}
        row.update({str(c): m for c, m in zip(self.problem.constraints, margins)})
        self.memo[key] = (row, q, margins)
        self.rows.append(row)

    def get(self, u):
        """(row, quantities, margins) of u (evaluated now, alone, if it is new)."""
        self.batch([u])
        return self.memo[self._key(u)]

    def scaled_objective(self, u) -> float:
        row = self.get(u)[0]
        f = row["objective"]
        if not math.isfinite(f):        # a failed design: well behind the start (its margins are -1)
            return 10.0
        return f / (self.f_scale or 1.0)

    def margins(self, u) -> np.ndarray:
        return np.array(self.get(u)[2], float)

    def best(self):
        """The best evaluated design's row: the least objective among the feasible ones, else the least
        violation."""
        ok = [r for r in self.rows if r["feasible"] and math.isfinite(r["objective"])]
        if ok:
            return min(ok, key=lambda r: r["objective"]), True
        return min(self.rows, key=lambda r: (r["violation"], r["objective"])), False


def _objective(problem, f) -> float:
    """The objective to minimize: the quantity itself, or minus log10 of a life (maximized)."""
    if f is None or (isinstance(f, float) and math.isnan(f)):
        return math.nan
    if problem.objective.split(".")[-1] in ("life", "life_hours"):
        return -math.log10(min(max(f, 1e-300), 1e300))
    return float(f)


def _fd_points(u: np.ndarray) -> list:
    """u and the forward- (backward- at the upper bound) difference points of its gradient."""
    pts = [u]
    for i in range(u.size):
        p = u.copy()
        p[i] += FD_STEP if u[i] + FD_STEP <= 1.0 else -FD_STEP
        pts.append(p)
    return pts


def _gradients(ev: Evaluator, u: np.ndarray):
    """(objective gradient, constraint Jacobian) in the unit box from one parallel batch."""
    pts = _fd_points(u)
    ev.batch(pts)
    f0, m0 = ev.scaled_objective(u), ev.margins(u)
    gf, jm = np.empty(u.size), np.empty((m0.size, u.size))
    for i, p in enumerate(pts[1:]):
        h = p[i] - u[i]
        gf[i] = (ev.scaled_objective(p) - f0) / h
        jm[:, i] = (ev.margins(p) - m0) / h
    return gf, jm


def run_slsqp(ev: Evaluator, u0: np.ndarray, maxiter: int, iterates: list):
    """SciPy SLSQP from u0 with the executor's finite differences; appends its iterates."""
    cons = [{"type": "ineq", "fun": (lambda u, j=j: ev.margins(u)[j]), "jac": (lambda u, j=j: _gradients(ev, u)[1][j])}
            for j in range(len(ev.problem.constraints))]

    def note(u):
        row = ev.get(u)[0]
        iterates.append({"iteration": len(iterates) + 1, "method": "slsqp", "evaluations": len(ev.rows),
                         **{k: row[k] for k in row if k not in ("evaluation", "task_s", "error")}})

    note(u0)
    return so.minimize(ev.scaled_objective, u0, jac=lambda u: _gradients(ev, u)[0], method="SLSQP",
                       bounds=[(0.0, 1.0)] * u0.size, constraints=cons, callback=note,
                       options={"maxiter": maxiter, "ftol": 1e-6})


def run_evolution(ev: Evaluator, maxiter: int, popsize: int, seed: int, iterates: list):
    """SciPy differential evolution, each generation one batch; infeasible designs ranked by violation."""
    def penalized(u):
        row, _, margins = ev.get(u)
        viol = max([0.0] + [-m for m in margins])
        f = ev.scaled_objective(u)
        return f if viol == 0.0 else _INFEASIBLE_BASE * (1.0 + viol)

    def generation(func, us):
        us = list(us)
        ev.batch(us)
        return [func(u) for u in us]

    def note(intermediate_result):
        u = intermediate_result.x
        row = ev.get(u)[0]
        iterates.append({"iteration": len(iterates) + 1, "method": "differential-evolution",
                         "evaluations": len(ev.rows), **{k: row[k] for k in row if k not in ("evaluation", "task_s",
                                                                                                "error")}})

    n = len(ev.problem.variables)
    return so.differential_evolution(penalized, [(0.0, 1.0)] * n, maxiter=maxiter, popsize=popsize, seed=seed,
                                     polish=False, updating="deferred", workers=generation, callback=note, tol=1e-3)


def optimize(problem, raw: dict, source: str, *, model=None, method: str = "slsqp", executor=None, cache=None,
             maxiter: int = 30, popsize: int = 6, seed: int = 1, progress: bool = False) -> dict:
    """Solve ``problem`` for the case ``raw`` (its designs on ``executor``: an open executor, a scheduler
    address, or None for the local pool; cached in the folder ``cache``); returns the result dict
    (optimize.json)."""
    if method not in METHODS:
        raise CaseError("--method", f"must be one of {', '.join(METHODS)}, got {method!r}")
    t0 = time.perf_counter()
    ev = Evaluator(problem, raw, source, model, executor, cache, progress)
    iterates: list = []
    u0 = np.array([(_start(raw, v) - v.low) / (v.high - v.low) for v in problem.variables])
    u0 = np.clip(u0, 0.0, 1.0)
    ev.batch([u0])
    if method == "differential-evolution":
        de = run_evolution(ev, maxiter, popsize, seed, iterates)
        start, _ = ev.best()
        u0 = np.array([(start[v.key] - v.low) / (v.high - v.low) for v in problem.variables])
        message = f"differential evolution: {de.message}; "
    else:
        message = ""
    sq = run_slsqp(ev, u0, maxiter, iterates)
    message += f"SLSQP: {sq.message}"
    best, feasible = ev.best()
    return _result(problem, ev, best, feasible, iterates, message, time.perf_counter() - t0)


def _start(raw: dict, var) -> float:
    """The case's own value of a varied key (the start), or the middle of its bounds."""
    node = raw
    for part in var.key.split("."):
        if isinstance(node, list):
            node = next((x for x in node if isinstance(x, dict) and x.get("name", x.get("joint")) == part),
                        node[int(part)] if part.isdigit() and int(part) < len(node) else None)
        elif isinstance(node, dict):
            node = node.get(part)
        else:
            node = None
    ok = isinstance(node, (int, float)) and not isinstance(node, bool) and var.low <= node <= var.high
    return float(node) if ok else 0.5 * (var.low + var.high)


def _result(problem, ev: Evaluator, best: dict, feasible: bool, iterates, message: str, wall: float) -> dict:
    q = ev.memo[ev._key([(best[v.key] - v.low) / (v.high - v.low) for v in problem.variables])][1]
    activity = [{"constraint": str(c), "value": q.get(c.quantity), "limit": c.limit, "margin": best[str(c)],
                 "active": abs(best[str(c)]) < ACTIVE_MARGIN, "met": best[str(c)] >= 0} for c in problem.constraints]
    return {"objective": problem.objective, "method": message, "feasible": feasible,
            "optimum": {v.key: best[v.key] for v in problem.variables}, "objective_value": q.get(problem.objective),
            "quantities": q, "constraints": activity,
            "variables": [{"key": v.key, "low": v.low, "high": v.high} for v in problem.variables],
            "analysis": problem.analysis, "window": problem.window, "correction": problem.correction,
            "evaluations": len(ev.rows), "computed": ev.computed, "cached": ev.cached, "wall_s": wall,
            "iterations": iterates, "rows": ev.rows}


def optimum_case_text(raw: dict, result: dict, header: str) -> str:
    """The case file of the optimum: the case as given with the optimal values set."""
    ovs = [f"{k}={v!r}" for k, v in result["optimum"].items()]
    return header + dumps_toml(apply_overrides(raw, ovs))


def write_outputs(folder, result: dict) -> list:
    """evaluations.csv, iterations.csv and optimize.json in ``folder``; their paths."""
    paths = []
    for name, rows in (("evaluations.csv", result["rows"]), ("iterations.csv", result["iterations"])):
        keys = list(rows[0]) if rows else []
        text = ",".join(keys) + "\n" + "\n".join(",".join(_cell(r.get(k)) for k in keys) for r in rows) + "\n"
        (folder / name).write_text(text, encoding="utf-8")
        paths.append(folder / name)
    body = {k: val for k, val in result.items() if k not in ("rows", "iterations")}
    (folder / "optimize.json").write_text(json.dumps(body, indent=1, default=str) + "\n", encoding="utf-8")
    return paths + [folder / "optimize.json"]


def _cell(x) -> str:
    if isinstance(x, float):
        return f"{x:.9g}"
    return json.dumps(x) if isinstance(x, str) and "," in x else str(x)
