"""``flexmech accuracy``: the error-against-run-time study of a case (docs/accuracy.md)."""

from __future__ import annotations

from .cli_args import add_scheduler, csv_list, out_folder, positive_int, scheduler_of
from .base.families import MODELS

__all__ = ["add_accuracy_parser", "cmd_accuracy"]


def add_accuracy_parser(sub) -> None:
    a = sub.add_parser("accuracy", help="error against run time over a ladder of steps and meshes (docs/accuracy.md)")
    a.add_argument("case", help="TOML case file")
    a.add_argument("--models", type=csv_list(str), default=None, metavar="M,M",
                   help=f"models to study, comma-separated, or 'all' ({', '.join(MODELS)}; default: the case's solver.model)")
    a.add_argument("--integrators", type=csv_list(str), default=None, metavar="I,I",
                   help="time integrators: case (the case's own, default), newmark[:BETA,GAMMA], hht[:ALPHA], "
                        "generalized-alpha[:RHO_INF]")
    a.add_argument("--dt-levels", type=positive_int, default=5, metavar="K",
                   help="time steps dt_0 * 2^k, k = 0..K-1, dt_0 <= the case's solver.dt (default 5)")
    a.add_argument("--elements", type=csv_list(int), default=[1, 2, 4, 8], metavar="N,N",
                   help="mesh ladder, elements per link (default 1,2,4,8)")
    a.add_argument("--grid", action="store_true", help="also run every (step, mesh) pair")
    a.add_argument("--ref-dt-factor", type=positive_int, default=4, metavar="F",
                   help="reference step dt_0 / F, F a power of 2 (default 4)")
    a.add_argument("--ref-elements", type=positive_int, default=None, metavar="N",
                   help="reference mesh, a multiple of 8 (default: 2 x the finest mesh, rounded up to a multiple of 8)")
    a.add_argument("--columns", nargs="+", default=None, help="outputs compared (default: the strain and displacement outputs)")
    a.add_argument("--tolerances", type=csv_list(float), default=[0.1, 0.01, 0.001], metavar="E,E",
                   help="relative errors for the cheapest-run table (default 0.1,0.01,0.001)")
    a.add_argument("--repeat", type=positive_int, default=1, metavar="R",
                   help="time each run R times and keep the minimum kernel time (default 1)")
    a.add_argument("--jobs", type=positive_int, default=None, metavar="J",
                   help="worker processes (default: every core; 1 for the least disturbed timings)")
    add_scheduler(a)
    a.add_argument("--clock", choices=("cpu", "wall"), default="cpu",
                   help="cost of a run: CPU time (default; robust on a shared machine) or wall time of the kernel")
    a.add_argument("--consistency", type=float, default=0.3,
                   help="largest difference of successive observed orders for Richardson extrapolation (default 0.3)")
    a.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE", help="override a case value")
    a.add_argument("--out", default=None, help="output folder (default: results/<case name>-accuracy); holds the resumable cache")
    a.add_argument("--no-plots", action="store_true", help="do not write accuracy.png")
    a.add_argument("--quiet", action="store_true", help="no progress bar")


def cmd_accuracy(args) -> int:
    from .studies.accuracy import accuracy_study  # start-up: only this command loads it

    models = args.models
    if models and [m.strip() for m in models] == ["all"]:
        models = list(MODELS)
    out = out_folder(args, "accuracy")
    st = accuracy_study(args.case, overrides=args.set, models=models, integrators=args.integrators,
                        dt_levels=args.dt_levels, elements=args.elements, grid=args.grid, ref_dt_factor=args.ref_dt_factor,
                        ref_elements=args.ref_elements, columns=args.columns, tolerances=args.tolerances,
                        repeat=args.repeat, jobs=args.jobs, out_dir=out, progress=not args.quiet,
                        scheduler=scheduler_of(args),
                        consistency=args.consistency, plots=not args.no_plots, clock=args.clock)
    b = st.batch
    print(f"{b['runs']} runs ({b['computed']} computed, {b['cached']} cached, {b['failed']} failed, "
          f"{b['retries']} retried) in {b['wall_s']:.1f} s on {b['executor']}")
    for m, ref in st.reference.items():
        for c, e in ref["columns"].items():
            if "time" in e:
                print(f"reference {m} {c}: Richardson time {'applied' if e['time']['applied'] else 'not applied'}, "
                      f"space {'applied' if e['space']['applied'] else 'not applied'}; uncertainty {e['uncertainty_rel']:.1e}")
            else:
                print(f"reference {m} {c}: none ({e.get('reason', '')})")
    for e in st.cheapest:
        if e["column"] != "worst" and len(st.columns) > 1:
            continue
        what = (f"{e['integrator']}, dt {e['dt']:.3g} s, {e['elements_per_link']} elements/link: kernel "
                f"{e['kernel_cpu_s']:.3g} s CPU, {e['kernel_s']:.3g} s wall, error {e['error']:.2g}") \
            if "integrator" in e else e.get("note", "")
        print(f"cheapest {e['model']} to {e['tolerance']:g} ({e['column']}): {what}")
    print("wrote " + ", ".join(str(p) for p in st.paths))
    return 0
