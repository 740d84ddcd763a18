"""The page itself: the template with its style, its script and the result's data put inside, so
that the one HTML file needs nothing else (docs/cli.md, ``flexmech view``), and where it goes."""

from __future__ import annotations

import html
import json
from importlib import resources
from pathlib import Path

from ..errors import FlexmechError

__all__ = ["render", "target", "PARTS"]

#: the files of the page, installed with the package (flexmech_py/meson.build)
PARTS = ("template.html", "view.css", "view.js")
SUFFIXES = (".html", ".htm")


def _part(name: str) -> str:
    return resources.files(__package__).joinpath(name).read_text(encoding="utf-8")


def render(data: dict, generator: str) -> str:
    """The HTML page of ``data`` (a payload of flexmech_py.view.*_data): the JSON inside a script
    element of type application/json, every ``<`` escaped so that no text of a result ends it."""
    blob = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("<", "\\u003c")
    page = _part("template.html")
    for mark, text in (("__TITLE__", html.escape(f"{data.get('title') or 'flexmech'} - flexmech view")),
                       ("__GENERATOR__", html.escape(generator)), ("__CSS__", _part("view.css")),
                       ("__DATA__", blob), ("__JS__", _part("view.js"))):
        page = page.replace(mark, text, 1)
    return page


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
