"""PNG plots of results (matplotlib, Agg backend).  Kept apart from the numerics:
nothing here computes physics; everything plotted is already in the result.

matplotlib is an optional dependency (``pip install flexmech[plot]``); without it
the plotting functions return no files and say so once on stderr.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

__all__ = ["plot_result", "line_figure", "have_matplotlib", "plot_stability", "work_precision_figure", "plot_samples"]

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
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure   # not pyplot: its import alone costs more than a run

    n = len(panels)
    crowded = any(len(p["series"]) > 4 for p in panels)   # legends go beside the axes
    height = 2.6 * n + 0.6
    fig = Figure(figsize=(10.5 if crowded else 8, height))
    FigureCanvasAgg(fig)
    axes = fig.subplots(n, 1, squeeze=False, sharex=False)
    for ax, p in zip(axes[:, 0], panels):
        for label, y, style in p["series"]:
            ax.plot(p["x"], y, label=label, **(style or {}))
        ax.set_ylabel(p["ylabel"])
        ax.set_xlabel(p.get("xlabel", xlabel))
        ax.grid(True, alpha=0.3)
        if crowded and len(p["series"]) > 1:
            ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
        elif len(p["series"]) > 1 or p["series"][0][0]:
            npts = sum(np.size(y) for _, y, _ in p["series"])
            ax.legend(fontsize=8, loc="best" if npts <= 20000 else "upper right")   # 'best' scans every point
    if title:
        fig.suptitle(title, fontsize=11)
    # fixed margins in inches (tight_layout measures every text and doubles the drawing time)
    top = 1.0 - (0.6 if title else 0.3) / height
    fig.subplots_adjust(left=0.8 / fig.get_figwidth() + 0.04, right=0.75 if crowded else 0.97,
                        bottom=0.55 / height, top=top, hspace=0.5)
    fig.savefig(path, dpi=110)
    return Path(path)


def plot_result(res, out_dir) -> list[Path]:
    """Plots of one run: every output against time (grouped by unit), and, for a
    mechanism with a ``crank_angle`` output, the strains against the crank angle."""
    out_dir = Path(out_dir)
    by_unit: dict[str, list[str]] = {}
    for name, unit in res.units.items():
        by_unit.setdefault(unit, []).append(name)
    panels = []
    for unit, names in by_unit.items():   # one panel per unit and order of magnitude
        peak = {n: float(np.nanmax(np.abs(res.columns[n]))) if res.columns[n].size else 0.0 for n in names}
        group, top = [], None
        for n in sorted(names, key=lambda n: -peak[n]):
            if group and peak[n] < top / 20.0:   # 20x smaller: invisible beside the others
                panels.append({"x": res.t, "ylabel": f"[{unit}]", "series": group})
                group = []
            if not group:
                top = max(peak[n], 1e-300)
            group.append((n, res.columns[n], None))
        panels.append({"x": res.t, "ylabel": f"[{unit}]", "series": group})
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


_MU_STYLE = {"real+": ("^", "tab:red", "+1"), "real-": ("v", "tab:purple", "−1"), "complex": ("o", "tab:orange", "")}


def _region_label(part: dict) -> str:
    if part["type"] != "complex":
        return _MU_STYLE[part["type"]][2]
    a, b = part["angle_deg"]
    return f"±{a:.0f}°" if round(a) == round(b) else f"±{a:.0f}–{b:.0f}°"


def _part_spans(regions):
    """(lo, hi, part) of every part of every region: boundaries halfway between the samples on either side."""
    for reg in regions:
        parts = reg["parts"]
        for k, part in enumerate(parts):
            left = parts[k - 1]["to"] if k > 0 else reg["below"]
            right = parts[k + 1]["from"] if k + 1 < len(parts) else reg["above"]
            yield (0.5 * (left + part["from"]) if left is not None else part["from"],
                   0.5 * (part["to"] + right) if right is not None else part["to"], part)


def _stability_top(ax, ok, regions, stable_rate):
    """Growth rate ln max|mu| / T (symlog) against speed: the threshold line and the stable band under it,
    unstable points marked by multiplier type, the unstable regions shaded and labelled with it."""
    sp = np.array([r["speed"] for r in ok])
    rate = np.array([r["growth_rate"] for r in ok])
    stable = np.array([bool(r["stable"]) for r in ok])
    kind = np.array([r.get("multiplier", "") for r in ok])
    ax.plot(sp, rate, "k-", lw=0.6)
    ax.plot(sp[stable], rate[stable], "b.", ms=2, label="stable")
    for k, (marker, color, sym) in _MU_STYLE.items():
        sel = ~stable & (kind == k)
        if sel.any():
            ax.plot(sp[sel], rate[sel], marker, color=color, ms=4, ls="none",
                    label=f"unstable, {'complex pair' if k == 'complex' else 'real ' + sym}")
    ax.set_yscale("symlog", linthresh=1e-3, linscale=0.5)
    ymax = max(10.0, float(rate.max()))
    ymin = min(-1e-3, float(rate.min()) * 3)
    ax.set_ylim(ymin, ymax * 30)
    if stable_rate is not None:
        ax.axhspan(ymin, stable_rate, color="tab:green", alpha=0.10, lw=0)
        ax.axhline(stable_rate, color="tab:green", lw=1.0, ls="--",
                   label=f"threshold {stable_rate:g} 1/s (|μ| = exp({stable_rate:g}·2π/Ω)): stable below")
    width = sp.max() - sp.min()
    n = 0
    for lo, hi, part in _part_spans(regions or []):
        color = _MU_STYLE[part["type"]][1]
        ax.axvspan(lo, hi, color=color, alpha=0.12, lw=0)
        if hi - lo > 0.015 * width:   # narrow parts: the markers say their type
            ax.text(0.5 * (lo + hi), ymax * 10 ** (1.0 - 0.45 * (n % 3)), _region_label(part), color=color,
                    fontsize=7, ha="center")
            n += 1
    ax.set_ylabel("growth rate ln max|μ| / T [1/s]")
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=7, loc="lower right")


def plot_stability(rows: list, path, *, title: str = "", regions=None, stable_rate: float | None = None,
                   nmodes: int = 3, kmax: int = 4):
    """Stability chart: top, the growth rate ln max|mu| / T (symlog) against crank speed with the stability
    threshold ``stable_rate`` and the stable band under it, the unstable points marked by the type of their dominant
    multiplier and the unstable ``regions`` (:func:`flexmech_py.regions.unstable_regions`) shaded and
    labelled with it (+1, -1, or the angle of a complex pair); bottom, the frozen natural-frequency
    bands along the cycle against speed with the lines k Omega / 2 (a band crossing k Omega / 2 at
    Omega means 2 omega_i = k Omega there).  Returns the path, or None without matplotlib."""
    if not have_matplotlib():
        return None
    import matplotlib.pyplot as plt

    ok = sorted((r for r in rows if "error" not in r), key=lambda r: r["speed"])
    if not ok:
        return None
    sp = np.array([r["speed"] for r in ok])
    nm = min(nmodes, sum(1 for k in ok[0] if k.startswith("omega") and k.endswith("_min")))
    lo = np.array([[r[f"omega{k}_min"] for k in range(1, nm + 1)] for r in ok])
    hi = np.array([[r[f"omega{k}_max"] for k in range(1, nm + 1)] for r in ok])
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(10, 8.5), sharex=True, gridspec_kw={"height_ratios": [1, 1.3]})
    _stability_top(ax1, ok, regions, stable_rate)
    for m in range(nm):
        ax2.fill_between(sp, lo[:, m], hi[:, m], alpha=0.35, label=f"ω{m + 1} along the cycle")
    for i in range(nm):
        for j in range(i + 1, nm):
            ax2.plot(sp, 0.5 * (lo[:, i] + lo[:, j]), "k--", lw=0.6)
            ax2.plot(sp, 0.5 * (hi[:, i] + hi[:, j]), "k--", lw=0.6)
            ax2.text(sp[-1], 0.5 * (hi[-1, i] + hi[-1, j]), f" (ω{i + 1}+ω{j + 1})/2", fontsize=7, va="center")
    top = 1.15 * float(np.max(hi[:, nm - 1]))
    for k in range(1, 2 * kmax + 1):
        ax2.plot(sp, k * sp / 2, color="gray", lw=0.8, ls="-" if k % 2 == 0 else ":")
        xk = min(sp[-1], 2 * top / k * 0.97)
        if xk > sp[0]:
            ax2.text(xk, k * xk / 2, f"{k}Ω/2" if k % 2 else (f"{k // 2}Ω" if k > 2 else "Ω"), fontsize=7, color="gray")
    ax2.set_ylim(0, top)
    ax2.set_xlabel("crank speed Ω [rad/s]")
    ax2.set_ylabel("frequency [rad/s]")
    ax2.grid(True, alpha=0.25)
    ax2.legend(fontsize=8, loc="upper left")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.subplots_adjust(left=0.08, right=0.88, top=0.92, bottom=0.07, hspace=0.08)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


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
    from matplotlib.ticker import NullFormatter

    n = len(panels)
    ncol = 2 if n > 1 else 1
    nrow = (n + ncol - 1) // ncol
    spare = nrow * ncol > n          # an empty panel slot takes the legend; otherwise it goes on the right
    width = 7.2 * ncol + (0.0 if spare else 4.2)
    fig, axes = plt.subplots(nrow, ncol, figsize=(width, 4.6 * nrow + 0.6), squeeze=False)
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
        ax.xaxis.set_minor_formatter(NullFormatter())   # minor labels collide on short decades
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    if handles and spare:
        list(axes.flat)[n].legend(list(handles.values()), list(handles.keys()), fontsize=8, loc="upper left")
    elif handles:
        fig.legend(list(handles.values()), list(handles.keys()), fontsize=7, loc="upper left",
                   bbox_to_anchor=((7.2 * ncol) / width, 0.93), borderaxespad=0.0)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout(rect=(0, 0, (7.2 * ncol) / width, 0.97))
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)


def plot_samples(path, inputs: dict, outputs: dict, corr: list, *, title: str = "", max_inputs: int = 4):
    """Monte-Carlo figure: a row per key output -- its histogram, then its scatter against each input
    (the ``max_inputs`` inputs with the largest |Spearman| first), the rank correlation in each panel.
    ``inputs``/``outputs``: {name: values over the successful samples}; ``corr``: rows of
    :func:`flexmech_py.sampling.correlations`.  Returns the path, or None without matplotlib."""
    if not have_matplotlib() or not outputs:
        return None
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    rho = {(c["output"], c["input"]): c["spearman"] for c in corr}
    strength = {i: max((abs(rho.get((o, i), 0.0)) if rho.get((o, i)) == rho.get((o, i)) else 0.0) for o in outputs)
                for i in inputs}
    shown = sorted(inputs, key=lambda i: -strength[i])[:max_inputs]
    nrow, ncol = len(outputs), 1 + len(shown)
    fig = Figure(figsize=(2.7 * ncol + 0.6, 2.3 * nrow + 0.8))
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrow, ncol, squeeze=False)
    for r, (oname, y) in enumerate(outputs.items()):
        ax = axes[r, 0]
        ax.hist(y, bins=max(5, min(40, int(np.sqrt(y.size)) + 1)), color="0.55", edgecolor="white")
        ax.axvline(np.mean(y), color="C3", lw=1.0)
        ax.set_ylabel(oname, fontsize=8)
        ax.set_title(f"mean {np.mean(y):.4g}, sd {np.std(y, ddof=1) if y.size > 1 else 0:.2g}", fontsize=7)
        for c, iname in enumerate(shown, start=1):
            ax = axes[r, c]
            ax.plot(inputs[iname], y, ".", ms=3, color="C0", alpha=0.7)
            ax.set_title(f"Spearman {rho.get((oname, iname), float('nan')):+.2f}", fontsize=7)
            if r == nrow - 1:
                ax.set_xlabel(iname, fontsize=8)
        if r == nrow - 1:
            axes[r, 0].set_xlabel("value (histogram)", fontsize=8)
    from matplotlib.ticker import MaxNLocator

    for ax in axes.flat:
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.25)
        ax.xaxis.get_offset_text().set_fontsize(7)
        ax.yaxis.get_offset_text().set_fontsize(7)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    return Path(path)
