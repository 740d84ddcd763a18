"""The slave of a flexmech FMI 2.0 co-simulation unit (``flexmech fmu``; docs/cli.md, docs/api.md).

This module is embedded in the unit (``resources/flexmech_fmu_slave.py``) by
:func:`flexmech_py.fmu.export_fmu`; the unit's binary (PythonFMU's) imports it on the host, where
Python and flexmech must be installed.  Its resources also hold the case (``case.toml``, the resolved
case written by :meth:`~flexmech_py.case.Case.write`) and ``flexmech_fmu.json`` (the model, the
inputs, the outputs and their units).

The unit is a :class:`~flexmech_py.run.stepping.Simulation` of the case: its inputs ``effort.<joint>``
are the efforts of force-driven joints [N m or N], held over each communication step (zero-order
hold); its outputs are the case's outputs at the end of the step.  A communication step must be a
whole number of the case's steps ``solver.dt`` and must start where the last one ended; time runs
from 0 to the case's ``solver.t_end``.  The master may save and restore the unit's state
(fmi2GetFMUstate / fmi2SetFMUstate: :meth:`Simulation.state` and :meth:`Simulation.restore`, in
memory; the state is not serializable).  A step that breaks these rules, or whose model loop fails, is
refused (fmi2Discard: the unit stays where it was and can go on) with a log message naming the rule or
the failure.

Imports are absolute: the unit loads this file as a top-level module, outside the package.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Status
from pythonfmu.default_experiment import DefaultExperiment

from flexmech_py.base.version import __version__
from flexmech_py.case import load_case
from flexmech_py.base.errors import FlexmechError
from flexmech_py.run.stepping import Simulation

#: the unit's description of itself, beside the case in its resources
SPEC_NAME = "flexmech_fmu.json"
#: the resolved case in its resources
CASE_NAME = "case.toml"
#: a communication step or time within this fraction of the case's step of a whole step counts as one
STEP_TOLERANCE = 1e-6


def steps_in(step_size: float, dt: float) -> int | None:
    """The number of case steps in a communication step, or None when it is not a whole number (> 0)."""
    n = round(step_size / dt)
    if n < 1 or abs(step_size - n * dt) > STEP_TOLERANCE * dt:
        return None
    return n


class FlexmechPlant(Fmi2Slave):
    """A flexmech case as an FMI 2.0 co-simulation slave (the module's docstring)."""

    author = "flexmech"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        folder = Path(self.resources)
        self.spec = json.loads((folder / SPEC_NAME).read_text(encoding="utf-8"))
        self.case_path = folder / CASE_NAME
        self.modelName = self.spec["model_name"]
        self.description = self.spec["description"]
        self.default_experiment = DefaultExperiment(0.0, self.spec["t_end"], self.spec["dt"])
        self.efforts = {j: 0.0 for j in self.spec["inputs"]}
        self.sim: Simulation | None = None       # built on first use (not when the unit is packed)
        if self.spec["flexmech_version"] != __version__:
            self.log(f"the unit was exported by flexmech {self.spec['flexmech_version']}; this host has flexmech "
                     f"{__version__}", Fmi2Status.warning)
        for joint, unit in self.spec["inputs"].items():
            self.register_variable(Real(f"effort.{joint}", causality=Fmi2Causality.input,
                                        variability=Fmi2Variability.continuous, start=0.0,
                                        description=f"effort on joint {joint} [{unit}], added to the case's force "
                                                    "law, held over each step",
                                        getter=lambda j=joint: self.efforts[j],
                                        setter=lambda v, j=joint: self._set_effort(j, v)))
        for name, unit in self.spec["outputs"].items():
            self.register_variable(Real(name, causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
                                        description=f"case output {name} [{unit}]",
                                        getter=lambda k=name: self._simulation().output(k)))

    def _set_effort(self, joint: str, value) -> None:
        value = float(value)
        if not math.isfinite(value):
            raise ValueError(f"effort.{joint} must be finite, got {value!r}")
        self.efforts[joint] = value

    def _simulation(self) -> Simulation:
        if self.sim is None:
            case = load_case(self.case_path)
            self.sim = Simulation(case, self.spec["model"], record=False)
        return self.sim

    # the FMU state (fmi2GetFMUstate / fmi2SetFMUstate, in memory; not serializable)
    def _get_fmu_state(self) -> dict:
        return {"simulation": self._simulation().state(), "efforts": dict(self.efforts)}

    def _set_fmu_state(self, state: dict) -> None:
        self._simulation().restore(state["simulation"])
        self.efforts = dict(state["efforts"])

    def _refuse(self, message: str) -> bool:
        self.log(message, Fmi2Status.discard)
        return False

    def setup_experiment(self, start_time: float, stop_time, tolerance) -> None:
        sim = self._simulation()
        if abs(start_time - sim.t) > STEP_TOLERANCE * sim.dt:
            raise ValueError(f"the unit starts at t = {sim.t:g} s (the case's start), not {start_time:g} s")
        if stop_time is not None and stop_time > sim.t_end + STEP_TOLERANCE * sim.dt:
            raise ValueError(f"stop time {stop_time:g} s is after the case's solver.t_end = {sim.t_end:g} s: "
                             "export the unit with --set solver.t_end=...")

    def do_step(self, current_time: float, step_size: float) -> bool:
        sim = self._simulation()
        n = steps_in(step_size, sim.dt)
        if n is None:
            return self._refuse(f"communication step {step_size:.9g} s is not a whole number of the case's "
                                f"solver.dt = {sim.dt:.9g} s: use a multiple of it")
        if abs(current_time - sim.t) > STEP_TOLERANCE * sim.dt:
            return self._refuse(f"the step starts at t = {current_time:.9g} s but the unit is at t = {sim.t:.9g} s "
                                "(it cannot go back or skip)")
        if sim.step + n > sim.prep.nsteps:
            return self._refuse(f"a step to t = {current_time + step_size:.9g} s passes the case's solver.t_end = "
                                f"{sim.t_end:.9g} s: export the unit with --set solver.t_end=...")
        try:
            sim.advance(n, inputs=self.efforts)
        except FlexmechError as exc:
            return self._refuse(f"flexmech: {exc}")
        return True
