"""The constraint-row vocabulary shared with the Fortran kernels (its one Python mirror).

A row is a scalar function g of two markers a and b (points of bodies, segment nodes or the ground,
each with a frame angle psi).  Fortran evaluates every row by the index of its kind, in one routine
per kind (the table in ``fortran/flexmech_markers.f90``), for every model: the rigid-body solver
(flexmech_mbs) and the coupled and nonlinear models (flexmech_coupled_rows).  A joint kind names its
rows and its coordinate by these indices (:meth:`flexmech_py.mechanism.joints.Joint.rigid_rows`,
``coordinate_row``); the kernels reject an index outside the table.

=====  ===============  ==============  =====  ==================================================
index  name             routine         unit   g; parameters (aux integer, d 2 reals in a's frame)
=====  ===============  ==============  =====  ==================================================
1      CON_POINT        row_point       m      (r_a - r_b)_i, i = aux (1: x, 2: y)
2      CON_ANGLE        row_angle       rad    psi_b - psi_a
3      CON_PROJECTION   row_projection  m      e . (r_b - r_a), e = R(psi_a) d
4      CON_GEAR         row_gear        m      d1 psi_a + d2 psi_b - (d1 + d2) theta, theta = angle of
                                               r_b - r_a on the branch around aux pi/2 (:func:`gear_theta`)
=====  ===============  ==============  =====  ==================================================
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["CON_POINT", "CON_ANGLE", "CON_PROJECTION", "CON_GEAR", "ROW_KINDS", "in_radians", "gear_branch",
           "gear_theta", "residual"]

CON_POINT, CON_ANGLE, CON_PROJECTION, CON_GEAR = 1, 2, 3, 4

#: index -> (name, unit of the row's value, Fortran routine in flexmech_markers)
ROW_KINDS = {
    CON_POINT: ("point", "m", "row_point"),
    CON_ANGLE: ("angle", "rad", "row_angle"),
    CON_PROJECTION: ("projection", "m", "row_projection"),
    CON_GEAR: ("gear", "m", "row_gear"),
}


def in_radians(kind: int) -> bool:
    """The row's value is an angle [rad] (scaled by the mechanism's length where rows are compared)."""
    return ROW_KINDS[kind][1] == "rad"


def gear_branch(c) -> int:
    """The branch (aux, 0..3) of CON_GEAR for a line of centres c = r_b - r_a: its nearest quarter turn."""
    return int(round(math.atan2(c[1], c[0]) / (0.5 * math.pi))) % 4


def gear_theta(c, branch: int) -> float:
    """The angle of c on CON_GEAR's branch ``branch`` [rad] (as row_gear computes it)."""
    x, y = {0: (c[0], c[1]), 1: (c[1], -c[0]), 2: (-c[0], -c[1]), 3: (-c[1], c[0])}[branch]
    return math.atan2(y, x) + branch * 0.5 * math.pi


def residual(kind: int, d, r):
    """g - value reduced as flexmech_markers' con_residual reduces it (arrays allowed): CON_ANGLE
    wrapped to (-pi, pi], CON_GEAR less the nearest 2 pi (n_a d1 + n_b d2), n in {-1, 0, 1}."""
    r = np.asarray(r, float)
    if kind == CON_ANGLE:
        return r - 2.0 * np.pi * np.round(r / (2.0 * np.pi))
    if kind == CON_GEAR:
        shifts = np.array([2.0 * np.pi * (na * d[0] + nb * d[1]) for na in (-1, 0, 1) for nb in (-1, 0, 1)])
        cand = r[..., None] - shifts
        return np.take_along_axis(cand, np.argmin(np.abs(cand), axis=-1)[..., None], -1)[..., 0]
    return r
