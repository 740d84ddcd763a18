"""PNG plots of results (matplotlib, Agg backend).  Kept apart from the numerics:
nothing here computes physics; everything plotted is already in the result.

matplotlib is an optional dependency (``pip install flexmech[plot]``); without it
the plotting functions return no files and say so once on stderr.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

__all__ = ["plot_result", "line_figure", "have_matplotlib", "work_precision_figure"]

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


def line_figure(path, panels, *, title=None, xlabel="t [s]"):
    """Write a PNG with one panel per entry of ``panels``.

    ``panels``: list of dicts with ``x``, ``series`` (list of (label, y, style-dict)),
    ``ylabel`` and optional ``xlabel``.  Returns the path, or None without matplotlib.
    """
    if not have_matplotlib():
        return None
    import matplotlib.pyplot as plt

    n = len(panels)
    crowded = any(len(p["series"]) > 4 for p in panels)   # legends go beside the axes
    fig, axes = plt.subplots(n, 1, figsize=(10.5 if crowded else 8, 2.6 * n + 0.6), squeeze=False, sharex=False)
    for ax, p in zip(axes[:, 0], panels):
        for label, y, style in p["series"]:
            ax.plot(p["x"], y, label=label, **(style or {}))
        ax.set_ylabel(p["ylabel"])
        ax.set_xlabel(p.get("xlabel", xlabel))
        ax.grid(True, alpha=0.3)
        if crowded and len(p["series"]) > 1:
            ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
        elif len(p["series"]) > 1 or p["series"][0][0]:
            ax.legend(fontsize=8, loc="best")
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def plot_result(res, out_dir) -> list[Path]:
    """Plots of one run: every output against time (grouped by unit), and, for a
    mechanism with a ``crank_angle`` output, the strains against the crank angle."""
    out_dir = Path(out_dir)
    by_unit: dict[str, list[str]] = {}
    for name, unit in res.units.items():
        by_unit.setdefault(unit, []).append(name)
    panels = [{"x": res.t, "ylabel": f"[{unit}]", "series": [(n, res.columns[n], None) for n in names]}
              for unit, names in by_unit.items()]
    title = f"{res.case['case']['title']} - model {res.model}"
    paths = [line_figure(out_dir / "timeseries.png", panels, title=title)]
    if "crank_angle" in res.columns:
        strains = [n for n, sp in res.case["outputs"].items() if sp["kind"] == "strain"]
        if strains:
            x = np.degrees(res.columns["crank_angle"])
            panels = [{"x": x, "xlabel": "crank angle [deg]", "ylabel": f"{n} [-]", "series": [("", res.columns[n], None)]}
                      for n in strains]
            paths.append(line_figure(out_dir / "strain_vs_crank_angle.png", panels, title=title))
    return [p for p in paths if p is not None]


def work_precision_figure(path, panels, *, title=None):
    """Write a log-log PNG with one panel per entry of ``panels`` (work-precision diagrams).

    ``panels``: list of dicts with ``title``, ``xlabel``, ``ylabel``, ``lines`` (dicts with
    ``label`` (None: not in the legend), ``x``, ``y``, ``color`` (an index), ``style``
    (line style, "" for markers only), ``marker``, optional ``alpha``) and ``hlines``
    (list of (y, label, "tol" | "ref")).  Non-positive values are left out (log axes).
    Returns the path, or None without matplotlib.
    """
    if not have_matplotlib():
        return None
    import matplotlib.pyplot as plt

    n = len(panels)
    ncol = 2 if n > 1 else 1
    nrow = (n + ncol - 1) // ncol
    fig, axes = plt.subplots(nrow, ncol, figsize=(7.2 * ncol + 4.2, 4.6 * nrow + 0.6), squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    handles = {}
    for ax, p in zip(axes.flat, panels):
        for ln in p["lines"]:
            pts = [(x, y) for x, y in zip(ln["x"], ln["y"]) if x > 0 and y > 0 and np.isfinite(x) and np.isfinite(y)]
            if not pts:
                continue
            xs, ys = zip(*pts)          # ladder order (timings need not be monotone)
            h, = ax.plot(xs, ys, linestyle=ln["style"] or "none", marker=ln.get("marker", "o") or None, ms=4,
                         color=colors[ln["color"] % len(colors)], alpha=ln.get("alpha", 1.0))
            if ln["label"]:
                handles.setdefault(ln["label"], h)
        for y, label, kind in p.get("hlines", []):
            ax.axhline(y, color="0.5" if kind == "tol" else "tab:red", lw=0.8, ls=":" if kind == "tol" else "-.")
            ax.annotate(label, (0.99, y), xycoords=("axes fraction", "data"), ha="right", va="bottom", fontsize=7,
                        color="0.4" if kind == "tol" else "tab:red")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(p["title"], fontsize=10)
        ax.set_xlabel(p["xlabel"])
        ax.set_ylabel(p["ylabel"])
        ax.grid(True, which="both", alpha=0.25)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    if handles:
        fig.legend(list(handles.values()), list(handles.keys()), fontsize=7, loc="upper left",
                   bbox_to_anchor=((7.2 * ncol) / (7.2 * ncol + 4.2), 0.93), borderaxespad=0.0)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout(rect=(0, 0, (7.2 * ncol) / (7.2 * ncol + 4.2), 0.97))
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)
