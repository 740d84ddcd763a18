"""How much of a result the page of ``flexmech view`` holds: the rule that bounds its size, stated
in the page itself and in docs/cli.md.

- Stations: a flexible link keeps at most STATION_CAP of its mesh nodes, every k-th from its start
  (k the smallest whole number that fits) plus its end node; rigid parts keep every point.
- Frames: at most FRAME_CAP, and at most POINT_FRAMES / (points kept) so that the shapes take at
  most about 2.6 MB (six 4-byte numbers per point and frame, base64); spread evenly over the frames
  there are, the first and the last included.
- Curves: every output column drawn with at most CURVE_POINTS points (the smallest and the largest
  value of every bucket of frames, flexmech_py.plots.decimate: every peak survives).

A long run's page is then about 3 MB whatever its length, and loads in well under a second.
"""

from __future__ import annotations

import math

import numpy as np

from ..shapes import Body, ShapeFrames, spread

__all__ = ["FRAME_CAP", "POINT_FRAMES", "STATION_CAP", "CURVE_POINTS", "frames_for", "thin_stations",
           "thin_frames", "rule_text"]

FRAME_CAP = 3000
POINT_FRAMES = 80_000
STATION_CAP = 33
CURVE_POINTS = 2000


def frames_for(points: int, available: int) -> int:
    """Frames kept of ``available`` for a mechanism drawn with ``points`` points."""
    return int(max(2, min(available, FRAME_CAP, POINT_FRAMES // max(points, 1))))


def _station_step(n: int) -> int:
    """Node step of a flexible link with n nodes: the smallest k with ceil((n - 1) / k) + 1 <= STATION_CAP."""
    return 1 if n <= STATION_CAP else math.ceil((n - 1) / (STATION_CAP - 1))


def thin_stations(sf: ShapeFrames) -> tuple[ShapeFrames, int]:
    """(sf with at most STATION_CAP nodes per flexible link, the number of points dropped)."""
    keep, bodies, start = [], [], 0
    for b in sf.bodies:
        n = b.sl.stop - b.sl.start
        idx = np.arange(n)
        if b.kind == "flexible":
            idx = np.unique(np.r_[idx[::_station_step(n)], n - 1])
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


def thin_frames(sf: ShapeFrames) -> ShapeFrames:
    """sf with at most :func:`frames_for` of its frames, spread evenly."""
    n = frames_for(sf.x.shape[1], sf.key.size)
    return sf if n >= sf.key.size else sf.select(spread(sf.key.size, n))


def rule_text() -> str:
    """The rule in one sentence, as the page states it."""
    return (f"at most {STATION_CAP} nodes per flexible link, at most {FRAME_CAP} frames and at most "
            f"{POINT_FRAMES:,} point-frames (spread evenly, first and last kept), curves with at most "
            f"{CURVE_POINTS} points each (every bucket's smallest and largest value)")
