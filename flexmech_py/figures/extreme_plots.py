"""The figures of the stability suite (:mod:`flexmech_py.studies.extreme`): one function per study's figure,
each drawn from the series the study returned.  matplotlib is imported when the figures are asked
for (the suite runs and tabulates without it)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..base.families import family

__all__ = ["plots"]


def plots(results: dict, out: Path, label: dict, spinup_reference: str) -> list[Path]:
    """The PNGs of the studies in ``results`` ({name: (rows, series)}) written into ``out``;
    ``label``: integrator label -> its name in legends; ``spinup_reference``: the spin-up run drawn
    bold.  Returns the paths ([] without matplotlib)."""
    try:
        import matplotlib   # start-up: only the figures need it
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt   # start-up: only the figures need it
    except ImportError:
        return []
    figures = {"spinup": lambda s: _spinup(plt, s, spinup_reference),
               "stiff": lambda s: _stiff(plt, s, label),
               "critical": lambda s: _critical(plt, s),
               "long_run": lambda s: _long_run(plt, s, label),
               "torque_step": lambda s: _torque_step(plt, s, label)}
    paths = []
    for name, draw in figures.items():
        if name in results:
            fname, fig = draw(results[name][1])
            fig.tight_layout()
            paths.append(out / fname)
            fig.savefig(paths[-1], dpi=110)
            plt.close(fig)
    return paths


def _spinup(plt, series: dict, reference: str):
    fig, axs = plt.subplots(len(series), 1, figsize=(8, 3 * len(series)), squeeze=False)
    for ax, (ws, runs) in zip(axs[:, 0], series.items()):
        stable = [np.max(np.abs(y)) for k, (t, y) in runs.items() if not k.endswith("/none")]
        lim = 1.3 * max(stable) if stable else 1.0
        for k, (t, y) in runs.items():
            ax.plot(t, y, label=k, lw=1.4 if k == reference else 1.0,
                    ls="--" if k.endswith("quasi_static") else "-")
        ax.set_ylim(-lim, lim)
        ax.axvline(15.0, color="0.6", lw=0.6)
        ax.set_title(f"spin-up to ω_s = {ws:g} rad/s (T = 15 s)", fontsize=9)
        ax.set_ylabel("tip transverse [m]")
        ax.legend(fontsize=7, loc="lower left")
    axs[-1, 0].set_xlabel("t [s]")
    return "extreme_spinup_tip.png", fig


def _stiff(plt, series: dict, label: dict):
    fig, ax = plt.subplots(figsize=(8, 3.5))
    for lab, (t, y) in series.items():
        ax.plot(t * 1e3, y, lw=0.8, label=label[lab])
    ax.set_xlabel("t [ms]")
    ax.set_ylabel("coupler midspan strain")
    ax.set_title("E × 10⁴, dt = 1e-4 s (280 × the highest period)", fontsize=9)
    ax.legend(fontsize=7)
    return "extreme_stiff_strain.png", fig


#: the resonance bands a speed's tags place it in: forced (k Omega = omega_i) and parametric or
#: combination (omega_i + omega_j = k Omega)
FORCED_TAGS = ("forced k=1 (ω1", "forced k=1 (ω2", "forced k=2 (ω1", "forced k=2 (ω2")
PARAMETRIC_TAGS = ("parametric k=1 (ω1+ω1)", "combination k=1 (ω1+ω2)", "parametric k=1 (ω2+ω2)")


def _critical(plt, pts: list):
    sp = np.array([p["speed"] for p in pts])
    fig, ax = plt.subplots(figsize=(8, 3.5))
    ax.semilogy(sp, [p["undamped"]["mu"] for p in pts], "-", color="C0", label="max|μ| (Floquet), undamped")
    ax.semilogy(sp, [p["damped"]["mu"] for p in pts], "-", color="C1", label="max|μ|, ζ = 1 % at 280 rad/s")
    ax.semilogy(sp, [p["undamped"]["per_cycle"] for p in pts], "o", ms=3, color="C0",
                label="time runs: growth per cycle, undamped")
    ax.semilogy(sp, [p["damped"]["per_cycle"] for p in pts], "s", ms=3, color="C1", label="time runs, damped")
    ax.axhline(1.0, color="0.5", lw=0.6)
    half = 0.5 * (sp[1] - sp[0]) if sp.size > 1 else 5.0
    for p in pts:
        tags = p["bands"].split(", ")
        if any(t.startswith(FORCED_TAGS) for t in tags):
            ax.axvspan(p["speed"] - half, p["speed"] + half, color="C2", alpha=0.12, lw=0)
        if any(t in PARAMETRIC_TAGS for t in tags):
            ax.axvspan(p["speed"] - half, p["speed"] + half, color="C3", alpha=0.12, lw=0)
    ax.set_xlabel("crank speed Ω [rad/s]")
    ax.set_ylabel("growth per crank cycle")
    ax.set_title("shaded (frozen ω₁, ω₂ along the cycle): green k·Ω = ω_i, k = 1, 2; red ω_i + ω_j = Ω", fontsize=9)
    ax.legend(fontsize=7)
    return "extreme_critical_speeds.png", fig


def _long_run(plt, series: dict, label: dict):
    fig, ax = plt.subplots(figsize=(8, 3.5))
    for lab, amp in series.items():
        m, _, l = lab.rpartition("/")
        ax.plot(np.arange(1, amp.size + 1), amp, lw=0.9, label=(m + ", " if m else "hac, ") + label[l])
    ax.set_xlabel("crank cycle")
    ax.set_ylabel("coupler strain, peak-to-peak per cycle")
    ax.legend(fontsize=7)
    return "extreme_long_run_amplitude.png", fig


def _torque_step(plt, series: dict, label: dict):
    keys = [k for k in series if family(k[0]).constrained] or list(series)
    fig, ax = plt.subplots(figsize=(8, 3.5))
    for (model, dt, lab) in keys:
        t, y = series[(model, dt, lab)]
        y = y - y.mean()
        w = 2 * np.pi * np.fft.rfftfreq(y.size, t[1] - t[0])
        ax.loglog(w[1:], np.abs(np.fft.rfft(y))[1:] / y.size, lw=0.8, label=f"{model}, dt {dt:g}, {label[lab]}")
    ax.set_xlabel("ω [rad/s]")
    ax.set_ylabel("|FFT| link-2 axial force [N]")
    ax.legend(fontsize=6)
    return "extreme_torque_step_spectrum.png", fig
