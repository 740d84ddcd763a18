"""The one mesh rule of every model family: where a flexible link's nodes are (docs/architecture.md)."""

from __future__ import annotations

import numpy as np

__all__ = ["mesh_fractions", "link_mesh", "joint_fractions", "uniform_mesh"]


def joint_fractions(mech, link) -> set:
    """Fractions of ``link`` where joints attach (each must be a mesh node)."""
    out = set()
    for j in mech.joints:
        for ref in mech.joint_points(j):
            if ref.body is link:
                out.add(float(link.fraction(ref.point)))
    return out


def link_mesh(link, n: int, extra=()) -> np.ndarray:
    """Node fractions (0 .. 1) of a link meshed with about n elements and a node at every named point
    (and at the fractions ``extra``, e.g. its joint points)."""
    cuts = sorted({0.0, 1.0} | {float(f) for f in link.points.values()} | {float(f) for f in extra})
    if len(cuts) == 2:
        return np.linspace(0.0, 1.0, n + 1)
    fr = [0.0]
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        if hi - lo <= 1e-12:
            continue
        k = max(1, int(round(n * (hi - lo))))
        fr += list(np.linspace(lo, hi, k + 1)[1:])
    return np.array(fr)


def mesh_fractions(mech, link, n: int) -> np.ndarray:
    """The one mesh rule of every model family: node fractions of a flexible link meshed with about
    ``n`` elements, a node at every named point and at every joint point on it (a joint at the middle
    of a link with an odd number of elements gets its own node in every family)."""
    return link_mesh(link, n, joint_fractions(mech, link))


def uniform_mesh(fracs: np.ndarray) -> bool:
    """True when a link's mesh fractions are equal elements."""
    return np.allclose(fracs, np.linspace(0.0, 1.0, fracs.size), rtol=0.0, atol=1e-14) and fracs.size > 1
