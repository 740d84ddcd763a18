"""Probe runs: a case on another discretization or with another model, advanced block by block beside
a run and matched with it at the steps of the run's grid they share (docs/theory.md section 21).

The error budget (:mod:`flexmech_py.checks.budget`) compares a run with cheaper runs of the same case: the
run's model on a coarser (or finer) mesh at four times the step, and the exact model on that grid.
A :class:`Probe` is one such run, pulled block by block up to a step of the run's grid (so it holds
one chunk, as the run does); its frames land in a :class:`FrameBuffer` keyed by the step of the run's
grid.  :class:`Matcher` holds the buffers of several runs and hands out the frames they all have.
A probe made before the run (``model = "auto"`` chooses the run's model from probes) keeps its frames
(up to KEEP_FRAMES_MAX) and is replayed beside the run instead of being made again.
"""

from __future__ import annotations

import time

import numpy as np

from ..base.errors import CaseError, MechanismError, SolverError

__all__ = ["FrameBuffer", "Probe", "Matcher", "largest_differences", "KEEP_FRAMES_MAX", "SKIP_COLUMNS"]

#: most frames a probe made before the run keeps for the budget (beyond them it is made again beside the run)
KEEP_FRAMES_MAX = 200_000
SKIP_COLUMNS = ("newton_iterations",)   # solver statistics, not outputs


class FrameBuffer:
    """Frames of one run waiting to be matched: steps (of the run's grid), times and columns; ``last``
    the last step seen (also after its frames were dropped)."""

    def __init__(self):
        self.steps, self.t, self.cols = np.zeros(0, np.int64), np.zeros(0), {}
        self.last = -1

    def add(self, steps, t, columns, every: int = 1) -> None:
        """Take the frames at ``steps`` that are multiples of ``every``."""
        steps = np.asarray(steps, np.int64)
        if steps.size == 0:
            return
        on = steps % every == 0
        self.steps, self.t = np.r_[self.steps, steps[on]], np.r_[self.t, np.asarray(t, float)[on]]
        for name, y in columns.items():
            if name not in SKIP_COLUMNS:
                self.cols[name] = np.r_[self.cols.get(name, np.zeros(0)), np.asarray(y, float)[on]]
        self.last = max(self.last, int(steps[-1]))

    def drop_through(self, step: float) -> None:
        keep = self.steps > step
        self.steps, self.t = self.steps[keep], self.t[keep]
        self.cols = {n: y[keep] for n, y in self.cols.items()}

    @property
    def frames(self) -> int:
        return int(self.steps.size)


class Probe:
    """A run of ``prep`` (its own mesh and step) with ``model`` pulled block by block; its frames in
    :attr:`buffer` at the steps of the run's grid (``ratio`` of the run's steps per probe step).  A
    probe that stops (SolverError, MechanismError) keeps its frames so far: :attr:`stopped_at` [s].
    With ``keep`` its frames also go to :attr:`kept` (dropped past KEEP_FRAMES_MAX frames)."""

    def __init__(self, prep, model: str, geometric: str | None, ratio: int, label: str, keep: bool = False):
        self.prep, self.model, self.geometric, self.ratio, self.label = prep, model, geometric, int(ratio), label
        self._blocks = None
        self.buffer = FrameBuffer()
        self.kept = FrameBuffer() if keep else None
        self.done = False
        self.stopped_at = None          # [s] where the probe stopped, when it did not reach the end
        self.reason = ""
        self.cpu_s = 0.0
        self.peaks: dict = {}           # largest |value| of every column over the frames made so far
        self.replayed_from = None       # the probe whose kept frames this one serves
        self.units: dict = {}

    @property
    def last(self) -> int:
        return self.buffer.last

    def advance_to(self, step: int) -> None:
        """Pull blocks until the probe has passed ``step`` of the run's grid, ended, or waits for the run
        whose rigid motion it takes."""
        while not self.done and self.buffer.last < step and self._next():
            pass

    def run_to_end(self) -> None:
        while not self.done:
            if not self._next():
                raise RuntimeError(f"the probe run of {self.label} waits for a run that has ended")  # pragma: no cover

    def _next(self) -> bool:
        """Pull one block; False when the probe waits for the run whose rigid motion it takes."""
        c0 = time.process_time()
        try:
            if self._blocks is None:
                self._blocks = self.prep.blocks(self.model, self.geometric)
            block = next(self._blocks)
        except StopIteration:
            self.done = True
            return True
        except SolverError as exc:
            self.done, block = True, exc.partial
            self._stopped(exc.time, str(exc).split(";")[0])
        except MechanismError as exc:   # the rigid motion stops here too: the run stops with it
            self.done, block = True, None
            self._stopped(exc.time, str(exc).split(";")[0])
        except CaseError as exc:        # the model cannot run this case at all
            self.done, block, self.reason = True, None, str(exc)
        finally:
            self.cpu_s += time.process_time() - c0
        if block is None:
            return self.done
        if block.t.size:
            self.units = self.units or dict(block.units)
            self._take(self.ratio * np.asarray(block.steps), block.t, block.columns)
        return True

    def _stopped(self, t, reason: str) -> None:
        self.stopped_at = float(t) if t is not None else 0.0
        self.reason = reason

    def _take(self, steps, t, columns) -> None:
        self.buffer.add(steps, t, columns)
        for name, y in columns.items():
            self.peaks[name] = max(self.peaks.get(name, 0.0), float(np.max(np.abs(y))))
        if self.kept is not None:
            self.kept.add(steps, t, columns)
            if self.kept.frames > KEEP_FRAMES_MAX:
                self.kept = None

    def replay(self) -> "Probe":
        """A probe serving this one's kept frames (all at once), or None when they were not kept."""
        if self.kept is None or not self.done:
            return None
        other = Probe(self.prep, self.model, self.geometric, self.ratio, self.label)
        other.buffer.add(self.kept.steps, self.kept.t, self.kept.cols)
        other.buffer.last = self.buffer.last
        other.done, other.stopped_at, other.reason = True, self.stopped_at, self.reason
        other.peaks, other.units, other.replayed_from = dict(self.peaks), dict(self.units), self
        return other


class Matcher:
    """Buffers of several runs by name; :meth:`common` the frames all of some of them hold, and
    :meth:`release` drops the frames no run can still match."""

    def __init__(self, names):
        self.buffers = {n: FrameBuffer() for n in names}
        self.sources: dict = {}          # name -> Probe whose buffer it is (pulled), else pushed

    def attach(self, name: str, probe: Probe) -> None:
        self.buffers[name] = probe.buffer
        self.sources[name] = probe

    def common(self, names) -> tuple[np.ndarray, np.ndarray, dict]:
        """(steps, t, {name: {column: values}}) at the steps every buffer of ``names`` holds."""
        bufs = [self.buffers[n] for n in names]
        steps = bufs[0].steps
        for b in bufs[1:]:
            steps = np.intersect1d(steps, b.steps, assume_unique=True)
        out, t = {}, np.zeros(0)
        for n, b in zip(names, bufs):
            idx = np.searchsorted(b.steps, steps)
            out[n] = {c: y[idx] for c, y in b.cols.items()}
            t = b.t[idx]
        return steps, t, out

    def release(self, pushed_last: int, finished: bool = False) -> None:
        """Drop the frames at steps every run has passed (a run that ended passes every step)."""
        upto = np.inf if finished else float(pushed_last)
        for n, p in self.sources.items():
            if not p.done:
                upto = min(upto, p.buffer.last)
        for b in self.buffers.values():
            b.drop_through(upto)


def largest_differences(a: Probe, b: Probe) -> tuple[dict, int]:
    """({column: max |a - b|}, frames compared) of two probes on one grid, advanced in step to their
    ends (the one behind first), holding about a block of each."""
    m = Matcher([])
    m.attach("a", a)
    m.attach("b", b)
    diff, frames = {}, 0
    while not (a.done and b.done):
        behind = min((p for p in (a, b) if not p.done), key=lambda p: p.last)
        behind.advance_to(behind.last + 1)
        _, t, f = m.common(["a", "b"])
        frames += int(t.size)
        for col, y in f["a"].items():
            if t.size and col in f["b"]:
                diff[col] = max(diff.get(col, 0.0), float(np.max(np.abs(y - f["b"][col]))))
        m.release(np.inf)
    return diff, frames
