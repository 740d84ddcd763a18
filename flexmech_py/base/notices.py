"""The warnings of a run, from the code that finds them to the user (docs/api.md, warnings).

A run keeps its warnings as text in ``res.extra["warnings"]`` (summary.json, the printed table) and
the kind of each in ``res.extra["warning_kinds"]`` ({message: kind}); :func:`add` records one.  The
Python API issues them as Python warnings of the kind's class (:func:`issue`:
:class:`~flexmech_py.base.errors.ValidityWarning`, ``AccuracyWarning``, ``MechanismWarning``,
``StabilityWarning``; a message recorded without a kind is a plain ``FlexmechWarning``), pointing at
the caller's line outside flexmech.  The command line prints the same messages itself, once, as
``flexmech: warning: ...`` lines, and silences the Python warnings (:func:`silenced`); so do batches
whose workers report warnings in their results.
"""

from __future__ import annotations

import contextlib
import sys
import warnings
from pathlib import Path

from .errors import AccuracyWarning, FlexmechWarning, MechanismWarning, StabilityWarning, ValidityWarning

__all__ = ["add", "kinds_of", "issue", "silenced", "CATEGORIES"]

#: the kind recorded with a message -> the class it is issued as
CATEGORIES = {"validity": ValidityWarning, "accuracy": AccuracyWarning, "mechanism": MechanismWarning,
              "stability": StabilityWarning}
_PACKAGE = Path(__file__).resolve().parents[1]   # the package's folder


def add(extra: dict, message: str, kind: str) -> None:
    """Record a warning ``message`` of ``kind`` (a key of CATEGORIES) in a result's ``extra``."""
    if kind not in CATEGORIES:
        raise ValueError(f"unknown warning kind {kind!r}; one of {', '.join(CATEGORIES)}")
    extra.setdefault("warnings", []).append(message)
    extra.setdefault("warning_kinds", {})[message] = kind


def kinds_of(messages, kind: str) -> dict:
    """{message: kind} for a list of messages of one kind (to merge into ``warning_kinds``)."""
    return {m: kind for m in messages}


def issue(extra: dict) -> None:
    """Issue every warning of a result's ``extra`` as a Python warning of its kind's class, attributed
    to the first caller outside flexmech."""
    kinds = extra.get("warning_kinds", {})
    level = _outside_level()
    for m in extra.get("warnings", []):
        warnings.warn(m, CATEGORIES.get(kinds.get(m), FlexmechWarning), stacklevel=level)


def _outside_level() -> int:
    """The stacklevel of warnings.warn called from :func:`issue` that names the first frame whose code is
    not flexmech's own (the user's line)."""
    frame, level = sys._getframe(1), 1        # level 1: issue() itself
    while frame is not None and _ours(frame.f_code.co_filename):
        frame, level = frame.f_back, level + 1
    return level


def _ours(filename: str) -> bool:
    try:
        return Path(filename).resolve().is_relative_to(_PACKAGE)
    except (OSError, ValueError):
        return False


@contextlib.contextmanager
def silenced():
    """Inside: flexmech's Python warnings are not shown (the command line and batch workers report the
    same messages their own way)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FlexmechWarning)
        yield
