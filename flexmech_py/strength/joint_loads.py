"""Bearing loads: the reaction envelope of every joint over a run, in the joint's own frame.

The force is the one body ``a`` of the joint exerts on body ``b`` (the ``reaction`` output's), from
the run's model when the block carries its reactions (``Result.reactions``: every superposition
model; the coupled and nonlinear models from their multipliers), else from the rigid-body solution
(``source`` says which).  A bearing catalogue asks for the load in the frame of the part that holds
the bearing: here the frame of the joint's first link (body a, else body b; the ground's frame when
neither is a link), its axis along the link: ``axial`` along it, ``normal`` across it.  Per joint:
the largest, smallest and RMS magnitude, when the largest acts, the mean load vector, and inside
the time window the whole load cycle (joint_loads.csv) -- what an equivalent dynamic bearing load
is computed from.
"""

from __future__ import annotations

import numpy as np

from .stress import in_window

__all__ = ["JointLoads"]


class JointLoads:
    """Joint reaction envelopes over a run's frames inside ``window`` = (t0, t1) [s] (None: every
    frame), fed block by block (:meth:`add`), with the load cycle there."""

    def __init__(self, case, window: tuple[float, float] | None = None):
        mech = case.mechanism
        self.window = window
        self.joints = [j.name for j in mech.joints]
        self.frame_link = {}
        for j in mech.joints:
            bodies = [p.body for p in mech.joint_points(j)]
            link = next((b for b in bodies if b is not None and b.kind == "link"), None)
            self.frame_link[j.name] = None if link is None else mech.link_index(link.name)
        self.acc = {name: {"max": 0.0, "t_max": 0.0, "min": np.inf, "sum2": 0.0, "sum": np.zeros(2), "n": 0}
                    for name in self.joints}
        self.cycle: dict[str, list] = {name: [] for name in self.joints}
        self.t_last = -np.inf
        self.source = None

    def _force(self, block, name: str) -> np.ndarray:
        if block.reactions is not None:
            self.source = "model"
            return block.reactions(name)
        self.source = "rigid"
        return block.rigid.reaction(name)

    def add(self, block) -> None:
        keep = in_window(block.t, self.t_last, self.window)
        if not np.any(keep):
            return
        t = block.t[keep]
        for name in self.joints:
            f = self._force(block, name)[keep]
            li = self.frame_link[name]
            phi = block.motion.phi[keep, li] if li is not None else np.zeros(t.size)
            c, s = np.cos(phi), np.sin(phi)
            fa, fn = c * f[:, 0] + s * f[:, 1], -s * f[:, 0] + c * f[:, 1]
            mag = np.hypot(f[:, 0], f[:, 1])
            a = self.acc[name]
            k = int(np.argmax(mag))
            if mag[k] > a["max"]:
                a["max"], a["t_max"] = float(mag[k]), float(t[k])
            a["min"] = min(a["min"], float(mag.min()))
            a["sum2"] += float(np.sum(mag * mag))
            a["sum"] += [float(np.sum(fa)), float(np.sum(fn))]
            a["n"] += t.size
            self.cycle[name].append(np.column_stack([t, fa, fn, mag, f[:, 2]]))
        self.t_last = float(t[-1])

    def summary(self, case) -> dict:
        """Per joint: max, min and RMS load magnitude [N], when the max acts, the mean load in the
        joint's frame, the frame's link and the source of the forces."""
        out = {}
        for name in self.joints:
            a = self.acc[name]
            n = max(a["n"], 1)
            li = self.frame_link[name]
            out[name] = {"max_N": a["max"], "t_max_s": a["t_max"], "min_N": float(a["min"]) if a["n"] else 0.0,
                         "rms_N": float(np.sqrt(a["sum2"] / n)), "mean_axial_N": float(a["sum"][0] / n),
                         "mean_normal_N": float(a["sum"][1] / n),
                         "frame": case["links"][li]["name"] if li is not None else "ground", "source": self.source}
        return out

    def cycle_rows(self) -> tuple[list[str], np.ndarray]:
        """(column names, rows) of the load cycle of every joint in the window (joint_loads.csv)."""
        cols, blocks = ["t"], []
        for name in self.joints:
            cols += [f"{name}_axial_N", f"{name}_normal_N", f"{name}_magnitude_N", f"{name}_moment_Nm"]
        parts = [np.concatenate(self.cycle[name]) if self.cycle[name] else np.empty((0, 5)) for name in self.joints]
        if not parts or parts[0].shape[0] == 0:
            return cols, np.empty((0, len(cols)))
        blocks = [parts[0][:, :1]] + [p[:, 1:] for p in parts]
        return cols, np.hstack(blocks)
