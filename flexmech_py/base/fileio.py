"""Files written whole or not at all, and the JSON encoding of numpy values (a leaf module)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

__all__ = ["atomic_write", "json_default", "csv_cell"]


def json_default(o):
    """``json.dumps(default=...)``: numpy scalars and arrays as Python numbers and lists."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o))


def atomic_write(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` whole or not at all (a temporary file renamed); an OSError names ``path``."""
    path = Path(path)
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except BaseException as exc:
        tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise OSError(exc.errno, exc.strerror, str(path)) from None
        raise


def csv_cell(v) -> str:
    """A CSV cell: booleans as true/false, floats to 10 digits, text quoted when it holds a comma, a
    quote or a line break (its quotes made single)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:.10g}"
    s = str(v)
    return '"' + s.replace('"', "'") + '"' if ("," in s or '"' in s or "\n" in s) else s
