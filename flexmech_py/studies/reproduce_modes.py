"""The part of ``flexmech reproduce`` that looks at the seed mechanisms rather than at their curves:
the frozen natural frequencies along the motion (the four-bar over one crank cycle at constant
speed, the manipulator over its run) with the drive speed harmonics, and one drawing per seed case
(the deformed mechanism at six instants of the ``hac`` run reproduce made, deflection magnified)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..case import load_case
from ..figures.drawing import plot_along
from .modes import frequencies_along
from ..figures.drawing import draw_frames
from ..models.shapes import ShapeCollector

__all__ = ["modes_section"]

#: (seed case, positions along the motion)
ALONG = (("fourbar_constant_speed", 72), ("manipulator_bricout", 48))
#: panels of each seed case's drawing, and the model drawn (the seed's case I)
PANELS, DRAWN_MODEL = 6, "hac"


def modes_section(out: Path, case_path, runs: dict, say) -> list[str]:
    """Write frequencies_along CSV/JSON/PNG and one drawing per seed case under ``out``; returns the
    report's lines.  ``case_path(name)`` locates a seed case; ``runs``: {seed case: {model: Result}},
    the runs reproduce made (each drawing is from its ``hac`` run)."""
    lines = ["", "## Natural frequencies along the motion, and the mechanisms drawn", "",
             "The lowest elastic natural frequencies of the mechanism frozen at positions of its rigid motion "
             "(`flexmech modes --along-cycle`, docs/theory.md §20), each mode's band and where a frequency meets a "
             "harmonic kΩ/2π of the drive speed (a resonance crossing); then each seed case drawn at "
             f"{PANELS} instants of its `{DRAWN_MODEL}` run, the elastic deflection magnified by the factor printed "
             "under it (`flexmech run CASE --draw`).  Regenerate: `flexmech reproduce`.", ""]
    for name, positions in ALONG:
        lines += _frequencies(out, load_case(case_path(name)), name, positions, say)
    for name, by_model in runs.items():
        lines += _drawing(out, by_model[DRAWN_MODEL], name, say)
    return lines


def _frequencies(out: Path, case, name: str, positions: int, say) -> list[str]:

    t0 = time.perf_counter()
    al = frequencies_along(case, positions, count=3)
    al.write(out / "modes" / name)
    png = plot_along(out / f"{name}_frequencies_along.png", al)
    say(f"{name}: frequencies at {positions} positions in {time.perf_counter() - t0:.2f} s")
    cross, turns = al.crossings(), bool(al.harmonics())
    rows = ["| mode | min [Hz] | max [Hz] | crossings with kΩ/2π |", "|---|---|---|---|"]
    for k in range(al.hz.shape[1]):
        ks = sorted({c["harmonic"] for c in cross if c["mode"] == k + 1})
        met = ", ".join(f"k = {h}" for h in ks) if ks else ("none" if turns else "–")
        rows.append(f"| {k + 1} | {np.min(al.hz[:, k]):.4g} | {np.max(al.hz[:, k]):.4g} | {met} |")
    if not turns:   # a swinging joint: its speed's harmonics force nothing periodic (Along.harmonics)
        rows += ["", f"No speed harmonics: {al.joint or 'the drive joint'} turns less than a revolution over the run."]
    img = [f"![{name} frequencies along the motion]({png.name})", ""] if png else []
    return [f"### {case['case']['title']} (model {al.model}, {positions} positions over {al.span})", "", *rows, "",
            *img, f"Files: `modes/{name}/frequencies_along.csv`, `.json`.", ""]


def _drawing(out: Path, res, name: str, say) -> list[str]:
    """The drawing of a seed case from its run ``res`` (a Result kept in memory)."""

    t0 = time.perf_counter()
    case = res.case
    shapes = ShapeCollector(case.mechanism, res.t.size, PANELS)
    shapes.add(res)
    sf = shapes.result()
    png, scale = draw_frames(out / f"{name}_drawing.png", sf, case.mechanism, np.arange(sf.key.size),
                             title=f"{case['case']['title']} - model {res.model}")
    say(f"{name}: drawn at {sf.key.size} instants in {time.perf_counter() - t0:.2f} s")
    if png is None:
        return []
    return [f"### {case['case']['title']}: the deformed mechanism, deflection × {scale:g}", "",
            f"![{name} drawn]({png.name})", ""]
