"""What a step taken from Python costs: :class:`flexmech_py.run.stepping.Simulation` advanced one step per
call against the batch run of the same case and model (part of ``flexmech bench``, docs/performance.md).

Both produce the run's frames (the stepping one through :meth:`Simulation.result`); CPU time of the
calling thread, in alternating pairs (batch, stepping), the smaller of each kind kept.  Reported per
model: the batch run's CPU time per step, the stepping one's, their ratio and the overhead of a call
(the difference per step), and whether the two results agree (the largest difference of any column
over that column's largest magnitude).
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from ..case import Case, load_case
from ..run.simulate import Prepared
from ..run.stepping import Simulation

__all__ = ["bench_stepping", "step_cost"]

MODELS = ("nonlinear", "coupled", "hac", "classic", "classic-translational")
#: steps of the seed four-bar run (full, quick)
STEPS = {False: 2000, True: 200}


def _timed(fn) -> tuple[float, object]:
    c0 = time.thread_time()
    out = fn()
    return time.thread_time() - c0, out


def _stepped(case, model: str):
    sim = Simulation(case, model)
    while sim.step < sim.prep.nsteps:
        sim.advance(1)
    return sim.result()


def step_cost(case, model: str, repeats: int = 3) -> dict:
    """Batch run against one-step calls for one model of a resolved case (estimate off)."""
    best_b = best_s = np.inf
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(repeats):
            tb, batch = _timed(lambda: Prepared(case).run(model, estimate=False))
            ts, stepped = _timed(lambda: _stepped(case, model))
            best_b, best_s = min(best_b, tb), min(best_s, ts)
    diff = max(float(np.max(np.abs(stepped.columns[k] - y)) / max(float(np.max(np.abs(y))), 1e-300))
               for k, y in batch.columns.items())
    n = batch.nsteps
    return {"model": model, "steps": n, "batch_cpu_s": best_b, "stepping_cpu_s": best_s, "ratio": best_s / best_b,
            "batch_us_per_step": 1e6 * best_b / n, "overhead_us_per_call": 1e6 * (best_s - best_b) / n,
            "max_rel_difference": diff}


def bench_stepping(seed, quick: bool, progress) -> list[dict]:
    """The seed four-bar (``seed``: its case file) stepped one step per call, every model family."""
    case = load_case(seed)
    sol = dict(case["solver"], t_end=STEPS[quick] * case["solver"]["dt"], error_estimate="none")
    case = Case(case, solver=sol)
    rows = []
    for model in MODELS:
        r = step_cost(case, model, repeats=1 if quick else 3)
        rows.append(r)
        progress(f"  {model}: batch {r['batch_us_per_step']:.3g} us/step, stepping {r['ratio']:.2f}x "
                 f"({r['overhead_us_per_call']:.3g} us per call), results differ by {r['max_rel_difference']:.2g}")
    return rows
