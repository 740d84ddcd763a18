"""Input shaping on the Bricout manipulator under PD joint control (docs/validation.md, "Input shaping").

The base joint makes a rest-to-rest move (cycloidal, ``TRAVEL`` rad in ``DURATION`` s, long enough to
excite the first mode, short enough to leave the arm ringing); a PD law on the base joint's angle and
rate follows the reference (unshaped, or convolved with a ZV, ZVD or EI shaper designed from the
frozen first mode, flexmech_py.studies.modes), a second PD law holds the elbow.  The loops are closed in
Python through :class:`flexmech_py.run.stepping.Simulation` (the efforts held over each step).  Reported:
the residual tip vibration (largest |transverse tip deflection| of link 2 over the ``WINDOW`` s after
the shaped move ends, and over that window less its first ``SETTLE`` s, where the PD loop's own
settling still bends the arm) per shaper, and again with the links' Young's modulus scaled by r^2 (the first
frequency off by the factor r) against the closed-form robustness curve V(r) of each shaper.

``python -m flexmech_py.studies.shaping_plot --out DIR`` runs it and writes shaping.json (the shapers'
impulses and every run), shaping_runs.csv and the robustness curve shaping_robustness.png.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..case import Case, load_case
from .modes import modes
from ..base.shaping import SHAPERS, RestToRest, design, residual_vibration
from ..run.stepping import Simulation

__all__ = ["pd_move", "study", "residual", "manipulator", "TRAVEL", "DURATION", "WINDOW", "GAINS"]

TRAVEL, DURATION, WINDOW = 0.5, 0.2, 0.5       # rad, s, s
#: the PD loop's own settling after the move [s]: its deflection is quasi-static, not the mode's ringing
SETTLE = 0.2
#: (kp [N m/rad], kd [N m s/rad]) of the base and of the elbow
GAINS = {"base": (1500.0, 120.0), "joint_2": (400.0, 20.0)}
DT, OUTPUT_EVERY = 1e-4, 5


def manipulator(stiffness_scale: float = 1.0, t_end: float = 1.0, dt: float = DT) -> Case:
    """The bundled manipulator with zero force laws (the PD loops give the torques), links' E scaled."""
    case = load_case("manipulator_bricout", [f"solver.t_end={t_end}", f"solver.dt={dt}",
                                             f"solver.output_every={OUTPUT_EVERY}", "solver.error_estimate=none",
                                             "drive.torques.base.constant=0", "drive.torques.joint_2.constant=0"])
    links = [dict(ln, youngs_modulus=ln["youngs_modulus"] * stiffness_scale) for ln in case["links"]]
    return Case(case, links=links)


def pd_move(case: Case, reference, model: str = "hac", gains=None) -> dict:
    """The PD-controlled run of ``case`` following ``reference`` (t -> (angle, rate) of the base) to
    solver.t_end; {t, tip deflection, base angle, torque}."""
    gains = GAINS if gains is None else gains
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = Simulation(case, model)
        (kp, kd), (kp2, kd2) = gains["base"], gains["joint_2"]
        beta0 = sim.joint("joint_2")[0]
        torque = []
        while sim.step < sim.prep.nsteps:
            (a, w), (b, wb) = sim.joint("base"), sim.joint("joint_2")
            r, rd = reference(sim.t)
            u = kp * (float(r) - a) + kd * (float(rd) - w)
            torque.append(u)
            sim.advance(inputs={"base": u, "joint_2": kp2 * (beta0 - b) - kd2 * wb})
        res = sim.result()
    return {"t": res.t, "tip": res["tip_transverse_deflection"], "alpha": res["alpha"],
            "torque": np.asarray(torque)[::OUTPUT_EVERY]}


def residual(run: dict, t_from: float, window: float = WINDOW) -> float:
    """Largest |tip deflection| [m] over [t_from, t_from + window]."""
    sel = (run["t"] >= t_from - 1e-12) & (run["t"] <= t_from + window + 1e-12)
    return float(np.max(np.abs(run["tip"][sel])))


def study(ratios=(0.8, 1.0, 1.2), shapers=("none",) + SHAPERS, model: str = "hac",
          duration: float = DURATION, window: float = WINDOW) -> dict:
    """Every shaper at every frequency ratio r (the links' E x r^2): residual vibration [m], its ratio to
    the unshaped move's at the same r, and the closed-form V(r)."""
    base_case = manipulator()
    f1 = float(modes(base_case, at=0.0, count=1, model=model).hz[0])
    move = RestToRest("cycloidal", 0.0, TRAVEL, duration)
    designed = {k: design(k, f1) for k in SHAPERS}
    rows = []
    for r in ratios:
        t_end = duration + 1.0 / f1 + window + 2 * DT
        case = manipulator(r * r, t_end)
        runs = {}
        for kind in shapers:
            sh = designed.get(kind)
            runs[kind] = pd_move(case, _reference(move, sh), model)
            end = duration + (0.0 if sh is None else sh.duration)
            rows.append({"ratio": r, "shaper": kind, "residual_m": residual(runs[kind], end, window),
                         "residual_settled_m": residual(runs[kind], end + SETTLE, window - SETTLE),
                         "predicted_V": float(residual_vibration(sh, r * f1))})
        none = next(x for x in rows if x["ratio"] == r and x["shaper"] == "none")
        for x in rows:
            if x["ratio"] == r:
                x["relative"] = x["residual_m"] / none["residual_m"]
                x["relative_settled"] = x["residual_settled_m"] / none["residual_settled_m"]
    return {"first_mode_hz": f1, "move": {"profile": "cycloidal", "travel_rad": TRAVEL, "duration_s": duration},
            "gains": GAINS, "dt_s": DT, "window_s": window, "model": model,
            "shapers": {k: s.as_dict() for k, s in designed.items()}, "rows": rows}


def _reference(move: RestToRest, shaper):
    """t -> (angle, rate) of the move, shaped (each impulse's share of the move, delayed)."""
    if shaper is None:
        return move

    def shaped(t):
        parts = [(a, move(max(t - ti, 0.0))) for a, ti in zip(shaper.amplitudes, shaper.times)]
        return sum(a * p[0] for a, p in parts), sum(a * p[1] * (t >= ti) for (a, p), ti in zip(parts, shaper.times))
    return shaped
