"""Materials of links: a small table of published values, or the user's own.

A link's ``material`` is a name from :data:`MATERIALS` (``material = "6061-T6"``) or a table of
values (``material = {youngs_modulus = 2.0e11, density = 7850, ...}``; ``name`` in the table starts
from that entry and the other keys replace its values).  The table's sources are listed in
docs/cases.md ("Materials"); they are typical handbook values, not design allowables.

S-N curve (stress amplitude S_a [Pa] at zero mean stress against cycles N to failure), Basquin's
form ``S_a = basquin_coefficient * N ** basquin_exponent`` above ``endurance_limit`` (0: none; the
curve goes on).  For the named materials the line is drawn, as Budynas and Nisbett (Shigley's
Mechanical Engineering Design, section 6-7) draw it, through ``0.9 S_u`` at 10^3 cycles and the
published fatigue strength ``S_f`` at ``fatigue_cycles``; steel and Ti-6Al-4V have an endurance
limit there, the aluminium alloys none (their S_f is the strength at 5e8 cycles and the line is
continued below it).
"""

from __future__ import annotations

import math

from ..base import validate as v
from ..base.errors import CaseError

__all__ = ["MATERIALS", "MATERIAL_KEYS", "material_values", "basquin_through", "LOW_CYCLE_FRACTION"]

#: Shigley's fraction f of the ultimate strength at 10^3 cycles (Budynas-Nisbett Fig. 6-18, S_u < 490 MPa: 0.9)
LOW_CYCLE_FRACTION = 0.9
LOW_CYCLES = 1.0e3


def basquin_through(ultimate: float, fatigue_strength: float, cycles: float) -> tuple[float, float]:
    """(coefficient [Pa], exponent) of S_a = a N^b through (10^3, 0.9 S_u) and (cycles, S_f)."""
    b = math.log10(fatigue_strength / (LOW_CYCLE_FRACTION * ultimate)) / math.log10(cycles / LOW_CYCLES)
    return LOW_CYCLE_FRACTION * ultimate / LOW_CYCLES ** b, b


def _entry(e, rho, sy, su, sf, nf, endurance: bool, source: str) -> dict:
    a, b = basquin_through(su, sf, nf)
    return {"youngs_modulus": e, "density": rho, "yield_strength": sy, "ultimate_strength": su,
            "fatigue_strength": sf, "fatigue_cycles": nf, "endurance_limit": sf if endurance else 0.0,
            "basquin_coefficient": a, "basquin_exponent": b, "source": source}


#: name -> values [SI]; the sources are in docs/cases.md ("Materials")
MATERIALS = {
    "structural-steel": _entry(210e9, 7850.0, 355e6, 470e6, 235e6, 1e6, True,
                               "EN 10025-2 S355 (t <= 16 mm, minimum yield and tensile strength), E and density "
                               "EN 1993-1-1 3.2.6; endurance limit 0.5 S_u (Budynas-Nisbett eq. 6-8)"),
    "6061-T6": _entry(68.9e9, 2700.0, 276e6, 310e6, 96.5e6, 5e8, False,
                      "ASM Handbook Vol. 2 (typical values; fatigue strength at 5e8 cycles, R.R. Moore)"),
    "7075-T6": _entry(71.7e9, 2810.0, 503e6, 572e6, 159e6, 5e8, False,
                      "ASM Handbook Vol. 2 (typical values; fatigue strength at 5e8 cycles, R.R. Moore)"),
    "2024-T3": _entry(73.1e9, 2780.0, 345e6, 483e6, 138e6, 5e8, False,
                      "ASM Handbook Vol. 2 (typical values; fatigue strength at 5e8 cycles, R.R. Moore)"),
    "Ti-6Al-4V": _entry(113.8e9, 4430.0, 880e6, 950e6, 510e6, 1e7, True,
                        "ASM Materials Properties Handbook: Titanium Alloys (1994), annealed, typical values; "
                        "unnotched fatigue limit at 1e7 cycles"),
}
#: the keys of a material table (``name`` picks an entry of MATERIALS to start from)
MATERIAL_KEYS = ("name", "youngs_modulus", "density", "yield_strength", "ultimate_strength", "endurance_limit",
                 "basquin_coefficient", "basquin_exponent")
_REQUIRED = ("youngs_modulus", "density")


def _named(name, where: str) -> dict:
    if not isinstance(name, str) or name not in MATERIALS:
        raise CaseError(where, f"unknown material {name!r}; materials are {', '.join(MATERIALS)}, or give a table "
                               "of values {youngs_modulus = ..., density = ..., yield_strength = ...}")
    return {"name": name, **MATERIALS[name]}


def material_values(spec, where: str) -> dict:
    """The resolved material table of a link's ``material`` (a name or a table) at ``where``."""
    if isinstance(spec, str):
        return _named(spec, where)
    if not isinstance(spec, dict):
        raise CaseError(where, f"must be a material name ({', '.join(MATERIALS)}) or a table of values; got {spec!r}")
    v.keys(spec, set(MATERIAL_KEYS), where)
    out = _named(spec["name"], f"{where}.name") if "name" in spec else {}
    given = {k: v.num(spec, k, where, nonneg=k == "endurance_limit", positive=k not in
                      ("endurance_limit", "basquin_exponent")) for k in MATERIAL_KEYS[1:] if k in spec}
    out.update(given)
    if given and "name" in out:
        out.pop("source", None)
        out["name"] = f"{out['name']} (modified)"
    for key in _REQUIRED:
        if key not in out:
            raise CaseError(f"{where}.{key}", "is missing; add it, or start from a named material with name = "
                                              f"'{next(iter(MATERIALS))}'")
    _check(out, where)
    return out


def _check(m: dict, where: str) -> None:
    """Values that contradict each other: yield above ultimate, a rising S-N line, half a Basquin pair."""
    if "yield_strength" in m and "ultimate_strength" in m and m["yield_strength"] > m["ultimate_strength"]:
        raise CaseError(f"{where}.yield_strength", f"({m['yield_strength']:g} Pa) exceeds ultimate_strength "
                                                   f"({m['ultimate_strength']:g} Pa); give yield <= ultimate")
    if ("basquin_coefficient" in m) != ("basquin_exponent" in m):
        missing = "basquin_exponent" if "basquin_coefficient" in m else "basquin_coefficient"
        raise CaseError(f"{where}.{missing}", "is missing; the S-N line S_a = basquin_coefficient * N^basquin_exponent "
                                              "needs both")
    if m.get("basquin_exponent", -1.0) >= 0.0:
        raise CaseError(f"{where}.basquin_exponent", f"must be < 0 (the amplitude falls with the cycles), got "
                                                     f"{m['basquin_exponent']}; typical metals: -0.05 to -0.15")
