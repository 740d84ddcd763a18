"""Sizes a user asks for, estimated before anything is allocated, and refused when they cannot fit.

A mesh, a run's steps and frames, a sweep's grid points and samples, a stability chart's speeds,
the positions along a cycle, an accuracy ladder: each is counted first, its memory estimated from
what one item costs (measured, constants below), and compared with the memory available
(MEMORY_SHARE of /proc/meminfo's MemAvailable; without it, HARD_LIMIT_BYTES).  A size that does not
fit is one CaseError naming the setting, the estimate and the largest setting that fits -- the way
a run too large for memory or disk is refused (:mod:`flexmech_py.run.runner`).
"""

from __future__ import annotations

import math

from .errors import CaseError
from .families import MODELS, family

__all__ = ["available_memory", "format_bytes", "format_count", "memory_budget", "check_count", "check_mesh",
           "check_elements", "check_points", "check_steps", "mesh_bytes", "MEMORY_SHARE", "MAX_STEPS"]

#: share of the available memory one command may plan to take
MEMORY_SHARE = 0.8
#: the budget when the available memory is not known [bytes]
HARD_LIMIT_BYTES = 2 ** 40
#: steps of one run at most: 2^40 steps take weeks at any speed, and t = i dt stays exact far below 2^53
MAX_STEPS = 2 ** 40
#: memory of the superposition models per element [bytes] (FE arrays, band, frame blocks; measured
#: 1.4 kB per DOF at 6 000-24 000 elements, three DOFs an element)
ELEMENT_BYTES = 4_500


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (Linux /proc/meminfo), or None when unknown."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def format_bytes(n: float) -> str:
    if not math.isfinite(n):
        return "an unbounded amount"
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1000 or unit == "PB":
            return f"{n:.3g} {unit}"
        n /= 1000.0
    return f"{n:.3g} PB"


def format_count(n) -> str:
    """12 345 -> '12,345'; 1e12 -> '1e+12'."""
    n = float(n) if not isinstance(n, int) else n
    if isinstance(n, float) and not math.isfinite(n):
        return "infinitely many"
    return f"{int(n):,}" if abs(n) < 1e7 else f"{float(n):.3g}"


def memory_budget() -> float:
    """Bytes one command may plan to take."""
    avail = available_memory()
    return MEMORY_SHARE * avail if avail is not None else float(HARD_LIMIT_BYTES)


def check_count(count, item_bytes: float, field: str, what: str, fix, fixed_bytes: float = 0.0) -> None:
    """Refuse ``count`` items of ``item_bytes`` each (plus ``fixed_bytes``) that do not fit in memory.
    ``what``: the items, plural (e.g. "grid points"); ``fix(n)``: the words of the setting that fits,
    given the largest count ``n`` that does."""
    budget = memory_budget()
    need = fixed_bytes + float(count) * item_bytes
    if need <= budget:
        return
    fits = max(0, int((budget - fixed_bytes) // max(item_bytes, 1.0)))
    raise CaseError(field, f"{format_count(count)} {what} take about {format_bytes(need)} of memory "
                           f"({format_bytes(item_bytes)} each) and {format_bytes(budget / MEMORY_SHARE)} is available: "
                           f"{fix(fits)}")


#: memory of one point of a batch [bytes] (a sweep's grid point or sample, a chart's speed): its task,
#: its result row, its cache entry's path (about 2.5 kB measured for the seed cases' outputs)
POINT_BYTES = 4_000


def check_points(n: int, field: str, fix) -> None:
    """Refuse a batch of ``n`` points (grid points, samples, speeds) whose bookkeeping would not fit in
    memory, before any list of them is made."""
    check_count(n, POINT_BYTES, field, "points", fix)


def _elements(case) -> int:
    return sum(int(ln.get("elements", 0)) for ln in case["links"] if not ln.get("rigid"))


def _dof2_bytes(model: str | None) -> int:
    """A family's set-up and run memory per squared DOF count (Family.dof2_bytes; measured: coupled
    17-31 B per ndof^2 at 9 000-72 000 DOFs), 0 for none or an unknown name."""
    return family(model).dof2_bytes if model in MODELS else 0


def _element_bytes(model: str | None) -> int:
    """A family's memory per element (Family.element_bytes; measured: nonlinear 7.7-8.7 kB per element
    at 3 000-6 000 elements, linear in the mesh), else ELEMENT_BYTES (the superposition models)."""
    own = family(model).element_bytes if model in MODELS else 0
    return own or ELEMENT_BYTES


def mesh_bytes(elements: int, model: str | None = None) -> float:
    """Estimated memory [bytes] of a mesh of ``elements`` elements in ``model`` (None: the cheapest)."""
    ndof = 3.0 * elements
    return _element_bytes(model) * float(elements) + _dof2_bytes(model) * ndof * ndof


def check_mesh(case, model: str | None = None, field: str = "mesh.elements_per_link") -> None:
    """Refuse a mesh (every flexible link's ``elements``) whose model would not fit in memory."""
    links = sum(1 for ln in case["links"] if not ln.get("rigid"))
    check_elements(_elements(case), links, model, field)


def check_elements(n: int, links: int, model: str | None = None, field: str = "mesh.elements_per_link") -> None:
    """Refuse ``n`` elements over ``links`` flexible links whose ``model`` (None: the cheapest) would not
    fit in memory; the message gives the largest power of two of elements per link that fits."""
    need, budget = mesh_bytes(n, model), memory_budget()
    if need <= budget:
        return
    links = max(1, links)
    per_link = 1
    while mesh_bytes(2 * per_link * links, model) <= budget:
        per_link *= 2
    kind = f"the {model} model of " if _dof2_bytes(model) or model in MODELS and family(model).element_bytes else ""
    example = f"{field} {per_link}" if field.startswith("--") else f"--set {field}={per_link}"
    raise CaseError(field, f"{kind}a mesh of {format_count(n)} elements takes about {format_bytes(need)} of memory and "
                           f"{format_bytes(budget / MEMORY_SHARE)} is available: use at most about "
                           f"{format_count(per_link)} elements per link (e.g. {example})")


def check_steps(nsteps: int, t_end: float, dt: float) -> None:
    """Refuse a run of more than MAX_STEPS steps (t_end / dt)."""
    if nsteps <= MAX_STEPS:
        return
    raise CaseError("solver.dt", f"the run has {format_count(nsteps)} steps (t_end {t_end:g} s / dt {dt:g} s), more than "
                                 f"the {format_count(MAX_STEPS)} one run can take: raise solver.dt to at least "
                                 f"{t_end / MAX_STEPS:.3g} s, or shorten solver.t_end")
