"""A run's output frames as they arrive, block by block (docs/theory.md section 19).

A run is integrated in chunks of steps; each chunk's frames come back as a *block* (a
:class:`~flexmech_py.run.results.Result` over those frames only).  This module holds what is made of
blocks without keeping them all:

- :func:`join` glues blocks into one Result (a run kept in memory);
- :class:`ColumnStats` the smallest, largest, largest absolute (and when) and final value of every
  column over all frames, as summary.json reports them;
- :class:`Envelope` a bounded set of frames for drawing: the frames are cut into at most
  ``buckets`` runs of consecutive frames, and in each run every column keeps the frames of its
  smallest and largest value, so every peak and trough of a record of any length survives;
- :func:`continue_angles` keeps angle columns continuous from one block to the next.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..mechanism.motion import LinkMotion, RigidMotion

__all__ = ["join", "select_frames", "ColumnStats", "Envelope", "continue_angles"]

TWO_PI = 2.0 * np.pi


def _cat(blocks, name: str, axis: int):
    first = getattr(blocks[0], name)
    if first is None:
        return None
    return np.concatenate([getattr(b, name) for b in blocks], axis=axis)


def join(blocks: list):
    """One Result over the frames of consecutive blocks (no frame repeated).  Run-level entries
    (``extra``, ``timing``, ``failure``) are the last block's: a block carries them accumulated
    over the run so far."""
    if len(blocks) == 1:
        return blocks[0]
    b0, bl = blocks[0], blocks[-1]
    res = dataclasses.replace(
        bl, t=_cat(blocks, "t", 0), columns={k: np.concatenate([b.columns[k] for b in blocks]) for k in b0.columns},
        q=_cat(blocks, "q", 0), qd=_cat(blocks, "qd", 0), qdd=_cat(blocks, "qdd", 0),
        u=_cat(blocks, "u", 1), v=_cat(blocks, "v", 1), a=_cat(blocks, "a", 1), rig=_cat(blocks, "rig", 2),
        axial=_cat(blocks, "axial", 1), steps=_cat(blocks, "steps", 0), state=_cat(blocks, "state", 1),
        motion=None if b0.motion is None else LinkMotion.concat([b.motion for b in blocks]),
        rigid=None if b0.rigid is None else RigidMotion.concat([b.rigid for b in blocks]),
        timing=dict(bl.timing), extra=dict(bl.extra))
    res.reactions = None if b0.reactions is None else b0.reactions.over(res)
    return res


def select_frames(res, sel: slice):
    """The frames ``sel`` of a Result (a block without its first frame, e.g.)."""
    out = dataclasses.replace(
        res, t=res.t[sel], columns={k: y[sel] for k, y in res.columns.items()}, q=res.q[sel], qd=res.qd[sel],
        qdd=res.qdd[sel], u=res.u[:, sel], v=res.v[:, sel], a=res.a[:, sel], rig=res.rig[:, :, sel],
        axial=None if res.axial is None else res.axial[:, sel], steps=None if res.steps is None else res.steps[sel],
        state=None if res.state is None else res.state[:, sel],
        motion=None if res.motion is None else res.motion.select(sel),
        rigid=None if res.rigid is None else res.rigid.select(sel))
    if res.reactions is not None:
        out.reactions = res.reactions.over(out, sel)
    return out


def continue_angles(columns: dict, previous: dict) -> None:
    """Shift, in place, every column of a block whose first frame (the previous block's last frame,
    computed again) differs from ``previous`` (that frame's values) by a whole number of turns: an
    angle unwrapped within the block from another start.  Other columns are left alone."""
    for name, y in columns.items():
        if name not in previous or y.size == 0:
            continue
        d = previous[name] - y[0]
        turns = np.round(d / TWO_PI)
        if turns != 0 and abs(d - turns * TWO_PI) <= 1e-9 * max(1.0, abs(previous[name])):
            columns[name] = y + turns * TWO_PI


class ColumnStats:
    """Per column over every frame added: ``min``, ``max``, ``peak_abs`` (largest |value|; NaN once a
    NaN appears), ``t_peak_abs`` and ``final``."""

    def __init__(self):
        self.columns: dict[str, dict] = {}
        self.frames = 0
        self.t_last = None

    def add(self, t: np.ndarray, columns: dict) -> None:
        if t.size == 0:
            return
        for name, y in columns.items():
            y = np.asarray(y, float)
            i = int(np.argmax(np.abs(y)))          # the first NaN when there is one
            new = {"min": float(y.min()), "max": float(y.max()), "peak_abs": float(abs(y[i])),
                   "t_peak_abs": float(t[i]), "final": float(y[-1])}
            old = self.columns.get(name)
            if old is not None:
                new["min"] = float(np.minimum(old["min"], new["min"]))
                new["max"] = float(np.maximum(old["max"], new["max"]))
                if np.isnan(old["peak_abs"]) or old["peak_abs"] >= new["peak_abs"]:
                    new["peak_abs"], new["t_peak_abs"] = old["peak_abs"], old["t_peak_abs"]
            self.columns[name] = new
        self.frames += int(t.size)
        self.t_last = float(t[-1])

    @classmethod
    def of(cls, t, columns: dict) -> "ColumnStats":
        st = cls()
        st.add(np.asarray(t), columns)
        return st


def _extremes(rows: np.ndarray, bucket: np.ndarray) -> np.ndarray:
    """Mask of the rows holding some column's smallest or largest value within their bucket (rows
    (n, 1 + ncol) [t, columns...] in frame order, bucket (n,) non-decreasing)."""
    keep = np.zeros(rows.shape[0], bool)
    if rows.shape[0] == 0:
        return keep
    starts = np.flatnonzero(np.r_[True, bucket[1:] != bucket[:-1]])
    ends = np.r_[starts[1:], rows.shape[0]] - 1
    for c in range(1, rows.shape[1]):
        order = np.lexsort((rows[:, c], bucket))   # by bucket, then value (NaN last)
        keep[order[starts]] = True                 # each bucket's smallest value
        keep[order[ends]] = True                   # and its largest
    return keep


class Envelope:
    """At most about ``2 x buckets x columns`` frames of a record of any length, for drawing (see the
    module's docstring).  ``t``, ``columns``: the kept frames in time order."""

    def __init__(self, buckets: int = 1000):
        self.buckets = int(buckets)
        self.width = 1                         # frames per bucket, a power of two
        self.names: list[str] | None = None
        self._done = np.zeros((0, 1))          # kept rows of finished buckets
        self._done_idx = np.zeros(0, np.int64)
        self._open = np.zeros((0, 1))          # kept rows of the bucket still filling
        self._open_idx = np.zeros(0, np.int64)
        self.frames = 0
        self._first = self._last = None

    def add(self, t: np.ndarray, columns: dict) -> None:
        if t.size == 0:
            return
        if self.names is None:
            self.names = list(columns)
            self._done = self._done.reshape(0, 1 + len(self.names))
            self._open = self._open.reshape(0, 1 + len(self.names))
        rows = np.column_stack([t] + [np.asarray(columns[n], float) for n in self.names])
        idx = np.arange(self.frames, self.frames + t.size)
        self.frames += int(t.size)
        if self._first is None:
            self._first = (rows[:1], idx[:1])
        self._last = (rows[-1:], idx[-1:])
        rows, idx = np.vstack([self._open, rows]), np.r_[self._open_idx, idx]
        bucket = idx // self.width
        keep = _extremes(rows, bucket)
        rows, idx, bucket = rows[keep], idx[keep], bucket[keep]
        open_ = bucket == bucket[-1]
        self._done = np.vstack([self._done, rows[~open_]])
        self._done_idx = np.r_[self._done_idx, idx[~open_]]
        self._open, self._open_idx = rows[open_], idx[open_]
        while self.frames // self.width > self.buckets:
            self._coarsen()

    def _coarsen(self) -> None:
        """Twice as many frames per bucket: keep the extremes of the merged buckets."""
        self.width *= 2
        rows, idx = np.vstack([self._done, self._open]), np.r_[self._done_idx, self._open_idx]
        bucket = idx // self.width
        keep = _extremes(rows, bucket)
        rows, idx, bucket = rows[keep], idx[keep], bucket[keep]
        open_ = bucket == bucket[-1]
        self._done, self._done_idx = rows[~open_], idx[~open_]
        self._open, self._open_idx = rows[open_], idx[open_]

    def _rows(self) -> np.ndarray:
        """The kept rows in frame order, the first and the last frame always among them."""
        rows, idx = np.vstack([self._done, self._open]), np.r_[self._done_idx, self._open_idx]
        if self._first is None:
            return rows
        if idx.size == 0 or idx[0] != self._first[1][0]:
            rows, idx = np.vstack([self._first[0], rows]), np.r_[self._first[1], idx]
        if idx[-1] != self._last[1][0]:
            rows = np.vstack([rows, self._last[0]])
        return rows

    @property
    def t(self) -> np.ndarray:
        return self._rows()[:, 0]

    @property
    def columns(self) -> dict:
        rows = self._rows()
        return {n: rows[:, 1 + k] for k, n in enumerate(self.names or [])}
