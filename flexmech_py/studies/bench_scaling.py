"""The scaling section of ``flexmech bench``: every bundled mechanism in every model over a mesh ladder
(docs/performance.md, "Scaling on every mechanism"), so that a regression on any topology shows.

Per case, model and mesh: the kernel's CPU time per step and per element and step, the Newton
iterations per step, and for the coupled and nonlinear models the structure of the step's linear
algebra as the kernel reports it (:meth:`flexmech_py.models.constrained.coupled.CoupledModel.structure`: the band's
half width, the unknowns eliminated densely, the operations of one factorization); per case and
model the fitted exponent of time per step against elements over the ladder, and the cost per
element relative to the seed four-bar's in the same model at the same mesh.  Generalized-alpha
(rho_inf 0.8), dt = 1e-5 s, no error estimate.  The full ladder is 4..64 elements per link, each
time the marginal cost ((kernel CPU of 3 s steps - of s steps) / 2 s: the set-up cancels); the quick
one 2 and 4 elements per link with one short run each (the tests run it).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from .bench_runs import bench_case, fit_exponent, table
from ..base.bundled import cases_dir
from ..case import load_case
from ..base.errors import CaseError, SolverError
from ..run.simulate import Prepared

__all__ = ["MODELS", "LADDER", "bench_scaling", "scaling_summary", "scaling_pivot", "scaling_rows"]

#: the model families (``nonlinear-shared``: the nonlinear model with solver.node_angles = "shared")
MODELS = ("hac", "classic", "classic-translational", "coupled", "nonlinear", "nonlinear-shared")
#: elements per link of the ladder, full and quick
LADDER = {False: (4, 8, 16, 32, 64), True: (2, 4)}
#: element-steps of one timed run per model kind (about 40-120 ms of kernel time on the machine of
#: docs/performance.md), and its limits in steps
WORK = {"superposition": 200_000, "coupled": 20_000, "nonlinear": 8_000}
QUICK_WORK = {"superposition": 4_000, "coupled": 800, "nonlinear": 400}
STEPS_MIN, STEPS_MAX = 10, 5000
SEED = "fourbar_hac"
#: the range of the fitted exponents (elements per link)
FIT_FROM, FIT_TO = 4, 64


def _kind(model: str) -> str:
    return model.split("-")[0] if model.startswith(("coupled", "nonlinear")) else "superposition"


def _steps(model: str, elements: int, quick: bool) -> int:
    work = (QUICK_WORK if quick else WORK)[_kind(model)]
    return int(min(STEPS_MAX, max(STEPS_MIN, round(work / max(elements, 1)))))


class _Runs:
    """The prepared runs of one case and mesh, by (steps, shared node angles): a run of a model times
    its kernel (CPU seconds) on them."""

    def __init__(self, path: Path, epl: int):
        self.path, self.epl, self.prepared = path, epl, {}

    def __call__(self, model: str, steps: int):
        """(kernel CPU seconds, prepared case, result) of one run of the given steps."""
        key = (steps, model == "nonlinear-shared")
        if key not in self.prepared:
            extra = ["solver.error_estimate='none'", "solver.integrator='generalized-alpha'"]
            if key[1]:
                extra.append("solver.node_angles='shared'")
            p = Prepared(bench_case(self.path, steps, 10, extra), elements_per_link=self.epl)
            p._checked = True   # the zero-stiffness check (a dense eigenvalue problem) would cost more than the run
            self.prepared[key] = p
        p = self.prepared[key]
        res = p.run("nonlinear" if key[1] else model)
        return p.last_cpu["kernel_cpu_s"], p, res


def _row(case: str, model: str, epl: int, steps: int, per_step: float, p, res) -> dict:
    base = "nonlinear" if model == "nonlinear-shared" else model
    nan = float("nan")
    row = {"case": case, "model": model, "elements_per_link": epl, "steps": steps}
    if base in ("coupled", "nonlinear"):
        cm = p.coupled[base]
        st = cm.solver or {}
        nel = int(sum(cm.n_el))
        row.update(elements=nel, unknowns=int(cm.nfree) + len(cm.rows), us_per_step=1e6 * per_step,
                   us_per_element_step=1e6 * per_step / nel,
                   newton_per_step=res.extra["coupled"]["newton"]["mean_per_step"], path=st.get("path", ""),
                   band_half_width=st.get("band_half_width", -1), dense_unknowns=st.get("dense_unknowns", -1),
                   flops_factor_per_element=st.get("flops_per_factorization", nan) / nel)
    else:
        fe = p.fe
        row.update(elements=fe.nel, unknowns=fe.nfree, us_per_step=1e6 * per_step,
                   us_per_element_step=1e6 * per_step / fe.nel, newton_per_step=nan, path="band",
                   band_half_width=fe.bandwidth, dense_unknowns=0, flops_factor_per_element=nan)
    return row


def bench_scaling(cases: Path, quick: bool, progress) -> list[dict]:
    """The rows of the scaling table (one per case, model and mesh; a failed run is a row of nan)."""
    rows = []
    for path in sorted(Path(cases).glob("*.toml")):
        flexible = sum(1 for ln in load_case(path).mechanism.links if not ln.rigid)
        for epl in LADDER[quick]:
            run = _Runs(path, epl)
            for model in MODELS:
                t0 = time.perf_counter()
                s = _steps(model, flexible * epl, quick)
                try:
                    if quick:
                        t, p, res = run(model, s)
                        rows.append(_row(path.stem, model, epl, s, t / s, p, res))
                    else:   # the marginal cost of 2 s steps: the set-up cancels
                        t1 = run(model, s)[0]
                        t3, p, res = run(model, 3 * s)
                        rows.append(_row(path.stem, model, epl, 3 * s, max(t3 - t1, 0.0) / (2 * s), p, res))
                except (CaseError, SolverError) as exc:    # reported, not fatal: the table goes on
                    progress(f"  {path.stem} {model} {epl} el/link: {type(exc).__name__}: {exc}".splitlines()[0])
                    rows.append(_failed_row(path.stem, model, epl, f"failed: {type(exc).__name__}"))
                    continue
                r = rows[-1]
                progress(f"  {path.stem:31s} {model:21s} {epl:3d} el/link {r['us_per_step']:10.1f} us/step "
                         f"{r['us_per_element_step']:7.3f} us/element  ({time.perf_counter() - t0:.1f} s)")
    return rows


def _failed_row(case: str, model: str, epl: int, why: str) -> dict:
    nan = float("nan")
    return {"case": case, "model": model, "elements_per_link": epl, "steps": 0, "elements": 0, "unknowns": 0,
            "us_per_step": nan, "us_per_element_step": nan, "newton_per_step": nan, "path": why,
            "band_half_width": -1, "dense_unknowns": -1, "flops_factor_per_element": nan}


def scaling_summary(rows: list[dict]) -> list[dict]:
    """Per case and model: the fitted exponent of time per step against elements (FIT_FROM..FIT_TO
    el/link, or the whole quick ladder) and of the operations per factorization, and the cost per
    element and step at the finest mesh relative to the seed four-bar's (same model and mesh)."""
    out = []
    seed = {(r["model"], r["elements_per_link"]): r["us_per_element_step"] for r in rows if r["case"] == SEED}
    for case in dict.fromkeys(r["case"] for r in rows):
        for model in MODELS:
            rs = [r for r in rows if r["case"] == case and r["model"] == model and FIT_FROM <= r["elements_per_link"] <= FIT_TO
                  and np.isfinite(r["us_per_step"])]
            if len(rs) < 2:
                rs = [r for r in rows if r["case"] == case and r["model"] == model and np.isfinite(r["us_per_step"])]
            if not rs:
                continue
            top = max(rs, key=lambda r: r["elements_per_link"])
            ref = seed.get((model, top["elements_per_link"]), float("nan"))
            fl = [(r["elements"], r["flops_factor_per_element"] * r["elements"]) for r in rs
                  if np.isfinite(r.get("flops_factor_per_element", float("nan")))]
            out.append({"case": case, "model": model,
                        "ladder": f"{rs[0]['elements_per_link']}..{top['elements_per_link']}",
                        "exponent_time": fit_exponent([r["elements"] for r in rs], [r["us_per_step"] for r in rs]),
                        "exponent_flops": fit_exponent(*zip(*fl)) if len(fl) >= 2 else float("nan"),
                        "us_per_element_step_finest": top["us_per_element_step"],
                        "relative_to_seed_fourbar": top["us_per_element_step"] / ref if ref > 0 else float("nan"),
                        "newton_per_step_finest": top.get("newton_per_step", float("nan"))})
    return out


def scaling_pivot(rows: list[dict]) -> list[dict]:
    """Kernel microseconds per step by case and model (rows) and elements per link (columns)."""
    ladder = sorted({r["elements_per_link"] for r in rows})
    out = []
    for case in dict.fromkeys(r["case"] for r in rows):
        for model in MODELS:
            rs = {r["elements_per_link"]: r for r in rows if r["case"] == case and r["model"] == model}
            if rs:
                out.append({"case": case, "model": model,
                            **{f"{e}": rs[e]["us_per_step"] if e in rs else math.nan for e in ladder}})
    return out


def scaling_rows(rows: list[dict]) -> list[dict]:
    """bench_summary.csv's rows of the scaling section: per case and model the fitted exponent, and for
    the nonlinear model the cost per element relative to the seed four-bar's."""
    out = []
    for f in scaling_summary(rows):
        key = f"scaling.{f['case']}.{f['model']}"
        out.append({"metric": f"{key}.exponent", "value": f["exponent_time"], "unit": "1",
                    "note": f"time per step ~ elements^p, {f['ladder']} el/link"})
        if f["model"].startswith("nonlinear"):
            out.append({"metric": f"{key}.relative_to_seed_fourbar", "value": f["relative_to_seed_fourbar"], "unit": "1",
                        "note": "kernel time per element and step at the finest mesh / the seed four-bar's"})
    return out


def main(argv=None) -> int:
    """``python -m flexmech_py.studies.bench_scaling [--quick] [CASES]``: this section of ``flexmech bench``
    alone, its two tables on stdout (docs/performance.md regenerates from it)."""
    ap = argparse.ArgumentParser(prog="python -m flexmech_py.studies.bench_scaling", description=main.__doc__)
    ap.add_argument("--quick", action="store_true", help="the quick ladder (2 and 4 elements per link)")
    ap.add_argument("cases", nargs="?", default=None, help="folder of case files (default: the bundled cases)")
    args = ap.parse_args(argv)
    rows = bench_scaling(Path(args.cases) if args.cases else cases_dir(), args.quick,
                         lambda msg: print(msg, file=sys.stderr, flush=True))
    pivot = scaling_pivot(rows)
    print("kernel CPU per step [us] against elements per link\n" + table(pivot, list(pivot[0])))
    print("\nfits\n" + table(scaling_summary(rows), ["case", "model", "ladder", "exponent_time", "exponent_flops",
                                                   "us_per_element_step_finest", "relative_to_seed_fourbar",
                                                   "newton_per_step_finest"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
