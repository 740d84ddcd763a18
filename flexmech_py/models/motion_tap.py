"""A run's rigid-body motion shared with the runs that go beside it on coarser grids (the step-doubling
run, the error budget's probes): the samples the run computes are kept at every ``ratio``-th step until
the coarser run takes them, so the rigid motion (a forward-dynamics integration for force drives) is
computed once (docs/theory.md section 21.5).  A run that takes its motion from a tap advances only as
far as the run it follows has sampled (:meth:`MotionTap.available`)."""

from __future__ import annotations

import numpy as np

from ..mechanism.motion import RigidMotion

__all__ = ["MotionTap"]


class MotionTap:
    """Samples of a run's rigid motion at the run's steps that are multiples of ``ratio``, numbered on
    the coarser grid (step k of the coarser grid is step ratio k of the run's)."""

    def __init__(self, ratio: int):
        self.ratio = int(ratio)
        self.parts: list = []       # (first coarse step, RigidMotion of consecutive coarse steps)
        self.last = -1              # the last step of the run offered
        self.closed = False         # the run has ended: no more samples will come

    def offer(self, i0: int, rm: RigidMotion) -> None:
        """Take the samples of the run's steps i0, i0 + 1, ... (rm) not offered before."""
        steps = i0 + np.arange(rm.t.size)
        on = (steps % self.ratio == 0) & (steps > self.last)
        if on.any():
            self.parts.append((int(steps[on][0]) // self.ratio, rm.select(np.flatnonzero(on))))
        if steps.size:
            self.last = max(self.last, int(steps[-1]))

    def available(self) -> int:
        """The last step of the coarser grid whose sample is here (or was taken)."""
        return self.last // self.ratio

    def take(self, k0: int, k1: int) -> RigidMotion:
        """The samples of the coarser grid's steps k0..k1 (all available); the ones before k0 are dropped."""
        pieces = []
        for first, rm in self.parts:
            lo, hi = max(k0, first), min(k1, first + rm.t.size - 1)
            if lo <= hi:
                pieces.append(rm.select(slice(lo - first, hi - first + 1)))
        self.parts = [(f, rm) for f, rm in self.parts if f + rm.t.size - 1 >= k0]
        if sum(p.t.size for p in pieces) != k1 - k0 + 1:
            raise RuntimeError(f"rigid-motion samples {k0}..{k1} are not all in the tap")  # pragma: no cover
        return pieces[0] if len(pieces) == 1 else RigidMotion.concat(pieces)
