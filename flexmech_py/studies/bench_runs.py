"""What every section of ``flexmech bench`` shares: a bundled case cut to a number of steps of the
benchmark's step, and the fitted exponent of a cost against a size."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from ..case import load_case

__all__ = ["DT", "bench_case", "fit_exponent", "table", "write_csv"]

DT = 1e-5      # s, the benchmark's step


def bench_case(path, nsteps: int, out_every: int, extra=()):
    """The case at path run for nsteps of DT; outputs at mid-link nodes dropped (1 element per link has none)."""
    case = load_case(path, overrides=[f"solver.dt={DT!r}", f"solver.t_end={nsteps * DT!r}",
                                      f"solver.output_every={out_every}", *extra])
    case["outputs"] = {k: sp for k, sp in case["outputs"].items()
                       if not isinstance(sp.get("at"), str) or sp["at"].endswith((".start", ".end"))}
    return case


def fit_exponent(x, y) -> float:
    """Least-squares slope of log y against log x (nan with fewer than 2 points)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    ok = (x > 0) & (y > 0) & np.isfinite(y)
    if ok.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(x[ok]), np.log(y[ok]), 1)[0])


def table(rows: list[dict], keys) -> str:
    """A fixed-width text table of the given columns."""
    def fmt(v):   # not applicable (nan): "-"
        return ("-" if math.isnan(v) else f"{v:.4g}") if isinstance(v, float) else str(v)
    cols = [[k] + [fmt(r[k]) for r in rows] for k in keys]
    w = [max(len(c) for c in col) for col in cols]
    lines = ["  ".join(c[i].rjust(wi) for c, wi in zip(cols, w)) for i in range(len(rows) + 1)]
    return "\n".join(lines[:1] + ["  ".join("-" * wi for wi in w)] + lines[1:])


def write_csv(path: Path, rows: list[dict]) -> None:
    """rows as a CSV file (the first row's keys as the header; floats to 6 significant digits)."""
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
