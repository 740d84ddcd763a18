"""The numbering of a finite-element system's free unknowns that keeps its band narrow (reverse
Cuthill-McKee over the unknowns' adjacency), shared by both model families' systems."""

from __future__ import annotations

import numpy as np

__all__ = ["reverse_cuthill_mckee", "rcm_free_numbering"]


def reverse_cuthill_mckee(neighbours: list) -> np.ndarray:
    """Reverse Cuthill-McKee order of a graph given as sorted neighbour arrays (self included).

    The algorithm of scipy.sparse.csgraph.reverse_cuthill_mckee (each component from its
    lowest-degree node, breadth first, each level's new nodes by increasing degree, reversed),
    written out so that a run does not import scipy.sparse (about 0.2 s of start-up)."""
    n = len(neighbours)
    degree = np.array([len(nb) for nb in neighbours])
    inds = np.argsort(degree)
    order = np.zeros(n, dtype=np.intp)
    visited = np.zeros(n, bool)
    N = 0
    for zz in range(n):
        seed = inds[zz]
        if visited[seed]:
            continue
        order[N] = seed
        N += 1
        visited[seed] = True
        level_start, level_end = N - 1, N
        while level_start < level_end:
            for ii in range(level_start, level_end):
                n_old = N
                for j in neighbours[order[ii]]:
                    if not visited[j]:
                        visited[j] = True
                        order[N] = j
                        N += 1
                new = order[n_old:N]
                order[n_old:N] = new[np.argsort(degree[new], kind="stable")]   # the insertion sort
            level_start, level_end = level_end, N
        if N == n:
            break
    return order[::-1]


def rcm_free_numbering(cliques, free_mask: np.ndarray) -> np.ndarray:
    """Free-DOF numbers (1-based; 0 = not free) by reverse Cuthill-McKee.

    cliques: 0-based DOF index arrays whose DOFs are all coupled (an element, a link);
    free_mask (ndof,) marks the DOFs to number.
    """
    free = np.flatnonzero(free_mask)
    pos = -np.ones(free_mask.size, int)
    pos[free] = np.arange(free.size)
    nbs = [set() for _ in range(free.size)]
    for dofs in cliques:
        f = pos[np.asarray(dofs)]
        f = [int(x) for x in f[f >= 0]]
        for a in f:
            nbs[a].update(f)
    perm = reverse_cuthill_mckee([np.array(sorted(nb), dtype=np.intp) for nb in nbs])
    order = np.empty(free.size, int)
    order[perm] = np.arange(free.size)
    out = np.zeros(free_mask.size, np.int32)
    out[free] = order + 1
    return out
