"""The output folder of ``flexmech run``: what a new run replaces there, and what it refuses.

A run lists the files it wrote in its summary.json (``files``).  A new run of the *same case file*
into that folder replaces them all, so no figure of the old run stays beside the new CSV (a
result written before the list existed: the names a run writes).  A folder holding the results of
another case, or run files of unknown origin (a killed run's ``timeseries.csv.part``, a CSV with no
summary), is refused unless ``overwrite``; other files in the folder are never touched.
"""

from __future__ import annotations

import json
from pathlib import Path

from .errors import CaseError

__all__ = ["claim", "RUN_FILES"]

#: the names a run writes (the plots are listed by the run itself)
RUN_FILES = ("timeseries.csv", "timeseries.csv.part", "summary.json", "timeseries.png",
             "strain_vs_crank_angle.png", "shape.csv", "drawing.png")


def _identity(case) -> str:
    c = case["case"]
    return str(c.get("path") or c.get("title", ""))


def claim(out_dir, case, overwrite: bool = False) -> list[Path]:
    """The files of an earlier run in ``out_dir`` that a run of ``case`` replaces (to remove when it
    writes its first frame); CaseError naming ``--out`` for a folder holding another run's results,
    unless ``overwrite``."""
    out = Path(out_dir)
    if not out.is_dir():
        if out.exists():
            raise CaseError("--out", f"{out} is a file, not a folder: choose another --out")
        return []
    present = [out / n for n in RUN_FILES if (out / n).exists()]
    summary = out / "summary.json"
    previous = _previous_run(summary) if summary.exists() else None
    if previous is not None:
        listed = [out / n for n in previous.get("files", []) if "/" not in n and (out / n).exists()]
        present = sorted(set(present) | set(listed))
    if not present:
        return []
    if overwrite:
        return present
    if previous is None:
        what = "the unfinished results of a run that was killed" if (out / "timeseries.csv.part").exists() \
            else "results of an unknown run"
        raise CaseError("--out", f"{out} holds {what} ({', '.join(p.name for p in present)}): choose another "
                                 "--out, or add --overwrite to replace them")
    if previous["case"] != _identity(case):
        raise CaseError("--out", f"{out} holds the results of another case ({previous['case']}): choose another "
                                 "--out, or add --overwrite to replace them")
    return present


def _previous_run(summary: Path) -> dict | None:
    """{'case': identity, 'files': [...]} of the run that wrote ``summary``, None when unreadable."""
    try:
        data = json.loads(summary.read_text(encoding="utf-8"))
        return {"case": _identity(data["input"]), "files": list(data.get("files", []))}
    except (OSError, ValueError, KeyError, TypeError):
        return None
