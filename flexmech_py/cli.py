"""The ``flexmech`` command line.

    flexmech run CASE.toml [--model M] [--dt S] [--elements-per-link N] [--integrator I] [--rho-inf X]
                 [--hht-alpha A] [--set KEY.PATH=VALUE ...] [--out DIR] [--overwrite] [--force]
                 [--quiet | --progress] [--no-plots] [--draw [N]] [--view]
    flexmech reproduce [--out DIR]
    flexmech compare RESULT_DIR --reference FILE.csv [--x t|crank_angle] [--columns C ...] [--out DIR]
    flexmech compare --models CASE.toml [--reference-model nonlinear] [--model-list M,M] [--set ...] [--out DIR]
    flexmech stability CASE.toml --speed START:STOP:N [--model M] [--geometric G] [--jobs N] [--out DIR]
    flexmech steady CASE.toml [--model M] [--geometric G] [--out DIR]
    flexmech draw RESULT_DIR [--frames N] [--scale S] [--gif] [--out FILE]
    flexmech view RESULT_DIR [--out FILE.html]
    flexmech modes CASE.toml [--at T | --crank-angle A] [--count N] [--along-cycle K] [--model M] [--closed-loop] [--out DIR]
    flexmech sweep CASE.toml --param KEY.PATH=START:STOP:N [--param ...] [--model M] [--jobs N] [--out DIR]
    flexmech sweep CASE.toml --sample KEY.PATH=normal:MEAN:SD [--sample ...] --samples N [--seed S] [--method lhs]
    flexmech accuracy CASE.toml [--models M,M] [--integrators I,I] [--dt-levels K] [--elements 1,2,4,8] [--grid] ...
    flexmech bench [--quick] [--out DIR] [--cases DIR]
    flexmech fmu CASE.toml --out FILE.fmu [--model M] [--inputs JOINT,...] [--outputs NAME,...] [--set ...]
    flexmech optimize CASE.toml --vary KEY.PATH=LO:HI [...] --objective Q [--constraint "Q <= V" ...] [--method M]
(run and steady take --stress and --fatigue CORRECTION, run also --window T0:T1: docs/cli.md "Design")

The multi-run commands (sweep, stability, accuracy, compare --models) run on the local process
pool (--jobs N) or, with --scheduler tcp://HOST:PORT | local:N (or FLEXMECH_SCHEDULER), on Dask.

Errors a user can cause print one line ``flexmech: error: ...`` and exit with code 2; a run whose
solver stopped writes its partial results, prints the diagnosis that way and exits with code 3, as
does a sweep or stability chart in which any run failed (the others are kept).  Ctrl-C stops a run
keeping the frames so far (marked ``interrupted``) and exits with code 130.
Validity warnings go to stderr as ``flexmech: warning: ...`` lines.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .base import notices
from .cli_accuracy import add_accuracy_parser, cmd_accuracy
from .cli_args import (add_scheduler, batch_line, out_folder, positive_float, positive_int, report_failures,
                       scheduler_of, warn, whole)
from .cli_design import add_design_options, add_optimize_parser, design_analysis, print_design, write_design
from .cli_fmu import add_fmu_parser, cmd_fmu
from .cli_run import add_view_parser, cmd_draw, cmd_run, cmd_view
from .base.errors import FlexmechError
from .base.families import MODEL_CHOICES, MODELS, large_deflection_reference
from .base.version import __version__

__all__ = ["main"]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="flexmech", description="Finite-element dynamics of flexible planar mechanisms.")
    p.add_argument("--version", action="version", version=f"flexmech {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in (_add_run_parsers, _add_compare_parsers, _add_draw_parsers, _add_sweep_parsers, add_accuracy_parser,
                add_fmu_parser):
        add(sub)
    return p


def _add_run_parsers(sub) -> None:
    """The "run" and "reproduce" commands."""
    from .case import INTEGRATORS  # start-up: the case schema loads only when a parser needs it

    r = sub.add_parser("run", help="run a case file and write timeseries.csv, summary.json and plots")
    r.add_argument("case", help="TOML case file (see docs/cases.md)")
    r.add_argument("--model", choices=MODEL_CHOICES,
                   help="model: a superposition load model, coupled, nonlinear, or auto (the cheapest one within "
                        "solver.tolerance; alias of --set solver.model=...; default: the case's solver.model, auto when "
                        "it names none)")
    r.add_argument("--dt", type=positive_float, help="time step [s] (default: the case's solver.dt)")
    r.add_argument("--elements-per-link", type=positive_int, help="beam elements per link (default: the case's mesh)")
    r.add_argument("--integrator", choices=INTEGRATORS,
                   help="time integrator (alias of --set solver.integrator=...; default: the case's, newmark)")
    r.add_argument("--rho-inf", type=float, metavar="X",
                   help="generalized-alpha spectral radius at infinite frequency, 0..1 (alias of --set "
                        "solver.rho_inf=X; implies --integrator generalized-alpha)")
    r.add_argument("--hht-alpha", type=float, metavar="A",
                   help="HHT alpha, 0..1/3 (alias of --set solver.hht_alpha=A; implies --integrator hht)")
    r.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                   help="override a case value, e.g. --set solver.t_end=0.1 --set links.coupler.area=5e-5; "
                        "an empty VALUE removes the key")
    r.add_argument("--out", default=None, help="output folder (default: results/<case name>-<model>)")
    r.add_argument("--no-plots", action="store_true", help="do not write PNG plots")
    r.add_argument("--draw", type=int, nargs="?", const=6, default=None, metavar="N",
                   help="keep the mechanism's points at N frames spread over the run (default 6) in shape.csv "
                        "and draw them, deflection magnified, in drawing.png (at most 12 panels; all frames: "
                        "flexmech draw OUT --gif)")
    r.add_argument("--view", action="store_true",
                   help="also write OUT/view.html: the run in one self-contained page (the mechanism deforming "
                        "over time, its strain, the curves; see flexmech view); keeps the shapes it needs in shape.csv")
    r.add_argument("--quiet", action="store_true", help="no cost estimate and no progress bar on stderr")
    r.add_argument("--progress", action="store_true",
                   help="draw the progress bar even when stderr is not a terminal (default: only on a terminal)")
    r.add_argument("--force", action="store_true",
                   help="run even when timeseries.csv would not fit on the disk of --out")
    r.add_argument("--overwrite", action="store_true",
                   help="replace the results of another run found in --out (files flexmech writes only)")
    add_design_options(r)

    rp = sub.add_parser("reproduce", help="regenerate the seed paper's Figs. 3-12 and a Markdown report")
    rp.add_argument("--out", default="reproduce", help="output folder (default: ./reproduce)")
    rp.add_argument("--cases", default=None, help="folder holding the seed case files (default: the bundled ones)")
    rp.add_argument("--no-gap", action="store_true",
                    help="skip the comparison of the linear configurations with the nonlinear model (about a minute)")
    rp.add_argument("--t-end", type=positive_float, default=None,
                    help="shorten every run to this many seconds (quick look; the seed's claims need the full runs)")


def _add_compare_parsers(sub) -> None:
    """The "compare", "stability" and "steady" commands."""
    c = sub.add_parser("compare", help="compare a result with a reference curve, or several models of one case")
    c.add_argument("result", nargs="?", help="a folder written by `flexmech run` (its timeseries.csv)")
    c.add_argument("--reference", help="reference CSV (format: docs/compare.md)")
    c.add_argument("--models", metavar="CASE", help="run several models of CASE and compare each with one of them")
    c.add_argument("--reference-model", default=large_deflection_reference().name, choices=MODELS,
                   help="the model compared against")
    c.add_argument("--model-list", default=",".join(MODELS),
                   help="comma-separated models to run with --models (default: all)")
    c.add_argument("--x", default="t", choices=("t", "crank_angle"), help="align by time or by (unwrapped) crank angle")
    c.add_argument("--columns", nargs="+", help="columns to compare (default: all in common)")
    c.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE", help="override a case value (--models)")
    c.add_argument("--elements-per-link", type=positive_int, help="beam elements per link (--models)")
    c.add_argument("--jobs", type=positive_int, default=None,
                   help="worker processes for --models (default: every core)")
    add_scheduler(c)
    c.add_argument("--out", default=None, help="output folder (default: RESULT_DIR/compare, or ./compare)")

    st = sub.add_parser("stability", help="Floquet stability chart of a constant-speed case over crank speeds")
    st.add_argument("case", help="TOML case file with a constant-speed kinematic drive")
    st.add_argument("--speed", required=True, metavar="START:STOP:N", help="crank speeds [rad/s]: START:STOP:N or a,b,c")
    st.add_argument("--model", choices=MODELS, help="superposition model (default: the case's solver.model)")
    st.add_argument("--geometric", choices=("none", "quasi_static"),
                    help="geometric stiffness (default: the case's solver.geometric_stiffness)")
    st.add_argument("--modes", type=positive_int, default=4, help="frozen natural frequencies reported (default 4)")
    st.add_argument("--jobs", type=positive_int, default=None, help="worker processes (default: every core)")
    st.add_argument("--resolution", type=float, default=None, metavar="R",
                    help="refine the speed grid down to R rad/s near region edges and peaks of |mu| (default: the "
                         "grid's median spacing / 16)")
    st.add_argument("--refine-rounds", type=whole(0), default=None, metavar="K",
                    help="at most K refinement rounds after the grid (default 8; 0: the grid only)")
    add_scheduler(st)
    st.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE", help="override a case value")
    st.add_argument("--out", default=None, help="output folder (default: results/<case name>-stability); "
                                                "finished speeds are cached in OUT/cache")
    st.add_argument("--no-plots", action="store_true", help="do not write stability.png")

    sd = sub.add_parser("steady", help="periodic steady state of a constant-speed case (shooting with the monodromy matrix)")
    sd.add_argument("case", help="TOML case file with a constant-speed kinematic drive")
    sd.add_argument("--model", choices=MODELS, help="superposition model (default: the case's solver.model)")
    sd.add_argument("--geometric", choices=("none", "quasi_static"),
                    help="geometric stiffness (default: the case's solver.geometric_stiffness)")
    sd.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE", help="override a case value")
    sd.add_argument("--out", default=None, help="output folder (default: results/<case name>-<model>-steady)")
    sd.add_argument("--no-plots", action="store_true", help="do not write PNG plots")
    add_design_options(sd, window=False)


def _add_draw_parsers(sub) -> None:
    """The "draw" and "modes" commands."""
    dr = sub.add_parser("draw", help="draw the mechanism at frames of a run written with `flexmech run --draw`")
    dr.add_argument("result", help="a folder written by `flexmech run --draw` (its shape.csv and summary.json)")
    dr.add_argument("--frames", type=positive_int, default=None,
                    help="panels (GIF: frames), spread over the frames kept (default 6; GIF: every frame kept)")
    dr.add_argument("--scale", type=positive_float, help="magnification of the elastic deflection "
                                                          "(default: its largest drawn as 10 %% of the mechanism)")
    dr.add_argument("--gif", action="store_true",
                    help="an animated GIF of the frames instead of a PNG of panels (default RESULT/drawing.gif)")
    dr.add_argument("--out", default=None, help="file to write (default: RESULT/drawing.png, with --gif RESULT/drawing.gif)")

    add_view_parser(sub)

    md = sub.add_parser("modes", help="natural frequencies and mode shapes of the mechanism frozen at one "
                                      "configuration, or along one cycle")
    md.add_argument("case", help="TOML case file")
    md.add_argument("--at", type=float, metavar="T", help="the instant [s] of the configuration (default 0)")
    md.add_argument("--crank-angle", type=float, metavar="A",
                    help="the configuration where the driven revolute joint first reaches A [deg] (mod 360)")
    md.add_argument("--count", type=positive_int, default=4, help="elastic modes to compute (default 4)")
    md.add_argument("--along-cycle", type=int, metavar="K",
                    help="also the frequencies at K positions over one cycle of the drive, with the crank "
                         "speed harmonics (CSV, JSON, PNG)")
    md.add_argument("--model", choices=MODELS, help="model (default: the case's solver.model)")
    md.add_argument("--geometric", choices=("none", "quasi_static"),
                    help="geometric stiffness of the superposition models (default: the case's)")
    md.add_argument("--elements-per-link", type=positive_int, help="beam elements per link (default: the case's mesh)")
    md.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE", help="override a case value")
    md.add_argument("--out", default=None, help="output folder (default: results/<case name>-<model>-modes)")
    md.add_argument("--no-plots", action="store_true", help="do not write PNG drawings")
    md.add_argument("--closed-loop", action="store_true",
                    help="the eigenvalues of the case's feedback loops closed at their gains, linearized at t = 0, "
                         "and the factor on those gains at which they lose stability (CSV, JSON)")


def _add_sweep_parsers(sub) -> None:
    """The "sweep" and "bench" commands."""
    sw = sub.add_parser("sweep", help="run a case over a parameter grid or Monte-Carlo samples in parallel "
                                      "(resumable) and tabulate it")
    sw.add_argument("case", help="TOML case file")
    sw.add_argument("--param", action="append", default=[], metavar="KEY.PATH=START:STOP:N",
                    help="a grid axis: KEY.PATH=START:STOP:N or KEY.PATH=a,b,c (repeat for a cartesian grid)")
    sw.add_argument("--sample", action="append", default=[], metavar="KEY.PATH=DIST",
                    help="a sampled value instead of a grid: KEY.PATH=normal:MEAN:SD, uniform:LO:HI or "
                         "lognormal:MEAN:SD (repeat for several)")
    sw.add_argument("--samples", type=positive_int, default=None, metavar="N", help="number of samples (--sample)")
    sw.add_argument("--seed", type=int, default=0, metavar="S", help="random seed of the samples (default 0)")
    sw.add_argument("--method", choices=("lhs", "sobol", "random"), default="lhs",
                    help="sampling: Latin hypercube (default), scrambled Sobol' (N a power of 2) or plain random")
    sw.add_argument("--model", choices=MODELS, help="model (default: the case's solver.model)")
    sw.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE", help="override a case value (all points)")
    sw.add_argument("--jobs", type=positive_int, default=None, help="worker processes (default: every core)")
    add_scheduler(sw)
    sw.add_argument("--out", default=None, help="output folder (default: results/<case name>-sweep, or -samples); "
                                                "finished runs are cached in OUT/cache")
    sw.add_argument("--no-plots", action="store_true", help="do not write samples.png (--sample)")
    add_optimize_parser(sub, add_scheduler, positive_int)
    b = sub.add_parser("bench", help="measure kernel, start-up, memory and solver costs (docs/performance.md)")
    b.add_argument("--quick", action="store_true", help="a reduced ladder (1..8 elements per link, fewer steps)")
    b.add_argument("--out", default="bench", help="output folder for the CSV files and bench.png (default: ./bench)")
    b.add_argument("--cases", default=None, help="folder holding the seed case files (default: the bundled ones)")


def _cmd_stability(args) -> int:
    from .case import load_case, study_model  # start-up: only this command loads it
    from .studies.floquet import REFINE_ROUNDS, parse_range, stability_chart  # start-up: only this command loads it
    from .run.outdir import ResultFolder  # start-up: only this command loads it

    case = load_case(args.case, overrides=args.set)
    speeds = parse_range(args.speed, "--speed")
    out = out_folder(args, "stability")
    model = study_model(args.model, case)
    geometric = args.geometric or case["solver"]["geometric_stiffness"]
    with ResultFolder(out, "stability") as rf:
        rows, runs = stability_chart(case, speeds, model=model, geometric=geometric, nmodes=args.modes, jobs=args.jobs,
                                     cache_dir=rf.out / "cache", resolution=args.resolution,
                                     refine_rounds=REFINE_ROUNDS if args.refine_rounds is None else args.refine_rounds,
                                     scheduler=scheduler_of(args))
        paths, regions = _write_chart(rows, case, model, geometric, rf.stage, plots=not args.no_plots)
        rf.commit()
    return _report_chart(rows, runs, regions, [rf.where(p) for p in paths])


def _write_chart(rows, case, model, geometric, folder: Path, plots: bool):
    """stability.csv, stability_regions.csv and stability.png of a chart; (paths, regions)."""
    from .studies.floquet import STABLE_RATE, write_stability_csv  # start-up: only this command loads it
    from .studies.regions import unstable_regions, write_regions_csv  # start-up: only this command loads it

    head = (f"case {case['case']['title']!r}; model {model}; geometric_stiffness {geometric}; "
            f"rayleigh {list(case['solver']['rayleigh'])}; dt <= {case['solver']['dt']:g} s; average acceleration; "
            f"unstable: growth rate > {STABLE_RATE:g} 1/s")
    regions = unstable_regions(rows)
    paths = [folder / "stability.csv", folder / "stability_regions.csv"]
    write_stability_csv(rows, paths[0], head)
    write_regions_csv(regions, paths[1], head)
    if plots:
        from .figures.study_plots import plot_stability  # start-up: only this command loads it

        p = plot_stability(rows, folder / "stability.png", regions=regions, stable_rate=STABLE_RATE,
                           title=f"{case['case']['title']}\nmodel {model}, geometric stiffness {geometric}, "
                                 f"Rayleigh {list(case['solver']['rayleigh'])}")
        paths += [p] if p else []
    return paths, regions


def _report_chart(rows, runs, regions, paths) -> int:
    """Console summary of a stability chart: its cost and refinement, the unstable regions with their
    multiplier type, failed speeds (exit code 3), the files written."""
    import math

    from .studies.floquet import STABLE_RATE  # start-up: only this command loads it
    from .studies.regions import describe_region  # start-up: only this command loads it

    bad = [r for r in rows if "error" in r]
    digits = max(0, math.ceil(0.5 - math.log10(runs.resolution))) if runs.resolution else 1
    refined = (f" + {runs.added} added in {runs.rounds} refinement round(s) to {runs.resolution:.3g} rad/s"
               if runs.rounds else "")
    print(f"{len(rows)} speeds ({len(rows) - runs.added} on the grid{refined}; {runs.computed} computed, "
          f"{runs.cached} cached, {runs.retries} retried) in {runs.wall_s:.1f} s on "
          f"{runs.executor or f'{runs.jobs} process(es)'}" + (f"; {len(bad)} failed" if bad else ""))
    print(f"unstable (growth rate ln max|mu| / T > {STABLE_RATE:g} 1/s): "
          + (f"{len(regions)} region(s)" if regions else "no speed"))
    for reg in regions:
        print("  " + describe_region(reg, digits))
    print("wrote " + ", ".join(str(p) for p in paths))
    speeds = {}   # error message -> the speeds that failed with it
    for r in bad:
        speeds.setdefault(r["error"], []).append(f"{r['speed']:g}")
    reasons = sorted(((f"{e} (speeds {', '.join(v)} rad/s)", len(v)) for e, v in speeds.items()), key=lambda x: -x[1])
    return report_failures(reasons, len(rows), "speeds")


def _cmd_steady(args) -> int:
    from .case import load_case  # start-up: only this command loads it
    from .studies.floquet import PeriodicCase, floquet, steady_state  # start-up: only this command loads it
    from .run.outdir import ResultFolder  # start-up: only this command loads it

    case = load_case(args.case, overrides=args.set)
    pc = PeriodicCase(case, args.model, geometric=args.geometric)
    da = design_analysis(args, pc.case, pc.fe, steady=True)
    with ResultFolder(out_folder(args, f"{pc.model}-steady"), "steady") as rf:
        fr = floquet(pc)
        res = steady_state(pc, fr)
        if da is not None:
            da.add(res)
        design_paths = write_design(da, res, rf.stage, plots=not args.no_plots) if da is not None else []
        paths = res.write(rf.stage) + design_paths
        if not args.no_plots:
            from .figures.plots import plot_result  # start-up: only this command loads it

            paths += plot_result(res, rf.stage)
        rf.commit()
    print(res.table())
    print_design(da)
    f = res.extra["floquet"]
    print(f"period {pc.period:.6g} s in {pc.nsteps} steps; largest Floquet multiplier |mu| = {f['max_abs_multiplier']:.8g} "
          f"({'stable' if f['stable'] else 'UNSTABLE'}); cond(I - Phi) = {f['cond_I_minus_Phi']:.3g}; "
          f"periodicity residual {f['periodicity_residual']:.2g}")
    warn(res.extra.get("warnings", []))
    print("wrote " + ", ".join(str(rf.where(p)) for p in paths))
    return 0


def _cmd_modes(args) -> int:
    from .case import load_case  # start-up: only this command loads it
    from .studies.modes import frequencies_along, modes  # start-up: only this command loads it
    from .run.outdir import ResultFolder  # start-up: only this command loads it

    case = load_case(args.case, overrides=args.set)
    if args.closed_loop:
        return _cmd_closed_loop(args, case)
    kw = {"count": args.count, "model": args.model, "geometric": args.geometric,
          "elements_per_link": args.elements_per_link}
    ms = modes(case, at=args.at, crank_angle=args.crank_angle, **kw)
    with ResultFolder(out_folder(args, f"{ms.model}-modes"), "modes") as rf:
        al = frequencies_along(case, args.along_cycle, **kw) if args.along_cycle is not None else None
        paths = ms.write(rf.stage) + (al.write(rf.stage) if al is not None else [])
        if not args.no_plots:
            from .figures.drawing import draw_modes, plot_along  # start-up: only this command loads it

            paths += [p for p in (draw_modes(rf.stage / "mode_shapes.png", ms),
                                  plot_along(rf.stage / "frequencies_along.png", al) if al is not None else None) if p]
        rf.commit()
    print(ms.table())
    if al is not None:
        print(f"along {al.span}: " + "; ".join(f"mode {k + 1} {al.hz[:, k].min():.4g}..{al.hz[:, k].max():.4g} Hz"
                                               for k in range(al.hz.shape[1]))
              + f"; {len(al.crossings())} crossings with the crank speed harmonics (frequencies_along.json)")
    print("wrote " + ", ".join(str(rf.where(p)) for p in paths))
    return 0


def _cmd_closed_loop(args, case) -> int:
    from .studies import control_eigen as ce  # start-up: only this command loads it
    from .run.outdir import ResultFolder  # start-up: only this command loads it

    for flag, given in (("--at", args.at), ("--crank-angle", args.crank_angle), ("--along-cycle", args.along_cycle),
                        ("--geometric", args.geometric)):
        if given is not None:
            raise FlexmechError(f"{flag}: not with --closed-loop (the loops are linearized about the state at t = 0)")
    loop = ce.linearize_loop(case, model=args.model, elements_per_link=args.elements_per_link)
    summary = ce.closed_loop_summary(loop, args.count, case["case"]["title"])
    with ResultFolder(out_folder(args, f"{loop.model}-closed-loop"), "modes") as rf:
        paths = ce.write_closed_loop(summary, rf.stage)
        rf.commit()
    print(ce.closed_loop_table(summary))
    print("wrote " + ", ".join(str(rf.where(p)) for p in paths))
    return 0


def _cmd_sweep(args) -> int:
    if bool(args.param) == bool(args.sample):
        raise FlexmechError("sweep: give the grid axes (--param KEY.PATH=START:STOP:N ...) or the sampled values "
                            "(--sample KEY.PATH=normal:MEAN:SD ... --samples N), one of the two")
    if args.sample:
        return _cmd_sample(args)
    if args.samples is not None:
        raise FlexmechError("--samples: goes with --sample KEY.PATH=DIST, not with a --param grid")
    from .studies.sweep import sweep  # start-up: only this command loads it

    out = out_folder(args, "sweep")
    sw = sweep(args.case, args.param, model=args.model, overrides=args.set, jobs=args.jobs, out_dir=out,
               scheduler=scheduler_of(args))
    print(batch_line(sw["batch"]))
    print("wrote " + ", ".join(str(p) for p in sw["paths"]))
    return report_failures(sw["failures"], len(sw["rows"]))


def _cmd_sample(args) -> int:
    from .studies.sampling import sample_study  # start-up: only this command loads it

    if args.samples is None:
        raise FlexmechError("--samples: give the number of samples N with --sample, e.g. --samples 64")
    out = out_folder(args, "samples")
    st = sample_study(args.case, args.sample, n=args.samples, seed=args.seed, method=args.method, model=args.model,
                      overrides=args.set, jobs=args.jobs, out_dir=out, scheduler=scheduler_of(args),
                      plots=not args.no_plots)
    warn(st["warnings"])
    print(batch_line(st["batch"]))
    rank = {}
    for c in st["correlations"]:
        rank.setdefault(c["output"], []).append(c)
    for s in st["statistics"]:
        if s["column"] in st["key_outputs"] and s["n"]:
            top = ", ".join(f"{c['input']} {c['spearman']:+.2f}" for c in rank.get(s["column"], [])[:3])
            print(f"{s['column']}: mean {s['mean']:.4g}, sd {s['sd']:.3g}, 5-95 % [{s['p5']:.4g}, {s['p95']:.4g}]; "
                  f"rank correlation {top}")
    print("wrote " + ", ".join(str(p) for p in st["paths"]))
    return report_failures(st["failures"], len(st["rows"]))


def _cmd_bench(args) -> int:
    from .studies.bench import report, run_bench  # start-up: only this command loads it

    res = run_bench(args.out, quick=args.quick, cases_dir=args.cases, progress=lambda msg: print(msg, flush=True))
    print(report(res))
    print("wrote " + ", ".join(str(p) for p in res["paths"]))
    return 0


def _cmd_compare(args) -> int:
    from .studies.compare import compare_models, compare_result_dir, table  # start-up: only this command loads it

    if args.models:
        from .case import load_case  # start-up: only this command loads it
        from .case import with_elements  # start-up: only this command loads it

        if args.result or args.reference:
            raise FlexmechError("compare: give either RESULT_DIR --reference FILE, or --models CASE, not both")
        case = load_case(args.models, overrides=args.set)
        if args.elements_per_link:
            case = with_elements(case, args.elements_per_link)
        models = [m.strip() for m in args.model_list.split(",") if m.strip()]
        bad = [m for m in models if m not in MODELS]
        if bad:
            raise FlexmechError(f"--model-list: unknown model(s) {', '.join(bad)}; choose from {', '.join(MODELS)}")
        out, runs, paths = compare_models(case, models, args.reference_model, x=args.x, columns=args.columns,
                                          out_dir="compare" if args.out is None else args.out, jobs=args.jobs,
                                          scheduler=scheduler_of(args))
        for m, metrics in out.items():
            print(f"{m} against {args.reference_model} (kernel {runs[m].timing['kernel_s']:.3f} s):")
            print(table(metrics))
    else:
        if not args.result or not args.reference:
            raise FlexmechError("compare: give RESULT_DIR and --reference FILE.csv, or --models CASE.toml")
        metrics, paths = compare_result_dir(args.result, args.reference, x=args.x, columns=args.columns,
                                            out_dir=args.out)
        print(table(metrics))
    print("wrote " + ", ".join(str(p) for p in paths[:4]) + (f" and {len(paths) - 4} more" if len(paths) > 4 else ""))
    return 0


def _cmd_reproduce(args) -> int:
    from .studies.reproduce import reproduce  # start-up: only this command loads it

    report = reproduce(args.out, cases_dir=args.cases, progress=lambda msg: print(msg, flush=True), t_end=args.t_end,
                       gap=not args.no_gap)
    print(f"wrote {report}")
    return 0


def _commands() -> dict:
    from .cli_optimize import cmd_optimize  # start-up: only this command loads it

    return {"run": cmd_run, "reproduce": _cmd_reproduce, "compare": _cmd_compare, "stability": _cmd_stability,
            "steady": _cmd_steady, "modes": _cmd_modes, "draw": cmd_draw, "view": cmd_view, "sweep": _cmd_sweep,
            "bench": _cmd_bench, "accuracy": cmd_accuracy, "fmu": cmd_fmu,
            "optimize": lambda args: cmd_optimize(args, scheduler_of(args))}


def main(argv: list[str] | None = None) -> int:
    from .base.errors import one_line, signal_words  # start-up: only this command loads it
    from .base.signals import exit_code, stop_on_signals  # start-up: only this command loads it

    parser = build_parser()
    args = parser.parse_args(argv)
    with stop_on_signals():     # SIGTERM and SIGHUP stop a command as Ctrl-C does (docs/cli.md, exit codes)
        try:
            with notices.silenced():   # each command prints the runs' warnings itself, once
                return _commands()[args.command](args)
        except FlexmechError as exc:
            print(f"flexmech: error: {exc}", file=sys.stderr)
            return exc.exit_code
        except OSError as exc:  # an input file the checks let through (they read their files themselves)
            print(f"flexmech: error: {one_line(exc.filename or '')}: {exc.strerror or exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt as exc:
            print(f"flexmech: {signal_words(exc)}", file=sys.stderr)
            return exit_code(exc)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
