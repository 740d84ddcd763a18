"""Shared test helpers.  The tests run against the INSTALLED flexmech_py
(pytest --import-mode=importlib, see pyproject.toml); this folder is put on
sys.path only so that tests can import their own helpers (numpy_reference)."""

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
