"""The case files that come with flexmech (the source tree's ``cases/``, installed as
``flexmech_py/cases``), reachable by name from any folder.

- :func:`case_path`: ``"fourbar_hac"``, ``"fourbar_hac.toml"``, ``"cases/fourbar_hac.toml"`` or
  ``"extreme/spinup_beam"`` -> the installed file's :class:`~pathlib.Path`.
- :func:`case_names`: every bundled case, as :func:`case_path` accepts it.
- :func:`resolve_case_path`: what ``load_case`` opens: the path itself when it is a file (or is
  absolute), else the bundled case of that name, so ``load_case("cases/fourbar_hac.toml")`` works
  from the repository root (the source file) and from any other folder (the installed copy).
"""

from __future__ import annotations

from pathlib import Path

from .errors import CaseError

__all__ = ["cases_dir", "case_names", "case_path", "resolve_case_path"]


def cases_dir() -> Path:
    """The folder of the bundled cases: the installed ``flexmech_py/cases``, else the source tree's."""
    here = Path(__file__).resolve().parents[1]   # the package's folder
    for cand in (here / "cases", here.parent / "cases"):
        if cand.is_dir():
            return cand
    return here / "cases"


def case_names() -> list[str]:
    """Names of the bundled cases (``fourbar_hac``, ``extreme/spinup_beam``, ...), sorted."""
    root = cases_dir()
    return sorted(p.relative_to(root).with_suffix("").as_posix() for p in root.rglob("*.toml"))


def _name(text: str) -> str:
    name = Path(text).as_posix()
    if name.startswith("./"):
        name = name[2:]
    if name.startswith("cases/"):
        name = name[len("cases/"):]
    return name[:-len(".toml")] if name.endswith(".toml") else name


def case_path(name: str) -> Path:
    """The installed file of a bundled case; CaseError naming the bundled cases when there is none."""
    path = cases_dir() / f"{_name(str(name))}.toml"
    if not path.is_file():
        raise CaseError("case file", f"{name!r} is not a bundled case; bundled: {', '.join(case_names())}")
    return path


def resolve_case_path(path) -> Path:
    """``path`` when it is a file or absolute; else the bundled case of that name, if there is one; else
    ``path`` unchanged (the reader then says it does not exist)."""
    p = Path(path)
    try:
        if p.is_absolute() or p.is_file() or ".." in p.parts:
            return p
        cand = cases_dir() / f"{_name(str(path))}.toml"
        return cand if cand.is_file() else p
    except OSError:                       # a name too long, ...: the reader says what is wrong
        return p
