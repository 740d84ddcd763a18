"""What a long run says while it goes: a one-line cost estimate and a progress bar with an ETA.

Both go to stderr (stdout keeps the run's table).  :class:`RunProgress` is the ``progress(done,
total)`` callback of :meth:`flexmech_py.run.simulate.Prepared.stream`: ``done`` and ``total`` are steps
(of the run and of its error estimate).  The cost estimate is printed once, when the run has been
stepping for CALIBRATION_S and the rest would take more than ESTIMATE_OVER_S; it projects the rate
of the latest block, not the time since the start: the start-up before the first block (the probes
of ``model = "auto"``, the error budget's first chunks) is a fixed cost, and dividing it by the first
block's share of the steps over-forecast the 4 s six-bar run as "about 1 min 12 s" (the blocks grow
along the run, so the latest one carries the least of their fixed costs).  The bar appears once the
run has been going for BAR_AFTER_S and is redrawn at most every REDRAW_S, only when the stream is a
terminal (or when forced).  Nothing here touches the numerics.
"""

from __future__ import annotations

import shutil
import sys
import time

__all__ = ["RunProgress", "format_duration"]

#: seconds of stepping (after the first block) over which the rate is measured before the cost is projected
CALIBRATION_S = 1.0
#: a run whose remaining time exceeds this [s] gets the one-line cost estimate
ESTIMATE_OVER_S = 3.0
#: seconds of run before the bar appears (a short run shows none)
BAR_AFTER_S = 2.0
#: shortest interval between two redraws of the bar [s]
REDRAW_S = 0.25


def format_duration(seconds: float) -> str:
    """'4.2 s', '3 min 05 s', '2 h 07 min'."""
    s = max(0.0, float(seconds))
    if s < 60:
        return f"{s:.2g} s" if s < 10 else f"{s:.0f} s"
    if s < 3600:
        return f"{int(s // 60)} min {int(s % 60):02d} s"
    return f"{int(s // 3600)} h {int(s % 3600 // 60):02d} min"


class RunProgress:
    """The progress(done, total) callback of a run.

    ``describe``: a callable returning the words after the time in the cost line (e.g. "12 000 000
    steps of 126 DOFs, about 1.3 GB of timeseries.csv"); ``bar``: True draws the bar, False never,
    None when ``stream`` is a terminal; ``quiet`` silences everything."""

    def __init__(self, describe=None, *, bar: bool | None = None, quiet: bool = False, stream=None,
                 clock=time.perf_counter):
        self.stream = sys.stderr if stream is None else stream
        self.describe = describe
        self.quiet = quiet
        self.bar = (bool(getattr(self.stream, "isatty", lambda: False)()) if bar is None else bar) and not quiet
        self.clock = clock
        self.t0 = clock()
        self.estimated = False
        self.anchor = None          # (time, fraction done) at the first block: the start-up is behind it
        self.prev = None            # (time, fraction done) at the block before the latest
        self.drawn = False
        self.last_draw = -1e9

    def __call__(self, done: int, total: int) -> None:
        if self.quiet or total <= 0:
            return
        now = self.clock() - self.t0
        frac = min(1.0, max(0.0, done / total))
        if self.anchor is None:
            self.anchor = self.prev = (now, frac)
            return
        if not self.estimated and now - self.anchor[0] >= CALIBRATION_S and frac > self.prev[1]:
            self.estimated = True
            left = self._left(now, frac)
            if left > ESTIMATE_OVER_S:
                self._line(f"flexmech: this run takes about {format_duration(now + left)}"
                           + (f" ({self.describe()})" if self.describe else "")
                           + "; Ctrl-C stops it and keeps the frames so far")
        if self.bar and now >= BAR_AFTER_S and now - self.last_draw >= REDRAW_S:
            self.last_draw = now
            self._draw(frac, now)
        if frac > self.prev[1]:
            self.prev = (now, frac)

    def _draw(self, frac: float, now: float) -> None:
        width = max(10, min(40, shutil.get_terminal_size((80, 20)).columns - 40))
        fill = int(round(frac * width))
        eta = self._left(now, frac)
        eta_s = format_duration(eta) if eta == eta else "?"
        self.stream.write(f"\r[{'#' * fill}{'.' * (width - fill)}] {100 * frac:5.1f} %  "
                          f"{format_duration(now)} elapsed, {eta_s} left ")
        self.stream.flush()
        self.drawn = True

    def _left(self, now: float, frac: float) -> float:
        """Seconds left at the latest block's rate (NaN before a second block)."""
        t_a, f_a = self.prev if self.prev is not None else (0.0, 0.0)
        if frac >= 1.0:
            return 0.0
        return (now - t_a) * (1.0 - frac) / (frac - f_a) if frac > f_a else float("nan")

    def _line(self, text: str) -> None:
        if self.drawn:
            self.stream.write("\n")
            self.drawn = False
        self.stream.write(text + "\n")
        self.stream.flush()

    def close(self, finished: bool = False) -> None:
        """End the bar's line (call when the run ended, however it ended; ``finished``: at 100 %)."""
        if self.drawn and finished:
            self._draw(1.0, self.clock() - self.t0)
        if self.drawn:
            self.stream.write("\n")
            self.stream.flush()
            self.drawn = False
