"""The numbers of docs/validation.md "Controllers in the loop": a PD-controlled link in its rigid limit
against the exact closed-loop response, the energy balance with the actuator's work, saturation with
clamping against an ODE of the same law, collocated against tip-position PD (the closed loop's
eigenvalues, control_eigen, against growth rates measured in time runs), the Bricout arm's residual
ringing with and without a ZV shaper, and the cost of a controller per step (the PI-held four-bar's
speed ripple: flexmech_py.studies.pi_motor).

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
from .control_eigen import Loop, critical_gain, linearize_loop

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
TAU = 0.15                  # the PD law k (e + TAU e') of the stability comparison [s]
#: Rayleigh damping [1/s, s] of the damped link: 2.0 % of critical in its first bending mode (24.9 Hz)
DAMPED = (0.0, 2.5e-4)
SMALL_MOVE = {"law": "rest_to_rest", "travel": 0.05, "duration": 0.1}   # 0.05 rad at the hub, or 0.05 m at the tip


def small_move(k: float, measure="joint", tau: float = TAU, t_end: float = 1.5, dt: float = 5e-4,
               rayleigh=(0.0, 0.0), elements: int = 4) -> dict:
    """The link under the PD law k (e + tau e') on the hub angle (``measure`` "joint") or on the tip's
    height (TIP) on a small move (SMALL_MOVE), with Rayleigh damping ``rayleigh``."""
    raw = link_case(kp=k, kd=tau * k, t_end=t_end, dt=dt, measure=measure, reference=SMALL_MOVE)
    raw["solver"]["rayleigh"] = list(rayleigh)
    raw["mesh"]["elements_per_link"] = elements
    return raw


def settles(k: float, measure="joint", tau: float = TAU, t_end: float = 1.5) -> float:
    """The largest error over the last fifth of the small move's run against the first fifth (< 1: the
    error fell over the run; > 1 or inf (the run stopped): it grew).  A finite-time measure: a loop
    with a slowly growing mode that the move barely excites can fall below 1 (see tip_undamped)."""
    try:
        y = run(small_move(k, measure, tau, t_end)).columns["hub_angle"]
    except SolverError:
        return float("inf")
    n = y.size // 5
    return float(np.abs(y[-n:] - 0.05).max() / np.abs(y[:n] - 0.05).max())


def growth_rate(raw: dict, f_hz: float, t_from: float = 0.4, window: float = 0.2) -> float:
    """The growth rate [1/s] (< 0: decay) of the hub angle's oscillation at f_hz in the run of ``raw``
    after t_from: in windows of ``window`` s, a least-squares fit of a cubic (the slow motion) plus
    A cos + B sin at f_hz; the slope of log hypot(A, B) against the windows' centres."""
    res = run(raw)
    t, y, w = res.t, res.columns["hub_angle"], 2.0 * np.pi * f_hz
    centres, amps = [], []
    for t0 in np.arange(t_from, t[-1] - window + 1e-9, window):
        m = (t >= t0) & (t < t0 + window)
        s = (t[m] - t0) / window - 0.5
        basis = np.c_[np.ones_like(s), s, s ** 2, s ** 3, np.cos(w * t[m]), np.sin(w * t[m])]
        coef = np.linalg.lstsq(basis, y[m], rcond=None)[0]
        centres.append(t0 + window / 2)
        amps.append(np.hypot(coef[4], coef[5]))
    return float(np.polyfit(centres, np.log(amps), 1)[0])


def eigen_loop(measure="joint", rayleigh=(0.0, 0.0), elements: int = 4) -> Loop:
    """The small-move link's loop linearized about rest (control_eigen), any gain."""
    return linearize_loop(validate_case(small_move(1.0, measure, rayleigh=rayleigh, elements=elements)))


def collocated_stability(gains=np.geomspace(0.01, 1e4, 61)) -> dict:
    """Hub-angle PD: the largest max Re lambda over ``gains`` by eigenvalues (2, 4, 8 elements per
    link; undamped), and the time runs' late/early error at k = 0.5, 5, 50."""
    out = {}
    for ne in (2, 4, 8):
        loop = eigen_loop(elements=ne)
        s = np.array([loop.abscissa(k, TAU * k) for k in gains])
        out[f"{ne}_elements"] = {"max_abscissa_per_s": float(s.max()), "at_k": float(gains[np.argmax(s)]),
                                 "untouched_hz": loop.untouched_hz.round(1).tolist()}
    out["time_late_over_early"] = {k: settles(k) for k in (0.5, 5.0, 50.0)}
    return out


def tip_undamped(gains=(0.5, 1.0, 2.0)) -> dict:
    """Tip-height PD on the undamped link: unstable at every positive gain (the eigenvalues: its
    first bending mode's real part grows from 0 as slope x k), against the growth rates measured in
    3 s time runs (dt 5e-4 s; at k = 1 also Newmark's average acceleration and dt / 2), and the
    finite-time settling measure at k = 1 over 1.5 s and 6 s."""
    out = {}
    for ne in (2, 4, 8):
        crit = critical_gain(eigen_loop(TIP, elements=ne), TAU)
        out[f"{ne}_elements"] = {k: crit[k] for k in ("kp", "f_hz", "slope_at_zero_per_s")}
    loop = eigen_loop(TIP)
    f_hz = out["4_elements"]["f_hz"]
    out["growth_per_s"] = {}
    for k in gains:     # runs as long as the mode grows by e^6 at most (to 0.02 rad: still linear), 3 s at most
        eig = loop.leading(k, TAU * k)["re_per_s"]
        out["growth_per_s"][k] = {"eigen": eig, "time": growth_rate(small_move(k, TIP, t_end=min(3.0, 0.4 + 6.0 / eig)),
                                                                    f_hz)}
    newmark = small_move(1.0, TIP, t_end=3.0)
    newmark["solver"]["integrator"] = "newmark"
    out["growth_per_s_k1_newmark"] = growth_rate(newmark, f_hz)
    out["growth_per_s_k1_dt_half"] = growth_rate(small_move(1.0, TIP, t_end=3.0, dt=2.5e-4), f_hz)
    out["late_over_early_k1"] = {"1.5 s": settles(1.0, TIP), "6 s": settles(1.0, TIP, t_end=6.0)}
    return out


def tip_damped(factors=(0.8, 1.2)) -> dict:
    """Tip-height PD on the link with Rayleigh damping DAMPED: the critical gain by eigenvalues (2, 4, 8
    elements), the growth rates of 3 s time runs at factors x that gain, and the time runs' critical
    gain (the zero of the growth rate, linear between the two)."""
    out = {}
    for ne in (2, 4, 8):
        crit = critical_gain(eigen_loop(TIP, DAMPED, ne), TAU)
        out[f"{ne}_elements"] = {"kp": crit["kp"], "f_hz": crit["f_hz"]}
    kc, f_hz = out["4_elements"]["kp"], out["4_elements"]["f_hz"]
    loop = eigen_loop(TIP, DAMPED)
    rates = {f * kc: (loop.leading(f * kc, TAU * f * kc)["re_per_s"],
                      growth_rate(small_move(f * kc, TIP, t_end=3.0, rayleigh=DAMPED), f_hz)) for f in factors}
    (k0, (_, g0)), (k1, (_, g1)) = rates.items()
    out["growth_per_s"] = {k: {"eigen": e, "time": g} for k, (e, g) in rates.items()}
    out["time_critical_kp"] = float(k0 - g0 * (k1 - k0) / (g1 - g0))
    return out


def swing_growth(k: float, t_end: float = 2.0) -> float:
    """The hub angle's largest peak-to-peak swing over the last three quarters of a small-move run
    under the P law k e on the tip's height, against its swing over the first eighth (about 1: a
    marginal loop keeps swinging; >> 1: it grew)."""
    y = run(small_move(k, TIP, tau=0.0, t_end=t_end)).columns["hub_angle"]
    n = y.size // 8
    return float(max(np.ptp(y[i * n:(i + 1) * n]) for i in range(2, 8)) / np.ptp(y[:n]))


def tip_proportional(factors=(0.985, 1.015)) -> dict:
    """Tip-height P feedback (tau = 0) on the undamped link: marginal (no damping anywhere) up to the
    gain at which the rigid mode, rising with k, and the first bending mode coalesce (flutter), by
    eigenvalues (2, 4, 8 elements); the swing growth of time runs at factors x that gain."""
    out = {}
    for ne in (2, 4, 8):
        crit = critical_gain(eigen_loop(TIP, elements=ne), 0.0)
        out[f"{ne}_elements"] = {"kp": crit["kp"], "f_hz": crit["f_hz"]}
    kc = out["4_elements"]["kp"]
    out["time_swing_growth"] = {f * kc: swing_growth(f * kc) for f in factors}
    return out


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


def bricout(model: str | None = None) -> dict:
    """The bundled Bricout PD cases: the residual vibration in the 0.5 s after each (shaped) move
    ends (half the peak-to-peak bending strain at the base and tip height), the peak strain, and
    whether the base's actuator reached its limit; ``model``: another model than the cases' own."""
    out = {}
    for name in ("manipulator_bricout_pd", "manipulator_bricout_pd_zv", "manipulator_bricout_pd_zvd"):
        case = load_case(case_path(name))
        ctl = case["controllers"][0]
        shaper = ctl.get("shaper")
        span = SHAPER_SPAN[shaper and shaper["kind"]] / shaper["frequency_hz"] if shaper else 0.0
        end = ctl["reference"]["duration"] + span
        c = run(case, model)
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
                     ("saturation", saturation), ("collocated stability", collocated_stability),
                     ("tip feedback, undamped", tip_undamped), ("tip feedback, damped", tip_damped),
                     ("tip P feedback", tip_proportional), ("bricout", bricout),
                     ("bricout under hac", lambda: bricout("hac")), ("cost", cost)):
        print(name, fn())


if __name__ == "__main__":
    main()
