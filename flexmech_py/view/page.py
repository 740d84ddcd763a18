"""The page itself: the template with its style, its script and the result's data put inside, so
that the one HTML file needs nothing else (docs/cli.md, ``flexmech view``), and where it goes."""

from __future__ import annotations

import html
import json
import re
from importlib import resources
from pathlib import Path

from ..base.errors import FlexmechError

__all__ = ["render", "target", "PARTS", "SCRIPTS"]

#: the script of the page, in the order its parts run (one function scope; each file < 600 lines)
SCRIPTS = ("view_core.js", "view_mechanism.js", "view_pages.js")
#: the files of the page, installed with the package (flexmech_py/meson.build)
PARTS = ("template.html", "view.css") + SCRIPTS
SUFFIXES = (".html", ".htm")


def _part(name: str) -> str:
    return resources.files(__package__).joinpath(name).read_text(encoding="utf-8")


def render(data: dict, generator: str) -> str:
    """The HTML page of ``data`` (a payload of flexmech_py.view.*_data): the JSON inside a script
    element of type application/json, every ``<`` escaped so that no text of a result ends it."""
    blob = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("<", "\\u003c")
    parts = {"TITLE": html.escape(f"{data.get('title') or 'flexmech'} - flexmech view"),
             "GENERATOR": html.escape(generator), "CSS": _part("view.css"), "DATA": blob,
             "JS": "\n".join(_part(s) for s in SCRIPTS)}
    # one pass: a result's text that happens to read __JS__ is not a place to fill
    return re.sub(r"__(TITLE|GENERATOR|CSS|DATA|JS)__", lambda m: parts[m.group(1)], _part("template.html"))


def target(out, folder: Path) -> Path:
    """The file to write: ``out`` (a folder: view.html inside it), else folder/view.html; FlexmechError
    naming --out for a name that is not .html or a folder that does not exist."""
    if out is None:
        return folder / "view.html"
    path = Path(out)
    if not str(out).strip():
        raise FlexmechError("--out: is empty; give a file name ending in .html (or leave it out)")
    if path.is_dir():
        return path / "view.html"
    if path.suffix.lower() not in SUFFIXES:
        raise FlexmechError(f"--out: {str(path)!r} ends in {path.suffix or 'no suffix'!r}; give a .html file")
    if not path.parent.is_dir():
        raise FlexmechError(f"--out: the folder {str(path.parent)!r} does not exist; create it or choose another --out")
    return path
