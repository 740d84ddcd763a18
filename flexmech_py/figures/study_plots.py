"""The figures of the studies (matplotlib, Agg backend): the stability chart of a speed sweep
(:func:`plot_stability`), the work-precision figure of an accuracy study
(:func:`work_precision_figure`) and the input-output panels of a sampling study
(:func:`plot_samples`).  Nothing here computes physics; every value drawn is in the study's rows.
Without matplotlib the functions write nothing and return None (or [])."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .plots import have_matplotlib, save_figure

__all__ = ["plot_stability", "work_precision_figure", "plot_samples", "spread", "region_label", "part_spans"]


def spread(values, gap: float) -> list[float]:
    """Label positions near ``values`` (same order) at least ``gap`` apart: overlapping ones are pushed
    apart symmetrically about their mean."""
    order = np.argsort(values)
    v = np.asarray(values, float)[order]
    groups = [[x] for x in v]
    merged = True
    while merged:   # merge neighbouring clusters whose spread extents overlap
        merged = False
        out = [groups[0]]
        for g in groups[1:]:
            a, b = out[-1], g
            ca = np.mean(a) + 0.5 * gap * (len(a) - 1)
            cb = np.mean(b) - 0.5 * gap * (len(b) - 1)
            if cb - ca < gap:
                out[-1] = a + b
                merged = True
            else:
                out.append(b)
        groups = out
    pos = [np.mean(g) + gap * (k - 0.5 * (len(g) - 1)) for g in groups for k in range(len(g))]
    res = np.empty(len(v))
    res[order] = pos
    return [float(x) for x in res]


_MU_STYLE = {"real+": ("^", "tab:red", "+1"), "real-": ("v", "tab:purple", "−1"), "complex": ("o", "tab:orange", "")}


def region_label(part: dict) -> str:
    """The label of an unstable region's part: +1, −1, or the angle of a complex pair (±a° or ±a–b°)."""
    if part["type"] != "complex":
        return _MU_STYLE[part["type"]][2]
    a, b = part["angle_deg"]
    return f"±{a:.0f}°" if round(a) == round(b) else f"±{a:.0f}–{b:.0f}°"


def part_spans(regions):
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
    for lo, hi, part in part_spans(regions or []):
        color = _MU_STYLE[part["type"]][1]
        ax.axvspan(lo, hi, color=color, alpha=0.12, lw=0)
        if hi - lo > 0.015 * width:   # narrow parts: the markers say their type
            ax.text(0.5 * (lo + hi), ymax * 10 ** (1.0 - 0.45 * (n % 3)), region_label(part), color=color,
                    fontsize=7, ha="center")
            n += 1
    ax.set_ylabel("growth rate ln max|μ| / T [1/s]")
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=7, loc="lower right")


def plot_stability(rows: list, path, *, title: str = "", regions=None, stable_rate: float | None = None,
                   nmodes: int = 3, kmax: int = 4):
    """Stability chart: top, the growth rate ln max|mu| / T (symlog) against crank speed with the stability
    threshold ``stable_rate`` and the stable band under it, the unstable points marked by the type of their dominant
    multiplier and the unstable ``regions`` (:func:`flexmech_py.studies.regions.unstable_regions`) shaded and
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
    pairs = [(i, j) for i in range(nm) for j in range(i + 1, nm)]
    for i, j in pairs:
        ax2.plot(sp, 0.5 * (lo[:, i] + lo[:, j]), "k--", lw=0.6)
        ax2.plot(sp, 0.5 * (hi[:, i] + hi[:, j]), "k--", lw=0.6)
    top = 1.15 * float(np.max(hi[:, nm - 1]))
    ys = spread([0.5 * (hi[-1, i] + hi[-1, j]) for i, j in pairs], 0.035 * top)   # labels apart, not overprinted
    for (i, j), y in zip(pairs, ys):
        ax2.text(sp[-1], y, f" (ω{i + 1}+ω{j + 1})/2", fontsize=7, va="center")
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
    save_figure(fig, path, dpi=110)
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
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return Path(path)


def plot_samples(path, inputs: dict, outputs: dict, corr: list, *, title: str = "", max_inputs: int = 4):
    """Monte-Carlo figure: a row per key output -- its histogram, then its scatter against each input
    (the ``max_inputs`` inputs with the largest |Spearman| first), the rank correlation in each panel.
    ``inputs``/``outputs``: {name: values over the successful samples}; ``corr``: rows of
    :func:`flexmech_py.studies.sampling.correlations`.  Returns the path, or None without matplotlib."""
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
    save_figure(fig, path, dpi=100)
    return Path(path)
