"""A case exported as an FMI 2.0 co-simulation unit (``flexmech fmu``; docs/cli.md, docs/api.md).

:func:`export_fmu` checks the unit's inputs and outputs on a :class:`~flexmech_py.run.stepping.Simulation`
of the case, then packs with PythonFMU (the optional extra ``flexmech[fmi]``) the slave
(:mod:`flexmech_py.fmu_slave`), the resolved case and a description of the unit into one ``.fmu``
file, written whole or not at all.  The unit runs wherever Python and flexmech are installed: its
binary (PythonFMU's, for Linux x86-64 and Windows x64) loads the host's Python and imports flexmech.
"""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
import tempfile
from pathlib import Path

from .base.version import __version__
from .case import Case
from .base.errors import CaseError, FlexmechError
from .base.families import MODELS
from .run.outdir import ResultFolder
from .run.stepping import Simulation

__all__ = ["export_fmu", "FmuInfo", "MISSING_EXTRA"]

#: the one line a user without PythonFMU reads
MISSING_EXTRA = "flexmech fmu needs PythonFMU: pip install 'flexmech[fmi]'"
#: the name of the slave module inside the unit (a top-level module there)
SLAVE_MODULE = "flexmech_fmu_slave"


@dataclasses.dataclass(frozen=True)
class FmuInfo:
    """What :func:`export_fmu` wrote: the file, the model identifier, the inputs {variable: unit}, the
    outputs {variable: unit}, the case's step and end time [s]."""

    path: Path
    model_name: str
    inputs: dict
    outputs: dict
    dt: float
    t_end: float


def _builder():
    try:
        from pythonfmu.builder import FmuBuilder
    except ImportError:
        raise FlexmechError(MISSING_EXTRA) from None
    return FmuBuilder


def model_identifier(out: Path) -> str:
    """The unit's model name and its binary's file name: a C identifier from the unit's file name."""
    name = "_".join(re.findall(r"[A-Za-z0-9]+", out.stem)) or "plant"
    return name if name[0].isalpha() else f"flexmech_{name}"


def _inputs(sim: Simulation, joints: list | None) -> dict:
    """{joint: unit} of the joints whose efforts the unit takes (default: every force-driven joint)."""
    if joints is None:
        joints = list(sim.base)
    if not joints:
        raise CaseError("--inputs", "the case has no force-driven joint: give a joint a drive with law = 'force' "
                                    "and constant = 0 to take an effort from the master")
    angular = {j.name: j.angular for j in sim.case.mechanism.joints}
    for j in joints:
        if j in sim.kinematic:
            raise CaseError("--inputs", f"joint {j!r} is prescribed by a kinematic drive: give it the law 'force' "
                                        "(constant = 0) in the case to actuate it")
        if j not in sim.base:
            raise CaseError("--inputs", f"no force-driven joint {j!r}; joints that take efforts: "
                                        f"{', '.join(sim.base) or 'none'}")
    return {j: "N m" if angular.get(j, True) else "N" for j in dict.fromkeys(joints)}


def _outputs(sim: Simulation, names: list | None) -> dict:
    """{output: unit} of the case's outputs the unit gives (default: all)."""
    units = sim.stepper.current_block(sim.step).units
    if names is None:
        names = list(units)
    for name in names:
        if name not in units:
            raise CaseError("--outputs", f"no output {name!r} in the case; its outputs: {', '.join(units)} "
                                         "(add one with --set 'outputs.NAME = {kind = ...}')")
    return {n: units[n] for n in dict.fromkeys(names)}


def describe(case: Case, name: str, model: str | None = None, inputs: list | None = None,
             outputs: list | None = None) -> dict:
    """The unit's description (``flexmech_fmu.json``) of a case, checked on a Simulation of it;
    ``name``: the model identifier."""
    model = case["solver"]["model"] if model is None else model
    if model not in MODELS:
        raise CaseError("--model", f"a unit runs one model; the case says {model!r}: give --model, one of "
                                   f"{', '.join(MODELS)}")
    sim = Simulation(case, model, record=False)
    spec_in = _inputs(sim, inputs)
    spec_out = _outputs(sim, outputs)
    collide = {f"effort.{j}" for j in spec_in} & set(spec_out)
    if collide:
        raise CaseError("--outputs", f"output {sorted(collide)[0]!r} has an input's name: rename the output")
    return {"flexmech_version": __version__, "model": model, "model_name": name,
            "description": f"{case['case'].get('title', 'flexmech case')} (flexmech, model {model})",
            "dt": sim.dt, "t_end": sim.t_end, "inputs": spec_in, "outputs": spec_out}


def export_fmu(case: Case, out, model: str | None = None, inputs: list | None = None,
               outputs: list | None = None) -> FmuInfo:
    """Write the FMI 2.0 co-simulation unit of ``case`` to ``out`` (a ``.fmu`` file): inputs
    ``effort.<joint>`` (default: every force-driven joint), outputs the case's (default: all).
    FlexmechError naming the extra when PythonFMU is absent; CaseError for bad inputs, outputs,
    model or file name."""
    builder = _builder()
    out = Path(out)
    if out.suffix != ".fmu":
        raise CaseError("--out", f"{out} must be a file name ending in .fmu (e.g. --out plant.fmu)")
    spec = describe(case, model_identifier(out), model, inputs, outputs)
    with tempfile.TemporaryDirectory(prefix="flexmech-fmu-") as tmp:
        src = Path(tmp)
        script = src / f"{SLAVE_MODULE}.py"
        shutil.copyfile(Path(__file__).with_name("fmu_slave.py"), script)
        (src / "flexmech_fmu.json").write_text(json.dumps(spec, indent=1) + "\n", encoding="utf-8")
        case.write(src / "case.toml")
        with ResultFolder(out, "fmu", single=True) as rf:
            builder.build_FMU(script, dest=rf.stage / out.name,
                              project_files=[src / "flexmech_fmu.json", src / "case.toml"],
                              needsExecutionTool="true", canHandleVariableCommunicationStepSize="true",
                              canGetAndSetFMUstate="true")
            rf.commit()
    return FmuInfo(out, spec["model_name"], {f"effort.{j}": u for j, u in spec["inputs"].items()},
                   spec["outputs"], spec["dt"], spec["t_end"])
