"""What the page of a ``flexmech run`` result shows, as plain data: the mechanism's shapes over time
(``shape.csv``, thinned by :mod:`~flexmech_py.view.decimate`), the bending strain and stress along
its flexible links, the output curves (``timeseries.csv``) in the panels of the PNG plots, and the
run's validity limits, failure, period-2 dt oscillations, error estimate and error budget placed on
the time axis (``summary.json``, read tolerantly: a section a run does not write is left out)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..case import Case
from ..figures.drawing import largest_drawn, magnification, mechanism_size
from ..base.errors import FlexmechError
from ..figures.glyphs import joint_marks, legend_words
from ..figures.plots import decimate, display_unit, panel_groups
from ..run.results import read_timeseries
from ..models.shapes import ShapeFrames, read_shape_csv
from . import decimate as thin
from .pack import f32, f64, finite
from .source import need, read_json

__all__ = ["run_payload", "mechanism_payload", "shape_payload"]

#: frames (those with the largest nodal displacement) whose drawn lines set the default magnification
SCALE_FRAMES = 40


def run_payload(folder: Path) -> dict:
    """The page data of the run result in ``folder``."""
    summary = read_json(folder / "summary.json", "a flexmech run's summary")
    case = _case_of(summary, folder / "summary.json")
    fix = f"write the mechanism's shapes with `flexmech run CASE --view --out {folder}` (or --draw N)"
    sf, key, _ = read_shape_csv(need(folder / "shape.csv", fix))
    if key != "t":
        raise FlexmechError(f"{folder / 'shape.csv'}: holds shapes by {key}, not frames of a run over time; {fix}")
    stored, miss = sf.key.size, thin.station_error(sf)
    sf, dropped = thin.thin_stations(sf)
    sf = thin.thin_frames(sf)
    cols, units = _read_curves(need(folder / "timeseries.csv", "the run's curves are missing: run the case again"))
    out = {"kind": "run", "title": case["case"]["title"], "model": summary.get("model", ""),
           "status": summary.get("status", "completed"), "t_end": finite(summary.get("t_end")),
           **mechanism_payload(case, sf), "shapes": shape_payload(sf), "field": _field(case, sf),
           "scale": _default_scale(sf), "curves": _curves(case, cols, units, summary),
           "marks": time_marks(summary), "warnings": _warnings(summary)}
    out["decimation"] = {"frames_run": int(summary.get("frames", cols["t"].size)), "frames_stored": int(stored),
                         "frames_kept": int(sf.key.size), "points_kept": int(sf.x.shape[1]),
                         "points_dropped": dropped, "rule": thin.rule_text(), "deflection_error": miss["deflection"],
                         "curvature_error": miss["curvature"],
                         "curve_error": max((s["drawn_error"] for p in out["curves"] for s in p["series"]), default=0.0),
                         "curve_bucket_s": thin.bucket_span(cols["t"])}
    return out


def _case_of(summary: dict, path: Path) -> Case:
    try:
        return Case(summary["input"])
    except (KeyError, TypeError, ValueError) as exc:
        raise FlexmechError(f"{path}: cannot be read as a flexmech run's summary (its input: {exc})") from None


def _read_curves(path: Path):
    try:
        return read_timeseries(path)
    except (OSError, ValueError, IndexError) as exc:
        raise FlexmechError(f"{path}: cannot be read as a flexmech timeseries ({exc})") from None


def mechanism_payload(case: Case, sf: ShapeFrames) -> dict:
    """The drawn bodies and the joints' glyph places (flexmech_py.figures.glyphs) of a mechanism in sf's layout."""
    links = {ln["name"]: ln for ln in case["links"]}
    marks = joint_marks(case.mechanism, sf)
    bodies = []
    for b in sf.bodies:
        ln = links.get(b.name, {})
        bodies.append({"name": b.name, "kind": b.kind, "start": b.sl.start, "n": b.sl.stop - b.sl.start,
                       "half_depth": finite(ln.get("half_depth")), "E": finite(ln.get("youngs_modulus"))})
    joints = [{"name": m.name, "kind": m.kind, "point": m.point, "driven": m.driven,
               "ground": None if m.ground is None else [float(v) for v in m.ground],
               "axis": None if m.axis is None else [float(v) for v in m.axis],
               "shapes": m.joint.glyph_shapes(), "ends": [_end(e) for e in m.ends]} for m in marks]
    return {"bodies": bodies, "joints": joints, "legend": legend_words(marks), "size": mechanism_size(sf)}


def _end(e):
    """A joint side for the page: its drawn point's index, a ground point [x, y] [m], or None."""
    if e is None or isinstance(e, (int, np.integer)):
        return None if e is None else int(e)
    return [float(v) for v in e]


def shape_payload(sf: ShapeFrames) -> dict:
    """sf's arrays for the page: key (f64), x, d (frame, point, xy), rot, kappa (frame, point) as f32."""
    return {"frames": int(sf.key.size), "points": int(sf.x.shape[1]), "key": f64(sf.key), "x": f32(sf.x),
            "d": f32(sf.d), "rot": f32(sf.rot), "kappa": None if sf.kappa is None else f32(sf.kappa)}


def _default_scale(sf: ShapeFrames) -> float:
    """The PNG drawings' magnification (drawing.magnification) over the frames with the largest nodal
    displacement, never below 1: a deflection already that large is shown as it is, not shrunk."""
    nodal = np.max(np.hypot(sf.d[..., 0], sf.d[..., 1]), axis=1)
    top = np.argsort(nodal)[-SCALE_FRAMES:]
    return max(1.0, magnification(mechanism_size(sf), max(largest_drawn(sf, int(i)) for i in top)))


def _field(case: Case, sf: ShapeFrames) -> dict | None:
    """The bending strain c kappa and stress E c kappa at the kept stations: their range over every kept
    frame (what the colour bar spans), None when shape.csv has no curvatures."""
    if sf.kappa is None:
        return None
    links = {ln["name"]: ln for ln in case["links"]}
    strain = np.full(sf.kappa.shape, np.nan)
    stress = np.full(sf.kappa.shape, np.nan)
    for b in sf.bodies:
        ln = links.get(b.name, {})
        if b.kind == "flexible" and ln.get("half_depth"):
            strain[:, b.sl] = ln["half_depth"] * sf.kappa[:, b.sl]
            stress[:, b.sl] = ln["youngs_modulus"] * strain[:, b.sl] / 1e6
    if not np.any(np.isfinite(strain)):
        return None
    return {"strain": {"min": float(np.nanmin(strain)), "max": float(np.nanmax(strain)), "unit": "-",
                       "label": "bending strain c·κ at the outer fibre"},
            "stress": {"min": float(np.nanmin(stress)), "max": float(np.nanmax(stress)), "unit": "MPa",
                       "label": "bending stress E·c·κ at the outer fibre"}}


def _curves(case: Case, cols: dict, units: dict, summary: dict) -> list[dict]:
    """The output columns in the PNG plots' panels, each thinned to CURVE_POINTS, with its error."""
    t = cols["t"]
    names = [n for n in cols if n != "t"]
    peaks = {n: float(np.nanmax(np.abs(cols[n]))) if cols[n].size and np.any(np.isfinite(cols[n])) else 0.0
             for n in names}
    panels = []
    for group in panel_groups(names, units, case["outputs"], peaks):
        unit, scale = units.get(group[0], ""), 1.0
        if unit == "m" and max(peaks[n] for n in group) < 0.1:
            unit, scale = "mm", 1e3
        series = []
        for n in group:
            x, y = decimate(t, cols[n], thin.CURVE_POINTS)
            series.append({"name": n, "t": f32(x), "y": f32(scale * y), "points": int(x.size),
                           "drawn_error": thin.curve_error(t, cols[n], x, y), "error": column_error(summary, n)})
        panels.append({"unit": display_unit(unit), "series": series})
    return panels


def _section(summary: dict, *keys):
    """summary[k0][k1]... when every level is a dict, else {}."""
    node = summary
    for k in keys:
        node = node.get(k) if isinstance(node, dict) else None
    return node if isinstance(node, dict) else {}


def column_error(summary: dict, name: str) -> dict:
    """A column's estimated errors as fractions of its peak: ``time`` (step doubling) and, from the
    error budget when the run made one, ``mesh``, ``model``, ``total``, ``dominant``; ``t_time`` where
    the step-doubling difference is largest."""
    out = {}
    est = _section(summary, "error_estimate", "columns", name)
    if est:
        out["time"], out["t_time"] = finite(est.get("relative")), finite(est.get("t_max_s"))
    bud = _section(summary, "error_budget", "columns", name)
    for k in ("time", "mesh", "model", "total"):
        if finite(bud.get(k)) is not None:
            out[k] = finite(bud[k])
    if isinstance(bud.get("dominant"), str):
        out["dominant"] = bud["dominant"]
    if bud.get("negligible"):
        out["negligible"] = str(bud["negligible"])
    tol = finite(_section(summary, "error_budget").get("tolerance"))
    if tol is not None:
        out["tolerance"] = tol
    return {k: v for k, v in out.items() if v is not None}


def time_marks(summary: dict) -> dict:
    """Where on the time axis the run's results stop being valid (``valid_until``, shaded after it),
    where it stopped (``failed_at``), and the instants of its limits and oscillations (``events``)."""
    events = []
    for link, v in _section(summary, "validity").items():
        if not isinstance(v, dict):
            continue
        for key, what in (("deflection_exceeds_at_s", "deflection past the small-deflection limit"),
                          ("compression_exceeds_at_s", "compressed beyond its Euler load"),
                          ("strain_exceeds_yield_at_s", "strain past its yield strain")):
            if finite(v.get(key)) is not None:
                events.append({"t": finite(v[key]), "kind": "validity", "text": f"{link}: {what}"})
    for f in _section(summary, "alternation").get("found", []) or []:
        if isinstance(f, dict) and finite(f.get("t_s")) is not None:
            events.append({"t": finite(f["t_s"]), "kind": "accuracy",
                           "text": f"{f.get('quantity', '?')}: a period-2 dt oscillation, largest here"})
    overall = _section(summary, "validity_overall")
    return {"valid_until": finite(overall.get("valid_until_s")), "failed_at": finite(summary.get("failed_at_s")),
            "events": sorted(events, key=lambda e: e["t"])}


def _warnings(summary: dict) -> list[dict]:
    """The run's warnings with their kinds (validity, accuracy, mechanism, stability; '' unknown)."""
    kinds = summary.get("warning_kinds") if isinstance(summary.get("warning_kinds"), dict) else {}
    return [{"text": str(w), "kind": str(kinds.get(w, ""))} for w in summary.get("warnings", []) or []]
