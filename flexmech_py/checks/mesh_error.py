"""The mesh part of the error budget (docs/theory.md section 21.2): the run's model on a mesh with
half (or, where halving is not possible, twice) the elements of every flexible link, at twice the
step like the step-doubling run S, and the Richardson estimate of the run's spatial error from their
difference with the order of the strain: with element lengths r h on the probe P,

    A h^p = (S - P) / (1 - r^p).

Without step doubling (``solver.error_estimate`` without ``time``) the run itself stands in for S and
the difference carries the probe's time error (3/4 of the step-doubling difference) as well.
"""

from __future__ import annotations

import copy
import math

from ..case import Case

__all__ = ["MESH_ORDER", "probe_elements", "remesh", "spatial_error", "elements_for",
           "NOT_CONVERGING"]

#: order of the spatial error assumed for every output: the curvature (strain) of the cubic Hermite
#: elements, the lowest among the outputs (positions, angles and drive torques converge at 3-4;
#: docs/validation.md "Error budget"), so the estimate errs on the safe side for them
MESH_ORDER = 2
#: output kinds without a mesh limit: a nodal load of the mesh scales with the element length
NOT_CONVERGING = ("inertia_load",)


def _flexible(case: dict) -> list[dict]:
    return [ln for ln in case["links"] if not ln.get("rigid")]


def probe_elements(case: dict, coarser: bool = True) -> tuple[dict, float]:
    """({link: elements}, r) of the probe mesh: every flexible link with half its elements when all have
    an even number and ``coarser`` (r = 2, the ratio of element lengths), else twice as many (r = 1/2;
    the probe then costs twice as much per step)."""
    links = _flexible(case)
    if coarser and links and all(ln["elements"] % 2 == 0 for ln in links):
        return {ln["name"]: ln["elements"] // 2 for ln in links}, 2.0
    return {ln["name"]: 2 * ln["elements"] for ln in links}, 0.5


def remesh(case: dict, elements: dict) -> Case:
    """A copy of the resolved ``case`` whose flexible links have ``elements`` ({link: count}), and
    without the outputs that have no mesh limit (a probe run does not evaluate them)."""
    out = Case(copy.deepcopy(dict(case)))
    out["outputs"] = {n: sp for n, sp in out["outputs"].items() if sp["kind"] not in NOT_CONVERGING}
    for ln in out["links"]:
        if ln["name"] in elements:
            ln["elements"] = int(elements[ln["name"]])
    counts = set(elements.values())
    if len(counts) == 1:
        out["mesh"]["elements_per_link"] = counts.pop()
    return out


def spatial_error(difference: float, ratio: float, order: float = MESH_ORDER) -> float:
    """|A h^p| from the largest difference between the run and the probe with element lengths r h."""
    return abs(difference) / abs(1.0 - ratio ** order)


def elements_for(elements: int, relative: float, tolerance: float, order: float = MESH_ORDER) -> int:
    """Elements per link that bring a spatial error ``relative`` at ``elements`` to half the tolerance
    (the mesh should not use up the whole budget), an even number."""
    n = elements * (2.0 * relative / tolerance) ** (1.0 / order)
    return max(elements + 2, 2 * math.ceil(n / 2.0))
