"""The measurements behind the coupled and nonlinear models' default integrator and the check for a
period-2·dt oscillation (docs/validation.md, "Constrained systems"; docs/theory.md section 15.4):

- ``trammel``: the trammel's drive force under the defaults against a converged run (dt/8), undamped
  and with the damping its step-doubling warning suggests, and under average acceleration;
- ``steps``: average acceleration's alternating drive force at t = 0.1 s for four steps (it does not
  shrink with the step);
- ``rho``: the difference from a dt/4 run of the trammel's drive force and the toggle four-bar's
  drive torque for the integrators (the phase error of resolved vibration grows with dissipation);
- ``bundled``: every bundled case in the coupled and nonlinear models under the default integrator
  and under average acceleration: the largest alternating part of any multiplier (the run's check).

    python -m flexmech_py.studies.constrained_study [--only trammel,steps,rho,bundled] [--out FILE.md]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ..base.bundled import case_names, case_path
from ..case import load_case
from ..base.errors import FlexmechError
from ..base.families import names
from ..run.simulate import Prepared

__all__ = ["trammel", "steps", "rho", "bundled", "main"]

NEWMARK = "solver.integrator='newmark'"
GALPHA = {r: ["solver.integrator='generalized-alpha'", f"solver.rho_inf={r}"] for r in (0.0, 0.5, 0.8, 0.9)}
DAMPED = "solver.rayleigh=[0,4.6e-6]"      # 2 % of critical at 1.4 kHz: what the trammel's estimate suggests


def _run(name: str, model: str, sets=(), refine: int = 1):
    """A run of a bundled case (``refine``: dt / refine, frames at the case's frame times)."""
    case = load_case(case_path(name), overrides=["solver.error_estimate='none'", *sets])
    if refine > 1:
        s = case["solver"]
        case = load_case(case_path(name), overrides=["solver.error_estimate='none'", *sets, f"solver.dt={s['dt'] / refine!r}",
                                                     f"solver.output_every={s['output_every'] * refine}"])
    return Prepared(case).run(model)


def _largest(res) -> str:
    lg = res.extra["alternation"]["largest"]
    return "0" if lg is None else f"{100 * lg['relative']:.3g} %"


def _diff(res, ref, col: str) -> tuple[float, float]:
    """(peak / reference peak - 1, max |y - y_ref| / reference peak) of a column."""
    y, yr = res[col], np.interp(res.t, ref.t, ref[col])
    pk = np.max(np.abs(yr))
    return np.max(np.abs(y)) / pk - 1.0, np.max(np.abs(y - yr)) / pk


def trammel() -> list[str]:
    out = ["| model | damping | integrator | drive force peak [N] | peak vs dt/8 | max \\|diff\\| / peak | "
           "largest alternating part |", "|---|---|---|---|---|---|---|"]
    for model in names(superposition=False):
        for damp in ((), (DAMPED,)):
            ref = _run("trammel", model, (*damp, *GALPHA[0.8]), refine=8)
            for label, sets in (("default", ()), ("newmark", (NEWMARK,))):
                res = _run("trammel", model, (*damp, *sets))
                dp, dd = _diff(res, ref, "drive_force")
                out.append(f"| {model} | {'a_K = 4.6e-6 s' if damp else 'none'} | {label} | "
                           f"{np.max(np.abs(res['drive_force'])):.5g} | {100 * dp:+.3g} % | {100 * dd:.3g} % | "
                           f"{_largest(res)} |")
    return out


def steps() -> list[str]:
    out = ["| dt [s] | alternating part of the drive force at 0.1 s [N] |", "|---|---|"]
    for dt in (2e-5, 1e-5, 5e-6, 2.5e-6):
        res = _run("trammel", "coupled", (NEWMARK, "solver.t_end=0.1", f"solver.dt={dt!r}"))
        amp = max((f["amplitude"] for f in res.extra["alternation"]["found"] if f["joint"] == "slide_a"), default=0.0)
        out.append(f"| {dt:g} | {amp:.3g} |")
    return out


def rho() -> list[str]:
    configs = [("newmark", [NEWMARK]), ("HHT α = 0.05", ["solver.integrator='hht'", "solver.hht_alpha=0.05"])] + \
              [(f"generalized-α ρ∞ = {r:g}", GALPHA[r]) for r in (0.9, 0.8, 0.5, 0.0)]
    out = ["| case (coupled) | column | " + " | ".join(c[0] for c in configs) + " |",
           "|---|---|" + "---|" * len(configs)]
    for name, col, sets in (("trammel", "drive_force", ["solver.t_end=0.1"]),
                            ("extreme/toggle_fourbar", "drive_torque", [])):
        ref = _run(name, "coupled", sets + GALPHA[0.8], refine=4)
        cells = [f"{100 * _diff(_run(name, 'coupled', sets + s), ref, col)[1]:.3g} %" for _, s in configs]
        out.append(f"| {name} | {col} | " + " | ".join(cells) + " |")
    return out


def bundled(t_cap: float = 0.5) -> list[str]:
    out = ["| case | t_end [s] | coupled, default | coupled, newmark | nonlinear, default | nonlinear, newmark |",
           "|---|---|---|---|---|---|"]
    for name in case_names():
        t_end = min(load_case(case_path(name))["solver"]["t_end"], t_cap if "spinup" not in name else 20.0)
        cells = []
        for model in names(superposition=False):
            for sets in ((), (NEWMARK,)):
                try:
                    res = _run(name, model, (*sets, f"solver.t_end={t_end!r}"))
                    cells.append(_largest(res) + (" (warns)" if res.extra["alternation"]["found"] else ""))
                except FlexmechError as exc:
                    cells.append(f"stopped at {getattr(exc, 'time', None) or '?'} s")
        out.append(f"| {name} | {t_end:g} | " + " | ".join(cells) + " |")
    return out


STUDIES = {"trammel": trammel, "steps": steps, "rho": rho, "bundled": bundled}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m flexmech_py.studies.constrained_study", description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", default=",".join(STUDIES), help="comma-separated: " + ", ".join(STUDIES))
    ap.add_argument("--out", type=Path, default=None, help="write the tables to this Markdown file too")
    args = ap.parse_args(argv)
    lines = []
    for key in (k.strip() for k in args.only.split(",")):
        table = [f"### {key}", ""] + STUDIES[key]() + [""]
        print("\n".join(table), flush=True)
        lines += table
    text = "\n".join(lines)
    if args.out is not None:
        args.out.write_text(text + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
