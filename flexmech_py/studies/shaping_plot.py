"""The shaper robustness curve: residual vibration against the ratio of the true first frequency to
the designed one, closed form (lines) and measured in PD-controlled runs of the manipulator (points,
flexmech_py.studies.shaping_study); and the command that regenerates docs/validation.md's shaping numbers:
``python -m flexmech_py.studies.shaping_plot --out DIR``."""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import numpy as np  # noqa: E402

from ..figures.plots import save_figure  # noqa: E402
from ..base.shaping import SHAPERS, Shaper, residual_vibration  # noqa: E402
from .shaping_study import study  # noqa: E402

__all__ = ["robustness_figure", "main"]

COLOURS = {"none": "0.4", "zv": "C0", "zvd": "C1", "ei": "C2"}


def robustness_figure(res: dict, path) -> Path:
    """shaping_robustness.png of a :func:`~flexmech_py.studies.shaping_study.study` result."""
    f1 = res["first_mode_hz"]
    r = np.linspace(0.7, 1.3, 301)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for kind in ("none",) + SHAPERS:
        if kind == "none":
            v = np.ones_like(r)
        else:
            d = res["shapers"][kind]
            sh = Shaper(kind, np.array(d["amplitudes"]), np.array(d["times_s"]), f1, d["damping"])
            v = residual_vibration(sh, r * f1)
        ax.plot(r, 100 * v, color=COLOURS[kind], label=f"{kind.upper() if kind != 'none' else 'unshaped'} (closed form)")
        pts = [x for x in res["rows"] if x["shaper"] == kind]
        ax.plot([x["ratio"] for x in pts], [100 * x["relative_settled"] for x in pts], "o", color=COLOURS[kind], mfc="none")
    ax.axvspan(0.8, 1.2, color="0.92", zorder=0)
    ax.set_xlabel("true first frequency / designed first frequency")
    ax.set_ylabel("residual vibration [% of unshaped]")
    ax.set_ylim(0, 110)
    ax.set_title(f"Shaper robustness, manipulator under PD control (f1 = {f1:.2f} Hz)\n"
                 "lines: closed form; circles: time runs (largest tip deflection 0.2-0.5 s after the move)", fontsize=9)
    ax.legend(fontsize=8, loc="upper center")
    ax.grid(alpha=0.3)
    save_figure(fig, Path(path), dpi=120)
    plt.close(fig)
    return Path(path)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m flexmech_py.studies.shaping_plot", description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="shaping", help="output folder (default ./shaping)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    res = study()
    (out / "shaping.json").write_text(json.dumps(res, indent=2) + "\n")
    with open(out / "shaping_runs.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(res["rows"][0]))
        w.writeheader()
        w.writerows(res["rows"])
    robustness_figure(res, out / "shaping_robustness.png")
    for row in res["rows"]:
        print(f"r = {row['ratio']:.1f}  {row['shaper']:>4}: residual {1e3 * row['residual_m']:.3f} mm "
              f"({100 * row['relative']:.1f} % of unshaped), after settling {1e3 * row['residual_settled_m']:.3f} mm "
              f"({100 * row['relative_settled']:.1f} %); closed form {100 * row['predicted_V']:.1f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
