"""``flexmech sweep``: one case over a cartesian grid of parameter values, in parallel and resumable.

Each grid point is the case with ``--set``-style overrides (``KEY.PATH=VALUE``), run by
:func:`~flexmech_py.run.parallel.run_tasks` (progress bar, one cached JSON per finished run, errors
as results; the local process pool or a Dask cluster).  The output is one summary table,
``sweep.csv`` (a row per point in grid order: the parameters, every output column's max |.|,
rms and final value, the validity measures, the kernel time, the run's time and worker, the
status), and ``sweep.json`` with the grid definition.  The first point is validated before
the batch starts: a bad key or value is one error, not a table of failed runs.  The same
machinery runs the Monte-Carlo samples of :mod:`flexmech_py.studies.sampling`.
"""

from __future__ import annotations

import copy
import json
import math
import time
from collections import Counter
from itertools import product
from pathlib import Path

import numpy as np

from ..case import parse_value, apply_overrides, read_case_file, validate_case
from ..base.errors import CaseError, FlexmechError
from ..base.names import safe_name
from ..run.outdir import ResultFolder
from ..base.sizes import check_points, format_count
from ..base.fileio import atomic_write, csv_cell, json_default
from ..base.version import versions
from ..run.simulate import simulate
from ..run.parallel import run_tasks
from ..run.parallel import using_executor

__all__ = ["parse_param", "grid_points", "sweep", "sweep_point", "point_overrides", "load_base", "check_first_point",
           "run_points", "write_table", "failure_reasons", "TIMING_COLUMNS", "VARYING_COLUMNS"]

#: columns that hold measured times (they differ between reruns)
TIMING_COLUMNS = ("kernel_s", "run_s", "task_s")
#: every column that may differ between reruns or executors: the times and the worker that ran the point
VARYING_COLUMNS = TIMING_COLUMNS + ("worker",)


def parse_param(text: str) -> tuple[str, list, str]:
    """``KEY.PATH=START:STOP:N`` (N evenly spaced values, ends included; whole numbers stay
    whole when START and STOP are) or ``KEY.PATH=a,b,c`` (TOML values or bare words).
    Returns (key, values, spec)."""
    if "=" not in text:
        raise CaseError("--param", f"{text!r} must look like KEY.PATH=START:STOP:N or KEY.PATH=a,b,c")
    key, spec = (s.strip() for s in text.split("=", 1))
    if not key or not spec:
        raise CaseError("--param", f"{text!r} needs a key and values, e.g. drive.speed=50:150:5")
    if spec.startswith("["):
        raise CaseError(f"--param {key}", "array values cannot be swept; sweep one scalar key at a time")
    if ":" in spec:
        parts = spec.split(":")
        try:
            if len(parts) != 3:
                raise ValueError
            a, b, n = parse_value(parts[0]), parse_value(parts[1]), int(parts[2])
            if isinstance(a, bool) or isinstance(b, bool) or not isinstance(a, (int, float)) or \
                    not isinstance(b, (int, float)) or n < 1:
                raise ValueError
        except ValueError:
            raise CaseError(f"--param {key}", f"{spec!r} must be START:STOP:N with numbers START, STOP and "
                                              "a whole N >= 1") from None
        check_points(n, f"--param {key}", lambda k: f"give at most {format_count(k)} values, e.g. "
                                                   f"{key}={parts[0]}:{parts[1]}:{min(k, 1000)}")
        vals = np.linspace(a, b, n) if n > 1 else np.array([a], float)
        if isinstance(a, int) and isinstance(b, int) and np.allclose(vals, np.round(vals)):
            values = [int(round(v)) for v in vals]
        else:
            values = [float(v) for v in vals]
    else:
        values = [parse_value(v.strip()) for v in spec.split(",") if v.strip()]
    if not values:
        raise CaseError(f"--param {key}", f"{spec!r} gives no values")
    return key, values, spec


def grid_points(params: list[tuple[str, list, str]]) -> list[dict]:
    """The cartesian grid as a list of {key: value}, the first parameter varying slowest."""
    keys = [k for k, _, _ in params]
    if len(set(keys)) != len(keys):
        raise CaseError("--param", f"a key is given twice: {', '.join(keys)}")
    check_points(math.prod(len(v) for _, v, _ in params), "--param",
                 lambda k: f"use at most {format_count(k)} grid points in all (fewer values per --param)")
    return [dict(zip(keys, combo)) for combo in product(*(v for _, v, _ in params))]


def _override(key: str, value) -> str:
    if isinstance(value, bool):
        return f"{key}={'true' if value else 'false'}"
    if isinstance(value, (int, float)):
        return f"{key}={value!r}"
    return f"{key}={json.dumps(value)}"


def point_overrides(point: dict) -> list[str]:
    """The ``KEY.PATH=VALUE`` overrides of one point {key: value}."""
    return [_override(k, v) for k, v in point.items()]


def sweep_point(task: dict) -> dict:
    """Worker of ``flexmech sweep``: one grid point.  ``task``: {"raw": the case file's TOML
    table, "source": its name, "overrides": [KEY.PATH=VALUE ...], "model": M or None}."""
    t0 = time.perf_counter()
    case = validate_case(apply_overrides(task["raw"], task["overrides"]), source=task["source"])
    res = simulate(case, model=task["model"])
    out = {"status": "ok", "model": res.model, "steps": res.nsteps, "dt": res.dt,
           "kernel_s": res.timing.get("kernel_s", float("nan"))}
    for name, y in res.columns.items():
        y = np.asarray(y, float)
        out[f"{name}_maxabs"] = float(np.max(np.abs(y)))
        out[f"{name}_rms"] = float(np.sqrt(np.mean(y * y)))
        out[f"{name}_final"] = float(y[-1])
    for link, v in res.extra.get("validity", {}).items():
        out[f"{link}_compression_over_euler"] = v["max_compression_over_euler"]
        out[f"{link}_tension_over_euler"] = v["max_tension_over_euler"]
        out[f"{link}_displacement_over_length"] = v["max_displacement_over_length"]
    out["run_s"] = time.perf_counter() - t0
    return out


def load_base(case_path, overrides=()) -> tuple[Path, dict]:
    """(path, raw case with ``overrides``) of a case file; a broken base case fails here, once."""
    path = Path(case_path)
    base = apply_overrides(read_case_file(path), list(overrides))
    validate_case(copy.deepcopy(base), source=str(path))
    return path, base


def check_first_point(base: dict, source: str, points: list[dict], what: str = "grid point") -> None:
    """Validate the case at the first point before any run: a mistyped key or a wrong value is one
    CaseError naming it, not a batch of failed runs."""
    ovs = point_overrides(points[0])
    try:
        validate_case(apply_overrides(base, ovs), source=source)
    except FlexmechError as exc:
        raise CaseError(f"the first {what} ({' '.join(ovs)})", str(exc)) from None


def run_points(path: Path, base: dict, points: list[dict], *, model, out: Path, executor, progress: bool = True):
    """Run the case at every point {key: value} on ``executor`` (cache in ``out/cache``).
    Returns (rows, batch): one row per point, the point's values first."""
    tasks = [{"raw": base, "source": path.name, "model": model, "overrides": point_overrides(pt)} for pt in points]
    batch = run_tasks(sweep_point, tasks, cache_dir=out / "cache", progress=progress, label="runs", scheduler=executor)
    rows = []
    for pt, r, sec, worker in zip(points, batch.results, batch.task_s, batch.task_worker):
        row = dict(pt)
        if "error" in r:
            row.update(status="error", error=f"{r.get('error_type', 'error')}: {r['error']}")
        else:
            row.update(r)
            row["error"] = ""
        row.update(task_s=sec, worker=worker)
        rows.append(row)
    return rows, batch


def write_table(path: Path, rows: list[dict], keys: list[str], header: str) -> list[str]:
    """Write the rows as CSV (the point's ``keys`` first, ``error`` last); returns the column names."""

    names = list(keys) + ["status", "model", "steps", "dt", "kernel_s", "run_s", "task_s", "worker"]
    for r in rows:
        names += [k for k in r if k not in names and k != "error"]
    names.append("error")
    lines = [f"# {header}", ",".join(names)] + [",".join(csv_cell(r.get(n, "")) for n in names) for r in rows]
    atomic_write(path, "\n".join(lines) + "\n")
    return names


def failure_reasons(rows: list[dict]) -> list[tuple[str, int]]:
    """Each distinct error message of the failed rows with its count, the most frequent first."""
    return Counter(r["error"] for r in rows if r.get("status") == "error").most_common()


def sweep(case_path, params: list[str], *, model: str | None = None, overrides=(), jobs: int | None = None,
          out_dir=None, progress: bool = True, scheduler=None) -> dict:
    """Run the case at every grid point of ``params`` (``KEY.PATH=START:STOP:N`` or ``KEY.PATH=a,b,c``
    strings) and write ``sweep.csv`` and ``sweep.json`` into ``out_dir`` (finished runs cached in
    ``out_dir/cache``).  ``scheduler``: None (local pool of ``jobs`` processes), a Dask scheduler
    address or ``local:N`` (:func:`~flexmech_py.run.parallel.open_executor`).
    Returns {"rows", "batch", "paths", "grid", "failures"}."""
    path, base = load_base(case_path, overrides)
    axes = [parse_param(p) for p in params]
    points = grid_points(axes)
    check_first_point(base, path.name, points)
    out = out_dir if out_dir is not None else Path("results") / f"{safe_name(path.stem)}-sweep"
    with using_executor(scheduler, jobs) as executor, ResultFolder(out, "sweep") as rf:   # connect first
        rows, batch = run_points(path, base, points, model=model, out=rf.out, executor=executor, progress=progress)
        keys = [k for k, _, _ in axes]
        csv = rf.stage / "sweep.csv"
        names = write_table(csv, rows, keys, f"flexmech {versions()['flexmech']} sweep of {path.name}: "
                            + "; ".join(f"{k} = {s}" for k, _, s in axes))
        info = {"case": str(path), "model": model, "overrides": list(overrides),
                "params": [{"key": k, "spec": s, "values": v} for k, v, s in axes],
                "points": len(points), "order": "cartesian, first parameter slowest (rows of sweep.csv)",
                "columns": names, "jobs": batch.jobs, "executor": batch.executor, "computed": batch.computed,
                "cached": batch.cached, "retries": batch.retries, "failed": batch.failed, "wall_s": batch.wall_s,
                "versions": versions()}
        js = rf.stage / "sweep.json"
        atomic_write(js, json.dumps(info, indent=2, default=json_default) + "\n")
        rf.commit()
    return {"rows": rows, "batch": batch, "paths": [rf.where(csv), rf.where(js)], "grid": points,
            "failures": failure_reasons(rows)}
