"""PNG plots of results (matplotlib, Agg backend).  Kept apart from the numerics:
nothing here computes physics; everything plotted is already in the result.

matplotlib is an optional dependency (``pip install flexmech[plot]``); without it
the plotting functions return no files and say so once on stderr.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

__all__ = ["plot_result", "line_figure", "have_matplotlib"]

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
