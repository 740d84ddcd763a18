"""Writing case files: a small TOML serializer for the tables flexmech reads (reading uses the
standard library's ``tomllib``).

Top-level scalars first, then tables, then arrays of tables; a table nested in a table whose values
are all scalars or lists (points, ground points, outputs) is written inline.  Floats are written with
``repr`` (shortest round-trip form), so a case written and read back is the same case.
"""

from __future__ import annotations

import json
import math

__all__ = ["dumps_toml"]


def dumps_toml(tables: dict) -> str:
    lines = []
    scalars = {k: val for k, val in tables.items() if not _is_table(val) and not _is_table_array(val)}
    for k, val in scalars.items():
        lines.append(f"{_key(k)} = {_value(val)}")
    for k, val in tables.items():
        if _is_table(val):
            lines += ["", f"[{_key(k)}]"] + _table_body(val)
    for k, val in tables.items():
        if _is_table_array(val):
            for item in val:
                lines += ["", f"[[{_key(k)}]]"] + _table_body(item)
    return "\n".join(lines).lstrip("\n") + "\n"


def _table_body(d: dict) -> list[str]:
    return [f"{_key(k)} = {_value(val)}" for k, val in d.items() if val is not None]


def _is_table(val) -> bool:
    return isinstance(val, dict)


def _is_table_array(val) -> bool:
    return isinstance(val, list) and bool(val) and all(isinstance(x, dict) for x in val)


def _key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() and k.isascii() else json.dumps(k)


def _value(val) -> str:
    if isinstance(val, bool):
        return "true" if val else "false"
    if isinstance(val, int):
        return str(val)
    if isinstance(val, float):
        if math.isnan(val):
            return "nan"
        if math.isinf(val):
            return "inf" if val > 0 else "-inf"
        return repr(val)
    if isinstance(val, str):
        return json.dumps(val)
    if isinstance(val, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in val) + "]"
    if isinstance(val, dict):
        return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in val.items() if x is not None) + "}"
    if hasattr(val, "item"):           # NumPy scalars
        return _value(val.item())
    raise TypeError(f"cannot write {type(val).__name__} to TOML")
