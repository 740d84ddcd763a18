"""``model = "auto"`` (the default of a case that names no model; docs/theory.md section 21.4): the
cheapest model whose estimated model error is within ``solver.tolerance``.

On the error budget's model grid (:func:`flexmech_py.checks.budget.probe_plan`) the exact model runs once
and the models of :data:`flexmech_py.checks.model_error.LADDER` run in turn, cheapest first: the first one
whose largest difference from the exact model (over the outputs that can be compared and are not
negligible, relative to the exact model's peak) is within the tolerance is chosen, else the exact
model.  The probes then serve the run's error budget (replayed, not made again), so a run that
chooses hac costs what a hac run with its budget costs; what auto adds is the probes of the models
it passed over.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

from . import model_error, scales
from .budget import probe_plan
from .budget_text import pct
from .probes import Probe, largest_differences

__all__ = ["Choice", "choose"]


@dataclass
class Choice:
    """The model auto chose: ``model``, ``geometric`` (superposition models), ``record`` (the
    ``model_choice`` entry of summary.json) and ``probes`` for the run's error budget."""

    model: str
    geometric: str | None
    record: dict
    probes: dict = field(default_factory=dict)


def _worst(diff: dict, ref: Probe, prep, model: str) -> tuple[float, str | None]:
    """(largest relative difference, its column) over the comparable, non-negligible columns."""
    tiny = scales.negligible(prep.case, ref.units, ref.peaks)
    worst, col = 0.0, None
    free = prep.setup.mode == "dynamic"
    for name, d in diff.items():
        if name in tiny or name not in ref.peaks or model_error.comparable(name, prep.case, model, free):
            continue
        rel = d / ref.peaks[name] if ref.peaks[name] > 0 else 0.0
        if not rel <= worst:
            worst, col = rel, name
    return worst, col


def _fresh(made: dict, grid, model, geometric, k: int) -> Probe:
    """The probe of (model, geometric) at step ratio k: replayed when made and kept, else made (and kept)."""
    key = (model, geometric, k)
    old = made.get(key)
    again = old.replay() if old is not None and old.done else None
    if again is not None:
        return again
    p = Probe(grid, model, geometric, k, model_error.label(model, geometric), keep=True)
    made[key] = p
    return p


def _try(made: dict, grids, prep, model: str, geo) -> dict:
    """The estimated model error of (model, geo) from its probe and the exact model's, an entry of ``tried``."""
    k = grids.model_step
    cand = _fresh(made, grids.grid_of(model), model, geo, k)
    ref = _fresh(made, grids.reference, *model_error.EXACT, k)
    diff, _ = largest_differences(cand, ref)
    est, col = _worst(diff, ref, prep, model)
    entry = {"label": model_error.label(model, geo), "model": model, "geometric": geo, "estimate": est,
             "column": col, "dt": cand.prep.dt}
    stopped = [p for p in (cand, ref) if p.stopped_at is not None or p.reason]
    if stopped:
        entry["partial"] = f"the probe run of {stopped[0].label} stopped: {stopped[0].reason}"
    return entry


def choose(prep, tolerance: float) -> Choice:
    """The model for a run of ``prep`` whose model is "auto" (see the module's docstring)."""
    c0 = time.process_time()
    grids, why = probe_plan(prep)
    exact = model_error.EXACT
    if grids is None:
        rec = {"model": exact[0], "geometric": None, "label": model_error.label(*exact), "tolerance": tolerance,
               "reason": f"no probe run is possible ({why}): the exact model", "tried": [], "cpu_s": 0.0}
        return Choice(exact[0], None, rec)
    made, tried, chosen = {}, [], None
    for model, geo in model_error.LADDER:
        if model_error.is_reference(model):
            break
        entry = _try(made, grids, prep, model, geo)
        tried.append(entry)
        if "partial" not in entry and math.isfinite(entry["estimate"]) and entry["estimate"] <= tolerance:
            chosen = (model, geo)
            break
    model, geo = chosen or exact
    rec = {"model": model, "geometric": geo, "label": model_error.label(model, geo), "tolerance": tolerance,
           "tried": tried, "probe_elements": {ln["name"]: ln["elements"] for ln in grids.model.case["links"]
                                              if not ln.get("rigid")}}
    if chosen is None:
        rec["reason"] = (f"no cheaper model is within the tolerance of {pct(tolerance)} of each output's peak: "
                         "the exact model")
    else:
        rec["reason"] = (f"the cheapest model whose estimated model error, {pct(tried[-1]['estimate'])}, is within "
                         f"the tolerance of {pct(tolerance)} of each output's peak")
    rec["cpu_s"] = time.process_time() - c0
    return Choice(model, geo, rec, {"grids": grids, "probes": made})
