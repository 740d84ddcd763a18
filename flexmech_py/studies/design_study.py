"""The measurements behind docs/validation.md "Stress and fatigue": what the stress and fatigue
post-processing costs against the run it reads, and how a batch of designs scales on a Dask
LocalCluster.  ``python -m flexmech_py.studies.design_study [--quick] [--cost-only]`` prints the tables (Markdown).

- cost: each case run once with the design analysis watching it (CPU time of this process; the
  analysis's own share is measured inside it): the seed cases at their own mesh, the seed four-bar
  at constant speed with 64 elements per link, the design case's steady state;
- speed-up: the same batch of designs of cases/fourbar_design.toml on a LocalCluster of 1 and of
  2 worker processes, alternating (1, 2, 1, 2, ...), wall time of each batch; no cache.
"""

from __future__ import annotations

import argparse
import time

from ..base.bundled import case_path
from ..case import load_case, read_case_file
from ..strength.analysis import DesignAnalysis, crank_period
from .floquet import PeriodicCase, floquet, steady_state
from ..base.notices import silenced
from .optimize_problem import design_point
from ..run.parallel import run_tasks
from ..run.runner import MemorySink, execute
from ..run.simulate import Prepared

__all__ = ["cost_rows", "speedup_rows", "main"]

#: the seed cases' material: 6061-T6's strengths and S-N line with the seed's E and density
SEED_MATERIAL = "{name = '6061-T6', youngs_modulus = 7.1e10, density = 2710.0}"


def _seed_overrides(case_name: str) -> list[str]:
    case = load_case(case_name)
    return [f"links.{ln['name']}.material={SEED_MATERIAL}" for ln in case["links"]
            if not ln.get("rigid") and ln.get("youngs_modulus") == 7.1e10 and ln.get("density") == 2710.0]


def _run_cost(name: str, overrides: list[str], elements=None) -> dict:
    case = load_case(name, _seed_overrides(name) + overrides)
    prep = Prepared(case, elements_per_link=elements)
    model = prep.case["solver"]["model"]
    period = crank_period(prep.case)
    t_end = prep.case["solver"]["t_end"]
    fatigue = period is not None and t_end >= period and all(
        ln.get("material") for ln in prep.case["links"] if not ln.get("rigid"))
    window = (t_end - period, t_end) if fatigue else None
    fe = prep.coupled[model].mesh if model in prep.coupled else prep.fe
    with silenced():
        da = DesignAnalysis(prep.case, fe, window=window, correction="goodman" if fatigue else None)
        res = execute(prep, model, MemorySink(prep.frames), estimate=False, observers=[da])
        cost = da.finish(res)["cost"]
    stations = sum(e.st.fractions.size for e in da.stress.links)
    return {"case": name + (f" ({elements} el/link)" if elements else ""), "model": model, "frames": res.t.size,
            "stations": stations, "fatigue": fatigue, **cost}


def _steady_cost(name: str) -> dict:
    with silenced():
        pc = PeriodicCase(load_case(name), None)
        da = DesignAnalysis(pc.case, pc.fe, correction="goodman", steady=True)
        res = steady_state(pc, floquet(pc))
        da.add(res)
        cost = da.finish(res)["cost"]
    return {"case": f"{name} (steady state)", "model": pc.model, "frames": res.t.size,
            "stations": sum(e.st.fractions.size for e in da.stress.links), "fatigue": True, **cost}


def cost_rows(quick: bool = False) -> list[dict]:
    rows = [_run_cost("fourbar_hac", []), _run_cost("fourbar_constant_speed", []),
            _run_cost("manipulator_bricout", []), _steady_cost("fourbar_design")]
    if not quick:
        rows.append(_run_cost("fourbar_constant_speed", [], elements=64))
    return rows


def _designs(n: int) -> list[dict]:
    raw = read_case_file(case_path("fourbar_design"))
    hs = [3.0e-3 + 0.25e-3 * k for k in range(n)]
    return [{"raw": raw, "source": "fourbar_design.toml", "model": None, "analysis": "steady", "window": None,
             "correction": "goodman", "fatigue": True, "joint_loads": True,
             "overrides": [f"links.coupler.section.height={h!r}", f"links.follower.section.height={h!r}"]}
            for h in hs]


def speedup_rows(designs: int = 4, pairs: int = 2) -> list[dict]:
    tasks = _designs(designs)
    rows = []
    for k in range(pairs):
        for workers in (1, 2):
            t0 = time.perf_counter()
            b = run_tasks(design_point, tasks, progress=False, scheduler=f"local:{workers}")
            rows.append({"pair": k + 1, "workers": workers, "designs": designs, "wall_s": time.perf_counter() - t0,
                         "failed": len(b.failed)})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m flexmech_py.studies.design_study")
    ap.add_argument("--quick", action="store_true", help="no 64 el/link run, one pair of batches")
    ap.add_argument("--cost-only", action="store_true", help="the post-processing cost table only (no LocalCluster)")
    args = ap.parse_args(argv)
    print("| case | model | frames | stations | fatigue | post-processing CPU [s] | run CPU [s] | fraction |")
    print("|---|---|---|---|---|---|---|---|")
    for r in cost_rows(args.quick):
        print(f"| {r['case']} | {r['model']} | {r['frames']} | {r['stations']} | {'yes' if r['fatigue'] else 'no'} | "
              f"{r['post_processing_cpu_s']:.3f} | {r['run_cpu_s']:.2f} | {r['fraction_of_run']:.1%} |")
    if args.cost_only:
        return 0
    print()
    print("| pair | LocalCluster workers | designs | wall [s] |")
    print("|---|---|---|---|")
    for r in speedup_rows(pairs=1 if args.quick else 2):
        print(f"| {r['pair']} | {r['workers']} | {r['designs']} | {r['wall_s']:.1f} |")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
