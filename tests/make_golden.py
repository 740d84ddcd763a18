"""Regenerate the present values of tests/golden_seed.json (run from anywhere: python tests/make_golden.py).

Golden numbers are regression anchors, not independent truth: they were computed by flexmech
itself, after its kernels were checked against the NumPy reference (test_kernels.py), its
element matrices against closed forms and the kinetic energy (test_beam.py), its rigid
dynamics against energy balance (test_rigid.py) and its time integration for order 2
(test_physics.py).  Regenerate only for an intended change of results, and say why in the commit.
"""

import json
import subprocess
from pathlib import Path

import numpy as np

import flexmech_py as fm
from flexmech_py.run.simulate import simulate_models

ROOT = Path(__file__).resolve().parents[1]
COLUMNS = {"fourbar_hac": ["crank_angle", "crank_speed", "strain_coupler_mid", "strain_follower_mid", "load_norm"],
           "fourbar_constant_speed": ["strain_coupler_mid", "strain_follower_mid"],
           "manipulator_bricout": ["tip_x", "tip_y", "tip_dx_elastic", "tip_dy_elastic", "alpha", "beta"],
           "manipulator_bricout_no_payload": ["tip_dx_elastic", "tip_dy_elastic"]}


def main():
    """Rewrite ``values_now`` (and its provenance); the historical ``values`` and their per-case
    tolerances stay as they are."""
    values = {}
    for name, cols in COLUMNS.items():
        runs = simulate_models(fm.load_case(ROOT / "cases" / f"{name}.toml"))
        for model, res in runs.items():
            for c in cols:
                y = res[c]
                values[f"{name}/{model}/{c}/peak_abs"] = float(np.max(np.abs(y)))
                values[f"{name}/{model}/{c}/final"] = float(y[-1])
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    path = ROOT / "tests" / "golden_seed.json"
    out = json.loads(path.read_text())
    out["provenance_now"] = (f"flexmech {fm.__version__} (git {commit}), the case files as committed (dt 1e-5 s, "
                             "2 elements per link, rigid motion by flexmech_ode rtol 1e-10); produced by "
                             "tests/make_golden.py")
    out["values_now"] = values
    path.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
