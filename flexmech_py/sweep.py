"""``flexmech sweep``: one case over a cartesian grid of parameter values, in parallel and resumable.

Each grid point is the case with ``--set``-style overrides (``KEY.PATH=VALUE``), run by
:func:`~flexmech_py.parallel.run_tasks` (progress bar, one cached JSON per finished run, errors
as results).  The output is one summary table, ``sweep.csv`` (a row per point in grid order:
the parameters, every output column's max |.|, rms and final value, the validity measures,
the kernel time, the status), and ``sweep.json`` with the grid definition.
"""

from __future__ import annotations

import copy
import json
import math
import time
from itertools import product
from pathlib import Path

import numpy as np

from .case import _parse_value, apply_overrides, read_case_file, validate_case
from .errors import CaseError

__all__ = ["parse_param", "grid_points", "sweep", "sweep_point", "TIMING_COLUMNS"]

#: columns that hold measured times (they differ between reruns; everything else is reproducible)
TIMING_COLUMNS = ("kernel_s", "run_s")


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
            a, b, n = _parse_value(parts[0]), _parse_value(parts[1]), int(parts[2])
            if isinstance(a, bool) or isinstance(b, bool) or not isinstance(a, (int, float)) or \
                    not isinstance(b, (int, float)) or n < 1:
                raise ValueError
        except ValueError:
            raise CaseError(f"--param {key}", f"{spec!r} must be START:STOP:N with numbers START, STOP and "
                                              "a whole N >= 1") from None
        vals = np.linspace(a, b, n) if n > 1 else np.array([a], float)
        if isinstance(a, int) and isinstance(b, int) and np.allclose(vals, np.round(vals)):
            values = [int(round(v)) for v in vals]
        else:
            values = [float(v) for v in vals]
    else:
        values = [_parse_value(v.strip()) for v in spec.split(",") if v.strip()]
    if not values:
        raise CaseError(f"--param {key}", f"{spec!r} gives no values")
    return key, values, spec


def grid_points(params: list[tuple[str, list, str]]) -> list[dict]:
    """The cartesian grid as a list of {key: value}, the first parameter varying slowest."""
    keys = [k for k, _, _ in params]
    if len(set(keys)) != len(keys):
        raise CaseError("--param", f"a key is given twice: {', '.join(keys)}")
    return [dict(zip(keys, combo)) for combo in product(*(v for _, v, _ in params))]


def _override(key: str, value) -> str:
    if isinstance(value, bool):
        return f"{key}={'true' if value else 'false'}"
    if isinstance(value, (int, float)):
        return f"{key}={value!r}"
    return f"{key}={json.dumps(value)}"


def sweep_point(task: dict) -> dict:
    """Worker of ``flexmech sweep``: one grid point.  ``task``: {"raw": the case file's TOML
    table, "source": its name, "overrides": [KEY.PATH=VALUE ...], "model": M or None}."""
    from .simulate import simulate

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


def sweep(case_path, params: list[str], *, model: str | None = None, overrides=(), jobs: int | None = None,
          out_dir=None, progress: bool = True) -> dict:
    """Run the case at every grid point of ``params`` (``KEY.PATH=START:STOP:N`` or ``KEY.PATH=a,b,c``
    strings) and write ``sweep.csv`` and ``sweep.json`` into ``out_dir`` (finished runs cached in
    ``out_dir/cache``).  Returns {"rows", "batch", "paths", "grid"}."""
    from .parallel import run_tasks
    from .results import _atomic_write, _json_default, versions

    path = Path(case_path)
    base = apply_overrides(read_case_file(path), list(overrides))
    validate_case(copy.deepcopy(base), source=str(path))      # a broken base case fails once, here
    axes = [parse_param(p) for p in params]
    points = grid_points(axes)
    tasks = [{"raw": base, "source": path.name, "model": model,
              "overrides": [_override(k, v) for k, v in pt.items()]} for pt in points]
    out = Path(out_dir) if out_dir is not None else Path("results") / f"{path.stem}-sweep"
    out.mkdir(parents=True, exist_ok=True)
    batch = run_tasks(sweep_point, tasks, jobs=jobs, cache_dir=out / "cache", progress=progress, label="runs")
    rows = []
    for pt, r in zip(points, batch.results):
        row = dict(pt)
        if "error" in r:
            row.update(status="error", error=f"{r.get('error_type', 'error')}: {r['error']}")
        else:
            row.update(r)
            row["error"] = ""
        rows.append(row)
    keys = [k for k, _, _ in axes]
    names = keys + ["status", "model", "steps", "dt", "kernel_s", "run_s"]
    for r in rows:
        names += [k for k in r if k not in names and k != "error"]
    names.append("error")
    lines = [f"# flexmech {versions()['flexmech']} sweep of {path.name}: " + "; ".join(f"{k} = {s}" for k, _, s in axes),
             ",".join(names)]
    for r in rows:
        lines.append(",".join(_cell(r.get(n, "")) for n in names))
    csv = out / "sweep.csv"
    _atomic_write(csv, "\n".join(lines) + "\n")
    info = {"case": str(path), "model": model, "overrides": list(overrides),
            "params": [{"key": k, "spec": s, "values": v} for k, v, s in axes],
            "points": len(points), "order": "cartesian, first parameter slowest (rows of sweep.csv)",
            "columns": names, "jobs": batch.jobs, "computed": batch.computed, "cached": batch.cached,
            "failed": batch.failed, "wall_s": batch.wall_s, "versions": versions()}
    js = out / "sweep.json"
    _atomic_write(js, json.dumps(info, indent=2, default=_json_default) + "\n")
    return {"rows": rows, "batch": batch, "paths": [csv, js], "grid": points}


def _cell(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:.10g}"
    s = str(v)
    return '"' + s.replace('"', "'") + '"' if ("," in s or '"' in s or "\n" in s) else s
