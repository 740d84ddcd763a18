"""The order of the nonlinear model's unknowns for its bordered saddle band (docs/theory.md section
12.6; fortran/flexmech_saddle_band.f90).

A Newton step of the nonlinear model solves ``[S G; Gᵀ 0]`` over the free DOFs and the constraint
rows' multipliers.  Numbered as one band, its half width is the widest reach of any segment or row:
a rigid body joined to three links, or a junction where three chains of elements meet, couples
unknowns that no single order keeps close, and the band widens with the mesh (the cost per step
grows with its square).  So the unknowns are split:

- the **border**: every rigid body's DOFs, the DOFs shared by three or more segments (a junction
  node), the DOFs that close a loop of segments, and every row that touches one of them or joins
  two chains; a few dozen unknowns whatever the mesh, eliminated densely (their Schur complement);
- the **interior**: the rest, which falls apart into *chains* of elements (a link, or links joined
  end to end), each numbered along its length from the end farther from the border, so that every
  chain is a narrow band (the interleaved multipliers of its own rows included) and the border
  couples to its last unknowns only.

:func:`bordered_numbering` returns the free numbers (interior chains first, border DOFs last) and
which rows are border rows; the kernel interleaves the interior rows' multipliers in the band.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from ..numbering import rcm_free_numbering

__all__ = ["bordered_numbering"]


def bordered_numbering(seg_cols, body_dofs, row_patterns, free_mask) -> tuple[np.ndarray, int, np.ndarray]:
    """(free_of, nbd, row_border) of the bordered saddle band.

    seg_cols: 0-based all-DOF indices of every segment's local vector; body_dofs: those of every rigid
    body; row_patterns: the all-DOF indices every constraint row's gradient can touch; free_mask
    (ndof,) the free DOFs.  free_of (ndof,) numbers the free DOFs 1..nfree (0: fixed), the chains'
    DOFs first (each chain contiguous) and the nbd border DOFs last; row_border (nrows,) is 1 for
    a border row.  A layout without any border (one chain: a single loop fixed to the ground, a
    serial arm) keeps the reverse Cuthill-McKee numbering it always had (the same band, and the same
    round-off as before the border existed)."""
    nd = free_mask.size
    segs = [np.unique([d for d in c if free_mask[d]]) for c in seg_cols]
    border = np.zeros(nd, bool)
    for dofs in body_dofs:
        border[[d for d in dofs if free_mask[d]]] = True
    uses = np.zeros(nd, int)
    for s in segs:
        uses[s] += 1
    border |= uses >= 3                          # junctions: three or more segments meet
    _cut_loops(segs, border)
    comp = _chains(nd, segs, border, free_mask)
    pats = [np.unique([d for d in p if free_mask[d]]) for p in row_patterns]
    row_border = np.array([_is_border_row(p, border, comp) for p in pats], np.int32)
    if not border[free_mask].any() and not row_border.any():
        rcm = rcm_free_numbering(list(seg_cols), free_mask)
        free = np.flatnonzero(rcm > 0)
        if not _far_rows_to_border(list(free[np.argsort(rcm[free])]), segs, pats, row_border).any():
            return rcm, 0, row_border
    order = []
    for c in range(int(comp.max()) + 1):
        order += _chain_order(np.flatnonzero(comp == c), segs, border, pats, row_border)
    row_border = _far_rows_to_border(order, segs, pats, row_border)
    order += list(np.flatnonzero(border & free_mask))
    free_of = np.zeros(nd, np.int32)
    free_of[np.array(order, int)] = np.arange(1, len(order) + 1)
    return free_of, int((border & free_mask).sum()), row_border


def _cut_loops(segs, border) -> None:
    """Loops of segments that meet no junction: the DOFs shared by the segment pair that closes one go
    to the border (a spanning forest of the segments stays), so that every chain is a path."""
    shared = {}
    for si, s in enumerate(segs):
        for d in s:
            if not border[d]:
                shared.setdefault(int(d), []).append(si)
    pairs = {}
    for d, ss in shared.items():
        if len(ss) == 2:
            pairs.setdefault(tuple(ss), []).append(d)
    parent = list(range(len(segs)))

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for (a, b), dofs in sorted(pairs.items()):
        ra, rb = find(a), find(b)
        if ra == rb:
            border[dofs] = True
        else:
            parent[ra] = rb


def _chains(nd, segs, border, free_mask) -> np.ndarray:
    """Chain number (0, 1, ...) of every interior free DOF, -1 elsewhere: the connected components of
    the segments' couplings without the border."""
    comp = -np.ones(nd, int)
    nbrs = _neighbours(nd, segs, border)
    c = 0
    for d in np.flatnonzero(free_mask & ~border):
        if comp[d] >= 0:
            continue
        comp[d] = c
        todo = [d]
        while todo:
            x = todo.pop()
            for y in nbrs[x]:
                if comp[y] < 0:
                    comp[y] = c
                    todo.append(y)
        c += 1
    return comp


def _neighbours(nd, segs, border) -> list:
    nbrs = [set() for _ in range(nd)]
    for s in segs:
        inner = [int(d) for d in s if not border[d]]
        for d in inner:
            nbrs[d].update(inner)
    for d, nb in enumerate(nbrs):
        nb.discard(d)
    return [sorted(nb) for nb in nbrs]


def _is_border_row(pat, border, comp) -> int:
    """A row is a border row when it touches a border DOF, no free DOF, or two chains."""
    if pat.size == 0 or border[pat].any():
        return 1
    return int(np.unique(comp[pat]).size > 1)


def _chain_order(dofs, segs, border, pats, row_border) -> list:
    """One chain's DOFs by Cuthill-McKee from the end farther from the border (its attachments last)."""
    inside = set(int(d) for d in dofs)
    nbrs = {d: set() for d in inside}
    attached = set()
    for s in segs:
        inner = [int(d) for d in s if int(d) in inside]
        for d in inner:
            nbrs[d].update(x for x in inner if x != d)
        if inner and border[s].any():
            attached.update(inner)
    for p, rb in zip(pats, row_border):
        if rb:
            attached.update(int(d) for d in p if int(d) in inside)
    ends = _peripheral_pair(nbrs, min(inside))
    dist = _distances(nbrs, attached) if attached else {d: 0 for d in inside}
    weight = {}
    for e in ends:       # attachments next to the end: those a start there would carry along the chain
        near = _distances(nbrs, [e])
        weight[e] = sum(1 for d in attached if near.get(d, 1 << 30) <= 1)
    start = max(ends, key=lambda e: (dist.get(e, 1 << 30), -weight[e], -len(nbrs[e]), -e))
    return _cuthill_mckee(nbrs, start)


def _distances(nbrs, sources) -> dict:
    dist = {s: 0 for s in sources}
    q = deque(sources)
    while q:
        x = q.popleft()
        for y in nbrs[x]:
            if y not in dist:
                dist[y] = dist[x] + 1
                q.append(y)
    return dist


def _peripheral_pair(nbrs, seed) -> tuple:
    """Two far-apart vertices (the ends of a chain): the farthest from seed, and the farthest from it
    (ties: the lower degree, then the lower number)."""
    def farthest(x):
        d = _distances(nbrs, [x])
        return min(d, key=lambda y: (-d[y], len(nbrs[y]), y))
    u = farthest(seed)
    return u, farthest(u)


def _cuthill_mckee(nbrs, start) -> list:
    order, seen = [start], {start}
    i = 0
    while i < len(order):
        new = sorted((y for y in nbrs[order[i]] if y not in seen), key=lambda y: (len(nbrs[y]), y))
        seen.update(new)
        order += new
        i += 1
    return order


def _far_rows_to_border(order, segs, pats, row_border) -> np.ndarray:
    """An interior row whose DOFs lie far apart in the chains' order (one that closes a loop within a
    chain) goes to the border: its multiplier would widen every chain's band."""
    pos = {d: i for i, d in enumerate(order)}
    reach = 0
    for s in segs:
        p = [pos[int(d)] for d in s if int(d) in pos]
        if p:
            reach = max(reach, max(p) - min(p))
    out = row_border.copy()
    for i, p in enumerate(pats):
        if not out[i]:
            q = [pos[int(d)] for d in p]
            if max(q) - min(q) > 2 * reach + 2:
                out[i] = 1
    return out
