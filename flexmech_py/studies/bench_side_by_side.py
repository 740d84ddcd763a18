"""The side-by-side sections of ``flexmech bench`` (docs/performance.md, "Side by side with
Exudyn"): the seed four-bar (nonlinear and coupled), the seed manipulator, and a multi-loop mechanism
(cases/sixbar_plate.toml: two loops sharing a rigid plate, a constant-speed drive, no Python callback
on either side) at 8, 16 and 32 elements per link, each against Exudyn's ANCF cable model
(:mod:`flexmech_py.studies.bench_exudyn`, :mod:`flexmech_py.studies.bench_exudyn_mechanism`); CPU of the time
integration on both sides, the ratio, and how far the midspan strains agree.  Exudyn is optional:
without it the sections are skipped with one line.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from . import bench_exudyn, bench_exudyn_mechanism
from .bench_runs import table
from ..base.bundled import cases_dir

__all__ = ["exudyn_sections", "exudyn_rows", "exudyn_report", "SIDE_BY_SIDE", "SIDE_BY_SIDE_MECHANISM"]

#: side-by-side runs with Exudyn: (model, elements per link, t_end [s]) in full and quick mode
SIDE_BY_SIDE = {False: [("nonlinear", 16, 0.25), ("coupled", 2, 0.25)], True: [("nonlinear", 4, 0.005), ("coupled", 2, 0.005)]}
#: alternating runs of each side per row, the smaller CPU time kept (full mode; quick mode one run)
SIDE_BY_SIDE_REPEATS = {False: 3, True: 1}


def bench_side_by_side(seed: Path, quick: bool, progress) -> list[dict]:
    """The seed four-bar in flexmech and in Exudyn (flexmech_py.studies.bench_exudyn), dt = 1.25e-5 s,
    generalized-alpha rho_inf = 0.8; [] with one line when Exudyn is not installed."""
    why = bench_exudyn.unavailable()
    if why is not None:
        progress(why)
        return []
    rows = []
    for model, epl, t_end in SIDE_BY_SIDE[quick]:
        r = bench_exudyn.side_by_side(seed, epl=epl, dt=1.25e-5, t_end=t_end, model=model,
                                      repeats=SIDE_BY_SIDE_REPEATS[quick])
        d, dr = r["strain_difference"], r["strain_difference_revolution"] or {}
        rows.append({"model": model, "elements_per_link": epl, "steps": int(round(t_end / 1.25e-5)),
                     "flexmech_cpu_s": r["flexmech_cpu_s"], "exudyn_cpu_s": r["exudyn_cpu_s"], "speedup": r["speedup"],
                     "repeats": len(r["flexmech_cpu_s_all"]),
                     "newton_per_step": r["newton"]["mean_per_step"],
                     "strain_coupler_diff": d["strain_coupler_mid"], "strain_follower_diff": d["strain_follower_mid"],
                     "first_revolution_s": r["first_revolution_s"] or "",
                     "strain_coupler_diff_rev": dr.get("strain_coupler_mid", ""),
                     "strain_follower_diff_rev": dr.get("strain_follower_mid", "")})
        rev = (f"; over the first crank revolution (0-{r['first_revolution_s']:.3g} s) {100 * dr['strain_coupler_mid']:.2g} % "
               f"and {100 * dr['strain_follower_mid']:.2g} %" if dr else "")
        best = f", the smaller of {len(r['flexmech_cpu_s_all'])} runs each" if len(r["flexmech_cpu_s_all"]) > 1 else ""
        progress(f"  {model}, {epl} el/link: flexmech {r['flexmech_cpu_s']:.3g} s, Exudyn {r['exudyn_cpu_s']:.3g} s CPU{best} "
                 f"({r['speedup']:.2f}x); midspan strains differ by {100 * d['strain_coupler_mid']:.2g} % (coupler), "
                 f"{100 * d['strain_follower_mid']:.2g} % (follower) of flexmech's peak over the run{rev}")
    return rows


#: the manipulator side by side: (elements per link, t_end [s]) in full and quick mode
SIDE_BY_SIDE_MANIPULATOR = {False: (8, 0.25), True: (4, 0.005)}


def bench_side_by_side_manipulator(cases: Path, quick: bool, progress) -> list[dict]:
    """The seed manipulator in flexmech (nonlinear) and in Exudyn, dt = 1.25e-5 s, generalized-alpha
    0.8, frames at every step; [] when Exudyn is not installed (bench_side_by_side says so)."""
    if bench_exudyn.unavailable() is not None:
        return []
    epl, t_end = SIDE_BY_SIDE_MANIPULATOR[quick]
    r = bench_exudyn.manipulator_side_by_side(cases / "manipulator_bricout.toml", epl=epl, t_end=t_end,
                                              repeats=SIDE_BY_SIDE_REPEATS[quick])
    row = {"model": "nonlinear", "elements_per_link": epl, "steps": int(round(t_end / 1.25e-5)),
           "flexmech_cpu_s": r["flexmech_cpu_s"], "exudyn_cpu_s": r["exudyn_cpu_s"], "speedup": r["speedup"],
           "repeats": len(r["flexmech_cpu_s_all"])}
    for fc, d in r["strain_difference"].items():
        for k, v in d.items():
            row[f"{k.replace('_mid', '')}_diff_{int(fc)}hz"] = v
    progress(f"  manipulator, {epl} el/link: flexmech {r['flexmech_cpu_s']:.3g} s, Exudyn {r['exudyn_cpu_s']:.3g} s CPU "
             f"({r['speedup']:.2f}x); midspan strains low-passed at 300 Hz differ by "
             f"{100 * r['strain_difference'][300.0]['strain_link1_mid']:.2g} % (link 1), "
             f"{100 * r['strain_difference'][300.0]['strain_link2_mid']:.2g} % (link 2) of flexmech's peak")
    return [row]


#: the multi-loop side by side: (elements per link, t_end [s]) in full and quick mode, and the case
SIDE_BY_SIDE_MECHANISM = {False: [(8, 0.05), (16, 0.05), (32, 0.05)], True: [(4, 0.002)]}
MECHANISM_CASE = "sixbar_plate.toml"


def bench_side_by_side_mechanism(cases: Path, quick: bool, progress) -> list[dict]:
    """The plate six-bar in flexmech (nonlinear, both node-angle forms) and in Exudyn, dt = 1.25e-5 s,
    generalized-alpha 0.8; [] when Exudyn is not installed (bench_side_by_side says so)."""
    if bench_exudyn.unavailable() is not None:
        return []
    rows = []
    for epl, t_end in SIDE_BY_SIDE_MECHANISM[quick]:
        for angles in ("relative", "shared"):
            r = bench_exudyn_mechanism.mechanism_side_by_side(cases / MECHANISM_CASE, epl=epl, t_end=t_end,
                                                               node_angles=angles, repeats=SIDE_BY_SIDE_REPEATS[quick])
            d = r["strain_difference"]
            rows.append({"case": Path(MECHANISM_CASE).stem, "node_angles": angles, "elements_per_link": epl,
                         "steps": int(round(t_end / 1.25e-5)), "flexmech_cpu_s": r["flexmech_cpu_s"],
                         "exudyn_cpu_s": r["exudyn_cpu_s"], "speedup": r["speedup"],
                         "repeats": len(r["flexmech_cpu_s_all"]), "newton_per_step": r["newton"]["mean_per_step"],
                         **{k.replace("_mid", "_diff"): v for k, v in d.items()}})
            progress(f"  six-bar, {epl} el/link, {angles} angles: flexmech {r['flexmech_cpu_s']:.3g} s, Exudyn "
                     f"{r['exudyn_cpu_s']:.3g} s CPU ({r['speedup']:.2f}x); midspan strains differ by "
                     + ", ".join(f"{100 * v:.2g} % ({k})" for k, v in d.items()) + " of flexmech's peak")
    return rows


def exudyn_sections(seed: Path, cases: Path, quick: bool, progress) -> dict:
    """Every side by side: {"exudyn": four-bar rows, "exudyn_manipulator": [row],
    "exudyn_mechanism": six-bar rows} (empty lists without Exudyn)."""
    return {"exudyn": bench_side_by_side(seed, quick, progress),
            "exudyn_manipulator": bench_side_by_side_manipulator(cases, quick, progress),
            "exudyn_mechanism": bench_side_by_side_mechanism(cases, quick, progress)}


def exudyn_rows(res: dict) -> list[dict]:
    """Summary rows of the side-by-side runs with Exudyn (CPU time ratios)."""
    exudyn, exudyn_manipulator = res["exudyn"], res["exudyn_manipulator"]
    rows = [{"metric": f"exudyn.{r['model']}.{r['elements_per_link']}_per_link.speedup", "value": r["speedup"],
             "unit": "1", "note": f"Exudyn CPU / flexmech CPU, seed four-bar, {r['steps']} steps of 1.25e-5 s"}
            for r in exudyn]
    rows += [{"metric": f"exudyn.manipulator.{r['elements_per_link']}_per_link.speedup", "value": r["speedup"],
              "unit": "1", "note": f"Exudyn CPU / flexmech CPU, seed manipulator, {r['steps']} steps of 1.25e-5 s"}
             for r in exudyn_manipulator]
    return rows + [{"metric": f"exudyn.{r['case']}.{r['node_angles']}.{r['elements_per_link']}_per_link.speedup",
                    "value": r["speedup"], "unit": "1",
                    "note": f"Exudyn CPU / flexmech CPU, {r['case']} (nonlinear), {r['steps']} steps of 1.25e-5 s"}
                   for r in res["exudyn_mechanism"]]


def exudyn_report(res: dict) -> list[str]:
    """The stdout tables of the side-by-side sections."""
    return ["", "side by side with Exudyn (seed four-bar, dt = 1.25e-5 s, generalized-alpha 0.8; CPU of the time integration)",
            table(res["exudyn"], ["model", "elements_per_link", "steps", "flexmech_cpu_s", "exudyn_cpu_s", "speedup",
                                  "newton_per_step", "strain_coupler_diff", "strain_follower_diff", "first_revolution_s",
                                  "strain_coupler_diff_rev", "strain_follower_diff_rev"])
            if res.get("exudyn") else "  (not run: Exudyn is not installed)",
            *(["", "side by side with Exudyn (seed manipulator, frames at every step; strain differences of the "
                   "low-passed signals, relative to flexmech's peak)",
               table(res["exudyn_manipulator"], list(res["exudyn_manipulator"][0]))]
              if res.get("exudyn_manipulator") else []),
            *(["", "side by side with Exudyn (multi-loop: plate six-bar, constant-speed drive, no Python callbacks; "
                   "strain differences relative to flexmech's peak)",
               table(res["exudyn_mechanism"], list(res["exudyn_mechanism"][0]))]
              if res.get("exudyn_mechanism") else [])]


def main(argv=None) -> int:
    """``python -m flexmech_py.studies.bench_side_by_side [--quick] [CASES]``: these sections of ``flexmech
    bench`` alone, their tables on stdout (docs/performance.md regenerates from it)."""
    ap = argparse.ArgumentParser(prog="python -m flexmech_py.studies.bench_side_by_side", description=main.__doc__)
    ap.add_argument("--quick", action="store_true", help="the quick sizes (4 elements per link, a few ms)")
    ap.add_argument("cases", nargs="?", default=None, help="folder of case files (default: the bundled cases)")
    args = ap.parse_args(argv)
    cases = Path(args.cases) if args.cases else cases_dir()
    res = exudyn_sections(cases / "fourbar_hac.toml", cases, args.quick,
                          lambda msg: print(msg, file=sys.stderr, flush=True))
    print("\n".join(exudyn_report(res)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
