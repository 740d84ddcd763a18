"""Shared test helpers.  The tests run against the INSTALLED flexmech_py
(pytest --import-mode=importlib, see pyproject.toml); this folder is put on
sys.path only so that tests can import their own helpers."""

import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, os.path.dirname(__file__))

ROOT = Path(__file__).resolve().parents[1]
CASES = ROOT / "cases"


@pytest.fixture
def cases_dir() -> Path:
    return CASES


def beam_case(n_el=4, length=1.0, area=1e-4, second_moment=1e-9, youngs_modulus=2e11, density=7800.0,
              drive=None, t_end=0.01, dt=1e-4, outputs=None, **solver):
    """A resolved case: one uniform link clamped at (0, 0) (a 1-link serial chain)."""
    import flexmech_py as fm

    return fm.validate_case({
        "mechanism": {"type": "serial"},
        "links": [{"name": "beam", "length": length, "area": area, "second_moment": second_moment,
                   "youngs_modulus": youngs_modulus, "density": density, "elements": n_el}],
        "drive": drive or {"type": "kinematic", "law": "constant_speed", "speed": 0.0},
        "solver": {"t_end": t_end, "dt": dt, **solver},
        "outputs": outputs or {"tip_v": {"kind": "displacement", "at": "beam.end", "component": "transverse"},
                               "tip_u": {"kind": "displacement", "at": "beam.end", "component": "axial"}},
    })


def assert_free_pendulum_conserves_energy(model: str, elements: int) -> None:
    """A flexible double pendulum released under gravity, no inputs: kinetic + strain + gravity
    potential energy stays constant (to 1e-6 of the peak kinetic energy) in the given model."""
    import numpy as np

    import flexmech_py as fm

    links = [{"name": f"l{k}", "length": 0.5, "area": 1e-4, "second_moment": 2e-10, "youngs_modulus": 7e10,
              "density": 2700.0, "elements": elements} for k in (1, 2)]
    case = fm.validate_case({
        "mechanism": {"type": "serial"}, "links": links, "joints": {"base": "pin", "joint_2": "pin"},
        "drive": {"type": "torque", "torques": [{"joint": "base", "constant": 0.0}]},
        "initial": {"angles": [0.3, 0.8]}, "loads": {"gravity": [0.0, -9.81]},
        "solver": {"t_end": 0.3, "dt": 2e-5, "output_every": 100},
        "outputs": {"a": {"kind": "joint_angle", "joint": "base"}}})
    res = fm.simulate(case, model=model)
    e = res["energy_kinetic"] + res["energy_potential"]
    assert np.max(res["energy_kinetic"]) > 0.1        # J: it really swings
    assert np.max(np.abs(e - e[0])) < 1e-6 * np.max(res["energy_kinetic"])


def interrupt_after_first_result(argv: list, out: Path, cwd: Path) -> tuple[int, int]:
    """Run ``flexmech ARGV --out OUT`` in a subprocess, press Ctrl-C (SIGINT) as soon as the first
    result is in OUT/cache; returns (exit code, results left in the cache)."""
    import signal
    import subprocess
    import time

    # SIGINT as a terminal delivers it: a suite started as a background job (its shell ignores SIGINT
    # there, and children inherit that) must not make the sweep ignore it
    p = subprocess.Popen([sys.executable, "-m", "flexmech_py", *argv, "--out", str(out)], cwd=cwd,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 60
    while not list((out / "cache").glob("*.json")) and time.monotonic() < deadline and p.poll() is None:
        time.sleep(0.005)
    p.send_signal(signal.SIGINT)
    rc = p.wait(timeout=60)
    return rc, len(list((out / "cache").glob("*.json")))
