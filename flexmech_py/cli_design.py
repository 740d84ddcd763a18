"""The design options of the command line: ``--stress``, ``--fatigue`` and ``--window`` of ``flexmech
run`` and ``flexmech steady``, and the options of ``flexmech optimize`` (its command:
flexmech_py.cli_optimize; docs/cli.md).

    flexmech run CASE --stress [--window T0:T1] [--fatigue goodman|gerber|none]
    flexmech steady CASE --stress [--fatigue goodman|gerber|none]
    flexmech optimize CASE --vary KEY=LO:HI [...] --objective Q [--constraint "Q <= V" ...]
                      [--method slsqp|differential-evolution] [--steady | --window T0:T1] [--jobs N | --scheduler S]
"""

from __future__ import annotations

from pathlib import Path

from .strength.analysis import DesignAnalysis, design_lines, parse_window
from .figures.design_plots import plot_stress_envelope
from .strength.fatigue import CORRECTIONS

__all__ = ["add_design_options", "add_optimize_parser", "design_analysis", "write_design", "print_design",
           "OPTIMIZE_METHODS"]

#: the optimizers of ``flexmech optimize`` (flexmech_py.studies.optimize.METHODS; here without importing SciPy's)
OPTIMIZE_METHODS = ("slsqp", "differential-evolution")


def add_design_options(p, window: bool = True) -> None:
    """--stress, --fatigue (and --window) of a command that runs a case."""
    p.add_argument("--stress", action="store_true",
                   help="stress envelope of every flexible link at every mesh station, safety factors and joint "
                        "loads (stress.csv, joint_loads.csv, design.json, stress_envelope.png)")
    p.add_argument("--fatigue", choices=CORRECTIONS, default=None, metavar="CORRECTION",
                   help="also the fatigue life by rainflow counting and Miner's rule, with this mean-stress "
                        f"correction ({', '.join(CORRECTIONS)}); implies --stress")
    if window:
        p.add_argument("--window", default=None, metavar="T0:T1",
                       help="analyse the frames in T0..T1 s only (for --fatigue: whole crank cycles of the part "
                            "that repeats)")


def design_analysis(args, case, fe=None, steady: bool = False):
    """The DesignAnalysis a command's options ask for, or None."""
    if not (args.stress or args.fatigue):
        return None
    window = parse_window(getattr(args, "window", None), case["solver"]["t_end"])
    return DesignAnalysis(case, fe, window=window, correction=args.fatigue, steady=steady)


def write_design(da, res, folder: Path, plots: bool) -> list:
    """The design files of a finished run (and its figure); prints nothing."""
    da.finish(res)
    paths = da.write(folder)
    if plots:
        p = plot_stress_envelope(folder / "stress_envelope.png", res.case, da.stress,
                                 f"{res.case['case']['title']} - model {res.model} - stress envelope")
        paths += [p] if p else []
    return paths


def print_design(da) -> None:
    if da is not None and da.report is not None:
        print("\n".join(design_lines(da.report)))


def add_optimize_parser(sub, add_scheduler, positive_int) -> None:
    o = sub.add_parser("optimize", help="the best design within bounds (SciPy SLSQP or differential evolution; "
                                        "runs in parallel, cached)")
    o.add_argument("case", help="TOML case file")
    o.add_argument("--vary", action="append", default=[], metavar="KEY.PATH=LO:HI", required=True,
                   help="a case value to vary and its bounds, e.g. links.coupler.section.height=0.5e-3:4e-3")
    o.add_argument("--objective", required=True, metavar="QUANTITY",
                   help="what to minimize: mass, peak_stress, safety_factor, life (maximized), LINK.mass, ... "
                        "or a named output (its largest |value|)")
    o.add_argument("--constraint", action="append", default=[], metavar="'QUANTITY <= VALUE'",
                   help="a limit, e.g. 'safety_factor >= 2' or 'life >= 1e8' (repeatable)")
    o.add_argument("--method", choices=OPTIMIZE_METHODS, default="slsqp", help="optimizer (default slsqp)")
    o.add_argument("--steady", action="store_true",
                   help="analyse the periodic steady state (constant-speed case, superposition model); default "
                        "when the case allows it and no --window is given")
    o.add_argument("--window", default=None, metavar="T0:T1", help="analyse the case's run over T0..T1 s")
    o.add_argument("--fatigue", choices=CORRECTIONS, default="goodman", help="mean-stress correction of the lives")
    o.add_argument("--model", default=None, help="model (default: the case's)")
    o.add_argument("--maxiter", type=positive_int, default=30, help="optimizer iterations at most (default 30)")
    o.add_argument("--popsize", type=positive_int, default=6, help="differential evolution: population per variable")
    o.add_argument("--seed", type=int, default=1, help="differential evolution: random seed (default 1)")
    o.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE", help="override a case value")
    o.add_argument("--jobs", type=positive_int, default=None, help="worker processes (default: every core)")
    add_scheduler(o)
    o.add_argument("--out", default=None, help="output folder (default: results/<case name>-optimize)")
    o.add_argument("--no-plots", action="store_true", help="do not write convergence.png")
