"""The ``flexmech optimize`` command (its options: :func:`flexmech_py.cli_design.add_optimize_parser`;
the optimizer: :mod:`flexmech_py.studies.optimize`).  Exit codes: 0 a feasible optimum, 4
(:data:`~flexmech_py.studies.optimize.EXIT_INFEASIBLE`) no feasible design within the bounds (the least
infeasible one is written, marked), 2 bad input, 3 when a design's run failed at the start."""

from __future__ import annotations

import copy
import sys
from pathlib import Path

from .case import SUPERPOSITION_MODELS, validate_case
from .strength.analysis import crank_period
from .figures.design_plots import plot_convergence
from .base.errors import CaseError
from .studies.optimize import EXIT_INFEASIBLE, optimize, optimum_case_text, write_outputs
from .studies.optimize_problem import Problem, parse_constraint, parse_vary
from .run.outdir import ResultFolder
from .run.parallel import using_executor
from .studies.sweep import load_base

__all__ = ["cmd_optimize"]


def _problem(args, case) -> Problem:
    variables = [parse_vary(t) for t in args.vary]
    keys = [v.key for v in variables]
    if len(set(keys)) != len(keys):
        raise CaseError("--vary", f"a key is given twice: {', '.join(keys)}")
    model = args.model or case["solver"]["model"]
    steady = args.steady or (args.window is None and crank_period(case) is not None and model in SUPERPOSITION_MODELS)
    if args.steady and args.window:
        raise CaseError("--window", "applies to a run; --steady analyses the periodic steady state: give one of the two")
    pr = Problem(variables, args.objective, [parse_constraint(c) for c in args.constraint],
                 "steady" if steady else "run", args.window, args.fatigue)
    pr.check_names(case)
    return pr


def cmd_optimize(args, scheduler) -> int:
    path, base = load_base(args.case, args.set)
    case = validate_case(copy.deepcopy(base), source=str(path))
    problem = _problem(args, case)
    out = Path(args.out) if args.out is not None else Path("results") / f"{path.stem}-optimize"
    with using_executor(scheduler, args.jobs) as executor, ResultFolder(out, "optimize") as rf:   # connect first
        result = optimize(problem, base, path.name, model=args.model, method=args.method, executor=executor,
                          cache=rf.out / "cache", maxiter=args.maxiter, popsize=args.popsize, seed=args.seed,
                          progress=sys.stderr.isatty())
        head = (f"# flexmech optimize: {'optimum' if result['feasible'] else 'NO FEASIBLE DESIGN: the least infeasible'}"
                f" of {path.name} ({problem.objective}; {', '.join(map(str, problem.constraints)) or 'no constraints'})\n")
        (rf.stage / "optimum.toml").write_text(optimum_case_text(base, result, head), encoding="utf-8")
        paths = [rf.stage / "optimum.toml"] + write_outputs(rf.stage, result)
        if not args.no_plots:
            p = plot_convergence(rf.stage / "convergence.png", result["rows"], problem.objective,
                                 f"{path.name}: {problem.objective} ({args.method})")
            paths += [p] if p else []
        rf.commit()
    _print_result(result, [rf.where(p) for p in paths])
    return 0 if result["feasible"] else EXIT_INFEASIBLE


def _print_result(r: dict, paths) -> None:
    word = "optimum" if r["feasible"] else "no feasible design; the least infeasible"
    print(f"{word}: " + ", ".join(f"{k} = {v:.6g}" for k, v in r["optimum"].items())
          + f"; {r['objective']} = {_num(r['objective_value'])}")
    for c in r["constraints"]:
        state = "active" if c["active"] else ("met" if c["met"] else "VIOLATED")
        print(f"  {c['constraint']}: {_num(c['value'])} ({state}, margin {c['margin']:+.3g})")
    print(f"{r['evaluations']} designs ({r['computed']} computed, {r['cached']} cached) in {r['wall_s']:.1f} s; "
          f"{r['method']}")
    print("wrote " + ", ".join(str(p) for p in paths))
    if not r["feasible"]:
        print(f"flexmech: error: no design within the bounds meets the constraints (exit {EXIT_INFEASIBLE}); widen "
              "the bounds or relax a constraint", file=sys.stderr)


def _num(x) -> str:
    return "n/a (the design's run failed)" if x is None else f"{x:.6g}"
