"""Which result a folder holds, for ``flexmech view``: a run (``summary.json`` and
``timeseries.csv`` of ``flexmech run``, with the shapes of ``run --view`` or ``--draw`` in
``shape.csv``), a ``flexmech modes`` result (``modes.json``, ``mode_shapes.csv``, and
``frequencies_along.*`` with ``--along-cycle``) or a ``flexmech stability`` chart
(``stability.csv``).  Anything else is refused with one line naming the folder and what would make
it viewable."""

from __future__ import annotations

import json
from pathlib import Path

from ..base.errors import FlexmechError

__all__ = ["kind_of", "read_json", "need"]

MAKERS = "a folder written by flexmech run --view (or --draw), flexmech modes or flexmech stability"


def kind_of(folder) -> str:
    """``run``, ``modes`` or ``stability``: what the result folder holds; FlexmechError otherwise."""
    folder = Path(folder)
    if not folder.exists():
        raise FlexmechError(f"{folder}: no such folder; give {MAKERS}")
    if not folder.is_dir():
        raise FlexmechError(f"{folder}: is a file, not a result folder; give {MAKERS}")
    if (folder / "modes.json").is_file() or (folder / "frequencies_along.json").is_file():
        return "modes"
    if (folder / "stability.csv").is_file():
        return "stability"
    if (folder / "summary.json").is_file():
        return "run"
    raise FlexmechError(f"{folder}: not a flexmech result (no summary.json, modes.json or stability.csv); give {MAKERS}")


def read_json(path: Path, what: str) -> dict:
    """The JSON object in ``path``; FlexmechError naming the file when it cannot be read as ``what``."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise FlexmechError(f"{path}: cannot be read as {what} ({getattr(exc, 'strerror', None) or exc})") from None
    if not isinstance(data, dict):
        raise FlexmechError(f"{path}: cannot be read as {what} (not a JSON object)")
    return data


def need(path: Path, fix: str) -> Path:
    """``path`` when it is a file; else FlexmechError saying it is missing and ``fix``."""
    if not path.is_file():
        raise FlexmechError(f"{path.parent}: no {path.name} there; {fix}")
    return path
