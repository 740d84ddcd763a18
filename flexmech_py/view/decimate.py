"""How much of a result the page of ``flexmech view`` holds: the rule that bounds its size, stated
in the page itself and in docs/cli.md.

- Stations: a flexible link keeps at most STATION_CAP of its mesh nodes, every k-th from its start
  (k the smallest whole number that fits) plus its end node; rigid parts keep every point.
- Frames: at most FRAME_CAP, and at most POINT_FRAMES / (points kept) so that the shapes take at
  most about 2.6 MB (six 4-byte numbers per point and frame, base64); spread evenly over the frames
  there are, the first and the last included.
- Curves: every output column drawn with at most CURVE_POINTS points (the smallest and the largest
  value of every bucket of frames, flexmech_py.figures.plots.decimate: every peak survives).

A long run's page is then about 3 MB whatever its length.  What the rule costs is measured on the
result itself and stated in the page: :func:`station_error` (the drawn line through the kept nodes
against every dropped node, and the strain colour there) and :func:`curve_error` (the drawn
polyline against every sample of the column).
"""

from __future__ import annotations

import math

import numpy as np

from ..models.shapes import Body, ShapeFrames, spread

__all__ = ["FRAME_CAP", "POINT_FRAMES", "STATION_CAP", "CURVE_POINTS", "frames_for", "thin_stations",
           "thin_frames", "rule_text", "station_error", "curve_error", "kept_points", "bucket_span"]

FRAME_CAP = 3000
POINT_FRAMES = 80_000
STATION_CAP = 33
CURVE_POINTS = 6000


def frames_for(points: int, available: int) -> int:
    """Frames kept of ``available`` for a mechanism drawn with ``points`` points."""
    return int(max(2, min(available, FRAME_CAP, POINT_FRAMES // max(points, 1))))


def _station_step(n: int) -> int:
    """Node step of a flexible link with n nodes: the smallest k with ceil((n - 1) / k) + 1 <= STATION_CAP."""
    return 1 if n <= STATION_CAP else math.ceil((n - 1) / (STATION_CAP - 1))


def _kept_nodes(n: int) -> np.ndarray:
    """The nodes kept of a flexible link with n nodes: every k-th from its start, and its end node."""
    return np.unique(np.r_[np.arange(0, n, _station_step(n)), n - 1])


def kept_points(bodies) -> int:
    """The points the page keeps of a mechanism drawn with ``bodies`` (flexmech_py.models.shapes.Body)."""
    return sum(_kept_nodes(b.sl.stop - b.sl.start).size if b.kind == "flexible" else b.sl.stop - b.sl.start
               for b in bodies)


def thin_stations(sf: ShapeFrames) -> tuple[ShapeFrames, int]:
    """(sf with at most STATION_CAP nodes per flexible link, the number of points dropped)."""
    keep, bodies, start = [], [], 0
    for b in sf.bodies:
        n = b.sl.stop - b.sl.start
        idx = _kept_nodes(n) if b.kind == "flexible" else np.arange(n)
        keep.append(b.sl.start + idx)
        labels = [b.labels[i] for i in idx]
        bodies.append(Body(b.name, b.kind, labels, slice(start, start + idx.size),
                           None if b.fracs is None else b.fracs[idx]))
        start += idx.size
    k = np.concatenate(keep)
    if k.size == sf.x.shape[1]:
        return sf, 0
    out = ShapeFrames(bodies, sf.key, sf.x[:, k], sf.d[:, k], sf.rot[:, k], None if sf.kappa is None else sf.kappa[:, k])
    return out, int(sf.x.shape[1] - k.size)


def _hermite_misses(x, d, rot, kappa, kept) -> tuple[float, float]:
    """(largest |drawn - true| displacement [m], largest |drawn - true| curvature [1/m]) at the nodes
    of one flexible link left out of ``kept``: the page draws a cubic Hermite curve through the kept
    nodes' transverse displacements and slopes (axial: linear) and colours linearly between them.
    x, d (frames, n, 2), rot, kappa (frames, n) of the link's nodes."""
    drop = np.setdiff1d(np.arange(x.shape[1]), kept)
    if drop.size == 0:
        return 0.0, 0.0
    e = x[:, -1] - x[:, 0]
    e = e / np.maximum(np.hypot(e[:, 0], e[:, 1]), 1e-300)[:, None]
    nrm = np.stack([-e[:, 1], e[:, 0]], axis=-1)
    s = np.einsum("fnk,fk->fn", x - x[:, :1], e)
    w, u = np.einsum("fnk,fk->fn", d, nrm), np.einsum("fnk,fk->fn", d, e)
    c = kept[np.searchsorted(kept, drop)]
    a = kept[np.searchsorted(kept, drop) - 1]
    le = s[:, c] - s[:, a]
    xi = (s[:, drop] - s[:, a]) / le
    h = (1 - 3 * xi**2 + 2 * xi**3, xi - 2 * xi**2 + xi**3, 3 * xi**2 - 2 * xi**3, xi**3 - xi**2)
    wd = h[0] * w[:, a] + h[1] * le * rot[:, a] + h[2] * w[:, c] + h[3] * le * rot[:, c]
    ud = (1 - xi) * u[:, a] + xi * u[:, c]
    miss = float(np.max(np.hypot(wd - w[:, drop], ud - u[:, drop])))
    if kappa is None:
        return miss, 0.0
    kd = (1 - xi) * kappa[:, a] + xi * kappa[:, c]
    return miss, float(np.nanmax(np.abs(kd - kappa[:, drop]), initial=0.0))


def station_error(sf: ShapeFrames) -> dict:
    """What :func:`thin_stations` costs on sf (the shapes before thinning): ``deflection``, the largest
    distance between the drawn line and a dropped node's true place as a fraction of the largest
    displacement of any point at any frame; ``curvature``, the largest error of the colour there as a
    fraction of that link's largest |kappa|; both 0 when nothing is dropped."""
    top = float(np.max(np.hypot(sf.d[..., 0], sf.d[..., 1]), initial=0.0))
    out = {"deflection": 0.0, "curvature": 0.0}
    for b in sf.bodies:
        n = b.sl.stop - b.sl.start
        if b.kind != "flexible" or n <= STATION_CAP:
            continue
        kap = None if sf.kappa is None else sf.kappa[:, b.sl]
        miss, kmiss = _hermite_misses(sf.x[:, b.sl], sf.d[:, b.sl], sf.rot[:, b.sl], kap, _kept_nodes(n))
        out["deflection"] = max(out["deflection"], miss / top if top > 0 else 0.0)
        kt = float(np.nanmax(np.abs(kap), initial=0.0)) if kap is not None else 0.0
        out["curvature"] = max(out["curvature"], kmiss / kt if kt > 0 else 0.0)
    return out


def bucket_span(t) -> float:
    """The time [s] of samples one kept smallest/largest pair stands for (0: every sample kept)."""
    t = np.asarray(t, float)
    if t.size <= CURVE_POINTS:
        return 0.0
    size = -(-t.size // max(1, CURVE_POINTS // 2 - 1))
    return float((t[-1] - t[0]) * size / (t.size - 1))


def curve_error(t, y, xd, yd) -> float:
    """The largest distance, along y, between the polyline (xd, yd) drawn of a column and its every
    sample (t, y), as a fraction of the column's largest |y| (0 for a column that is 0 or empty)."""
    t, y = np.asarray(t, float), np.asarray(y, float)
    ok = np.isfinite(y)
    okd = np.isfinite(yd)
    if not np.any(ok) or not np.any(okd):
        return 0.0
    top = float(np.max(np.abs(y[ok])))
    if top == 0.0:
        return 0.0
    drawn = np.interp(t[ok], np.asarray(xd, float)[okd], np.asarray(yd, float)[okd])
    return float(np.max(np.abs(drawn - y[ok]))) / top


def thin_frames(sf: ShapeFrames) -> ShapeFrames:
    """sf (its stations thinned already) with at most :func:`frames_for` of its frames, spread evenly."""
    n = frames_for(sf.x.shape[1], sf.key.size)
    return sf if n >= sf.key.size else sf.select(spread(sf.key.size, n))


def rule_text() -> str:
    """The rule in one sentence, as the page states it."""
    return (f"at most {STATION_CAP} nodes per flexible link, at most {FRAME_CAP} frames and at most "
            f"{POINT_FRAMES:,} point-frames (spread evenly, first and last kept), curves with at most "
            f"{CURVE_POINTS} points each (every bucket's smallest and largest value)")
