"""The ``flexmech run`` and ``flexmech draw`` commands (their options: :mod:`flexmech_py.cli`).

A run streams its frames into the staging folder of a :class:`~flexmech_py.run.outdir.ResultFolder`
(:class:`~flexmech_py.run.runner.FileSink`), writes its drawing and plots there, and puts them all in
place of the folder's earlier run only when it completed.  A run that stops (a solver failure, a
singular position, Ctrl-C, SIGTERM, SIGHUP, a full disk) writes the frames so far, marked, and
leaves the earlier run untouched (docs/cli.md, "What is left on disk").
"""

from __future__ import annotations

import sys
from pathlib import Path

from .cli_design import design_analysis, print_design, write_design
from .base.errors import FlexmechError, Interrupted, MechanismError, OutputError, SolverError
from .base.names import safe_name
from .run.outdir import ResultFolder, claim
from .base.signals import exit_code

__all__ = ["cmd_run", "cmd_draw", "cmd_view", "add_view_parser", "integrator_overrides", "MAX_PANELS"]

#: panels of the drawing.png of ``run --draw`` (more frames stay in shape.csv for ``flexmech draw --gif``)
MAX_PANELS = 12
#: bytes a kept shape frame takes per drawn point (x, y, dx, dy, rotation)
SHAPE_POINT_BYTES = 40


def integrator_overrides(args) -> list[str]:
    """The ``--set`` overrides that ``--model``, ``--integrator``, ``--rho-inf`` and ``--hht-alpha`` stand
    for (the case is validated with them: e.g. a controlled case's model)."""
    out = [f'solver.model="{args.model}"'] if getattr(args, "model", None) else []
    integrator = args.integrator
    if integrator is None and args.rho_inf is not None:
        integrator = "generalized-alpha"
    elif integrator is None and args.hht_alpha is not None:
        integrator = "hht"
    if integrator is not None:
        out.append(f'solver.integrator="{integrator}"')
    if args.rho_inf is not None:
        out.append(f"solver.rho_inf={args.rho_inf!r}")
    if args.hht_alpha is not None:
        out.append(f"solver.hht_alpha={args.hht_alpha!r}")
    return out


def _shapes(args, prep):
    """The ShapeCollector of ``--draw N`` and ``--view`` (None without either); its frames' memory
    checked first.  ``--view`` keeps as many frames as the page holds (flexmech_py.view.decimate)."""
    from .models.shapes import ShapeCollector, body_points  # start-up: only this command loads it
    from .base.sizes import check_count, format_count  # start-up: only this command loads it
    from .view.decimate import frames_for, kept_points  # start-up: only this command loads it

    if args.draw is not None and args.draw < 2:
        raise FlexmechError(f"--draw: needs 2 frames or more, got {args.draw}")
    count = args.draw or 0
    if args.view:
        count = max(count, frames_for(kept_points(body_points(prep.case.mechanism, prep.fe.node_frac)), prep.frames))
    if not count:
        return None
    kept = min(count, prep.frames)
    points = sum(int(ln.get("elements", 0)) + 1 for ln in prep.case["links"]) + 4 * len(prep.case["links"]) + 8
    check_count(kept, SHAPE_POINT_BYTES * points, "--draw", "drawn frames",
                lambda n: f"draw at most {format_count(n)} frames (e.g. --draw {max(2, min(n, 1000))})")
    return ShapeCollector(prep.case.mechanism, prep.frames, count, prep.coupled)


def cmd_run(args) -> int:
    from .case import load_case  # start-up: only this command loads it
    from .base.progress import RunProgress  # start-up: only this command loads it
    from .run.runner import FileSink, execute  # start-up: only this command loads it
    from .run.simulate import Prepared  # start-up: only this command loads it

    case = load_case(args.case, overrides=args.set + integrator_overrides(args))
    prep = Prepared(case, dt=args.dt, elements_per_link=args.elements_per_link)
    model = args.model or prep.case["solver"]["model"]
    out = args.out if args.out is not None else Path("results") / f"{safe_name(Path(args.case).stem)}-{model}"
    shapes = _shapes(args, prep)
    design = design_analysis(args, prep.case)     # its stations: the mesh of the model that runs
    stopped, paths = None, []
    with ResultFolder(out, "run", claim=lambda: claim(out, prep.case, args.overwrite), overwrite=args.overwrite) as rf:
        sink = FileSink(rf.stage, frames_total=prep.frames, force=args.force)
        progress = RunProgress(lambda: _run_cost(prep, model, sink), bar=True if args.progress else None,
                               quiet=args.quiet)
        try:
            res = execute(prep, model, sink, progress=progress, observers=[o for o in (shapes, design) if o])
        except (Interrupted, SolverError, MechanismError, OutputError) as exc:   # frames so far written, marked
            progress.close()
            if getattr(exc, "partial", None) is None:
                raise
            rf.stopped(str(exc), marked=True)
            stopped = exc
        else:
            progress.close(finished=True)
            paths = _extras(res, shapes, sink, rf.stage, plots=not args.no_plots, design=design,
                            draw=args.draw is not None, view=args.view)
            rf.commit()
    if stopped is not None:
        return _report_stopped(stopped, [rf.where(p) for p in sink.paths], rf)
    print(res.table())
    print_design(design)
    print("wrote " + ", ".join(str(rf.where(p)) for p in paths))
    for w in res.extra.get("warnings", []):
        print(f"flexmech: warning: {w}", file=sys.stderr)
    return 0


def _extras(res, shapes, sink, stage: Path, plots: bool, design=None, draw: bool = False,
            view: bool = False) -> list[Path]:
    """The drawing (``--draw``), the design files, the plots and the page (``--view``) of a completed
    run, and its summary listing every file."""
    paths = list(sink.paths)
    if design is not None:
        paths += write_design(design, res, stage, plots=plots)
    if shapes is not None:
        paths += _write_drawing(res, shapes.result(), stage, plots=plots and draw)
    if plots:
        from .figures.plots import plot_result  # start-up: only this command loads it

        paths += plot_result(res.plot_view(), stage)
    page = [stage / "view.html"] if view else []
    if len(paths) > len(sink.paths) or design is not None or page:
        res.extra["files"] = [p.name for p in paths + page]
        res.write_summary(stage)
    if view:
        from .view import page_of  # start-up: only this command loads it

        page[0].write_text(page_of(stage)[0], encoding="utf-8")
    return paths + page


def _write_drawing(res, sf, out: Path, plots: bool) -> list[Path]:
    """shape.csv (the points kept by ``run --draw``) and, with plots, drawing.png."""
    from .models.shapes import spread, write_shape_csv  # start-up: only this command loads it

    head = [f"flexmech run --draw/--view; case {res.case['case']['title']!r}; model {res.model}",
            "per frame (index, t [s]) every drawn point: x, y its rigid position [m]; dx, dy its elastic "
            "displacement [m]; rot the elastic rotation of its body there [rad]; kappa a flexible link's "
            "curvature at its nodes [1/m]"]
    paths = [write_shape_csv(out / "shape.csv", sf, head, key="t")]
    if plots:
        from .figures.drawing import draw_frames  # start-up: only this command loads it

        p, _ = draw_frames(out / "drawing.png", sf, res.case.mechanism, spread(sf.key.size, MAX_PANELS),
                           title=f"{res.case['case']['title']} - model {res.model}")
        paths += [p] if p else []
    return paths


def _run_cost(prep, model: str, sink) -> str:
    """The words of a run's cost line: steps, DOFs, the size of timeseries.csv."""
    from .base.sizes import format_bytes  # start-up: only this command loads it

    dofs = prep.coupled[model].ndof if model in prep.coupled else prep.fe.nfree
    return (f"{prep.nsteps:,} steps of {dofs} DOFs, {prep.frames:,} frames, about "
            f"{format_bytes(sink.projected_bytes)} of timeseries.csv")


def _report_stopped(exc, paths, rf) -> int:
    """Table, written files, warnings and the reason of a run that stopped; its exit code (3 failed,
    130 Ctrl-C, 128 + N for signal N)."""
    res = exc.partial
    code = exit_code(exc) if isinstance(exc, KeyboardInterrupt) else 3
    print(res.table())
    where = "" if rf.kept == rf.out else f"; {rf.out} keeps its earlier results"
    print(f"wrote partial results (up to t = {res.all_stats().t_last:.6g} s): "
          + ", ".join(str(p) for p in paths) + where)
    for w in res.extra.get("warnings", []):
        print(f"flexmech: warning: {w}", file=sys.stderr)
    print(f"flexmech: {'error' if code == 3 else 'stopped'}: {exc}", file=sys.stderr)
    return code


# ----------------------------------------------------------------------------- draw
#: what `flexmech draw --out` may end in: the still image formats, and GIF for --gif
STILL_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".webp", ".tif", ".tiff", ".eps")


def _draw_target(args, folder: Path) -> Path:
    """The file ``flexmech draw`` writes: --out (a folder: the default name inside it), else in RESULT."""
    name = "drawing.gif" if args.gif else "drawing.png"
    if args.out is None:
        return folder / name
    path = Path(args.out)
    if not str(args.out).strip():
        raise FlexmechError("--out: is empty; give a file name (e.g. --out drawing.png) or leave it out")
    if path.is_dir():
        return path / name
    allowed = (".gif",) if args.gif else STILL_SUFFIXES
    if path.suffix.lower() not in allowed:
        kinds = "a .gif file (--gif animates)" if args.gif else f"one of {', '.join(STILL_SUFFIXES)} (or .gif with --gif)"
        raise FlexmechError(f"--out: {str(path)!r} ends in {path.suffix or 'no suffix'!r}; give {kinds}")
    return path


def _draw_input(folder: Path):
    """(shape frames, case, summary) of a folder written by ``flexmech run --draw``."""
    import json

    from .case import Case  # start-up: only this command loads it
    from .models.shapes import read_shape_csv  # start-up: only this command loads it

    if not (folder / "shape.csv").is_file():
        raise FlexmechError(f"{folder}: no shape.csv there; write one with `flexmech run CASE --draw --out {folder}`")
    sf, _, _ = read_shape_csv(folder / "shape.csv")
    try:
        summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
        case = Case(summary["input"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise FlexmechError(f"{folder}/summary.json: cannot be read as a flexmech run's summary ({exc})") from None
    return sf, case, summary


def cmd_draw(args) -> int:
    from .figures.drawing import animate_frames, draw_frames  # start-up: only this command loads it
    from .models.shapes import spread  # start-up: only this command loads it

    folder = Path(args.result)
    sf, case, summary = _draw_input(folder)
    frames = args.frames or (sf.key.size if args.gif else 6)
    idx = spread(sf.key.size, frames)
    path = _draw_target(args, folder)
    title = f"{case['case']['title']} - model {summary.get('model', '')}"
    with ResultFolder(path, "draw", single=True) as rf:
        draw = animate_frames if args.gif else draw_frames
        p, scale = draw(rf.stage / path.name, sf, case.mechanism, idx, scale=args.scale, title=title)
        if p is None:
            raise FlexmechError("draw: needs matplotlib and Pillow (pip install matplotlib)")
        rf.commit()
    print(f"wrote {path} ({idx.size} frames, deflection x {scale:g})")
    return 0


# ----------------------------------------------------------------------------- view
def add_view_parser(sub) -> None:
    """The ``flexmech view`` command's options."""
    vw = sub.add_parser("view", help="one self-contained HTML page of a result: the mechanism deforming over time, "
                                     "curves, warnings; mode shapes; stability charts")
    vw.add_argument("result", help="a folder written by flexmech run --view (or --draw), flexmech modes or "
                                   "flexmech stability")
    vw.add_argument("--out", default=None, metavar="FILE.html",
                    help="the page to write (default RESULT/view.html; a folder: view.html inside it)")


def cmd_view(args) -> int:
    from .base.sizes import format_bytes  # start-up: only this command loads it
    from .view import write_view  # start-up: only this command loads it

    info = write_view(args.result, args.out)
    what = f"; {info.frames} frames of {info.points} points" if info.kind == "run" else ""
    print(f"wrote {info.path} ({format_bytes(info.bytes)}, a {info.kind} result{what}; open it in a browser)")
    return 0
