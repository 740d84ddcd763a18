"""flexmech fmu: a case exported as an FMI 2.0 co-simulation unit, loaded by an FMI master (fmpy), with a
PD loop closed from the master's side; the same loop closed on fm.Simulation directly gives the same
motion (to rounding) when the master's step is the case's, and when it is a multiple of it (the unit
holds the master's effort over its steps, as Simulation.advance does)."""

import math
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
import xml.etree.ElementTree as ET

from pathlib import Path

import numpy as np
import pytest

import flexmech_py as fm
from flexmech_py.cli import main
from flexmech_py.fmu import MISSING_EXTRA, export_fmu
from flexmech_py.run.stepping import Simulation

DATA = Path(__file__).parent / "data"

pytest.importorskip("pythonfmu", reason="PythonFMU (pip install 'flexmech[fmi]') packs the unit")
fmpy = pytest.importorskip("fmpy", reason="fmpy (pip install fmpy) is the FMI master that loads the unit")
from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

DT = 2e-4
T_END = 0.06
KP, KD, REF = 3000.0, 150.0, 0.05    # N m/rad, N m s/rad, rad: PD on the manipulator's base joint


def _case():
    """The Bricout arm with both joint torques zero (force-driven, actuated from outside) and the
    base joint's rate as an output."""
    return fm.load_case("manipulator_bricout", [
        f"solver.t_end={T_END}", f"solver.dt={DT}", "solver.error_estimate=none",
        "drive.torques.base.constant=0", "drive.torques.joint_2.constant=0",
        "outputs.alpha_rate={kind = 'joint_speed', joint = 'base'}"])


def _torque(angle, rate):
    return KP * (REF - angle) - KD * rate


def _direct_loop(case, every):
    """The PD loop closed on fm.Simulation: (times, alpha, tip_dy_elastic) at each master step."""
    sim = Simulation(case, "hac", record=False)
    rows = []
    while sim.step + every <= sim.prep.nsteps:
        out = sim.outputs()
        rows.append((sim.t, out["alpha"], out["tip_dy_elastic"]))
        sim.advance(every, inputs={"base": _torque(out["alpha"], out["alpha_rate"])})
    out = sim.outputs()
    rows.append((sim.t, out["alpha"], out["tip_dy_elastic"]))
    return np.array(rows)


class Unit:
    """An exported unit instantiated through fmpy's low-level FMI 2.0 API."""

    def __init__(self, path, tmp_path, stop=None):
        self.md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=extract(str(path), str(tmp_path / "unzipped")),
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="plant")
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0, stopTime=stop)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()

    def get(self, *names):
        return self.fmu.getReal([self.vr[n] for n in names])

    def step(self, t, h, torque):
        self.fmu.setReal([self.vr["effort.base"]], [torque])
        self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)

    def close(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


def _fmu_loop(unit, every):
    h = every * DT
    n = round(T_END / h)
    rows = []
    for k in range(n):
        alpha, rate, dy = unit.get("alpha", "alpha_rate", "tip_dy_elastic")
        rows.append((k * h, alpha, dy))
        unit.step(k * h, h, _torque(alpha, rate))
    alpha, dy = unit.get("alpha", "tip_dy_elastic")
    rows.append((n * h, alpha, dy))
    return np.array(rows)


@pytest.fixture(scope="module")
def plant(tmp_path_factory):
    path = tmp_path_factory.mktemp("fmu") / "plant.fmu"
    info = export_fmu(_case(), path, model="hac", inputs=["base"], outputs=["alpha", "alpha_rate", "tip_dy_elastic"])
    return path, info


def test_the_unit_describes_its_inputs_outputs_case_and_steps(plant):
    path, info = plant
    assert info.inputs == {"effort.base": "N m"} and list(info.outputs) == ["alpha", "alpha_rate", "tip_dy_elastic"]
    with zipfile.ZipFile(path) as z:
        names = set(z.namelist())
        root = ET.fromstring(z.read("modelDescription.xml"))
        embedded = fm.load_case(_case_file(z, path))
    assert {"resources/case.toml", "resources/flexmech_fmu.json", "resources/flexmech_fmu_slave.py"} <= names
    assert any(n.startswith("binaries/linux64/") for n in names)
    variables = {v.get("name"): v.get("causality") for v in root.iter("ScalarVariable")}
    assert variables == {"effort.base": "input", "alpha": "output", "alpha_rate": "output", "tip_dy_elastic": "output"}
    assert float(root.find("DefaultExperiment").get("stepSize")) == pytest.approx(DT, rel=1e-12)
    assert embedded["solver"]["t_end"] == T_END and embedded["drives"][0]["constant"] == 0.0


def _case_file(z, path):
    out = path.with_name("embedded.toml")
    out.write_bytes(z.read("resources/case.toml"))
    return out


@pytest.mark.parametrize("every", [1, 4])
def test_a_pd_loop_closed_by_the_master_is_the_loop_closed_on_simulation(plant, tmp_path, every):
    """The master's step equal to the case's step (every = 1) and four of them (ZOH over 4 steps)."""
    unit = Unit(plant[0], tmp_path, stop=T_END)
    try:
        got = _fmu_loop(unit, every)
    finally:
        unit.close()
    want = _direct_loop(_case(), every)
    assert got.shape == want.shape
    np.testing.assert_allclose(got[:, 0], want[:, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[:, 1], want[:, 1], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(got[:, 2], want[:, 2], rtol=1e-10, atol=1e-12 * np.abs(want[:, 2]).max())
    # the loop acts: the arm turns toward the reference and its tip bends (a test that can fail)
    assert 0.4 * REF < got[-1, 1] < REF and np.abs(got[:, 2]).max() > 1e-3


def test_steps_that_break_the_rules_are_refused(plant, tmp_path):
    unit = Unit(plant[0], tmp_path)
    try:
        with pytest.raises(Exception, match="discard"):
            unit.step(0.0, 1.5 * DT, 0.0)               # not a whole number of the case's steps
        unit.step(0.0, 2 * DT, 1.0)
        with pytest.raises(Exception, match="discard"):
            unit.step(DT, 2 * DT, 1.0)                   # goes back
        with pytest.raises(Exception, match="discard"):
            unit.step(2 * DT, T_END, 1.0)                # passes solver.t_end
        unit.step(2 * DT, DT, 1.0)                       # the unit goes on after a refusal
        assert math.isfinite(unit.get("alpha")[0]) and unit.get("alpha")[0] > 0.0
    finally:
        unit.close()
    with pytest.raises(Exception, match="fmi2SetupExperiment"):
        Unit(plant[0], tmp_path / "late", stop=2 * T_END)   # the master's stop time after solver.t_end


def test_a_saved_state_replays_the_same_steps(plant, tmp_path):
    """fmi2GetFMUstate / fmi2SetFMUstate: the steps after a restore repeat those after the save."""
    unit = Unit(plant[0], tmp_path)
    try:
        for k in range(10):
            unit.step(k * DT, DT, 20.0)
        saved, before = unit.fmu.getFMUstate(), unit.get("alpha", "tip_dy_elastic")
        unit.step(10 * DT, 10 * DT, -30.0)
        first = unit.get("alpha", "tip_dy_elastic")
        unit.fmu.setFMUstate(saved)
        assert unit.get("alpha", "tip_dy_elastic") == before
        unit.step(10 * DT, 10 * DT, -30.0)
        assert unit.get("alpha", "tip_dy_elastic") == first and first != before
        unit.fmu.freeFMUstate(saved)
    finally:
        unit.close()


def test_cli_writes_a_unit_and_refuses_bad_input_in_one_line(tmp_path, capsys):
    case = tmp_path / "arm.toml"
    _case().write(case)
    assert main(["fmu", str(case), "--out", str(tmp_path / "arm.fmu"), "--model", "hac"]) == 0
    out = capsys.readouterr().out
    assert "effort.base, effort.joint_2" in out and "multiple of 0.0002 s" in out and (tmp_path / "arm.fmu").is_file()
    for argv, field in [(["--inputs", "nowhere"], "--inputs"), (["--outputs", "nothing"], "--outputs"),
                        (["--out", str(tmp_path / "arm.zip")], "--out")]:
        args = ["fmu", str(case), "--out", str(tmp_path / "b.fmu"), "--model", "hac", *argv]
        assert main(args) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and err.startswith(f"flexmech: error: {field}:"), err
    assert not (tmp_path / "b.fmu").exists()
    kinematic = tmp_path / "fourbar.toml"
    fm.load_case("fourbar_constant_speed").write(kinematic)
    assert main(["fmu", str(kinematic), "--out", str(tmp_path / "c.fmu"), "--model", "hac"]) == 2
    assert "no force-driven joint" in capsys.readouterr().err


def test_without_pythonfmu_the_command_names_the_extra(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "pythonfmu.builder", None)      # import fails as if not installed
    case = tmp_path / "arm.toml"
    _case().write(case)
    assert main(["fmu", str(case), "--out", str(tmp_path / "arm.fmu")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"flexmech: error: {MISSING_EXTRA}" and "flexmech[fmi]" in err
    assert not (tmp_path / "arm.fmu").exists()


def _shared_libpython():
    """The running Python's shared library, or None (a Python built without one)."""
    name = sysconfig.get_config_var("INSTSONAME") or sysconfig.get_config_var("LDLIBRARY") or ""
    path = Path(sysconfig.get_config_var("LIBDIR") or "") / name
    return path if sysconfig.get_config_var("Py_ENABLE_SHARED") and ".so" in name and path.is_file() else None


def test_a_master_written_in_c_runs_the_unit_with_the_hosts_python_preloaded(plant, tmp_path):
    """docs/cli.md, "What the unit needs on the host": a non-Python master on Linux, with the shared
    libpython preloaded and flexmech on PYTHONPATH, gets the same P loop as Simulation."""
    cc, lib = shutil.which("cc") or shutil.which("gcc"), _shared_libpython()
    if cc is None or lib is None or not sys.platform.startswith("linux"):
        pytest.skip("needs Linux, a C compiler and a Python built with its shared library")
    master = tmp_path / "master"
    subprocess.run([cc, "-O1", "-o", str(master), str(DATA / "fmi2_master.c"), "-ldl"], check=True)
    unzipped = Path(extract(str(plant[0]), str(tmp_path / "unit")))
    md = read_model_description(str(plant[0]))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    binary = unzipped / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
    steps, kp = 100, 2000.0
    argv = [str(master), str(binary), md.guid, (unzipped / "resources").as_uri(), str(vr["effort.base"]),
            str(vr["alpha"]), str(steps), repr(DT), repr(kp), repr(REF)]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sysconfig.get_paths()[k] for k in ("purelib", "platlib")))
    bare = subprocess.run(argv, capture_output=True, text=True, env=env, timeout=120)
    assert bare.returncode == 1 and "undefined symbol" in bare.stdout       # the documented failure
    run = subprocess.run(argv, capture_output=True, text=True, env=dict(env, LD_PRELOAD=str(lib)), timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    sim = Simulation(_case(), "hac", record=False)
    for _ in range(steps):
        sim.advance(1, inputs={"base": kp * (REF - sim.output("alpha"))})
    y = float(run.stdout.split()[-1])
    assert y == pytest.approx(sim.output("alpha"), rel=1e-13) and y > 0.1 * REF
