"""Unstable regions of a Floquet stability chart (``flexmech stability``), from its rows alone.

- :func:`multiplier_type`: what the dominant multiplier is — real and positive (it left the unit
  circle at +1), real and negative (at -1: period doubling, e.g. the principal parametric
  resonance 2 omega = Omega) or one of a complex pair (off the circle at exp(+-i theta): a
  combination resonance of two modes).  Read from the multiplier itself, not from a frequency formula.
- :func:`refinement_speeds`: the speeds a further round of the chart computes: the midpoint of
  every interval whose ends disagree (stable/unstable, or two unstable speeds whose dominant
  multipliers are of different types), and of both intervals beside an interior extremum of
  ln|mu| on the wrong side of the verdict (a stable local maximum that may hide a narrow unstable
  pocket, an unstable local minimum that may hide a stable gap), while the interval is wider than
  the resolution.
- :func:`unstable_regions`: runs of consecutive unstable speeds, each split into parts of one
  multiplier type, with the stable speeds that bracket it; :func:`describe_region` one line of text.

Rows are the dicts of :func:`flexmech_py.studies.floquet.stability_chart` (``speed``, ``max_abs_mu``,
``growth_rate``, ``stable``, ``mu_re``, ``mu_im``; rows with ``error`` are skipped).
"""

from __future__ import annotations

import math

import numpy as np

from ..base.fileio import atomic_write

__all__ = ["multiplier_type", "TYPE_TEXT", "PEAK_PROMINENCE", "REAL_TOLERANCE", "default_resolution",
           "refinement_speeds", "unstable_regions", "describe_region", "write_regions_csv"]

#: |Im mu| / |mu| below which a multiplier is real (LAPACK returns an exact 0 for a real eigenvalue)
REAL_TOLERANCE = 1e-8
#: an interior extremum of ln|mu| (per period) is refined when it stands out from both neighbours by more
#: than this: ten times the O(dt^2) defect of the undamped map on the seed four-bar (1e-4 per period)
PEAK_PROMINENCE = 1e-3
#: the default resolution is the median spacing of the user's grid over this
RESOLUTION_DIVISOR = 16

TYPE_TEXT = {"real+": "real +1 side", "real-": "real -1 side, period doubling", "complex": "complex pair"}


def multiplier_type(re: float, im: float) -> str:
    """``real+``, ``real-`` or ``complex`` for the multiplier re + i im."""
    if abs(im) <= REAL_TOLERANCE * math.hypot(re, im):
        return "real+" if re > 0 else "real-"
    return "complex"


def default_resolution(speeds) -> float | None:
    """The median spacing of the distinct speeds over RESOLUTION_DIVISOR (None for a single speed)."""
    s = np.unique(np.asarray(speeds, float))
    return float(np.median(np.diff(s))) / RESOLUTION_DIVISOR if s.size > 1 else None


def _chart(rows):
    ok = sorted((r for r in rows if "error" not in r), key=lambda r: r["speed"])
    s = np.array([r["speed"] for r in ok])
    lnmu = np.log(np.array([r["max_abs_mu"] for r in ok])) if ok else np.zeros(0)
    stable = np.array([bool(r["stable"]) for r in ok])
    return ok, s, lnmu, stable


def refinement_speeds(rows, resolution: float) -> list[float]:
    """New speeds for one more round (empty: nothing left to refine at this resolution)."""
    ok, s, lnmu, stable = _chart(rows)
    kinds = [multiplier_type(r["mu_re"], r["mu_im"]) for r in ok]
    new = set()

    def split(i):   # the midpoint of the interval (s[i], s[i + 1]) while it is wider than the resolution
        if 0 <= i < s.size - 1 and s[i + 1] - s[i] > resolution:
            new.add(float(0.5 * (s[i] + s[i + 1])))

    for i in range(s.size - 1):
        if stable[i] != stable[i + 1] or (not stable[i] and kinds[i] != kinds[i + 1]):
            split(i)
    for i in range(1, s.size - 1):
        nb = lnmu[[i - 1, i + 1]]
        if (stable[i] and lnmu[i] - nb.max() > PEAK_PROMINENCE) or \
                (not stable[i] and nb.min() - lnmu[i] > PEAK_PROMINENCE):
            split(i - 1)
            split(i)
    return sorted(new)


def _part(rows) -> dict:
    top = max(rows, key=lambda r: r["max_abs_mu"])
    kind = multiplier_type(top["mu_re"], top["mu_im"])
    part = {"type": kind, "from": rows[0]["speed"], "to": rows[-1]["speed"], "max_abs_mu": top["max_abs_mu"],
            "at": top["speed"], "growth_rate": top["growth_rate"], "samples": len(rows)}
    if kind == "complex":
        ang = [abs(math.degrees(math.atan2(r["mu_im"], r["mu_re"]))) for r in rows]
        part["angle_deg"] = [min(ang), max(ang)]
    return part


def unstable_regions(rows) -> list[dict]:
    """Runs of consecutive unstable speeds: ``from``/``to`` (first and last unstable speed), ``below``/
    ``above`` (the stable speeds bracketing it, None at the end of the chart), ``max_abs_mu``, ``at``,
    ``growth_rate`` (at the largest |mu|) and ``parts``: sub-runs of one multiplier type (``type``,
    ``from``, ``to``, ``max_abs_mu``, ``at``, ``growth_rate``, ``angle_deg`` [min, max] of a complex pair)."""
    ok, s, _, stable = _chart(rows)
    regions, i = [], 0
    while i < len(ok):
        if stable[i]:
            i += 1
            continue
        j = i
        while j + 1 < len(ok) and not stable[j + 1]:
            j += 1
        run = ok[i:j + 1]
        parts, k = [], 0
        while k < len(run):
            kind = multiplier_type(run[k]["mu_re"], run[k]["mu_im"])
            m = k
            while m + 1 < len(run) and multiplier_type(run[m + 1]["mu_re"], run[m + 1]["mu_im"]) == kind:
                m += 1
            parts.append(_part(run[k:m + 1]))
            k = m + 1
        top = max(run, key=lambda r: r["max_abs_mu"])
        regions.append({"from": float(s[i]), "to": float(s[j]), "below": float(s[i - 1]) if i > 0 else None,
                        "above": float(s[j + 1]) if j + 1 < len(ok) else None, "max_abs_mu": top["max_abs_mu"],
                        "at": top["speed"], "growth_rate": top["growth_rate"], "parts": parts})
        i = j + 1
    return regions


def _label(part: dict) -> str:
    if part["type"] == "complex":
        a, b = part["angle_deg"]
        return f"complex pair at +-{a:.0f}{'' if round(a) == round(b) else f'..{b:.0f}'} deg"
    return TYPE_TEXT[part["type"]]


def _span(lo: float, hi: float, f: str) -> str:
    """``lo-hi``, or the one speed when the run has a single sample (never a zero-width ``x-x``)."""
    return f.format(lo) if lo == hi else f"{f.format(lo)}-{f.format(hi)}"


def describe_region(region: dict, digits: int = 1) -> str:
    """One line: the speeds, the largest |mu| and the multiplier type of every part.  A region of one
    unstable sample is said to be one: its width is below the chart's spacing there, between the
    stable speeds that bracket it."""
    f = f"{{:.{digits}f}}"
    lo, hi = region["from"], region["to"]
    below, above = region["below"], region["above"]
    if lo == hi:
        around = [x for x in (below, above) if x is not None]
        where = (f" (one unstable sample: the region is narrower than the spacing there, inside "
                 f"{f.format(below if below is not None else lo)}-{f.format(above if above is not None else hi)})"
                 if around else " (one unstable sample)")
        text = f"{f.format(lo)} rad/s{where}"
    else:
        edges = [x for x in (lo - below if below is not None else None, above - hi if above is not None else None)
                 if x is not None]
        text = f"{_span(lo, hi, f)} rad/s" + (f" (edges within {f.format(max(edges))})" if edges else "")
    text += (f": max |mu| {region['max_abs_mu']:.4g} at {f.format(region['at'])} "
             f"(growth {region['growth_rate']:.3g} 1/s)")
    parts = region["parts"]
    if len(parts) == 1:
        return f"{text}, {_label(parts[0])}"
    return text + "; " + ", ".join(f"{_label(p)} {_span(p['from'], p['to'], f)}" for p in parts)


def write_regions_csv(regions: list, path, header: str = "") -> None:
    """stability_regions.csv: one row per part of every unstable region."""

    names = ["region", "speed_from", "speed_to", "stable_below", "stable_above", "multiplier", "angle_min_deg",
             "angle_max_deg", "max_abs_mu", "at_speed", "growth_rate"]
    units = ["1", "rad/s", "rad/s", "rad/s", "rad/s", "", "deg", "deg", "1", "rad/s", "1/s"]
    lines = [f"# {header}" if header else "# flexmech stability: unstable regions",
             "# units: " + ",".join(units), ",".join(names)]
    for k, reg in enumerate(regions, start=1):
        for p in reg["parts"]:
            ang = p.get("angle_deg", ["", ""])
            cells = [k, p["from"], p["to"], reg["below"], reg["above"], p["type"], ang[0], ang[1], p["max_abs_mu"],
                     p["at"], p["growth_rate"]]
            lines.append(",".join("" if c is None else (f"{c:.10g}" if isinstance(c, float) else str(c)) for c in cells))
    atomic_write(path, "\n".join(lines) + "\n")
