"""What a run's blocks of frames carry besides their model's outputs: the time and counters
accumulated over the blocks, the values a block continues from, the kinematic drives' effort columns
of the constrained family, and the integrator's summary."""

from __future__ import annotations

import time

import numpy as np

from ..models.constrained import outputs as cpl_out
from ..case import integrator_coefficients, integrator_of
from .frames import continue_angles, select_frames
from .results import Result

__all__ = ["Accumulated", "add_control_columns", "last_values", "after_first", "coupled_curvature",
           "drive_column_joints", "drive_columns", "integrator_summary"]


class Accumulated:
    """What a run's blocks carry accumulated: wall and CPU time of the rigid motion, the kernel's
    samples and the kernel, geometric-stiffness iterations, the largest reaction residual."""

    def __init__(self):
        self.clock = dict.fromkeys(("rigid_s", "rigid_cpu_s", "samples_s", "samples_cpu_s", "kernel_s",
                                    "kernel_cpu_s"), 0.0)
        self.geo_iters = 0
        self.reaction_residual = 0.0
        self.deflection = None          # the run's DeflectionReference

    def add_time(self, what: str, t0: float, c0: float) -> None:
        self.clock[f"{what}_s"] += time.perf_counter() - t0
        self.clock[f"{what}_cpu_s"] += time.thread_time() - c0

    def timing(self) -> dict:
        return {"rigid_s": self.clock["rigid_s"], "kernel_s": self.clock["kernel_s"]}

    def cpu(self) -> dict:
        return {"rigid_cpu_s": self.clock["rigid_cpu_s"], "kernel_cpu_s": self.clock["kernel_cpu_s"],
                "rigid_samples_s": self.clock["samples_s"]}


def last_values(block: Result, prev: dict | None) -> dict | None:
    """The last frame's value of every column (what the next block continues from)."""
    if block.t.size == 0:
        return prev
    return {k: float(y[-1]) for k, y in block.columns.items()}


def after_first(res: Result, prev: dict | None) -> Result:
    """A chunk's block without its first frame when a block came before (that frame is the previous
    block's last, evaluated again: angle columns continue from it)."""
    if prev is None:
        return res
    continue_angles(res.columns, prev)
    return select_frames(res, slice(1, None))


def coupled_curvature(cm, res: Result, li: int, frac: float) -> np.ndarray:
    return cpl_out.curvature(cm, res.state, li, frac)


def drive_column_joints(cm) -> dict:
    """{column: joint} of the kinematic drives' extra columns: ``drive_torque`` (``drive_force`` on a
    guided joint) for a single drive, ``drive_torque_<joint>`` for several; a name the case's
    outputs already use is left to them."""
    kin = [d for d in cm.case.mechanism.drives if d.kinematic]
    out = {}
    for d in kin:
        angular = cm.case.mechanism.joint(d.joint).angular
        name = ("drive_torque" if angular else "drive_force") + ("" if len(kin) == 1 else f"_{d.joint}")
        if name not in cm.case["outputs"]:
            out[name] = d.joint
    return out


def drive_columns(cm, fr, units: dict) -> dict:
    """The kinematic drives' torque (force on a guided joint) from the model's multipliers, as extra
    columns (names: :func:`drive_column_joints`)."""
    out = {}
    for name, joint in drive_column_joints(cm).items():
        out[name] = cpl_out.drive_force(cm, fr, joint)
        units[name] = "N m" if cm.case.mechanism.joint(joint).angular else "N"
    return out


def add_control_columns(case, outputs: dict, columns: dict, units: dict) -> None:
    """The feedback controllers' outputs {name: (nf,)} as the columns control_<name> [N m or N]."""
    for name, u in outputs.items():
        joint = next(c["joint"] for c in case["controllers"] if c["name"] == name)
        columns[f"control_{name}"] = u
        units[f"control_{name}"] = "N m" if case.mechanism.joint(joint).angular else "N"


def integrator_summary(sol: dict, model: str) -> dict:
    """summary.json's ``integrator`` entry: the name, its case parameter(s) and the kernel's
    (am, af, beta, gamma), whether it is the model family's default (the case names none), and the
    divergence limit [m]."""
    integ = integrator_of(sol, model)
    name = integ["integrator"]
    am, af, beta, gamma = integrator_coefficients(name, integ)
    params = {k: integ[k] for k in ("hht_alpha", "rho_inf") if k in integ}
    return {"name": name, **params, "am": am, "af": af, "beta": beta, "gamma": gamma,
            "default": "integrator" not in sol, "divergence_limit_m": sol.get("divergence_limit")}
