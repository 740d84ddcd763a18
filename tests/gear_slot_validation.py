"""Full-size validation numbers of the gear pair and the pin in a slot (docs/validation.md):
``python tests/gear_slot_validation.py`` prints them (a few minutes).  The tests
(tests/test_gear_slot.py) check the same quantities at reduced sizes."""

from __future__ import annotations

import warnings

import numpy as np

import flexmech_py as fm
from flexmech_py.mechanism import MotionSource, prepare_motion
from flexmech_py.studies.modes import modes

import test_gear_slot as t


def _diff(res, ref, name) -> float:
    return float(np.max(np.abs(res[name] - ref[name])) / np.max(np.abs(ref[name])))


def main() -> None:
    warnings.simplefilter("ignore")
    tt = np.linspace(0.0, 0.3, 3001)
    for mesh in ("external", "internal"):
        _, rm = t._rigid(t._gear_train(mesh), tt)
        s = 1.0 if mesh == "external" else -1.0
        rho = -s * t.R_A / t.R_B
        a, b = rm.joint("motor"), rm.joint("pivot_b")
        ratio = np.max(np.abs((b[:, 0] - b[0, 0]) - rho * (a[:, 0] - a[0, 0])))
        react = rm.reaction("mesh")
        hand = np.abs(t.J2 * b[:, 2]) / t.R_B
        tooth = np.max(np.abs(np.hypot(react[:, 0], react[:, 1]) - hand)) / np.max(hand)
        print(f"gear train ({mesh}): ratio error {ratio:.1e} rad, tooth force vs J2 alpha_b / r_b {tooth:.1e} (relative), "
              f"peak tooth force {np.max(hand):.4g} N")
    exact = t._geared_shaft_omega()
    for n in (4, 8, 16):
        spec = t._gear_train(flexible=True)
        spec["mesh"] = {"elements_per_link": n}
        case = fm.validate_case(spec)
        errs = {m: modes(case, count=1, model=m).omega[0] / exact - 1 for m in ("classic", "coupled", "nonlinear")}
        print(f"geared shaft, {n} el: closed form {exact:.6f} rad/s; relative errors "
              + ", ".join(f"{m} {e:.2e}" for m, e in errs.items()))
    for name, outputs in (("geared_fivebar", ("strain_distal1_mid", "strain_distal2_mid", "mesh_moment")),
                          ("scotch_yoke", ("crank_tip_transverse", "strain_crank_root", "slot_force_x"))):
        ref = fm.simulate(fm.load_case(name, overrides=["solver.model=nonlinear"]))
        print(f"{name} (bundled size): nonlinear energy drift "
              f"{ref.summary()['coupled']['energy_balance']['relative_drift']:.2e}")
        for model in ("classic", "hac", "coupled"):
            res = fm.simulate(fm.load_case(name, overrides=[f"solver.model={model}"]))
            extra = ""
            if model == "coupled":
                c = res.summary()["coupled"]
                extra = (f"; energy drift {c['energy_balance']['relative_drift']:.2e}, row violations "
                         + ", ".join(f"{k} {v:.1e}" for k, v in c["constraint_violation"].items()))
            print(f"  {model} vs nonlinear: " + ", ".join(f"{o} {_diff(res, ref, o):.2e}" for o in outputs) + extra)
    case = fm.load_case("scotch_yoke")
    rm = MotionSource(prepare_motion(case.mechanism), rtol=1e-12, atol=1e-14)(np.linspace(0, 0.09, 9001))
    th, x = rm.joint("crank_pivot")[:, 0], rm.joint("guide")
    print(f"scotch yoke rigid: |x - r cos theta| max {np.max(np.abs(0.1 + x[:, 0] - 0.1 * np.cos(th))):.1e} m, "
          f"slot force vs m x'' {np.max(np.abs(-rm.reaction('pin')[:, 0] - 0.5 * x[:, 2])) / np.max(np.abs(0.5 * x[:, 2])):.1e}")


if __name__ == "__main__":
    main()
