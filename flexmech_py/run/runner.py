"""One run carried out: a model's blocks of frames (:meth:`flexmech_py.run.simulate.Prepared.blocks`)
through the guards into a sink, and how the run ended (docs/theory.md section 19).

:func:`execute` feeds every block to the validity tracker, to the check for a period-2 dt
oscillation (:class:`flexmech_py.checks.alternation.AlternationCheck`), to the error budget
(:class:`flexmech_py.checks.budget.ErrorBudget`: the step-doubling run at 2 dt and the mesh and model probes
advance block by block beside the run) and to a sink: :class:`MemorySink` keeps every
frame (``Prepared.run``), :class:`FileSink` writes them to timeseries.csv as they come and keeps only
the last block, the column statistics and a bounded envelope for the plots (``Prepared.stream``, the
``flexmech run`` command).  A run that stops keeps its frames, marked: a failed step (SolverError,
with the diagnosis of :func:`flexmech_py.checks.guards.failed`), a singular rigid position (MechanismError),
or the user's Ctrl-C (:class:`~flexmech_py.base.errors.Interrupted`).
"""

from __future__ import annotations

import dataclasses
import shutil
import time
from pathlib import Path

from ..checks import alternation, auto_model, guards
from ..checks.budget import TOLERANCE, ErrorBudget, parts_of
from ..base.families import AUTO, MODEL_CHOICES
from ..base.errors import CaseError, Interrupted, MechanismError, OutputError, SolverError, signal_words
from .frames import ColumnStats, Envelope, join
from .outdir import PARTIAL_DIR, ResultFolder, claim, release_reserve
from .results import TimeseriesWriter, csv_rows
from ..base.signals import held_signals
from ..base.sizes import MEMORY_SHARE, available_memory, format_bytes, format_count

__all__ = ["execute", "stream_to_folder", "MemorySink", "FileSink", "available_memory", "format_bytes"]

#: share of the free disk space a streamed run's timeseries.csv may take
DISK_SHARE = 0.9


def _block_bytes(block) -> int:
    arrays = [block.t, block.q, block.qd, block.qdd, block.u, block.v, block.a, block.rig, block.axial, block.state]
    arrays += list(block.columns.values())
    if block.rigid is not None:
        arrays += [block.rigid.z, block.rigid.zd, block.rigid.zdd, block.rigid.lam, block.rigid.jq, block.rigid.dv]
    return sum(a.nbytes for a in arrays if a is not None)


class MemorySink:
    """Every frame kept: the result is the blocks joined.  A run whose frames would not fit in memory
    (MEMORY_SHARE of what is available, measured on its first block) is refused."""

    def __init__(self, frames_total: int):
        self.frames_total = int(frames_total)
        self.blocks: list = []

    def add(self, block) -> None:
        if not self.blocks and block.t.size:
            self._check_memory(block)
        if block.t.size:
            self.blocks.append(block)

    def _check_memory(self, block) -> None:
        per_frame = _block_bytes(block) / block.t.size
        need, avail = per_frame * self.frames_total, available_memory()
        if avail is not None and need > MEMORY_SHARE * avail:
            every = block.case["solver"]["output_every"] * int(need / (0.5 * MEMORY_SHARE * avail) + 1)
            raise CaseError("solver.output_every",
                            f"keeping every frame of this run in memory takes about {format_bytes(need)} "
                            f"({format_count(self.frames_total)} frames of {format_bytes(per_frame)}) and "
                            f"{format_bytes(avail)} is "
                            f"available: raise solver.output_every (e.g. --set solver.output_every={every}), or write "
                            "the frames to files as they come (flexmech run, Prepared.stream)")

    def result(self):
        return join(self.blocks) if self.blocks else None

    def close(self, res) -> list[Path]:
        return []


class FileSink:
    """Frames written to ``out_dir``/timeseries.csv as they come (:class:`TimeseriesWriter`); kept: the
    last block (what the guards read of a stopped run), the statistics of every column and an
    :class:`Envelope` for the plots.  Nothing is created before the first block.  With
    ``frames_total``, the size of timeseries.csv is projected from the first block, and a run that
    would not fit on the disk is refused (CaseError naming ``solver.output_every``) unless ``force``.
    ``out_dir`` is normally the staging folder of a :class:`~flexmech_py.run.outdir.ResultFolder`."""

    def __init__(self, out_dir, *, frames_total: int | None = None, force: bool = False):
        self.out = Path(out_dir)
        self.frames_total = frames_total
        self.force = force
        self.writer = None
        self.last = None
        self.stats, self.envelope = ColumnStats(), Envelope()
        self.paths: list[Path] = []

    def add(self, block) -> None:
        if block.t.size == 0:
            return
        if self.writer is None:
            if self.frames_total and not self.force:
                self._check_disk(block)
            self.out.mkdir(parents=True, exist_ok=True)
            self.writer = TimeseriesWriter(self.out)
        with held_signals():     # a block is in the file and in the statistics, or in neither
            self.writer.add(block)
            self.stats.add(block.t, block.columns)
            self.envelope.add(block.t, block.columns)
            self.last = block

    @property
    def projected_bytes(self) -> float:
        """Size timeseries.csv will have [B], projected from the rows written so far."""
        w = self.writer
        if w is None or w.rows == 0 or not self.frames_total:
            return 0.0
        return w.bytes / w.rows * self.frames_total

    def _check_disk(self, block) -> None:
        """Refuse a run whose timeseries.csv (projected from the first block's rows) would not fit."""
        per_row = len(csv_rows(block.t, block.columns).encode("utf-8")) / block.t.size
        need = per_row * self.frames_total
        folder = next((p for p in [self.out, *self.out.absolute().parents] if p.exists()), Path("."))
        free = shutil.disk_usage(folder).free
        if need <= DISK_SHARE * free:
            return
        sol = block.case["solver"]
        every = sol["output_every"] * max(2, int(need / (0.5 * DISK_SHARE * max(free, 1.0)) + 1))
        fix = (f"raise solver.output_every (e.g. --set solver.output_every={format_count(every)}), shorten "
               "solver.t_end, choose another --out, or run anyway with --force") if free > 0 else \
            "free some space on that disk or choose another --out"
        raise CaseError("solver.output_every",
                        f"this run writes about {format_bytes(need)} to timeseries.csv "
                        f"({format_count(self.frames_total)} frames of {per_row:.0f} B, one every "
                        f"{sol['output_every']} of its steps of {block.dt:.3g} s) and {format_bytes(free)} is free "
                        f"on the disk of {self.out.parent if self.out.name == PARTIAL_DIR else self.out}: {fix}")

    def result(self):
        if self.last is None:
            return None
        return dataclasses.replace(self.last, stats=self.stats, envelope=self.envelope)

    def close(self, res) -> list[Path]:
        """timeseries.csv and summary.json of the run (partial or not)."""
        if res is None:
            if self.writer is not None:
                self.writer.abandon()
            return []
        csv = self.writer.finish(res)
        res.extra["files"] = ["timeseries.csv", "summary.json"]
        self.paths = [csv, res.write_summary(self.out)]
        return self.paths

    @property
    def bytes_written(self) -> int:
        return 0 if self.writer is None else self.writer.bytes


def _take(block, sink, validity, budget, observers=()) -> None:
    sink.add(block)
    validity.add(block)
    if budget is not None:
        budget.add(block)
    for obs in observers:
        obs.add(block)


def estimate_parts(prep, estimate) -> tuple:
    """The error-budget parts of a run: the case's ``solver.error_estimate`` (``estimate`` None or
    True), none (False), or a setting such as "time+mesh"."""
    if estimate is None or estimate is True:
        return parts_of(prep.case["solver"].get("error_estimate", "all"))
    if estimate is False:
        return ()
    return parts_of(estimate)


def execute(prep, model: str | None, sink, *, geometric=None, estimate=None, diagnose: bool = True,
            u0=None, v0=None, progress=None, observers=()):
    """Run one model of ``prep`` into ``sink``; returns the Result (see the module's docstring).
    ``model`` "auto" runs the model :func:`flexmech_py.checks.auto_model.choose` picks; ``estimate``: the parts
    of the error budget (:func:`estimate_parts`).  ``progress(done, total)``: called after every block
    with the work done and to do (steps of the run and of its step-doubling run); ``observers``:
    objects whose ``add(block)`` sees every block (e.g. :class:`flexmech_py.models.shapes.ShapeCollector`)."""
    t_start = time.perf_counter()
    model = prep.case["solver"]["model"] if model is None else model
    if model not in MODEL_CHOICES:
        raise CaseError("model", f"must be one of {', '.join(MODEL_CHOICES)}, got {model!r}")
    parts = estimate_parts(prep, estimate)
    tolerance = prep.case["solver"].get("tolerance", TOLERANCE)
    choice = auto_model.choose(prep, tolerance) if model == AUTO else None
    if choice is not None:
        model, geometric = choice.model, choice.geometric
    validity = guards.ValidityTracker()
    alternating = alternation.AlternationCheck(prep, model)
    observers = (*observers, alternating)
    budget = ErrorBudget(prep, model, geometric, parts, tolerance, choice.probes if choice else None) if parts else None
    doubling = budget.sd if budget is not None else None
    total = prep.nsteps + (doubling.coarse_steps if doubling else 0)
    stop = None
    try:
        for block in prep.blocks(model, geometric, u0=u0, v0=v0):
            _take(block, sink, validity, budget, observers)
            if progress is not None:
                progress(_work_done(block, doubling), total)
    except SolverError as exc:
        if exc.partial is None:
            raise
        _take(exc.partial, sink, validity, None, observers)
        stop = exc
    except MechanismError as exc:
        stop = exc
    except KeyboardInterrupt as exc:   # Ctrl-C, or SIGTERM/SIGHUP (errors.Terminated)
        stop = exc
    except OSError as exc:             # writing the frames failed (a full disk)
        stop = exc
    prep.end_shared_motion()
    res = sink.result()
    if res is None:               # nothing to keep: the stop happened before the first frame
        sink.close(None)
        if isinstance(stop, KeyboardInterrupt):
            raise Interrupted(f"{signal_words(stop)} before the first frame", signum=getattr(stop, "signum", None))
        if isinstance(stop, (SolverError, MechanismError)):
            stop.partial = None
        raise stop if stop is not None else Interrupted("stopped before the first frame")
    if choice is not None:
        res.extra["model_choice"] = choice.record
    return _finish(prep, model, geometric, res, sink, stop, (validity, alternating), budget, diagnose, t_start)


def _work_done(block, doubling) -> int:
    done = int(block.steps[-1]) if block.steps is not None and block.steps.size else 0
    if doubling is not None and doubling.cmp is not None:
        done += max(0, doubling.cmp.coarse_last // 2)
    return done


def _finish(prep, model, geometric, res, sink, stop, checks, budget, diagnose, t_start):
    """Guards, estimate and files of a run that ended (or stopped: raise after the files are written)."""
    res.timing["total_s"] = prep.t_prepare + time.perf_counter() - t_start
    for check in checks:      # validity, then the period-2 dt alternation
        check.finish(res)
    prep.report_mechanism(res)
    if isinstance(stop, SolverError):
        stop.partial = res
        err = guards.failed(prep, model, geometric, stop, diagnose=diagnose, rerun=prep.rerun)
        sink.close(res)
        raise err
    if isinstance(stop, KeyboardInterrupt):
        raise _interrupted(res, sink, "during the run", stop)
    if isinstance(stop, OSError):
        raise _write_failed(res, sink, stop)
    try:
        if budget is None:
            res.extra["error_estimate"] = {"method": "none"}
        else:
            res.extra["error_estimate"], res.extra["error_budget"] = budget.finish(res)
    except KeyboardInterrupt as exc:
        res.extra["error_estimate"] = {"method": "none", "reason": signal_words(exc)}
        raise _interrupted(res, sink, "during the error estimate (the run itself completed)", exc) from None
    res.timing["total_s"] = prep.t_prepare + time.perf_counter() - t_start
    if isinstance(stop, MechanismError):
        err = guards.rigid_failure(res, stop)
        sink.close(res)
        raise err
    sink.close(res)
    return res


def _interrupted(res, sink, when: str, stop) -> Interrupted:
    """Mark ``res`` as stopped by the user or a signal, write it, and return the exception to raise."""
    t_last = res.all_stats().t_last
    msg = f"{signal_words(stop)} {when}; frames up to t = {t_last:.6g} s are kept"
    res.failure = {"cause": "interrupted", "time_s": t_last, "message": msg}
    if getattr(stop, "signum", None):
        res.failure["signal"] = stop.name
    res.extra.setdefault("error_estimate", {"method": "none", "reason": "the run was interrupted"})
    sink.close(res)
    return Interrupted(msg, partial=res, signum=getattr(stop, "signum", None))


def _write_failed(res, sink, exc: OSError) -> OutputError:
    """Mark ``res`` as cut short by a failed write (a full disk): the file keeps its whole blocks, its
    status line and summary.json say so (the staging folder's reserve gives the room)."""
    t_last = res.all_stats().t_last
    msg = (f"writing {exc.filename or 'timeseries.csv'} failed ({exc.strerror or exc}); frames up to t = "
           f"{t_last:.6g} s are kept")
    res.failure = {"cause": "write_failed", "time_s": t_last, "message": msg, "file": exc.filename}
    res.extra.setdefault("error_estimate", {"method": "none", "reason": "writing the frames failed"})
    release_reserve(sink.out)
    sink.close(res)
    return OutputError(msg, path=exc.filename, partial=res)


def stream_to_folder(prep, out_dir, model: str | None = None, *, force: bool = False, **kw):
    """:meth:`flexmech_py.run.simulate.Prepared.stream`: the run streamed into a
    :class:`~flexmech_py.run.outdir.ResultFolder` ``out_dir`` -- in place of the folder's earlier run only
    when it completes; a run that stops raises as :func:`execute` does, its frames so far written and
    marked (in ``out_dir`` when it held no run, else beside it in ``out_dir/flexmech-partial``)."""
    stopped = None
    with ResultFolder(out_dir, "run", claim=lambda: claim(out_dir, prep.case, overwrite=True)) as rf:
        sink = FileSink(rf.stage, frames_total=prep.frames, force=force)
        try:
            res = execute(prep, model, sink, **kw)
        except (Interrupted, SolverError, MechanismError, OutputError) as exc:
            if getattr(exc, "partial", None) is None:
                raise
            rf.stopped(str(exc), marked=True)
            stopped = exc
        else:
            rf.commit()
    if stopped is not None:
        raise stopped
    return res
