"""PNG plots of results (matplotlib, Agg backend).  Kept apart from the numerics:
nothing here computes physics; everything plotted is already in the result.

matplotlib is an optional dependency (``pip install flexmech[plot]``); without it
the plotting functions return no files and say so once on stderr.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

__all__ = ["plot_result", "line_figure", "have_matplotlib", "save_figure", "decimate", "panel_groups", "display_unit",
           "coincidences", "legend_corner", "mechanism_sketch", "MAX_POINTS", "PNG_OPTIONS"]

#: points drawn per line at most: about the width of a screen in pixels, min and max of every bucket kept
MAX_POINTS = 2000
#: two curves of a panel closer than this fraction of the panel's peak are drawn as one (and said so)
COINCIDE = 0.01
PNG_OPTIONS = {"compress_level": 1}   # zlib level 6 (the default) spends more time than the drawing

_warned = False


def have_matplotlib() -> bool:
    global _warned
    try:
        import matplotlib

        matplotlib.use("Agg")
        return True
    except ImportError:
        if not _warned:
            print("flexmech: matplotlib is not installed, no PNG plots written (pip install matplotlib)",
                  file=sys.stderr)
            _warned = True
        return False


def save_figure(fig, path, **kw) -> None:
    """``fig.savefig(path, **kw)``; a write that fails (a full disk) raises OSError naming ``path`` (the
    image writer itself does not, and removes the file it began)."""
    try:
        fig.savefig(path, **kw)
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, str(path)) from None


def decimate(x, y, max_points: int = MAX_POINTS):
    """(x, y) reduced to at most ``max_points`` points for drawing: the samples are cut into
    ``max_points // 2 - 1`` consecutive buckets and each keeps its smallest and largest value (in
    their order), plus the first and last sample, so every peak and trough survives.  Shorter
    inputs are returned as they are."""
    x, y = np.asarray(x), np.asarray(y)
    n = y.size
    if n <= max_points:
        return x, y
    size = -(-n // max(1, max_points // 2 - 1))        # samples per bucket
    nb = -(-n // size)                                  # buckets (the last one padded with the last sample)
    pad = np.concatenate([y, np.full(nb * size - n, y[-1])]).reshape(nb, size)
    base = np.arange(nb) * size
    with np.errstate(invalid="ignore"):
        keep = np.concatenate([[0, n - 1], base + np.argmin(pad, axis=1), base + np.argmax(pad, axis=1)])
    keep = np.unique(np.minimum(keep, n - 1))
    return x[keep], y[keep]


def display_unit(unit: str) -> str:
    """The unit as an axis label shows it: a dimensionless quantity (strain, ``1``) is ``-``."""
    return "-" if unit in ("1", "", "-") else unit


def _short(label: str) -> str:
    """A label up to its first parenthesis: 'case I (hac, Eq. 15)' -> 'case I'."""
    return label.split(" (", 1)[0]


def coincidences(series, tol: float = COINCIDE) -> dict:
    """{k: (j, d)}: series k lies on the earlier series j (max |y_k - y_j| = d times the largest |y| of
    all series, d <= tol): at a panel's scale the two are one line."""
    ys = [np.asarray(y, float) for _, y, _ in series]
    scale = max((float(np.nanmax(np.abs(y))) for y in ys if y.size), default=0.0)
    out = {}
    if scale <= 0:
        return out
    for k in range(1, len(ys)):
        for j in range(k):
            if j in out or ys[j].shape != ys[k].shape:
                continue
            d = float(np.nanmax(np.abs(ys[k] - ys[j]))) / scale
            if d <= tol:
                out[k] = (j, d)
                break
    return out


def _coincide_text(k: np.ndarray, ref: np.ndarray, ref_label: str) -> str:
    """How far series k lies from the series ``ref`` it is drawn on, relative to the reference's own peak
    (not the panel's: a small reference curve in a panel of large ones keeps its true relative difference)."""
    diff = float(np.nanmax(np.abs(np.asarray(k, float) - np.asarray(ref, float))))
    if diff == 0:
        return "identical"
    peak = float(np.nanmax(np.abs(ref)))
    return f"max |diff| {100 * diff / peak:.2g} % of {ref_label}'s peak" if peak > 0 else f"max |diff| {diff:.2g}"


def _mark_coincident(series, tol=COINCIDE):
    """Series with a second label line on every curve drawn over an earlier one, dashed when unstyled."""
    out = list(series)
    for k, (j, _) in coincidences(series, tol).items():
        label, y, style = out[k]
        if label and series[j][0]:
            ref = _short(series[j][0])
            label = f"{label}\n   on {ref}: {_coincide_text(y, series[j][1], ref)}"
        if not style:
            style = {"ls": "--", "lw": 1.2}
        out[k] = (label, y, style)
    return out


def legend_corner(points, size, pad: float = 0.02):
    """An axes corner ('upper right', 'upper left', 'lower left', 'lower right', in that order) where a
    legend of ``size`` (width, height as axes fractions) covers none of ``points`` ((x, y) arrays in
    axes fractions); None when every corner holds data."""
    w, h = size[0] + pad, size[1] + pad
    if w >= 0.6 or h >= 0.9:
        return None
    for loc, (right, top) in (("upper right", (1, 1)), ("upper left", (0, 1)), ("lower left", (0, 0)),
                              ("lower right", (1, 0))):
        inside = True
        for u, v in points:
            su = (u > 1 - w) if right else (u < w)
            sv = (v > 1 - h) if top else (v < h)
            if np.any(su & sv):
                inside = False
                break
        if inside:
            return loc
    return None


def _axes_fractions(panel, drawn):
    """The drawn points of a panel as fractions of its axes (matplotlib's default 5 % data margins),
    densified where a line has few points so that its segments count too."""
    xs = np.concatenate([np.asarray(x, float) for x, _ in drawn])
    ys = np.concatenate([np.asarray(y, float) for _, y in drawn])
    fin = np.isfinite(xs) & np.isfinite(ys)
    if not fin.any():
        return []
    x0, x1 = float(xs[fin].min()), float(xs[fin].max())
    y0, y1 = float(ys[fin].min()), float(ys[fin].max())
    dx, dy = (x1 - x0) or 1.0, (y1 - y0) or 1.0
    lo_x, lo_y = x0 - 0.05 * dx, y0 - 0.05 * dy
    pts = []
    for x, y in drawn:
        x, y = np.asarray(x, float), np.asarray(y, float)
        if 1 < x.size < 400 and np.all(np.diff(x) > 0):
            xd = np.linspace(x[0], x[-1], 400)
            x, y = xd, np.interp(xd, x, y)
        pts.append(((x - lo_x) / (1.1 * dx), (y - lo_y) / (1.1 * dy)))
    return pts


_FS = 7.5   # legend font size [pt]


def _legend_inches(labels) -> tuple[float, float]:
    """Estimated legend box (width, height) [in] of these labels, DejaVu Sans at _FS pt."""
    lines = [ln for lab in labels for ln in lab.split("\n")]
    w_pt = 0.56 * _FS * max(len(ln) for ln in lines) + 4.2 * _FS
    h_pt = len(labels) * 0.55 * _FS + len(lines) * 1.17 * _FS + 0.9 * _FS
    return w_pt / 72, h_pt / 72


def _layout(panels, title, shared):
    """Figure geometry [in] and margins: (width, height, left, right, top, bottom, hspace, axes width, axes height)."""
    n = len(panels)
    height = 2.35 * n + (0.75 if title else 0.45) + (0.0 if shared else 0.35 * (n - 1))
    hspace = (0.3 if any(p.get("title") for p in panels) else 0.16) if shared else 0.45
    width = 8.0
    left, right = 0.95 / width, 0.97
    head = (0.55 if title else 0.25) + (0.25 if panels[0].get("title") else 0.0)   # room for the first panel's title
    height += head - (0.55 if title else 0.25)
    top, bottom = 1.0 - head / height, 0.5 / height
    ax_h = height * (top - bottom) / (n + hspace * (n - 1))
    return width, height, left, right, top, bottom, hspace, width * (right - left), ax_h


def _legend_spots(prepared, ax_w, ax_h):
    """Per panel: a corner for its legend, "none" (no labels) or None (beside the axes); and the
    width [in] the legends beside the axes need."""
    spots, beside = [], 0.0
    for p, _, drawn, labels in prepared:
        if not labels:
            spots.append("none")
            continue
        w_in, h_in = _legend_inches(labels)
        spots.append(legend_corner(_axes_fractions(p, drawn), (w_in / ax_w, h_in / ax_h)))
        if spots[-1] is None:
            beside = max(beside, w_in + 0.15)
    return spots, beside


def _draw_panel(ax, p, series, drawn, spot):
    from matplotlib.ticker import MaxNLocator

    for (label, _, style), (xd, yd) in zip(series, drawn):
        ax.plot(xd, yd, label=label or None, **(style or {}))
    ax.set_ylabel(p["ylabel"])
    if p.get("title"):
        ax.set_title(p["title"], fontsize=8.5, loc="left")
    ax.yaxis.set_major_locator(MaxNLocator(5))
    ax.ticklabel_format(axis="y", style="sci", scilimits=(-3, 4), useMathText=True)   # short tick labels:
    # a strain of 5e-4 is ticked 5 with x10^-4 above the axis, so the label keeps its place at the left
    ax.xaxis.set_major_locator(MaxNLocator(6))
    ax.grid(True, alpha=0.3)
    if spot is None:
        ax.legend(fontsize=_FS, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    elif spot != "none":
        ax.legend(fontsize=_FS, loc=spot, borderaxespad=0.4)


def line_figure(path, panels, *, title=None, xlabel="t [s]"):
    """Write a PNG with one panel per entry of ``panels``.

    ``panels``: list of dicts with ``x``, ``series`` (list of (label, y, style-dict); label "" for
    no legend entry), ``ylabel`` and optional ``xlabel`` and ``title`` (the panel's own, small).
    Curves are drawn with at most :data:`MAX_POINTS` points (:func:`decimate`); a curve lying on an
    earlier one of its panel (:func:`coincidences`) says so in its label; a legend goes into an empty
    corner of its panel, else beside it.  Panels with the same abscissa share it (labels on the bottom
    panel only).  Returns the path, or None without matplotlib.
    """
    if not have_matplotlib():
        return None
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure   # not pyplot: its import alone costs more than a run

    n = len(panels)
    prepared = []
    for p in panels:
        series = _mark_coincident(p["series"])
        prepared.append((p, series, [decimate(p["x"], y) for _, y, _ in series], [lab for lab, _, _ in series if lab]))
    xl = [p.get("xlabel", xlabel) for p in panels]
    shared = n > 1 and len(set(xl)) == 1 and all(np.array_equal(p["x"], panels[0]["x"]) for p in panels[1:])
    width, height, left, right, top, bottom, hspace, ax_w, ax_h = _layout(panels, title, shared)
    spots, beside = _legend_spots(prepared, ax_w, ax_h)
    if beside:   # the axes keep their size in inches; the figure grows on the right
        left, right = left * width / (width + beside), right * width / (width + beside)
        width += beside
    fig = Figure(figsize=(width, height))
    FigureCanvasAgg(fig)
    axes = fig.subplots(n, 1, squeeze=False, sharex=shared)[:, 0]
    for i, (ax, (p, series, drawn, _), spot) in enumerate(zip(axes, prepared, spots)):
        _draw_panel(ax, p, series, drawn, spot)
        if not shared or i == n - 1:
            ax.set_xlabel(xl[i])
        elif shared:
            ax.tick_params(labelbottom=False)
    if title:   # centred over the axes, not over a figure widened for a legend beside them
        fig.suptitle(title, fontsize=10.5, x=0.5 * (left + right), y=1.0 - 0.12 / height, va="top")   # 0.12 in
        # from the top whatever the height (the default 2 % of a tall figure reached the first panel)
    # fixed margins (tight_layout measures every text and doubles the drawing time)
    fig.subplots_adjust(left=left, right=right, bottom=bottom, top=top, hspace=hspace)
    save_figure(fig, path, dpi=100, pil_kwargs=PNG_OPTIONS)
    return Path(path)


def _panel_key(name: str, spec: dict | None) -> tuple:
    """What an output is about: (kind, place) -- outputs of one kind at one place share a panel."""
    if spec is None:   # a column the model adds (energies, Newton iterations): grouped by unit
        return ("", "")
    place = spec.get("at") or spec.get("link") or spec.get("joint") or spec.get("body") or ""
    return (spec["kind"], str(place))


def panel_groups(names, units: dict, specs: dict, peaks: dict, max_series: int = 4) -> list[list[str]]:
    """The columns ``names`` in panels: one unit and kind each, outputs at one place together, at
    most ``max_series`` curves and no curve 20 times smaller than another (``peaks``: each column's
    largest |value|; ``specs``: the case's outputs; a column without one is grouped by its unit)."""
    groups: list[list[str]] = []
    for name in names:
        key = (units.get(name, ""),) + _panel_key(name, specs.get(name))
        if groups and (units.get(groups[-1][0], ""),) + _panel_key(groups[-1][0], specs.get(groups[-1][0])) == key:
            groups[-1].append(name)
        else:
            groups.append([name])
    merged: list[list[str]] = []
    for g in groups:   # neighbours of one unit and kind share a panel while it stays small
        last = merged[-1] if merged else None
        if (last and units.get(last[0]) == units.get(g[0]) and len(last) + len(g) <= max_series
                and _panel_key(last[0], specs.get(last[0]))[0] == _panel_key(g[0], specs.get(g[0]))[0]):
            last.extend(g)
        else:
            merged.append(list(g))
    out = []
    for g in merged:
        part, top = [], None
        for nm in g:
            if part and (len(part) >= max_series or peaks[nm] < top / 20.0 or peaks[nm] > 20.0 * top):
                out.append(part)
                part = []
            if not part:
                top = max(peaks[nm], 1e-300)
            part.append(nm)
        out.append(part)
    return out


def _result_panels(res, x, names=None, max_series: int = 4) -> list[dict]:
    """Panels of a result's columns (:func:`panel_groups`); lengths in mm when they stay below 0.1 m,
    dimensionless columns as [-]."""
    names = list(names or res.columns)
    peaks = {nm: float(np.nanmax(np.abs(res.columns[nm]))) if res.columns[nm].size else 0.0 for nm in names}
    return [_panel(res, x, g) for g in panel_groups(names, res.units, res.case["outputs"], peaks, max_series)]


def _panel(res, x, names) -> dict:
    unit = res.units.get(names[0], "")
    scale = 1.0
    if unit == "m" and max(float(np.nanmax(np.abs(res.columns[n]))) for n in names) < 0.1:
        scale, unit = 1e3, "mm"
    kind = res.case["outputs"].get(names[0], {}).get("kind", "energy" if unit == "J" else "")
    if not kind and all(n.startswith("control_") for n in names):
        kind = "controller output"
    what = names[0] if len(names) == 1 else kind.replace("_", " ")
    return {"x": x, "ylabel": f"{what} [{display_unit(unit)}]".strip(),
            "series": [(n if len(names) > 1 else "", scale * res.columns[n], None) for n in names]}


def plot_result(res, out_dir) -> list[Path]:
    """Plots of one run: every output against time (:func:`_result_panels`), and, for a mechanism
    with a ``crank_angle`` output, the strains against the crank angle."""
    out_dir = Path(out_dir)
    title = f"{res.case['case']['title']} - model {res.model}"
    paths = [line_figure(out_dir / "timeseries.png", _result_panels(res, res.t), title=title)]
    if "crank_angle" in res.columns:
        strains = [n for n, sp in res.case["outputs"].items() if sp["kind"] == "strain"]
        if strains:
            x = np.degrees(res.columns["crank_angle"])
            panels = [dict(p, xlabel="crank angle [deg]") for p in _result_panels(res, x, strains, max_series=1)]
            paths.append(line_figure(out_dir / "strain_vs_crank_angle.png", panels, title=title))
    return [p for p in paths if p is not None]


def _sketch_geometry(res):
    """Frame-0 geometry of a result's links: [(name, start, end, [(fraction, node number)])],
    [(position, name)] of the ground joints, [(position, text)] of the lumped masses and hub inertias."""
    fe, m, mech = res.fe, res.motion, res.case.mechanism
    links, ends = [], {}
    for li, ln in enumerate(res.case["links"]):
        p0 = np.array([m.ox[0, li], m.oy[0, li]])
        d = ln["length"] * np.array([np.cos(m.phi[0, li]), np.sin(m.phi[0, li])])
        links.append((ln["name"], p0, p0 + d, [(f, fe.node_of[li][k] + 1) for k, f in enumerate(fe.node_frac[li])]))
        ends[ln["name"]] = (p0, d)
    at = {}
    for lk in mech.links:
        p0, d = ends[lk.name]
        for f, mass in lk.lumped:
            at.setdefault(tuple(np.round(p0 + f * d, 9)), []).append(f"{mass:g} kg")
        for f, inertia in lk.hubs:
            at.setdefault(tuple(np.round(p0 + f * d, 9)), []).append(f"{inertia:g} kg m²")
    grounds = []
    for j in res.case["joints"]:
        sides = [c.split(".", 1) for c in j["connects"]]
        body = [s for s in sides if s[0] != "ground"]
        if len(body) == 1 and len(sides) == 2 and body[0][0] in ends:
            p0, d = ends[body[0][0]]
            grounds.append((p0 + mech.links[[lk.name for lk in mech.links].index(body[0][0])].fraction(body[0][1]) * d,
                            j["name"]))
    return links, grounds, [(np.array(p), ", ".join(txt)) for p, txt in at.items()]


def mechanism_sketch(path, res, *, title=None):
    """The mechanism of a result at t = 0 (a reader's Figs. 2 and 9 of the seed): links as bars, the
    finite-element nodes numbered as flexmech numbers them, ground joints, lumped masses and hub inertias
    with their values.  Links only (rigid bodies are not drawn).  Returns the path, or None without
    matplotlib."""
    if not have_matplotlib():
        return None
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    links, grounds, masses = _sketch_geometry(res)
    pts = np.array([p for _, a, b, _ in links for p in (a, b)])
    ext = np.ptp(pts, axis=0)
    span = float(np.max(ext)) or 1.0
    aspect = (ext[1] + 0.3 * span) / (ext[0] + 0.3 * span)
    fig = Figure(figsize=(6.4, float(np.clip(5.2 * aspect + 1.1, 2.8, 6.5))))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    off = 0.035 * span
    numbered = set()
    for name, a, b, nodes in links:
        ax.plot([a[0], b[0]], [a[1], b[1]], "-", color="0.25", lw=3, solid_capstyle="round", zorder=1)
        d = (b - a) / np.hypot(*(b - a))
        mid = 0.5 * (a + b) + off * np.array([-d[1], d[0]])
        angle = float(np.degrees(np.arctan2(d[1], d[0])))
        angle = angle - 180 if angle > 90 else angle + 180 if angle < -90 else angle   # text reads left to right
        ax.text(mid[0], mid[1], name, fontsize=9, ha="center", va="center", color="C0", rotation=angle,
                rotation_mode="anchor", zorder=3)
        for f, k in nodes:
            p = a + f * (b - a)
            ax.plot(*p, "o", ms=5, mfc="white", mec="k", zorder=2)
            if k not in numbered:   # a joint node belongs to two links
                numbered.add(k)
                ax.annotate(str(k), p, xytext=(5, -11), textcoords="offset points", fontsize=7.5)
    driven = {d["joint"] for d in res.case["drives"]}
    for g, name in grounds:
        ax.plot(*g, "^", ms=13, mfc="0.8", mec="k", zorder=0)
        if name in driven:
            ax.annotate(f"{name} (driven)", g, xytext=(-6, -22), textcoords="offset points", fontsize=7.5,
                        ha="center", color="0.3")
    for p, txt in masses:
        ax.plot(*p, "o", ms=10, color="C3", alpha=0.45, zorder=2)
        ax.annotate(txt, p, xytext=(8, 7), textcoords="offset points", fontsize=7.5, color="C3",
                    bbox={"fc": "white", "ec": "none", "alpha": 0.8, "pad": 1})
    ax.set_aspect("equal", adjustable="datalim")
    ax.margins(0.15)
    ax.set_xlabel("X [m]")
    ax.set_ylabel("Y [m]")
    ax.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title, fontsize=9.5)
    fig.subplots_adjust(left=0.12, right=0.97, bottom=0.6 / fig.get_figheight(), top=1 - 0.55 / fig.get_figheight())
    save_figure(fig, path, dpi=100, pil_kwargs=PNG_OPTIONS)
    return Path(path)
