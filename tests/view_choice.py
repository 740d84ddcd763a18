"""How the page of ``flexmech view`` is made, measured (docs/cli.md, "flexmech view: how the page is
made"): the same view of a result written two ways -- flexmech's own page (a small script on
canvases, ``flexmech view``) and a plotly figure written by plotly's ``write_html`` with its bundle
inside (the mechanism's links as lines through markers coloured by strain, the curves in subplots,
one plotly frame per kept frame with the cursor as a shape, plotly's slider and play button) --
and both opened in headless Chromium: file size, time from the navigation to the first drawing,
time per slider step over STEPS steps (our page only: see _plotly), JavaScript heap.  Loads alternate between the two pages
(REPEAT pairs, medians); a page that does not answer within the browser driver's 120 s is reported as such.  Needs plotly (``pip install plotly``), selenium and Chromium
(tests/browser.py)::

    .venv/bin/python tests/view_choice.py RESULT [RESULT ...]   # folders of flexmech run --view

A maintained library should win unless it costs too much: this script is the evidence.
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from browser import Browser, missing  # noqa: E402

REPEAT = 2
STEPS = 50


def plotly_page(folder: Path, path: Path) -> Path:
    """The view of a run result as a plotly figure (self-contained: the plotly bundle inside)."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    from flexmech_py.case import Case
    from flexmech_py.figures.drawing import deformed_lines
    from flexmech_py.figures.glyphs import joint_marks
    from flexmech_py.run.results import read_timeseries
    from flexmech_py.models.shapes import read_shape_csv
    from flexmech_py.view import page_of
    from flexmech_py.view.decimate import CURVE_POINTS, thin_frames, thin_stations
    from flexmech_py.view.source import read_json
    from flexmech_py.figures.plots import decimate

    _, data = page_of(folder)
    summary = read_json(folder / "summary.json", "a summary")
    case = Case(summary["input"])
    sf, _ = thin_stations(read_shape_csv(folder / "shape.csv")[0])
    sf = thin_frames(sf)
    scale, field = data["scale"], data["field"]["strain"]
    half = {b["name"]: b["half_depth"] for b in data["bodies"]}
    cols, units = read_timeseries(folder / "timeseries.csv")
    panels = data["curves"]
    fig = make_subplots(rows=len(panels), cols=2, column_widths=[0.5, 0.5], horizontal_spacing=0.08,
                        specs=[[{"rowspan": len(panels)}, {}]] + [[None, {}] for _ in panels[1:]], shared_xaxes=True)
    marks = joint_marks(case.mechanism, sf)

    def mech_traces(i):
        out = []
        for b in sf.bodies:
            x, d, r = sf.x[i, b.sl], sf.d[i, b.sl], sf.rot[i, b.sl]
            line = deformed_lines(b, x, d, r, scale)
            if b.kind == "flexible" and sf.kappa is not None:
                k = half[b.name] * sf.kappa[i, b.sl]
                s = np.linspace(0, k.size - 1, line.shape[0])
                strain = np.interp(s, np.arange(k.size), k)
                out.append(go.Scatter(x=line[:, 0], y=line[:, 1], mode="lines+markers", line={"color": "#444", "width": 2},
                                      marker={"color": strain, "colorscale": "RdBu_r", "cmin": field["min"],
                                              "cmax": field["max"], "size": 7, "colorbar": {"x": 0.45, "len": 0.8}},
                                      showlegend=False))
            else:
                out.append(go.Scatter(x=line[:, 0], y=line[:, 1], mode="lines", line={"width": 4}, showlegend=False))
        pts = np.array([sf.x[i, m.point] + scale * sf.d[i, m.point] for m in marks if m.point is not None])
        out.append(go.Scatter(x=pts[:, 0], y=pts[:, 1], mode="markers", marker={"color": "white", "size": 8,
                                                                               "line": {"color": "black", "width": 1}},
                              showlegend=False))
        return out

    for b in sf.bodies:     # the ghost
        fig.add_trace(go.Scatter(x=sf.x[0, b.sl, 0], y=sf.x[0, b.sl, 1], mode="lines", showlegend=False,
                                 line={"color": "#8c8c8c", "dash": "dash", "width": 1}), row=1, col=1)
    first = len(fig.data)
    for tr in mech_traces(0):
        fig.add_trace(tr, row=1, col=1)
    moving = list(range(first, len(fig.data)))
    for r, p in enumerate(panels, start=1):
        for s in p["series"]:
            x, y = decimate(cols["t"], cols[s["name"]], CURVE_POINTS)
            fig.add_trace(go.Scatter(x=x, y=y, mode="lines", name=s["name"]), row=r, col=2)
    rows = len(panels)

    def cursor(t):
        return [{"type": "line", "x0": t, "x1": t, "yref": f"y{r + 1} domain" if r > 1 else "y2 domain", "y0": 0, "y1": 1,
                 "xref": f"x{r + 1}" if r > 1 else "x2", "line": {"color": "black", "width": 1}} for r in range(1, rows + 1)]
    frames = [go.Frame(data=mech_traces(i), traces=moving, layout={"shapes": cursor(float(sf.key[i]))}, name=str(i))
              for i in range(sf.key.size)]
    fig.frames = frames
    steps = [{"method": "animate", "label": f"{sf.key[i]:.4g}",
              "args": [[str(i)], {"mode": "immediate", "frame": {"duration": 0, "redraw": True}, "transition": {"duration": 0}}]}
             for i in range(sf.key.size)]
    fig.update_layout(sliders=[{"steps": steps, "currentvalue": {"prefix": "t = "}}], shapes=cursor(float(sf.key[0])),
                      updatemenus=[{"type": "buttons", "buttons": [
                          {"label": "play", "method": "animate", "args": [None, {"frame": {"duration": 40, "redraw": True}}]},
                          {"label": "pause", "method": "animate", "args": [[None], {"mode": "immediate"}]}]}],
                      width=1380, height=860, title=data["title"])
    fig.update_yaxes(scaleanchor="x", scaleratio=1, row=1, col=1)
    fig.write_html(str(path), include_plotlyjs=True, full_html=True, auto_play=False, div_id="plotly-view")
    return path


def _own(b: Browser, page: Path, steps: int) -> dict:
    load = b.open(page)
    n = b.js("return window.flexmechView.frames")
    ms = b.js(f"""const v = window.flexmechView, n = v.frames, t0 = performance.now();
                 for (let k = 0; k < {steps}; k++) v.setFrame(Math.round(k * (n - 1) / {steps - 1}));
                 return performance.now() - t0;""")
    return {"load_s": load, "step_ms": ms / steps, "heap_mb": b.js("return performance.memory.usedJSHeapSize") / 1e6,
            "frames": n}


def _plotly(b: Browser, page: Path, steps: int) -> dict:
    b.driver.get(page.resolve().as_uri())
    end = time.time() + 120
    while time.time() < end:
        if b.js("const g = document.getElementById('plotly-view'); return !!(g && g._fullLayout && g._transitionData "
                "&& g._transitionData._frames && g._transitionData._frames.length)"):
            break
        time.sleep(0.05)
    load = b.js("return performance.now()") / 1000.0
    # plotly's slider steps are not timed: Plotly.animate's promise, awaited step by step, did not
    # come back within the browser driver's 120 s even on a 201-frame page (headless Chromium)
    return {"load_s": load, "step_ms": float("nan"), "heap_mb": b.js("return performance.memory.usedJSHeapSize") / 1e6}


def measure(folders) -> list[dict]:
    from flexmech_py.view import write_view

    rows = []
    work = Path(tempfile.mkdtemp(prefix="flexmech-view-choice-"))
    b = Browser(1400, 900)
    try:
        for folder in map(Path, folders):
            own = write_view(folder, work / f"{folder.name}-own.html").path
            t0 = time.process_time()
            other = plotly_page(folder, work / f"{folder.name}-plotly.html")
            made = time.process_time() - t0
            runs = {"own": [], "plotly": []}
            for _ in range(REPEAT):                 # alternating pairs
                runs["own"].append(_own(b, own, STEPS))
                runs["plotly"].append(_plotly(b, other, STEPS))
            for name, page in (("own", own), ("plotly", other)):
                med = {k: statistics.median(r[k] for r in runs[name]) for k in ("load_s", "step_ms", "heap_mb")}
                rows.append({"result": folder.name, "page": name, "bytes": page.stat().st_size, **med,
                             "frames": runs["own"][0]["frames"], "plotly_write_s": made if name == "plotly" else None})
    finally:
        b.close()
    return rows


def table(rows) -> str:
    lines = ["| result | page | frames | file size | load to first drawing | per slider step | JS heap |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['result']} | {r['page']} | {r['frames']} | {r['bytes'] / 1e6:.2f} MB | {r['load_s']:.2f} s | "
                     + (f"{r['step_ms']:.1f} ms" if r['step_ms'] == r['step_ms'] else "not timed") + f" | {r['heap_mb']:.0f} MB |")
    return "\n".join(lines)


if __name__ == "__main__":
    why = missing()
    if why:
        sys.exit(f"tests/view_choice.py: {why}")
    if len(sys.argv) < 2:
        sys.exit(__doc__.split("\n\n")[1])
    print(table(measure(sys.argv[1:])))
