"""Drawings of the mechanism (matplotlib, Agg): the deformed links over the rigid configuration at
chosen instants (the mode shapes of ``flexmech modes``), and the frequencies
along a cycle with the crank speed harmonics.  Nothing here computes physics: the points and their
displacements come from :mod:`flexmech_py.models.shapes`, the frequencies from :mod:`flexmech_py.studies.modes`.

Every drawing of a deformation states its magnification: the elastic displacements are multiplied by
a factor (1-2-5 rounded, :func:`magnification`) so that the largest one is about a tenth of the
mechanism's size; the rigid configuration is drawn dashed underneath.
"""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np

from .glyphs import (BODY_COLOURS, BODY_STYLES, GROUND_GUIDE, GROUND_PIVOT, RIGID_GHOST, glyph_of, joint_marks,
                     legend_words, shape_lines)
from .plots import PNG_OPTIONS, have_matplotlib, save_figure

__all__ = ["magnification", "deformed_lines", "draw_frames", "animate_frames", "draw_modes", "plot_along",
           "TARGET_FRACTION"]

#: the largest magnified displacement as a fraction of the mechanism's size
TARGET_FRACTION = 0.1
SUBDIVISIONS = 8          # points per element of a flexible link's drawn curve (cubic Hermite)
RIGID_STYLE = {"color": RIGID_GHOST["colour"], "lw": RIGID_GHOST["width"], "ls": (0, RIGID_GHOST["dash"])}
#: matplotlib's marker of each glyph shape (flexmech_py.figures.glyphs)
MARKERS = {"circle": "o", "square": "s", "triangle": "^"}


def magnification(size: float, dmax: float, fraction: float = TARGET_FRACTION) -> float:
    """The factor that makes the largest displacement ``dmax`` about ``fraction`` of ``size``, rounded
    down to 1, 2 or 5 times a power of ten (1 when nothing moves)."""
    if not (dmax > 0.0 and size > 0.0):
        return 1.0
    raw = fraction * size / dmax
    p = 10.0 ** math.floor(math.log10(raw))
    return max(m for m in (1.0, 2.0, 5.0, 10.0) if m * p <= raw * (1 + 1e-12)) * p


def factor_text(s: float) -> str:
    """A magnification as printed: x 200, x 5e+04, x 0.5."""
    return f"× {s:.0f}" if 1 <= s < 1e5 else f"× {s:.0e}" if s >= 1e5 else f"× {s:g}"


def mechanism_size(sf) -> float:
    """The mechanism's size [m]: the largest extent of its rigid positions over all instants of sf."""
    pts = sf.x.reshape(-1, 2)
    return float(np.max(np.ptp(pts, axis=0))) or 1.0


def deformed_lines(body, x: np.ndarray, d: np.ndarray, rot: np.ndarray, scale: float) -> np.ndarray:
    """(n, 2) the drawn line of one body at one instant: a flexible link's nodes joined by the cubic
    Hermite interpolation of its transverse displacement and slope (axial linear), in its rigid frame;
    a rigid body's points as they are.  x, d (npts, 2), rot (npts,) of the body's points only."""
    xd = x + scale * d
    if body.kind != "flexible" or x.shape[0] < 2:
        return xd
    e = x[-1] - x[0]
    length = float(np.hypot(*e)) or 1.0
    e = e / length
    n = np.array([-e[1], e[0]])
    w, u = d @ n, d @ e
    s = np.linspace(0.0, 1.0, SUBDIVISIONS + 1)[:-1]
    h = np.stack([1 - 3 * s**2 + 2 * s**3, s - 2 * s**2 + s**3, 3 * s**2 - 2 * s**3, -s**2 + s**3])
    out = []
    for k in range(x.shape[0] - 1):
        le = float(np.hypot(*(x[k + 1] - x[k])))
        wk = h[0] * w[k] + h[1] * le * rot[k] + h[2] * w[k + 1] + h[3] * le * rot[k + 1]
        uk = (1 - s) * u[k] + s * u[k + 1]
        base = x[k] + s[:, None] * (x[k + 1] - x[k])
        out.append(base + scale * (uk[:, None] * e + wk[:, None] * n))
    out.append(xd[-1:])
    return np.concatenate(out)


def largest_drawn(sf, i: int) -> float:
    """The largest displacement [m] along the drawn lines of instant i (the interpolated curves of the
    flexible links included, not only their nodes)."""
    out = 0.0
    for b in sf.bodies:
        x, d, r = sf.x[i, b.sl], sf.d[i, b.sl], sf.rot[i, b.sl]
        moved = deformed_lines(b, x, d, r, 1.0) - deformed_lines(b, x, d, r, 0.0)
        if moved.size:
            out = max(out, float(np.max(np.hypot(moved[:, 0], moved[:, 1]))))
    return out


def _outline(body, pts: np.ndarray) -> np.ndarray:
    """A rigid body's drawn outline: its points around their centroid (closed), or the line through two."""
    if body.kind != "body" or pts.shape[0] < 3:
        return pts
    c = pts.mean(axis=0)
    order = np.argsort(np.arctan2(pts[:, 1] - c[1], pts[:, 0] - c[0]))
    return np.concatenate([pts[order], pts[order[:1]]])


def _draw_instant(ax, sf, i: int, scale: float, marks, colours) -> None:
    """One instant: rigid configuration dashed, deformed bodies solid, joints and ground."""
    for b, col in zip(sf.bodies, colours):
        x, d, r = sf.x[i, b.sl], sf.d[i, b.sl], sf.rot[i, b.sl]
        rigid = _outline(b, x) if b.kind == "body" else (x if b.kind == "flexible" else x[:2])
        ax.plot(rigid[:, 0], rigid[:, 1], zorder=1, **RIGID_STYLE)
        line = deformed_lines(b, x, d, r, scale)
        if b.kind == "rigid_link":
            line = line[:2]
        line = _outline(b, line)
        if BODY_STYLES[b.kind]["fill"] and line.shape[0] > 3:
            ax.fill(line[:, 0], line[:, 1], color=col, alpha=BODY_STYLES[b.kind]["fill"], zorder=2)
        ax.plot(line[:, 0], line[:, 1], "-", color=col, lw=BODY_STYLES[b.kind]["width"],
                solid_capstyle="round", zorder=3)
    for m in marks:
        if m.point is not None:
            _draw_joint(ax, m, sf.x[i, m.point] + scale * sf.d[i, m.point])
            ends = [e if e is None or isinstance(e, np.ndarray) else sf.x[i, e] + scale * sf.d[i, e] for e in m.ends]
            for line in (shape_lines(m.joint.glyph_shapes(), *ends) if all(e is not None for e in ends) else ()):
                ax.plot(line[:, 0], line[:, 1], "-", color="0.2", lw=1.0, zorder=4)   # the kind's own outline


def _draw_joint(ax, m, pos) -> None:
    """A joint's glyph at ``pos`` and, on the ground, its pivot or its guide (flexmech_py.figures.glyphs)."""
    if m.axis is not None:          # a guide on the ground: its line, not a pivot
        ax.axline(m.ground, xy2=m.ground + m.axis, color=GROUND_GUIDE["colour"], lw=GROUND_GUIDE["width"], zorder=0)
    elif m.ground is not None:
        g = GROUND_PIVOT
        ax.plot(*m.ground, marker=MARKERS[g["marker"]], ms=g["size"], mfc=g["fill"], mec=g["edge"], zorder=0)
    g = glyph_of(m.kind)
    ax.plot(*pos, marker=MARKERS[g["marker"]], ms=g["size"], mfc=g["driven_fill"] if m.driven else g["fill"],
            mec=g["edge"], zorder=4)


def _symbols(marks) -> str:
    """The legend of the joint marks drawn (only those present)."""
    return ", ".join(legend_words(marks))


def _instants(sf, idx, scale: float | None):
    """(idx as an int array, the magnification: ``scale``, or :func:`magnification` of the largest
    displacement drawn over those instants)."""
    idx = np.atleast_1d(np.asarray(idx, int))
    if scale is not None:
        return idx, float(scale)
    dmax = max((largest_drawn(sf, int(i)) for i in idx), default=0.0)
    return idx, magnification(mechanism_size(sf), dmax)


def _colours(sf) -> list:
    return [BODY_COLOURS[k % len(BODY_COLOURS)] for k in range(len(sf.bodies))]


def _frame_axes(ax, lo, hi) -> None:
    """One panel's frame: the common limits, equal aspect, small ticks, a light grid."""
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    ax.tick_params(labelsize=7)
    ax.grid(True, alpha=0.25)


def _limits(sf, idx, scale: float):
    pts = [sf.x[idx].reshape(-1, 2), (sf.x[idx] + scale * sf.d[idx]).reshape(-1, 2)]
    pts = np.concatenate(pts)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.08 * max(float(np.max(hi - lo)), 1e-9)
    return lo - pad, hi + pad


def _panel_grid(n: int, span):
    """(rows, columns, figure width, height) for n equal-aspect panels of extent span (dx, dy)."""
    cols = min(n, 3 if span[0] >= span[1] else 4)
    rows = math.ceil(n / cols)
    width = 3.4 * cols + 0.6
    panel_h = 3.4 * float(np.clip(span[1] / max(span[0], 1e-12), 0.35, 1.6))
    return rows, cols, width, rows * (panel_h + 0.45) + 0.95


def _figure(width, height):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height))
    FigureCanvasAgg(fig)
    return fig


def _legend_line(fig, text: str) -> float:
    """The legend under the panels, wrapped to the figure's width (about 17 characters of 8 pt text per
    inch); returns the fraction of the figure's height it takes."""
    width, height = fig.get_size_inches()
    lines = textwrap.wrap(text, width=max(40, int(17 * width)))
    fig.text(0.5, 0.012, "\n".join(lines), ha="center", va="bottom", fontsize=8, color="0.25")
    return (0.012 * height + 0.16 * len(lines)) / height


def draw_frames(path, sf, mech, idx, *, scale: float | None = None, title: str = "", labels=None, legend=None):
    """PNG of the mechanism at the instants idx of sf (panels in a grid, one scale for all): the
    deflection magnified by ``scale`` (default :func:`magnification` of the largest displacement over
    those instants), rigid configuration dashed; panel titles ``labels`` (default t = ...).  Returns
    (path, scale) or (None, scale) without matplotlib."""
    idx, scale = _instants(sf, idx, scale)
    if not have_matplotlib():
        return None, scale
    lo, hi = _limits(sf, idx, scale)
    rows, cols, width, height = _panel_grid(idx.size, hi - lo)
    fig = _figure(width, height)
    axes = fig.subplots(rows, cols, squeeze=False)
    marks, colours = joint_marks(mech, sf), _colours(sf)
    for n, ax in enumerate(axes.ravel()):
        if n >= idx.size:
            ax.set_visible(False)
            continue
        _draw_instant(ax, sf, int(idx[n]), scale, marks, colours)
        _frame_axes(ax, lo, hi)
        ax.set_title(labels[n] if labels is not None else f"t = {sf.key[idx[n]]:.4g} s", fontsize=9)
        if n % cols == 0:
            ax.set_ylabel("Y [m]", fontsize=8)
        if n // cols == rows - 1 or n + cols >= idx.size:
            ax.set_xlabel("X [m]", fontsize=8)
    fig.suptitle(title, fontsize=9.5)
    bottom = _legend_line(fig, (legend or f"elastic deflection {factor_text(scale)} (magnified)")
                          + ", rigid configuration dashed; " + _symbols(marks))
    fig.tight_layout(rect=(0, bottom, 1, 1))
    save_figure(fig, path, dpi=100, pil_kwargs=PNG_OPTIONS)
    return Path(path), scale


def animate_frames(path, sf, mech, idx, *, scale: float | None = None, title: str = "", fps: float = 12.0):
    """Animated GIF (matplotlib's Pillow writer) of the mechanism at the instants idx of sf, one
    frame each, on fixed axes and one magnification for all (default as :func:`draw_frames`); the
    time and the magnification written on every frame.  Returns (path, scale) or (None, scale)
    without matplotlib or Pillow."""
    idx, scale = _instants(sf, idx, scale)
    if not have_matplotlib():
        return None, scale
    try:
        from matplotlib.animation import PillowWriter
    except ImportError:
        return None, scale
    lo, hi = _limits(sf, idx, scale)
    _, _, width, height = _panel_grid(1, hi - lo)
    fig = _figure(width * 1.35, height * 1.35)
    ax = fig.subplots()
    writer = PillowWriter(fps=fps)
    try:
        _animate(writer, fig, ax, path, idx, sf, scale, mech, lo, hi, title)
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, str(path)) from None
    return Path(path), scale


def _animate(writer, fig, ax, path, idx, sf, scale, mech, lo, hi, title) -> None:
    """The frames of :func:`animate_frames`, written by ``writer``."""
    marks, colours = joint_marks(mech, sf), _colours(sf)
    with writer.saving(fig, str(path), dpi=80):
        for i in idx:
            ax.clear()
            _draw_instant(ax, sf, int(i), scale, marks, colours)
            _frame_axes(ax, lo, hi)
            ax.set_xlabel("X [m]", fontsize=8)
            ax.set_ylabel("Y [m]", fontsize=8)
            ax.set_title(f"{title}\nt = {sf.key[i]:.4f} s, elastic deflection {factor_text(scale)}", fontsize=8.5)
            fig.tight_layout()
            writer.grab_frame()


def draw_modes(path, ms, *, title: str | None = None):
    """PNG of the mode shapes of a :class:`flexmech_py.studies.modes.ModeSet`, one panel each, every shape
    scaled so that its largest displacement is TARGET_FRACTION of the mechanism's size."""
    sf = ms.shapes
    n = sf.key.size
    size = mechanism_size(sf)
    scaled = sf.select(slice(None))
    scaled.d = sf.d.copy()
    scaled.rot = sf.rot.copy()
    for k in range(n):
        dm = largest_drawn(sf, k)
        if dm > 0:
            scaled.d[k] *= TARGET_FRACTION * size / dm
            scaled.rot[k] *= TARGET_FRACTION * size / dm
    labels = [f"mode {k + 1}: " + ("rigid (a free DOF)" if ms.rigid[k] else f"{ms.hz[k]:.4g} Hz") for k in range(n)]
    where = f"t = {ms.t:.4g} s" + (f", {ms.joint} at {ms.crank_angle:.4g}°" if ms.joint else "")
    title = title or f"{ms.case['case']['title']}\nmode shapes, model {ms.model}, {where}"
    if not have_matplotlib():
        return None
    p, _ = draw_frames(path, scaled, ms.case.mechanism, np.arange(n), scale=1.0, title=title, labels=labels,
                       legend=f"each mode shape drawn with its largest displacement {TARGET_FRACTION:.0%} of the "
                              "mechanism's size (a mode's amplitude is arbitrary)")
    return p


def plot_along(path, al, *, title: str | None = None):
    """The frozen natural frequencies along the cycle (:class:`flexmech_py.studies.modes.Along`) with the crank
    speed harmonics k Omega / 2 pi drawn over them (grey) and their crossings marked."""
    if not have_matplotlib():
        return None
    fig = _figure(8.0, 5.2)
    ax = fig.subplots()
    hz = al.hz
    top = 1.12 * float(np.nanmax(hz))
    for k in range(hz.shape[1]):
        ax.plot(al.x, hz[:, k], "-o", ms=2.5, lw=1.6, label=f"f{k + 1}", zorder=3)
    ks = al.harmonics()
    for k in ks:
        y = al.harmonics_hz(k)
        ax.plot(al.x, y, color="0.6", lw=0.8, ls="-" if k % 5 == 0 or k == 1 else ":", zorder=1)
        j = int(np.argmax(np.where(y <= 0.97 * top, y, -np.inf)))
        if y[j] > 0.03 * top and (k <= 5 or k % 5 == 0 or k == ks[-1]):
            ax.text(al.x[j], y[j], f" {k}Ω", fontsize=7, color="0.4", va="bottom", ha="right" if j else "left")
    cross = al.crossings()
    if cross:
        ax.plot([c["x"] for c in cross], [c["f_hz"] for c in cross], "x", color="k", ms=6, mew=1.2,
                label=f"f = kΩ/2π ({len(cross)})", zorder=4)
    ax.set_ylim(0, top)
    ax.set_xlim(float(np.min(al.x)), float(np.max(al.x)))
    ax.set_xlabel(al.xlabel)
    ax.set_ylabel("natural frequency [Hz]")
    ax.grid(True, alpha=0.25)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    note = (f"grey: crank speed harmonics kΩ/2π, k = 1..{ks[-1]}" + (" (more above the frame)" if len(ks) == 20 else "")
            if ks else ("no crank speed (no revolute drive)" if al.speed is None
                        else f"{al.joint} turns less than a revolution: no speed harmonics drawn"))
    ax.set_title(f"{al.t.size} positions over {al.span}; {note}", fontsize=8, loc="left")
    fig.suptitle(title or f"{al.case['case']['title']}\nfrozen natural frequencies along the motion, model {al.model}"
                 + (", geometric stiffness" if al.geometric else ""), fontsize=9.5)
    fig.tight_layout()
    save_figure(fig, path, dpi=100, pil_kwargs=PNG_OPTIONS)
    return Path(path)
