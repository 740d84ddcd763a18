"""The numbers of docs/validation.md "Controllers in the loop": a PD-controlled link in its rigid limit
against the exact closed-loop response, the energy balance with the actuator's work, saturation with
clamping against an ODE of the same law, the Bricout arm's residual ringing with and without a ZV
shaper, and the cost of a controller per step (the PI-held four-bar's speed ripple:
flexmech_py.studies.pi_motor).

    python -m flexmech_py.studies.control_study
"""

from __future__ import annotations

import copy
import time
import warnings

import numpy as np
from scipy import signal
from scipy.integrate import solve_ivp

from ..base.bundled import case_path
from ..case import load_case, validate_case
from ..base.errors import SolverError
from ..run.simulate import Prepared

RHO, AREA, LENGTH = 2700.0, 1.0e-4, 1.0
ROTOR = 0.01                                    # the hub's own inertia [kg m^2] (the motor's rotor)
J_HUB = RHO * AREA * LENGTH ** 3 / 3.0 + ROTOR  # the link's and the rotor's inertia about the hub [kg m^2]
TRAVEL, DURATION = 0.5, 0.3                     # the link's rest-to-rest move [rad], [s]


def link_case(stiffness=1.0, t_end=0.6, dt=1e-3, model="coupled", **controller) -> dict:
    """A uniform aluminium link (1 m) on a hub with a rotor, driven through a force drive by one
    controller (default PD, kp 2 N m/rad, kd 0.3 N m s/rad) on a cycloidal move of 0.5 rad in 0.3 s;
    ``stiffness`` scales Young's modulus (1e4: the rigid limit)."""
    ctl = {"joint": "hub", "kp": 2.0, "kd": 0.3,
           "reference": {"law": "rest_to_rest", "travel": TRAVEL, "duration": DURATION}}
    ctl.update(controller)
    return {"case": {"title": "controlled link"}, "mechanism": {"ground": {"O": [0.0, 0.0]}},
            "links": [{"name": "arm", "length": LENGTH, "area": AREA, "second_moment": 1.0e-9,
                       "youngs_modulus": 7.0e10 * stiffness, "density": RHO, "start": [0.0, 0.0], "angle": 0.0}],
            "mesh": {"elements_per_link": 4},
            "joints": [{"name": "hub", "type": "revolute", "connects": ["ground.O", "arm.start"]}],
            "drives": [{"joint": "hub", "law": "force"}],
            "rotary_inertias": [{"at": "arm.start", "inertia": ROTOR}],
            "controllers": [ctl],
            "solver": {"t_end": t_end, "dt": dt, "model": model, "error_estimate": "none"},
            "outputs": {"hub_angle": {"kind": "joint_angle", "joint": "hub"},
                        "torque": {"kind": "drive_force", "joint": "hub"}}}


def run(raw, model=None):
    """The run of a raw case dict (warnings silenced, no error estimate)."""
    case = validate_case(copy.deepcopy(raw)) if not hasattr(raw, "mechanism") else raw
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Prepared(case).run(model or case["solver"]["model"], estimate=False)


def cycloid(t, travel=TRAVEL, duration=DURATION):
    """(value, rate) of the cycloidal rest-to-rest move from 0."""
    s = np.clip(np.asarray(t, float) / duration, 0.0, 1.0)
    return (travel * (s - np.sin(2 * np.pi * s) / (2 * np.pi)),
            np.where(s < 1.0, travel / duration * (1.0 - np.cos(2 * np.pi * s)), 0.0))


def closed_loop(t, kp, kd):
    """J theta'' = kp (r - theta) + kd (r' - theta') of the rigid link, exactly (scipy's lsim: the
    matrix exponential, the input linear between samples)."""
    r, rd = cycloid(t)
    plant = signal.StateSpace([[0, 1], [-kp / J_HUB, -kd / J_HUB]], [[0, 0], [kp / J_HUB, kd / J_HUB]],
                              [[1, 0]], [[0, 0]])
    return signal.lsim(plant, np.c_[r, rd], t)[1]


def saturated_pid(t, kp, ki, kd, limit, clamp=True):
    """The rigid link under sat(kp e + ki I + kd e'), I' = e (held while saturated and pushed further
    when ``clamp``), by solve_ivp: the continuous loop the discrete law approximates."""
    def rhs(tt, x):
        r, rd = cycloid(np.array(tt))
        e, ed = r - x[0], rd - x[1]
        ur = kp * e + ki * x[2] + kd * ed
        u = np.clip(ur, -limit, limit)
        held = clamp and ur != u and e * (ur - u) > 0
        return [x[1], u / J_HUB, 0.0 if held else e]
    return solve_ivp(rhs, (t[0], t[-1]), [0.0, 0.0, 0.0], t_eval=t, max_step=1e-3, rtol=1e-9, atol=1e-12).y[0]


TIP = {"point": "arm.end", "direction": [0.0, 1.0]}     # the tip's height [m] (the link starts along x)


def settles(k: float, measure="joint", tau: float = 0.15, t_end: float = 1.5) -> float:
    """A small move (0.05 rad at the hub, or 0.05 m at the tip) under the PD law k (e + tau e') on the
    hub angle or on the tip's height: the largest error over the last fifth of the run against the
    first fifth (< 1: the loop settles; > 1 or inf (the run stopped): it does not)."""
    ref = {"law": "rest_to_rest", "travel": 0.05, "duration": 0.1}
    raw = link_case(kp=k, kd=tau * k, t_end=t_end, dt=5e-4, measure=measure, reference=ref)
    try:
        y = run(raw).columns["hub_angle"]
    except SolverError:
        return float("inf")
    n = y.size // 5
    return float(np.abs(y[-n:] - 0.05).max() / np.abs(y[:n] - 0.05).max())


def tip_feedback(lo: float = 0.5, hi: float = 50.0, iters: int = 6) -> dict:
    """Collocated PD (hub angle) against tip-position PD with the same law k (e + 0.15 s e'): the
    collocated loop settles at every k tried, the tip loop only below a critical k, bracketed by
    bisection between a k that settles and one that does not."""
    collocated = {k: settles(k) for k in (0.5, 5.0, 50.0)}
    if not (settles(lo, TIP) < 1.0 <= settles(hi, TIP)):
        raise ValueError(f"the tip loop does not change from settling at k = {lo} to not at k = {hi}")
    for _ in range(iters):
        mid = (lo * hi) ** 0.5
        lo, hi = (mid, hi) if settles(mid, TIP) < 1.0 else (lo, mid)
    return {"collocated_late_over_early": collocated, "tip_critical_k_between": (lo, hi)}


def rigid_limit() -> dict:
    out = {}
    for model in ("coupled", "nonlinear"):
        res = run(link_case(stiffness=1e4), model)
        y = closed_loop(res.t, 2.0, 0.3)
        c = res.columns
        e = c["energy_kinetic"] + c["energy_potential"]
        out[model] = {"max_error_rad": float(np.abs(c["hub_angle"] - y).max()), "peak_rad": float(np.abs(y).max()),
                      "energy_vs_work": float(abs(e[-1] - c["work_inputs"][-1]) / np.abs(c["work_inputs"]).max())}
    return out


def flexible_energy() -> float:
    c = run(link_case(kp=5.0, kd=0.5, t_end=0.4)).columns
    e = c["energy_kinetic"] + c["energy_potential"]
    return float(np.abs(e - c["work_inputs"]).max() / np.abs(c["work_inputs"]).max())


def saturation() -> dict:
    gains, limit = dict(kp=20.0, ki=40.0, kd=1.5), 0.6
    res = run(link_case(stiffness=1e4, limit=limit, t_end=1.5, **gains))
    y = res.columns["hub_angle"]
    clamped, wound = saturated_pid(res.t, limit=limit, **gains), saturated_pid(res.t, limit=limit, clamp=False, **gains)
    return {"max_output": float(np.abs(res.columns["control_hub_pid"]).max()),
            "error_vs_ode_rad": float(np.abs(y - clamped).max()),
            "overshoot_clamped": float(y.max() - TRAVEL), "overshoot_without_clamping_ode": float(wound.max() - TRAVEL)}


#: the span of each shaper's impulses in periods of its mode (undamped: ZV 1/2, ZVD 1)
SHAPER_SPAN = {None: 0.0, "zv": 0.5, "zvd": 1.0}


def bricout() -> dict:
    """The bundled Bricout PD cases: the residual vibration in the 0.5 s after each (shaped) move
    ends (half the peak-to-peak bending strain at the base and tip height), the peak strain, and
    whether the base's actuator reached its limit."""
    out = {}
    for name in ("manipulator_bricout_pd", "manipulator_bricout_pd_zv", "manipulator_bricout_pd_zvd"):
        case = load_case(case_path(name))
        ctl = case["controllers"][0]
        shaper = ctl.get("shaper")
        span = SHAPER_SPAN[shaper and shaper["kind"]] / shaper["frequency_hz"] if shaper else 0.0
        end = ctl["reference"]["duration"] + span
        c = run(case)
        t, s, tip = c.t, c.columns["root_strain"], c.columns["tip_y"]
        w = (t >= end) & (t <= end + 0.5)
        out[name] = {"move_end_s": end, "residual_strain_amplitude": float((s[w].max() - s[w].min()) / 2),
                     "residual_tip_y_amplitude_m": float((tip[w].max() - tip[w].min()) / 2),
                     "peak_strain": float(np.abs(s).max()),
                     "base_torque_peak": float(np.abs(c.columns["base_torque"]).max()),
                     "alpha_final": float(c.columns["alpha"][-1])}
    return out


def cost(pairs: int = 5) -> dict:
    """CPU time of the link's run with its controller against the same run with the force law alone
    (alternating pairs; the ratio of medians)."""
    with_ctl = validate_case(link_case(t_end=2.0, dt=1e-4))
    raw = link_case(t_end=2.0, dt=1e-4)
    del raw["controllers"]
    without = validate_case(raw)
    times = {"controller": [], "none": []}
    for _ in range(pairs):
        for key, case in (("controller", with_ctl), ("none", without)):
            c0 = time.process_time()
            run(case)
            times[key].append(time.process_time() - c0)
    med = {k: float(np.median(v)) for k, v in times.items()}
    return {**med, "steps": 20000, "extra_per_step_us": (med["controller"] - med["none"]) / 20000 * 1e6}


def main() -> None:
    for name, fn in (("rigid limit", rigid_limit), ("flexible link energy", flexible_energy),
                     ("saturation", saturation), ("tip feedback", tip_feedback), ("bricout", bricout), ("cost", cost)):
        print(name, fn())


if __name__ == "__main__":
    main()
