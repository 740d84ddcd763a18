"""Checks of single values in user input (case files, ``--set`` overrides, Python dicts).

Every failure is a :class:`~flexmech_py.base.errors.CaseError` naming the field (``where.key``) and the
fix.  The lowest layer of the input handling: the mechanism schema and the case schema use it.
"""

from __future__ import annotations

import math
import re

from .errors import CaseError

__all__ = ["num", "whole", "text", "vector", "keys", "identifier", "NAME"]

NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def num(d: dict, key: str, where: str, *, default=None, positive=False, nonneg=False, required=False):
    """A finite number ``d[key]`` (float), or ``default`` when absent."""
    if key not in d:
        if required:
            raise CaseError(f"{where}.{key}", "is missing; add it (a number in SI units)")
        return default
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise CaseError(f"{where}.{key}", f"must be a number, got {v!r}")
    v = float(v)
    if not math.isfinite(v):
        raise CaseError(f"{where}.{key}", f"must be finite, got {v!r}")
    if positive and v <= 0:
        raise CaseError(f"{where}.{key}", f"must be > 0, got {v!r}")
    if nonneg and v < 0:
        raise CaseError(f"{where}.{key}", f"must be >= 0, got {v!r}")
    return v


def whole(d: dict, key: str, where: str, *, default=None, minimum=1):
    """A whole number ``d[key]`` >= minimum, or ``default`` when absent."""
    if key not in d:
        return default
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, int) and not (isinstance(v, float) and v.is_integer()):
        raise CaseError(f"{where}.{key}", f"must be a whole number, got {v!r}")
    v = int(v)
    if v < minimum:
        raise CaseError(f"{where}.{key}", f"must be >= {minimum}, got {v}")
    return v


def text(d: dict, key: str, where: str, *, default=None, choices=None, required=False):
    """A string ``d[key]`` (one of ``choices`` when given), or ``default`` when absent."""
    if key not in d:
        if required:
            hint = f" (one of {', '.join(map(repr, choices))})" if choices else ""
            raise CaseError(f"{where}.{key}", f"is missing; add it{hint}")
        return default
    v = d[key]
    if not isinstance(v, str):
        raise CaseError(f"{where}.{key}", f"must be a string, got {v!r}")
    if choices is not None and v not in choices:
        raise CaseError(f"{where}.{key}", f"must be one of {', '.join(map(repr, choices))}, got {v!r}")
    return v


def vector(d: dict, key: str, where: str, n: int, *, default=None, nonneg=False):
    """A list of ``n`` finite numbers ``d[key]``, or ``default`` when absent."""
    if key not in d:
        return default
    v = d[key]
    if not isinstance(v, (list, tuple)) or len(v) != n:
        raise CaseError(f"{where}.{key}", f"must be a list of {n} numbers, got {v!r}")
    return [num({"x": x}, "x", f"{where}.{key}", nonneg=nonneg) for x in v]


def keys(d, allowed, where: str) -> None:
    """``d`` is a table whose keys are all in ``allowed``."""
    if not isinstance(d, dict):
        raise CaseError(where, f"must be a table, got {d!r}")
    for k in d:
        if k not in allowed:
            raise CaseError(f"{where}.{k}", f"unknown key; allowed keys here: {', '.join(sorted(allowed))}")


def identifier(d: dict, key: str, where: str, taken=None) -> str:
    """A required name (letters, digits, _) not yet in ``taken``."""
    name = text(d, key, where, required=True)
    if not NAME.match(name):
        raise CaseError(f"{where}.{key}", f"must be an identifier (letters, digits, _), got {name!r}")
    if taken is not None and name in taken:
        raise CaseError(f"{where}.{key}", f"duplicate name {name!r}; give each its own name")
    return name
