"""The physical scale of an output column, and which columns are negligible against it: zero by
construction or tiny against their scale (the y of a pin that moves on the x axis, 1e-17 m on a
0.3 m mechanism).  A negligible column is never the "worst column" of an error estimate: its
relative error is round-off over round-off (docs/stability.md "Error estimate").

Scales: a length (unit m) against the mechanism's size (its largest distance between points), an
angle (rad) against one radian, any other unit against the largest peak of the columns in the same
unit (a column alone in its unit is negligible only when it is zero).
"""

from __future__ import annotations

import math

__all__ = ["TINY", "column_scales", "negligible"]

#: a column whose largest |value| is at most TINY times its scale is negligible (rigid-motion
#: tolerances put noise at about 1e-12 of the size; elastic outputs are far above 1e-9)
TINY = 1e-9


def column_scales(case, units: dict, peaks: dict) -> dict:
    """{column: scale} in the column's unit (see the module's docstring)."""
    by_unit: dict = {}
    for name, pk in peaks.items():
        if math.isfinite(pk):
            by_unit[units.get(name, "")] = max(by_unit.get(units.get(name, ""), 0.0), pk)
    size = case.mechanism.characteristic_length()
    out = {}
    for name in peaks:
        unit = units.get(name, "")
        out[name] = size if unit == "m" else 1.0 if unit == "rad" else by_unit.get(unit, 0.0)
    return out


def negligible(case, units: dict, peaks: dict) -> dict:
    """{column: why it is negligible} for the columns that are (the others are left out)."""
    scales = column_scales(case, units, peaks)
    out = {}
    for name, pk in peaks.items():
        if not math.isfinite(pk):
            continue
        unit = units.get(name, "")
        if pk == 0.0:
            out[name] = "zero at every frame"
        elif pk <= TINY * scales[name]:
            against = ("the mechanism's size" if unit == "m" else "1 rad" if unit == "rad"
                       else f"the largest output in {unit or 'the same unit'}")
            out[name] = f"its peak {pk:.3g} {unit} is below {TINY:g} of {against} ({scales[name]:.3g} {unit})"
    return out
