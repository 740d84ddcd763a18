"""What the page of a ``flexmech modes`` result shows: each mode shape (``mode_shapes.csv``) scaled
as in ``mode_shapes.png`` (its largest drawn displacement TARGET_FRACTION of the mechanism's size),
with its frequency and kind (``modes.json``) and the relative bending strain along its flexible
links; and, when the folder has them, the frequencies along the cycle (``frequencies_along.*`` of
``--along-cycle``) with the crank speed harmonics and their crossings."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..case import Case
from ..figures.drawing import TARGET_FRACTION, largest_drawn, mechanism_size
from ..base.errors import FlexmechError
from ..studies.modes import turn_angle
from ..models.shapes import ShapeFrames, read_shape_csv
from .chart_data import read_csv_table
from .pack import finite
from .run_data import mechanism_payload, shape_payload
from .source import read_json

__all__ = ["modes_payload", "hermite_curvatures"]


def modes_payload(folder: Path) -> dict:
    """The page data of the ``flexmech modes`` result in ``folder``."""
    out = {"kind": "modes", "modes": None, "along": None}
    if (folder / "modes.json").is_file():
        out.update(_mode_shapes(folder))
    if (folder / "frequencies_along.json").is_file():
        out["along"] = along_payload(folder)
        out.setdefault("title", out["along"]["title"])
        out.setdefault("model", out["along"]["model"])
    return out


def _mode_shapes(folder: Path) -> dict:
    info = read_json(folder / "modes.json", "a flexmech modes summary")
    fix = f"it is written with modes.json by `flexmech modes CASE --out {folder}`"
    path = folder / "mode_shapes.csv"
    if not path.is_file():
        raise FlexmechError(f"{folder}: no mode_shapes.csv beside modes.json; {fix}")
    sf, key, _ = read_shape_csv(path)
    try:
        case, modes = Case(info["input"]), list(info["modes"])
        kinds = [{"mode": int(m["mode"]), "f_hz": float(m["f_hz"]), "kind": str(m["kind"])} for m in modes]
    except (KeyError, TypeError, ValueError) as exc:
        raise FlexmechError(f"{folder / 'modes.json'}: cannot be read as a flexmech modes summary ({exc})") from None
    if key != "f_hz" or sf.key.size != len(kinds):
        raise FlexmechError(f"{path}: does not hold the {len(kinds)} mode shapes of modes.json; {fix}")
    sf = _scaled(sf)
    where = f"t = {info.get('t_s', 0):.4g} s" + (f", {info['crank_joint']} at {info['crank_angle_deg']:.4g}°"
                                                  if info.get("crank_joint") else "")
    return {"title": case["case"]["title"], "model": info.get("model", ""), "where": where,
            "geometric": info.get("geometric_stiffness", "none"), **mechanism_payload(case, sf),
            "shapes": shape_payload(sf), "modes": kinds, "fraction": TARGET_FRACTION}


def _scaled(sf: ShapeFrames) -> ShapeFrames:
    """Every mode shape scaled so that its largest drawn displacement is TARGET_FRACTION of the
    mechanism's size (as mode_shapes.png), with its relative curvature (largest |kappa| 1)."""
    size = mechanism_size(sf)
    d, rot = sf.d.copy(), sf.rot.copy()
    for k in range(sf.key.size):
        dm = largest_drawn(sf, k)
        if dm > 0:
            d[k] *= TARGET_FRACTION * size / dm
            rot[k] *= TARGET_FRACTION * size / dm
    out = ShapeFrames(sf.bodies, sf.key, sf.x, d, rot)
    kap = hermite_curvatures(out)
    peak = np.nanmax(np.abs(kap), axis=1, initial=0.0)
    out.kappa = kap / np.where(peak > 0, peak, 1.0)[:, None]
    return out


def hermite_curvatures(sf: ShapeFrames) -> np.ndarray:
    """(n, npts) the curvature [1/m] at a flexible link's nodes of the cubic Hermite field of its
    transverse displacement and slope in the link's rigid frame (the mean of the two elements at an
    interior node; NaN at a rigid part's points): exact for the superposition models' shapes, and
    for the linearized shapes of the coupled ones, whose chord rotation is linear along the link."""
    out = np.full(sf.rot.shape, np.nan)
    for b in sf.bodies:
        if b.kind != "flexible" or b.sl.stop - b.sl.start < 2:
            continue
        x, d, th = sf.x[:, b.sl], sf.d[:, b.sl], sf.rot[:, b.sl]
        e = x[:, -1] - x[:, 0]
        e = e / np.maximum(np.hypot(e[:, 0], e[:, 1]), 1e-300)[:, None]
        w = d[..., 1] * e[:, None, 0] - d[..., 0] * e[:, None, 1]
        le = np.hypot(*np.moveaxis(np.diff(x, axis=1), -1, 0))
        w1, w2, t1, t2 = w[:, :-1], w[:, 1:], th[:, :-1], th[:, 1:]
        k0 = (-6 * w1 - 4 * le * t1 + 6 * w2 - 2 * le * t2) / le**2
        k1 = (6 * w1 + 2 * le * t1 - 6 * w2 + 4 * le * t2) / le**2
        kap = np.empty_like(w)
        kap[:, 0], kap[:, -1] = k0[:, 0], k1[:, -1]
        kap[:, 1:-1] = 0.5 * (k1[:, :-1] + k0[:, 1:])
        out[:, b.sl] = kap
    return out


def along_payload(folder: Path) -> dict:
    """The frequencies along the cycle: f_k(x), the crank speed harmonics k Omega / 2 pi, crossings."""
    info = read_json(folder / "frequencies_along.json", "a flexmech frequencies-along summary")
    cols, _ = read_csv_table(folder / "frequencies_along.csv")
    nmodes = sum(1 for c in cols if c.startswith("f") and c.endswith("_hz"))
    crank = info.get("x", "").startswith("crank angle") and "crank_angle_deg" in cols
    x = cols["t"]
    if crank:
        ang = cols["crank_angle_deg"]
        x = ang - (ang[0] - turn_angle(float(ang[0])))
    series = [{"name": f"f{k}", "x": x.tolist(), "y": cols[f"f{k}_hz"].tolist()} for k in range(1, nmodes + 1)]
    harmonics = []
    if "crank_speed_rad_s" in cols:
        hz = cols["crank_speed_rad_s"] / (2 * np.pi)
        harmonics = [{"k": int(k), "y": (k * hz).tolist()} for k in info.get("harmonics", []) or []]
    crossings = [{"x": finite(c.get("x")), "f_hz": finite(c.get("f_hz")), "mode": c.get("mode"),
                  "harmonic": c.get("harmonic"), "t": finite(c.get("t"))}
                 for c in info.get("crossings", []) or [] if isinstance(c, dict)]
    return {"title": info.get("title", ""), "model": info.get("model", ""), "span": info.get("span", ""),
            "xlabel": info.get("x", "t [s]"), "x": x.tolist(), "series": series, "harmonics": harmonics,
            "crossings": crossings}
