"""The per-run time-step error estimate (``solver.error_estimate = "time"``; docs/stability.md, "Error
estimate"): step doubling.  :class:`StepDoubling` runs the same model at 2 dt on the same rigid motion,
block by block beside the run; the error of the dt run is ~ |y_dt - y_2dt| / (2^p - 1), p = ORDER.  Past
ERROR_WARN a warning names the worst column and, from the order observed against a third run at 4 dt,
the step that would meet the threshold.  :func:`error_estimate` does the same for a run held in memory.
"""

from __future__ import annotations

import math
import time
from types import SimpleNamespace

import numpy as np

from ..base import notices
from . import scales
from .alternation import alternation_cause
from ..base.errors import MechanismError, SolverError
from .guards import fmt_time
from .ringing import DifferenceFrequency, ringing_cause

__all__ = ["StepDoubling", "error_estimate", "coarse_grid", "ORDER", "ERROR_WARN"]

ORDER = 2          # order of accuracy in time of every integrator flexmech ships (Newmark family, HHT, gen.-alpha)
#: estimated time-step error, relative to the column's peak, above which a run warns (docs/stability.md)
ERROR_WARN = 0.05
#: largest |observed order - ORDER| at which the step that meets ERROR_WARN is predicted (as accuracy.py)
ORDER_TOLERANCE = 0.3
SKIP_COLUMNS = ("newton_iterations",)   # solver statistics, not outputs


def coarse_grid(nsteps: int, out_every: int) -> tuple[int, int]:
    """(steps, output decimation) of a run on every second step of a grid of ``nsteps`` steps with
    frames every ``out_every``: frames on the fine run's frames (every frame when out_every is even,
    every second one when it is odd; the grid then ends at the last frame both share)."""
    if out_every % 2 == 0:
        return nsteps // 2, out_every // 2
    return out_every * (nsteps // (2 * out_every)), out_every


class _Frames:
    """Frames of one run waiting to be compared: steps (on the fine grid), times and columns."""

    def __init__(self):
        self.steps, self.t, self.cols = np.zeros(0, np.int64), np.zeros(0), {}
        self.last = -1

    def add(self, steps, t, columns) -> None:
        self.steps, self.t = np.r_[self.steps, steps], np.r_[self.t, t]
        for name, y in columns.items():
            if name not in SKIP_COLUMNS:
                self.cols[name] = np.r_[self.cols.get(name, np.zeros(0)), np.asarray(y, float)]
        self.last = int(self.steps[-1]) if self.steps.size else self.last

    def drop_through(self, step: int) -> None:
        keep = self.steps > step
        self.steps, self.t = self.steps[keep], self.t[keep]
        self.cols = {n: y[keep] for n, y in self.cols.items()}


#: most frames of the run at 2 dt that StepDoubling keeps for the observed order (beyond them the
#: run at 2 dt is made again beside the one at 4 dt)
KEEP_FRAMES_MAX = 200_000
#: a run at 2 dt with more frames than this is compared at every second of them
FRAMES_FULL = 400


class StepComparison:
    """max |y_fine - y_coarse| of every column where a run (fed block by block, :meth:`add_fine`) and
    the same run on every second step (``coarse_prep``, advanced block by block beside it) have a
    frame at the same step.  Also over the frames of the run at four times the step (``sub``: every
    and last fine step of that grid's frames), for the observed order, and the coarse run's frames on
    that grid are kept (``keep``: every and last coarse step, at most KEEP_FRAMES_MAX frames) for
    comparing it with the run at four times the step later.  Holds about one block of each besides."""

    def __init__(self, coarse_prep, model: str, geometric, sub: tuple[int, int] | None = None,
                 keep: tuple[int, int] | None = None):
        self.coarse = coarse_prep.blocks(model, geometric)
        self.sub, self.keep = sub, keep
        self.diff, self.t_at, self.diff_sub = {}, {}, {}
        self.frames = 0
        self.failed = None                   # the coarse run's SolverError, if it stopped
        self.done = False
        self.waiting = False                 # the coarse run waits for the run's rigid motion (a MotionTap)
        self.kernel_s, self.wall_s = 0.0, 0.0
        self._fine, self._coarse = _Frames(), _Frames()
        self.kept = _Frames() if keep else None
        self.spectrum = DifferenceFrequency()     # the differences' frequency (ringing, flexmech_py/checks/ringing.py)
        #: callables f(steps on the fine grid, t, columns) that see every frame of the coarse run
        self.observers: list = []

    def kept_block(self):
        """The coarse run's kept frames as one block (steps on its own grid), or None when not kept."""
        if self.kept is None:
            return None
        return SimpleNamespace(steps=self.kept.steps, t=self.kept.t, columns=self.kept.cols)

    @property
    def coarse_last(self) -> int:
        """The last step the coarse run reached, on the fine grid."""
        return self._coarse.last

    def add_fine(self, block) -> None:
        """Take the block's frames and advance the coarse run to them."""
        if block.t.size == 0:
            return
        self._fine.add(block.steps, block.t, block.columns)
        self.waiting = False
        while not self.done and not self.waiting and self._coarse.last < self._fine.last:
            self._advance()
        self._match()

    def _advance(self) -> None:
        t0 = time.perf_counter()
        try:
            cb = next(self.coarse)
        except StopIteration:
            self.done = True
            return
        except SolverError as exc:
            self.failed, self.done = exc, True
            cb = exc.partial
        except MechanismError:     # the rigid motion stops here too: compare what both have
            self.done = True
            return
        finally:
            self.wall_s += time.perf_counter() - t0
        if cb is None:
            self.waiting = cb is None and not self.done
            return
        if cb.t.size == 0:
            return
        self.kernel_s = cb.timing.get("kernel_s", self.kernel_s)
        self._coarse.add(2 * cb.steps, cb.t, cb.columns)
        for obs in self.observers:
            obs(2 * cb.steps, cb.t, cb.columns)
        self._keep(cb)

    def _keep(self, cb) -> None:
        if self.kept is None:
            return
        every, last = self.keep
        on = (((cb.steps % every) == 0) & (cb.steps <= last)) | (cb.steps == last)
        self.kept.add(cb.steps[on], cb.t[on], {n: np.asarray(y)[on] for n, y in cb.columns.items()})
        if self.kept.steps.size > KEEP_FRAMES_MAX:
            self.kept = None

    def _match(self) -> None:
        f, c = self._fine, self._coarse
        common, fi, ci = np.intersect1d(f.steps, c.steps, assume_unique=True, return_indices=True)
        self.frames += int(common.size)
        if common.size:
            on_sub = ((common % self.sub[0] == 0) & (common <= self.sub[1])) if self.sub else np.zeros(common.size, bool)
            for name, y in f.cols.items():
                if name not in c.cols:
                    continue
                sd = y[fi] - c.cols[name][ci]
                self.spectrum.add(name, c.t[ci], sd)
                d = np.abs(sd)
                k = int(np.argmax(d))
                if not (self.diff.get(name, -1.0) >= d[k]):
                    self.diff[name], self.t_at[name] = float(d[k]), float(c.t[ci[k]])
                if on_sub.any():
                    self.diff_sub[name] = max(self.diff_sub.get(name, 0.0), float(np.max(d[on_sub])))
        upto = max(f.last, c.last) if self.done else min(f.last, c.last)   # compared, or without a partner
        f.drop_through(upto)
        c.drop_through(upto)

    def finish(self) -> None:
        """Advance the coarse run to its end (the fine run has ended)."""
        while not self.done:
            self._advance()
        self._match()


def error_estimate(prep, res, geometric=None) -> dict:
    """The step-doubling estimate of a run already held in memory (``res``, a run of ``prep``)."""
    sd = StepDoubling(prep, res.model, geometric)
    sd.add(res)
    return sd.finish(res)


class StepDoubling:
    """Step-doubling estimate of the time-discretization error of every output column, made while the
    run goes (the same model at 2 dt on the same rigid motion, ``prep.coarsened()``): the error of the
    dt run ~ |y_dt - y_2dt| / (2^p - 1), p = ORDER; past ERROR_WARN a warning with the step that would
    meet it (:func:`_estimate_warning`)."""

    def __init__(self, prep, model: str, geometric=None):
        self.prep, self.model, self.geometric = prep, model, geometric
        self.pc = self._coarse_prep()
        self.cmp = None
        if self.pc is not None:
            ncc, occ = coarse_grid(self.pc.nsteps, self.pc.out_every)
            four = ncc >= occ >= 1          # a run at 4 dt has frames: compare with it, keep 2 dt on its grid
            self.cmp = StepComparison(self.pc, model, geometric, sub=(4 * occ, 4 * ncc) if four else None,
                                      keep=(2 * occ, 2 * ncc) if four else None)

    def _coarse_prep(self):
        """The run at 2 dt (``prep.coarsened()``), with a frame at every second of its frames when it has
        more than FRAMES_FULL (its outputs cost per frame; the differences are compared at its frames)."""
        pc = self.prep.coarsened()
        return pc.thinned(2) if pc is not None and pc.frames > FRAMES_FULL else pc

    @property
    def coarse_steps(self) -> int:
        return 0 if self.pc is None else self.pc.nsteps

    def add(self, block) -> None:
        if self.cmp is not None:
            self.cmp.add_fine(block)

    def finish(self, res) -> dict:
        """The ``error_estimate`` entry of the finished run ``res`` (a warning also into its warnings)."""
        out = {"method": "time", "order": ORDER, "dt": self.prep.dt}
        if self.cmp is None:
            return dict(out, method="none", reason="too few steps for a run at 2 dt")
        cmp = self.cmp
        cmp.finish()
        out["coarse_dt"] = self.pc.dt
        if cmp.failed is not None:
            exc = cmp.failed
            out.update(failed=f"the run at 2 dt stopped at t = {fmt_time(exc.time)} s", columns={}, worst_column=None)
            notices.add(res.extra,
                        f"error estimate: the same run at 2 dt = {self.pc.dt:.3g} s stopped at t = {fmt_time(exc.time)} s, "
                        "so the step dt is close to the limit of this model; check with a smaller solver.dt", "accuracy")
            return out
        out.update(kernel_s=cmp.kernel_s, wall_s=cmp.wall_s, frames_compared=cmp.frames)
        fac = 1.0 / (2 ** ORDER - 1)
        stats = res.all_stats().columns
        tiny = scales.negligible(res.case, res.units, {n: stats[n]["peak_abs"] for n in cmp.diff if n in stats})
        cols, worst = {}, (None, -1.0)
        for name, d in cmp.diff.items():
            emax, peak = fac * d, stats[name]["peak_abs"]
            rel = emax / peak if peak > 0 else (0.0 if emax == 0 else float("inf"))
            cols[name] = {"max_abs": emax, "relative": rel, "t_max_s": cmp.t_at[name]}
            if name in tiny:              # round-off over round-off: never the worst column
                cols[name]["negligible"] = tiny[name]
            elif rel > worst[1]:
                worst = (name, rel)
        out.update(columns=cols, worst_column=worst[0], worst_relative=worst[1] if worst[0] else None)
        over = {n: c["relative"] for n, c in cols.items()
                if np.isfinite(c["relative"]) and c["relative"] > ERROR_WARN and n not in tiny}
        if over:
            name = max(over, key=over.get)
            order = self._observed_order(name)
            cause = alternation_cause(res, name) or ringing_cause(
                name, cmp.spectrum.frequency(name), cmp.spectrum.span(name), order, self.prep.dt)
            out["warning"] = _estimate_warning(self.prep.dt, name, over, order, cause)
            notices.add(res.extra, out["warning"]["message"], "accuracy")
        return out

    def _observed_order(self, name: str) -> float | None:
        """Observed order of ``name``'s time error from the runs at dt, 2 dt and a third one at 4 dt (made
        only when the estimate passes ERROR_WARN): log2 of max |y_2dt - y_4dt| over max |y_dt - y_2dt| on
        the 4 dt frames.  The 2 dt run's frames on that grid were kept while it ran (made again only when
        there were more than KEEP_FRAMES_MAX).  None when there is no run at 4 dt (too few steps, or it
        failed)."""
        d12 = self.cmp.diff_sub.get(name)
        pc = self._coarse_prep()
        if d12 is None or pc is None or pc.coarsened() is None:
            return None
        second = StepComparison(pc.coarsened(), self.model, self.geometric)
        kept = self.cmp.kept_block()
        try:
            for block in ([kept] if kept is not None else pc.blocks(self.model, self.geometric)):
                second.add_fine(block)
        except (SolverError, MechanismError):
            return None
        second.finish()
        d24 = second.diff.get(name)
        if second.failed is not None or not d24 or not d12:
            return None
        return float(np.log2(d24 / d12))


def _round_down(x: float, digits: int = 2) -> float:
    """x rounded down to ``digits`` significant digits (a step printed shorter must not grow)."""
    scale = 10.0 ** (math.floor(math.log10(x)) - digits + 1)
    return math.floor(x / scale * (1 + 1e-12)) * scale


def _estimate_warning(dt: float, name: str, over: dict, order: float | None, cause: dict | None = None) -> dict:
    """The warning of an estimate past ERROR_WARN: the worst column, and the step that would meet the
    threshold, dt (ERROR_WARN / estimate)^(1/p), p = min(observed order, ORDER).  Promised only when the
    observed order is within ORDER_TOLERANCE of ORDER (the runs are in the asymptotic range); otherwise the
    order-2 step is a first guess (none when the error does not shrink with the step, p < 1).  ``cause``:
    what the difference is when it is not a time-step error (undamped ringing, flexmech_py.checks.ringing; a
    period-2 dt oscillation, flexmech_py.checks.alternation): the warning names it and what would remove it."""
    rel = over[name]
    more = f" ({len(over)} outputs above it)" if len(over) > 1 else ""
    head = (f"error estimate: the time-step error of {name} is about {100 * rel:.3g} % of its peak (step doubling), "
            f"above the {100 * ERROR_WARN:g} % threshold{more}; ")
    seen = f"observed order {order:.2g} from runs at dt, 2 dt and 4 dt" if order is not None else "no run at 4 dt"
    out = {"column": name, "observed_order": order, "suggested_dt": None}
    if cause is not None:     # not a time-step error: ringing (flexmech_py/checks/ringing.py) or a period-2 dt oscillation
        return dict(out, **{k: x for k, x in cause.items() if k != "message"}, message=head + cause["message"])
    if order is not None and abs(order - ORDER) <= ORDER_TOLERANCE:
        dt_new = _round_down(dt * (ERROR_WARN / rel) ** (1.0 / min(order, ORDER)))
        out["suggested_dt"] = dt_new
        return dict(out, message=head + f"dt = {dt_new:.2g} s instead of {dt:.3g} s would meet it ({seen}): "
                                        f"--dt {dt_new:.2g} or --set solver.dt={dt_new:.2g}")
    guess = (f"; were it of order {ORDER}, dt = {dt * (ERROR_WARN / rel) ** (1.0 / ORDER):.2g} s would meet it"
             if order is None or order >= 1.0 else "; the error does not shrink with the step")
    return dict(out, message=head + f"the runs are not in the asymptotic range ({seen}, expected {ORDER}), so no step "
                                    f"can be promised{guess}; check against a run at a much smaller dt "
                                    "(`flexmech accuracy`)")
