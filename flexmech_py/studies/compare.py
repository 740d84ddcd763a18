"""Compare a result with a reference curve (a digitized published curve, or another model's run).

Reference CSV format (``docs/compare.md``): ``#`` comment lines first — one ``# source: ...``
line is required (the citation), an optional ``# units: ...`` line gives the unit of every
column — then a header line with the column names and the data rows.  ``timeseries.csv``
files written by flexmech have this format, so any run can serve as a reference.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..definitions import definition_notes
from ..base.errors import CaseError, FlexmechError, MechanismError, SolverError
from ..base.fileio import atomic_write
from ..base.inputs import read_text
from ..base.names import inside, safe_name
from ..run.outdir import ResultFolder
from ..figures.plots import display_unit, line_figure
from ..run.results import read_timeseries
from ..models.superposition.outputs import output_unit
from ..run.simulate import simulate
from ..run.parallel import run_tasks

__all__ = ["read_reference", "compare_columns", "compare_result_dir", "compare_models", "model_run", "ModelRun"]

#: the units flexmech writes (outputs.output_unit, simulate.py), and the angle units converted to them
KNOWN_UNITS = ("s", "m", "m/s", "m/s^2", "rad", "rad/s", "rad/s^2", "1", "1/m", "N", "N m", "J")
CONVERTED_UNITS = {"deg": ("rad", np.pi / 180.0), "deg/s": ("rad/s", np.pi / 180.0),
                   "deg/s^2": ("rad/s^2", np.pi / 180.0)}


def _text(path: Path) -> str:
    """The file as text (inputs.read_text: a readable regular UTF-8 file, byte-order mark dropped);
    CaseError (one line, naming the first byte that is not text) for anything else."""
    text = read_text(path, "--reference", "CSV file", "give a CSV file (format: docs/compare.md)")
    nul = text.find("\0")
    if nul >= 0:
        raise CaseError("--reference", f"{path} is not a text CSV file (byte 0x00 at offset {nul}); give a "
                                       "comma-separated text file (format: docs/compare.md)")
    return text


def _row(path: Path, lineno: int, line: str, header: list) -> list[float]:
    """One data row as numbers; CaseError naming the line and the column for a short, long or bad row."""
    cells = line.split(",")
    if len(cells) != len(header):
        values = f"{len(cells)} value" + ("" if len(cells) == 1 else "s")
        raise CaseError("--reference", f"{path}, line {lineno}: {values}, but the header names "
                                       f"{len(header)} columns ({', '.join(header)}); every data row needs one "
                                       "number per column")
    out = []
    for name, cell in zip(header, cells):
        try:
            v = float(cell)
        except ValueError:
            raise CaseError("--reference", f"{path}, line {lineno}, column {name!r}: {cell.strip()!r} is not a "
                                           "number; data rows must hold numbers only") from None
        if not np.isfinite(v):
            raise CaseError("--reference", f"{path}, line {lineno}, column {name!r}: {cell.strip()} is not a finite "
                                           "number; remove the row or fill in the value")
        out.append(v)
    return out
_ERRORS = {"MechanismError": MechanismError, "SolverError": SolverError}


def read_reference(path) -> tuple[dict, dict, str]:
    """({column: array}, {column: unit}, source) of a reference CSV; CaseError on a bad file."""
    path = Path(path)
    source, units, header, rows = "", [], None, []
    for lineno, line in enumerate(_text(path).splitlines(), start=1):
        if line.startswith("#"):
            key, _, val = line[1:].partition(":")
            if key.strip() == "source":
                source = val.strip()
            elif key.strip() == "units":
                units = [u.strip() for u in val.split(",")]
        elif not line.strip():
            continue
        elif header is None:
            header = [h.strip() for h in line.split(",")]
            twice = sorted({h for h in header if header.count(h) > 1})
            if twice:
                raise CaseError("--reference", f"{path}, line {lineno}: the header names {twice[0]!r} twice; give "
                                               "every column its own name")
        else:
            rows.append(_row(path, lineno, line, header))
    if header is None:
        raise CaseError("--reference", f"{path}: no header line; the first non-comment line names the columns")
    if len(rows) < 2:
        raise CaseError("--reference", f"{path}: needs at least two data rows")
    if units and len(units) != len(header):
        raise CaseError("--reference", f"{path}: the '# units:' line has {len(units)} entries for {len(header)} columns")
    for name, unit in zip(header, units):
        if unit and unit not in KNOWN_UNITS and unit not in CONVERTED_UNITS:
            raise CaseError("--reference", f"{path}: unknown unit {unit!r} of column {name!r} in the '# units:' line; "
                                           f"use flexmech's units ({', '.join(KNOWN_UNITS)}) or "
                                           f"{', '.join(CONVERTED_UNITS)} for angles")
    if not source:
        raise CaseError("--reference", f"{path}: add a '# source: <citation>' line saying where the curve comes from")
    data = np.array(rows, float)
    return ({h: data[:, i] for i, h in enumerate(header)}, dict(zip(header, units)) if units else {}, source)


def _unit_factor(column: str, ref_unit: str | None, res_unit: str | None) -> float:
    """Factor turning the reference column into the result's unit; CaseError when they cannot match."""
    if not ref_unit or ref_unit == res_unit:
        return 1.0
    if ref_unit in CONVERTED_UNITS:
        to, factor = CONVERTED_UNITS[ref_unit]
        if res_unit is None or res_unit == to:
            return factor
        ref_unit = f"{ref_unit} (an angle)"
    if res_unit is None:
        return 1.0
    raise CaseError("--reference", f"column {column!r} is in {ref_unit} in the reference but in {res_unit} in the "
                                   "result; convert the reference column or correct its '# units:' entry")


def _peak(x, y):
    i = int(np.argmax(np.abs(y)))
    return float(y[i]), float(x[i])


def compare_columns(res_cols: dict, ref_cols: dict, x: str = "t", columns=None, ref_units=None,
                    res_units=None) -> dict:
    """Metrics of every compared column: the result interpolated onto the reference abscissa.

    x: ``t`` or ``crank_angle`` (unwrapped).  ``ref_units``/``res_units`` ({column: unit}, optional): a reference
    column in deg, deg/s or deg/s^2 is converted to rad; other units must equal the result's (CaseError).
    Returns {column: {max_error, rms_error (relative to the reference peak), peak_ref, peak_result,
    peak_error (relative), peak_shift (in x units), correlation, points, x_range}}.
    """
    ref_units, res_units = ref_units or {}, res_units or {}
    for name, cols in (("result", res_cols), ("reference", ref_cols)):
        if x not in cols:
            raise CaseError("--x", f"the {name} has no column {x!r}; columns: {', '.join(cols)}")
    xr = np.asarray(res_cols[x], float)
    xf = np.asarray(ref_cols[x], float) * _unit_factor(x, ref_units.get(x), res_units.get(x, "s" if x == "t" else "rad"))
    if np.any(np.diff(xr) <= 0):
        raise CaseError("--x", f"the result's {x!r} is not increasing (the crank turns backwards?); compare by time")
    order = np.argsort(xf, kind="stable")
    same = np.flatnonzero(np.diff(xf[order]) == 0)
    if same.size:
        rows = sorted(order[same[0]:same[0] + 2] + 1)
        raise CaseError("--reference", f"{x} = {xf[order[same[0]]]:.10g} appears twice (data rows {rows[0]} and "
                                       f"{rows[1]}); give each {x} once (remove or average the duplicates)")
    common = [c for c in ref_cols if c != x and c in res_cols] if columns is None else list(columns)
    if not common:
        raise CaseError("--columns", f"no column in common; result: {', '.join(res_cols)}; "
                                     f"reference: {', '.join(ref_cols)}")
    out = {}
    for c in common:
        if c not in res_cols or c not in ref_cols:
            raise CaseError("--columns", f"{c!r} is not in both files")
        scale_ref = _unit_factor(c, ref_units.get(c), res_units.get(c))
        xs, yf = xf[order], scale_ref * np.asarray(ref_cols[c], float)[order]
        sel = (xs >= xr[0]) & (xs <= xr[-1])
        if sel.sum() < 2:
            raise CaseError("--x", f"the result ({xr[0]:.4g}..{xr[-1]:.4g}) and the reference "
                                   f"({xs[0]:.4g}..{xs[-1]:.4g}) do not overlap in {x}")
        xs, yf = xs[sel], yf[sel]
        yr = np.interp(xs, xr, np.asarray(res_cols[c], float))
        pf, xpf = _peak(xs, yf)
        pr, xpr = _peak(xs, yr)
        scale = abs(pf) if pf != 0 else 1.0
        err = yr - yf
        corr = float(np.corrcoef(yr, yf)[0, 1]) if np.std(yr) > 0 and np.std(yf) > 0 else float("nan")
        out[c] = {"max_error": float(np.max(np.abs(err)) / scale), "rms_error": float(np.sqrt(np.mean(err ** 2)) / scale),
                  "peak_ref": pf, "peak_result": pr, "peak_error": (abs(pr) - abs(pf)) / scale,
                  "peak_shift": xpr - xpf, "correlation": corr, "points": int(xs.size),
                  "x_range": [float(xs[0]), float(xs[-1])], "_x": xs, "_ref": yf, "_res": yr}
    return out


def _axis_label(name: str, unit: str | None) -> str:
    return f"{name} [{display_unit(unit)}]" if unit is not None else name


def _write(metrics: dict, out_dir: Path, x: str, title: str, labels=("result", "reference"), extra=None,
           units=None) -> list[Path]:
    """compare.json, compare.csv and one PNG per column (the two curves, then their difference).
    ``units``: {column: unit} of the result; the abscissa is ``t`` [s] or the crank angle [rad]."""
    out_dir.mkdir(parents=True, exist_ok=True)
    units = units or {}
    xlabel = "t [s]" if x == "t" else f"{x.replace('_', ' ')} [{units.get(x, 'rad')}]"
    paths = []
    for c, m in metrics.items():
        u, k = units.get(c), 1.0
        if u == "m" and max(np.max(np.abs(m["_ref"])), np.max(np.abs(m["_res"]))) < 0.1:
            u, k = "mm", 1e3   # small lengths in mm, as the reports quote them
        note = "\nnot the same quantity in the two models (compare.json: definition_note)" if m.get("definition_note") else ""
        p = line_figure(inside(out_dir, f"compare_{safe_name(c)}.png"),
                        [{"x": m["_x"], "ylabel": _axis_label(c, u),
                          "series": [(labels[1], k * m["_ref"], {"color": "k", "lw": 1.4}),
                                     (labels[0], k * m["_res"], {"color": "C3", "lw": 1.0})]},
                         {"x": m["_x"], "ylabel": _axis_label(f"{labels[0]} - {labels[1]}", u),
                          "series": [("", k * (m["_res"] - m["_ref"]), {"color": "C3", "lw": 0.8})]}],
                        title=f"{title}: {c} (max error {100 * m['max_error']:.3g} % of the reference peak){note}",
                        xlabel=xlabel)
        if p:
            paths.append(p)
    clean = {c: {k: v for k, v in m.items() if not k.startswith("_")} for c, m in metrics.items()}
    js = out_dir / "compare.json"
    atomic_write(js, json.dumps({"x": x, **(extra or {}), "columns": clean}, indent=2) + "\n")
    csv = out_dir / "compare.csv"
    keys = ["max_error", "rms_error", "peak_ref", "peak_result", "peak_error", "peak_shift", "correlation", "points"]
    atomic_write(csv, "column," + ",".join(keys) + "\n"
                  + "".join(f"{c}," + ",".join(f"{m[k]:.6g}" for k in keys) + "\n" for c, m in clean.items()))
    return [js, csv] + paths


def table(metrics: dict) -> str:
    """The printed table; a column whose two curves are not the same quantity is marked * and explained
    under the table (:func:`definition_notes`)."""
    lines = [f"{'column':<26} {'max err':>9} {'rms err':>9} {'peak err':>9} {'peak shift':>11} {'corr':>7}"]
    notes = {}          # note -> the columns it explains
    for c, m in metrics.items():
        mark = "*" if m.get("definition_note") else ""
        lines.append(f"{c + mark:<26} {100 * m['max_error']:>8.3g}% {100 * m['rms_error']:>8.3g}% "
                     f"{100 * m['peak_error']:>8.3g}% {m['peak_shift']:>11.4g} {m['correlation']:>7.4f}")
        if mark:
            notes.setdefault(m["definition_note"], []).append(c)
    return "\n".join(lines + [f"  * {', '.join(cols)}: {note}" for note, cols in notes.items()])


def compare_result_dir(result_dir, reference, x="t", columns=None, out_dir=None):
    """Compare a run folder (its timeseries.csv) with a reference CSV; writes compare.* into out_dir
    (default RESULT_DIR/compare; a :class:`~flexmech_py.run.outdir.ResultFolder`: whole or not at all)."""
    result_dir = Path(result_dir)
    ts = result_dir / "timeseries.csv"
    if not ts.is_file():
        raise CaseError("RESULT_DIR", f"{str(result_dir)!r} holds no timeseries.csv; give a folder written by "
                                      "`flexmech run`")
    try:
        res_cols, res_units = read_timeseries(ts)
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise CaseError("RESULT_DIR", f"{ts} cannot be read as a flexmech timeseries.csv ({exc}); run the case "
                                      "again") from None
    ref_cols, ref_units, source = read_reference(reference)
    metrics = compare_columns(res_cols, ref_cols, x=x, columns=columns, ref_units=ref_units, res_units=res_units)
    with ResultFolder(Path(out_dir) if out_dir is not None else result_dir / "compare", "compare") as rf:
        paths = _write(metrics, rf.stage, x, "comparison", units=res_units,
                       extra={"reference": str(reference), "source": source, "result": str(result_dir)})
        rf.commit()
    return metrics, [rf.where(p) for p in paths]


def _case_units(case: dict) -> dict:
    """{output: unit} of a case's outputs (outputs.output_unit)."""
    return {name: output_unit(spec, case) for name, spec in case["outputs"].items()}


@dataclass
class ModelRun:
    """What :func:`compare_models` keeps of one model's run: frame times, output columns, timings."""

    model: str
    t: np.ndarray
    columns: dict
    timing: dict


def model_run(task: dict) -> dict:
    """Worker of ``compare --models`` (a :func:`~flexmech_py.run.parallel.run_tasks` task): one model of one
    case.  ``task``: {"case": validated case, "model": M}; returns the frame times, columns and timings."""
    res = simulate(task["case"], model=task["model"])
    return {"model": res.model, "t": res.t, "columns": res.columns, "timing": res.timing,
            "rigid_motion": res.extra.get("mechanism", {}).get("rigid_motion", "kinematic")}


def compare_models(case: dict, models, reference_model="nonlinear", x="t", columns=None, out_dir="compare", *,
                   jobs: int | None = None, scheduler=None, progress: bool = False):
    """Run several models of one case (each a task of :func:`~flexmech_py.run.parallel.run_tasks`: the local
    pool of ``jobs`` processes or the Dask ``scheduler``) and compare each with reference_model.
    Returns ({model: metrics}, {model: :class:`ModelRun`}, paths)."""
    models = list(dict.fromkeys(list(models) + [reference_model]))
    with ResultFolder(out_dir, "compare-models") as rf:
        batch = run_tasks(model_run, [{"case": case, "model": m} for m in models], jobs=jobs, scheduler=scheduler,
                          progress=progress, label="models")
        out, runs, paths = _compare_runs(case, models, batch, reference_model, x, columns, rf.stage)
        rf.commit()
    return out, runs, [rf.where(p) for p in paths]


def _compare_runs(case, models, batch, reference_model, x, columns, out_dir: Path):
    """Each model's run against the reference model's: metrics, runs, and the files in out_dir/<model>/."""
    for m, r in zip(models, batch.results):
        if "error" in r:
            raise _ERRORS.get(r["error_type"], FlexmechError)(f"model {m}: {r['error']}")
    runs = {m: ModelRun(m, np.asarray(r["t"]), {c: np.asarray(y) for c, y in r["columns"].items()}, r["timing"])
            for m, r in zip(models, batch.results)}
    ref = runs[reference_model]
    ref_cols = {"t": ref.t, **ref.columns}
    free_motion = any(r.get("rigid_motion") == "dynamic" for r in batch.results)
    out, paths = {}, []
    for m in models:
        if m == reference_model:
            continue
        cols = {"t": runs[m].t, **runs[m].columns}
        use = columns or [c for c in case["outputs"] if c in cols and c in ref_cols]
        out[m] = compare_columns(cols, ref_cols, x=x, columns=use)
        for c, note in definition_notes(case, m, reference_model, free_motion).items():
            if c in out[m]:
                out[m][c]["definition_note"] = note
        paths += _write(out[m], inside(out_dir, safe_name(m)), x, f"{m} against {reference_model}", labels=(m, reference_model),
                        extra={"model": m, "reference_model": reference_model,
                               "kernel_s": runs[m].timing["kernel_s"], "reference_kernel_s": ref.timing["kernel_s"]},
                        units=_case_units(case))
    return out, runs, paths
