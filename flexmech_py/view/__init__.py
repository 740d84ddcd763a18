"""``flexmech view``: one self-contained HTML page of a result -- the mechanism deforming over time
with its strain along the links, the output curves with a cursor on the time slider, the run's
validity and error marked on the time axis; a ``modes`` result's shapes animated; a stability
chart with hover read-outs (docs/cli.md).  The page is drawn by a small script on canvases
(view.js, view.css, template.html: package data), every byte inside the file: it opens offline,
from any folder, without a server.  Why a script of our own and not a plotting library: the
measurements in docs/cli.md ("flexmech view: how the page is made").

Python::

    from flexmech_py.view import write_view
    info = write_view("results/fourbar_hac-hac")        # results/fourbar_hac-hac/view.html
    info.path, info.bytes, info.kind
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..base.version import __version__
from ..figures.glyphs import table
from .chart_data import stability_payload
from .modes_data import modes_payload
from ..run.outdir import ResultFolder
from .page import render, target
from .run_data import run_payload
from .source import kind_of

__all__ = ["write_view", "page_of", "ViewInfo"]


@dataclass
class ViewInfo:
    """A page written: its ``path``, size in ``bytes``, the result's ``kind`` (run, modes,
    stability) and, for a run, the frames and points it holds."""

    path: Path
    bytes: int
    kind: str
    frames: int | None = None
    points: int | None = None


def page_of(folder) -> tuple[str, dict]:
    """(the HTML page, its data) of the result in ``folder``."""
    folder = Path(folder)
    kind = kind_of(folder)
    data = {"run": run_payload, "modes": modes_payload, "stability": stability_payload}[kind](folder)
    data["glyphs"] = table()
    return render(data, f"flexmech {__version__} view"), data


def write_view(folder, out=None) -> ViewInfo:
    """Write the page of the result in ``folder`` to ``out`` (default folder/view.html; a folder:
    view.html inside it).  FlexmechError (one line, exit code 2) for a folder that is not a result, a
    result without what the page needs, or a file that cannot be written; the page is written whole
    or not at all (flexmech_py.run.outdir.ResultFolder: beside its name, then renamed)."""
    folder = Path(folder)
    path = target(out, folder)
    html, data = page_of(folder)
    with ResultFolder(path, "view", single=True) as rf:
        (rf.stage / path.name).write_text(html, encoding="utf-8")
        rf.commit()
    sh = data.get("shapes") or {}
    return ViewInfo(path, len(html.encode("utf-8")), data["kind"], sh.get("frames"), sh.get("points"))
