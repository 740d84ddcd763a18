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

Runs go through :func:`flexmech_py.run.parallel.run_tasks` (resumable cache under
``<out>/cache``; a failing run is a data point, not a crash).  Timing: each task measures
its own kernel time, wall (``Result.timing["kernel_s"]``) and CPU (process time spent inside
the kernel entry points ``FEModel.run`` / ``CoupledModel.run``, which excludes the time the
process waits for a core on a busy machine); ``repeat`` runs it several times in the same
process and keeps the minimum, and runs of a few milliseconds are repeated up to
``MAX_REPEAT`` times.  ``jobs = 1`` avoids the runs competing with each other for the cores.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from .accuracy_analysis import (Outcome, cheapest_runs, observed_orders, references, richardson, run_rows,
                                successive_orders)
from .accuracy_plan import plan_runs, settings_of
from .accuracy_runs import DEFAULT_KINDS, INTEGRATORS, Integrator, parse_integrators, run_point
from ..base.errors import CaseError
from ..run.outdir import ResultFolder
from ..run.parallel import run_tasks
from ..base.fileio import atomic_write, json_default

__all__ = ["accuracy_study", "run_point", "richardson", "successive_orders", "parse_integrators", "Integrator",
           "Study", "INTEGRATORS", "DEFAULT_KINDS"]


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



def accuracy_study(case_path, *, overrides=(), models=None, integrators=None, dt_levels: int = 5,
                   elements=(1, 2, 4, 8), grid: bool = False, ref_dt_factor: int = 4, ref_elements: int | None = None,
                   columns=None, tolerances=(0.1, 0.01, 0.001), repeat: int = 1, jobs: int | None = None,
                   out_dir="accuracy", progress: bool = True, consistency: float = 0.3, plots: bool = True,
                   clock: str = "cpu", scheduler=None) -> Study:
    """Run the error-against-time study of one case file and write its files into ``out_dir``
    (through a :class:`~flexmech_py.run.outdir.ResultFolder`: whole or not at all; the runs cached in
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


def _study(case_path, *, overrides, models, integrators, dt_levels, elements, grid, ref_dt_factor, ref_elements,
           columns, tolerances, repeat, jobs, out_dir, progress, consistency, plots, clock, scheduler, stage) -> Study:
    """The study of :func:`accuracy_study`, its runs cached in ``out_dir/cache`` and its files written
    into ``stage``."""
    if clock not in ("cpu", "wall"):
        raise CaseError("--clock", f"must be cpu or wall, got {clock!r}")
    s = settings_of(case_path, overrides=overrides, models=models, integrators=integrators, dt_levels=dt_levels,
                    elements=elements, ref_dt_factor=ref_dt_factor, ref_elements=ref_elements, columns=columns,
                    tolerances=tolerances)
    plan = plan_runs(s, grid, repeat)
    batch = run_tasks(run_point, [plan.points[k]["task"] for k in plan.keys], jobs=jobs,
                      cache_dir=Path(out_dir) / "cache", progress=progress, label="accuracy runs", scheduler=scheduler)
    out = Outcome(plan.keys, batch)
    reference, yref = references(s, plan, out, consistency)
    rows = run_rows(s, plan, out, yref, clock)
    row_of = dict(zip(plan.keys, rows))
    settings = {"case": s.source, "overrides": list(overrides), "t_end": s.t_end, "case_dt": s.dt_case,
                "dt0": s.t_end / s.N0, "dt_levels": s.kmax + 1, "elements": s.elements, "case_mesh": s.case_mesh,
                "grid": grid, "ref_dt": s.t_end / (s.N0 * 2 ** s.r), "ref_elements": s.n_ref, "frames": s.n_coarse + 1,
                "frame_interval": s.t_end / s.n_coarse, "models": s.models,
                "integrators": [i.label for i in s.integrators], "columns": s.columns, "tolerances": s.tolerances,
                "repeat": repeat, "consistency": consistency, "clock": clock}
    batch_info = {"runs": len(plan.keys), "computed": batch.computed, "cached": batch.cached,
                  "failed": len(batch.failed), "jobs": batch.jobs, "wall_s": batch.wall_s, "retries": batch.retries,
                  "executor": batch.executor}
    study = Study(rows=rows, orders=observed_orders(s, plan, out, reference, row_of), reference=reference,
                  cheapest=cheapest_runs(s, plan, out, reference, row_of), columns=s.columns, batch=batch_info,
                  settings=settings)
    study.paths = _write(study, stage, plots, plan.points, plan.keys, plan.ladders)
    return study


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
        from ..figures.study_plots import work_precision_figure  # start-up: only a study with figures loads matplotlib

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
