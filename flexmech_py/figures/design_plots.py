"""Figures of the design commands: the stress envelope drawn along the mechanism, and an
optimization's convergence.  Plotting only: the numbers come from flexmech_py.strength.analysis and
flexmech_py.studies.optimize; nothing here computes them."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .plots import have_matplotlib, save_figure

__all__ = ["plot_stress_envelope", "plot_convergence"]


def _mechanism_panel(ax, case, env, config, vmax, plt):
    from matplotlib.collections import LineCollection

    ox, oy, phi = config
    for li, ln in enumerate(case["links"]):       # every link's axis, the flexible ones coloured below
        c, s = np.cos(phi[li]), np.sin(phi[li])
        ax.plot([ox[li], ox[li] + ln["length"] * c], [oy[li], oy[li] + ln["length"] * s], color="0.75", lw=6,
                solid_capstyle="round", zorder=1)
    lc, notes = None, []
    for le in env.links:
        st = le.st
        li = st.index
        c, s = np.cos(phi[li]), np.sin(phi[li])
        x, y = ox[li] + st.fractions * st.length * c, oy[li] + st.fractions * st.length * s
        mag = np.maximum(le.smax, -le.smin) / 1e6
        seg = np.stack([np.column_stack([x[:-1], y[:-1]]), np.column_stack([x[1:], y[1:]])], axis=1)
        lc = LineCollection(seg, cmap="inferno_r", norm=plt.Normalize(0.0, vmax), lw=5, zorder=2)
        lc.set_array(0.5 * (mag[:-1] + mag[1:]))
        ax.add_collection(lc)
        k = int(np.argmax(mag))
        ax.plot(x[k], y[k], marker="*", ms=14, color="tab:blue", mec="white", zorder=3)
        sf = f", SF {st.yield_strength / (mag[k] * 1e6):.2g}" if st.yield_strength and mag[k] > 0 else ""
        notes.append(f"{st.name}: {mag[k]:.3g} MPa at {st.fractions[k]:.2g} L{sf}")
    ax.text(0.02, 0.98, "\n".join(notes), transform=ax.transAxes, va="top", fontsize=8,
            bbox={"facecolor": "white", "alpha": 0.85, "edgecolor": "0.7"})
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.margins(0.15, 0.35)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title("largest |stress| along the links (star: critical station)", fontsize=9)
    return lc


def _finish(fig, path, title: str, plt) -> Path:
    """Title, layout, the file written (naming it when the write fails), the figure closed."""
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def plot_stress_envelope(path, case, env, title: str) -> Path | None:
    """stress_envelope.png: the mechanism at the window's first frame with each flexible link coloured by
    the largest |outer-fibre stress| at its stations, and the envelope (largest tension, largest
    compression) along every link with its yield strength.  ``env``: a StressEnvelope that has seen
    the run."""
    if not have_matplotlib() or not env.links or env.config is None:
        return None
    import matplotlib.pyplot as plt

    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(12, 4.8), gridspec_kw={"width_ratios": [1.1, 1]})
    vmax = max(float(np.max(np.maximum(le.smax, -le.smin))) for le in env.links) / 1e6
    lc = _mechanism_panel(ax0, case, env, env.config, vmax, plt)
    if lc is not None:
        fig.colorbar(lc, ax=ax0, label="largest |stress| [MPa]", shrink=0.85)
    for k, le in enumerate(env.links):
        color = f"C{k}"
        ax1.plot(le.st.fractions, le.smax / 1e6, "-", color=color, label=f"{le.st.name} max")
        ax1.plot(le.st.fractions, le.smin / 1e6, "--", color=color, label=f"{le.st.name} min")
        if le.st.yield_strength:
            ax1.axhline(le.st.yield_strength / 1e6, color=color, lw=0.8, ls=":")
            ax1.axhline(-le.st.yield_strength / 1e6, color=color, lw=0.8, ls=":")
    ax1.axhline(0.0, color="0.5", lw=0.5)
    ax1.set_xlabel("station along the link [fraction of its length]")
    ax1.set_ylabel("outer-fibre stress [MPa]")
    ax1.set_title("envelope over the frames (dotted: +-yield strength)", fontsize=9)
    ax1.legend(fontsize=7, ncol=2)
    ax1.grid(alpha=0.3)
    return _finish(fig, path, title, plt)


def plot_convergence(path, rows: list[dict], objective: str, title: str) -> Path | None:
    """convergence.png: the objective of every evaluated design (dots feasible, crosses not), the best
    feasible so far, and the largest constraint violation."""
    if not have_matplotlib() or not rows:
        return None
    import matplotlib.pyplot as plt

    k = np.arange(1, len(rows) + 1)
    f = np.array([r["objective"] for r in rows], float)
    ok = np.array([r["feasible"] for r in rows], bool)
    viol = np.array([r["violation"] for r in rows], float)
    best = np.minimum.accumulate(np.where(ok, f, np.inf))
    fig, (ax0, ax1) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    ax0.plot(k[ok], f[ok], "o", ms=3, color="C0", label="feasible design")
    ax0.plot(k[~ok], f[~ok], "x", ms=4, color="C3", label="infeasible design")
    if np.any(np.isfinite(best)):
        ax0.step(k, np.where(np.isfinite(best), best, np.nan), where="post", color="k", lw=1.2,
                 label="best feasible so far")
    ax0.set_ylabel(objective)
    ax0.legend(fontsize=8)
    ax0.grid(alpha=0.3)
    if np.any(~ok):
        ax1.semilogy(k[~ok], np.maximum(viol[~ok], 1e-12), "x", ms=4, color="C3")
    ax1.set_ylabel("largest violation of\nan infeasible design")
    ax1.set_xlabel("evaluation")
    ax1.grid(alpha=0.3)
    return _finish(fig, path, title, plt)
