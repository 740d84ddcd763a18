"""The PI-held four-bar (cases/fourbar_pi_motor.toml) against the rigid linkage's own closed loop: the
numbers of docs/validation.md "Controllers in the loop" on that case.

The rigid four-bar with a torque on its crank has one degree of freedom, the crank angle θ, and its
kinetic energy ½ M(θ) θ̇²: its equation is M(θ) θ̈ + ½ M′(θ) θ̇² = τ.  M(θ) is computed here from
the linkage's own kinematics (closed-form loop closure, its θ-derivatives by central differences),
independently of flexmech's rigid-body solver; the closed loop is that equation under the case's
controller law, integrated with scipy's solve_ivp.  The same kinematics with Newton–Euler gives the
rigid linkage's axial forces in the coupler and the follower at a constant crank speed, whose ratio
to the Euler load says at which speeds the linear models can be valid at all, whatever drives the
crank.

    python -m flexmech_py.studies.pi_motor
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline

from ..base.bundled import case_path
from ..case import load_case
from ..run.simulate import Prepared

__all__ = ["RigidFourbar", "reference", "rigid_closed_loop", "ripple", "run_case", "euler_ratios", "main"]

H = 1e-4    # rad: the central-difference step of the θ-derivatives


class RigidFourbar:
    """The bundled four-bar template's rigid linkage: links crank O2-A, coupler A-B, follower O4-B as
    uniform bars (mass ρ A L, centroidal inertia m L²/12), point masses at A and B, a rotor on the
    crank; open assembly (B on the left of A → O4)."""

    def __init__(self, case):
        ground = case["mechanism"]["ground"]
        self.o2, self.o4 = np.array(ground["O2"], float), np.array(ground["O4"], float)
        links = {ln["name"]: ln for ln in case["links"]}
        self.length = [links[n]["length"] for n in ("crank", "coupler", "follower")]
        self.mass = [links[n]["density"] * links[n]["area"] * links[n]["length"] for n in ("crank", "coupler", "follower")]
        self.point = {pm["at"]: pm["mass"] for pm in case.get("point_masses", [])}
        assert set(self.point) <= {"crank.end", "coupler.end"}, self.point
        self.rotor = sum(r["inertia"] for r in case.get("rotary_inertias", []) if r["at"] == "crank.start")
        self.flex = {n: (links[n]["youngs_modulus"], links[n]["second_moment"], links[n]["length"]) for n in links}
        grid = np.linspace(-0.1, 2 * np.pi + 0.1, 1441)
        self._m = CubicSpline(grid, [self._mass_at(t) for t in grid])
        self._dm = self._m.derivative()

    def geometry(self, th: float) -> np.ndarray:
        """[crank centre (2), A (2), coupler centre (2), B (2), follower centre (2), φ2, φ3, φ4]."""
        la, lb, lc = self.length
        a = self.o2 + la * np.array([np.cos(th), np.sin(th)])
        d = self.o4 - a
        dist = np.hypot(*d)
        x = (dist ** 2 + lb ** 2 - lc ** 2) / (2 * dist)
        u = d / dist
        b = a + x * u + np.sqrt(lb ** 2 - x ** 2) * np.array([-u[1], u[0]])
        phi3, phi4 = np.arctan2(*(b - a)[::-1]), np.arctan2(*(b - self.o4)[::-1])
        return np.concatenate([(self.o2 + a) / 2, a, (a + b) / 2, b, (self.o4 + b) / 2, [th, phi3, phi4]])

    def derivatives(self, th: float):
        """(g, ∂g/∂θ, ∂²g/∂θ²) of :meth:`geometry` (angles continuous across ±π)."""
        g0, gp, gm = self.geometry(th), self.geometry(th + H), self.geometry(th - H)
        for g in (gp, gm):
            g[-3:] = g0[-3:] + np.angle(np.exp(1j * (g[-3:] - g0[-3:])))
        return g0, (gp - gm) / (2 * H), (gp - 2 * g0 + gm) / H ** 2

    def _mass_at(self, th: float) -> float:
        _, d1, _ = self.derivatives(th)
        (ma, mb, mc), (la, lb, lc) = self.mass, self.length
        w = d1[10:13]
        return (ma * d1[0:2] @ d1[0:2] + mb * d1[4:6] @ d1[4:6] + mc * d1[8:10] @ d1[8:10]
                + self.point.get("crank.end", 0.0) * d1[2:4] @ d1[2:4]
                + self.point.get("coupler.end", 0.0) * d1[6:8] @ d1[6:8]
                + (ma * la ** 2 / 12 + self.rotor) * w[0] ** 2 + mb * lb ** 2 / 12 * w[1] ** 2
                + mc * lc ** 2 / 12 * w[2] ** 2)

    def inertia(self, th) -> tuple[np.ndarray, np.ndarray]:
        """M(θ) [kg m²] and M′(θ) of the linkage (with the rotor) about the crank pivot."""
        x = np.mod(th, 2 * np.pi)
        return self._m(x), self._dm(x)

    def axial_forces(self, th: float, w: float, al: float = 0.0) -> tuple[float, float]:
        """(coupler, follower) midspan axial force [N], tension > 0, of the rigid linkage at crank angle
        th, speed w and acceleration al (Newton–Euler on the coupler with the mass at B and the follower)."""
        g, d1, d2 = self.derivatives(th)
        acc = d2 * w ** 2 + d1 * al
        a, b, gb, gc = g[2:4], g[6:8], g[4:6], g[8:10]
        (_, mb, mc), (_, lb, lc) = self.mass, self.length
        mB = self.point.get("coupler.end", 0.0)
        aB, aGb, aGc = acc[6:8], acc[4:6], acc[8:10]

        def row(r):           # the moment of a unit force (x, y) at arm r
            return [-r[1], r[0]]
        # unknowns: F_A (crank on coupler), F_B (coupler on follower), F_O (ground on follower)
        mat = np.zeros((6, 6))
        rhs = np.zeros(6)
        mat[0:2, 0:2], mat[0:2, 2:4] = np.eye(2), -np.eye(2)
        rhs[0:2] = mb * aGb + mB * aB
        mat[2, 0:2], mat[2, 2:4] = row(a - gb), np.negative(row(b - gb))
        rhs[2] = mb * lb ** 2 / 12 * acc[11] + _cross(b - gb, mB * aB)
        mat[3:5, 2:4], mat[3:5, 4:6] = np.eye(2), np.eye(2)
        rhs[3:5] = mc * aGc
        mat[5, 2:4], mat[5, 4:6] = row(b - gc), row(self.o4 - gc)
        rhs[5] = mc * lc ** 2 / 12 * acc[12]
        f_b = np.linalg.solve(mat, rhs)[2:4]
        e3, e4 = (np.array([np.cos(p), np.sin(p)]) for p in g[11:13])
        # the outer half (midspan to B) of each link: its inertia force against the force at B
        n_coupler = -((mb / 2) * (aGb + aB) / 2 + mB * aB + f_b) @ e3
        n_follower = -((mc / 2) * (aGc + aB) / 2 - f_b) @ e4
        return float(n_coupler), float(n_follower)


def _cross(r, f) -> float:
    return float(r[0] * f[1] - r[1] * f[0])


def reference(ref: dict, t):
    """(r, ṙ) of a spin-up or constant-speed reference from 0 (docs/cases.md)."""
    t = np.asarray(t, float)
    if ref["law"] == "constant_speed":
        return ref["speed"] * t, np.full_like(t, ref["speed"])
    ws, T = ref["final_speed"], ref["spinup_time"]
    c = T / (2 * np.pi)
    r = np.where(t < T, ws / T * (t ** 2 / 2 + c ** 2 * (np.cos(t / c) - 1)), ws * (t - T / 2))
    return r, np.where(t < T, ws / T * (t - c * np.sin(t / c)), ws)


def rigid_closed_loop(case, t) -> dict:
    """The rigid linkage under the case's one collocated, continuous controller and its constant load
    torque: M θ̈ + ½ M′ θ̇² = sat(kp e + kd ė + ki ∫e) + load, by solve_ivp (LSODA, rtol 1e-9); the
    integral held while saturated (clamping).  {"angle", "speed", "torque"} at the times t."""
    rig = RigidFourbar(case)
    (ctl,) = case["controllers"]
    assert ctl["sample_time"] == 0.0 and ctl["delay"] == 0.0 and ctl["measure"] == "joint", ctl
    load = sum(d.get("constant", 0.0) for d in case["drives"] if d["joint"] == ctl["joint"])
    lo, hi = ctl["limits"]

    def law(tt, x):
        r, rd = reference(ctl["reference"], tt)
        e, ed = r - x[0], rd - x[1]
        raw = ctl["kp"] * e + ctl["kd"] * ed + ctl["ki"] * x[2]
        return np.clip(raw, lo, hi), raw, e

    def rhs(tt, x):
        u, raw, e = law(tt, x)
        m, dm = rig.inertia(x[0])
        held = raw != u and e * (raw - u) > 0
        return [x[1], (u + load - 0.5 * dm * x[1] ** 2) / m, 0.0 if held else e]

    sol = solve_ivp(rhs, (0.0, float(t[-1])), [0.0, 0.0, 0.0], t_eval=t, method="LSODA", rtol=1e-9,
                    atol=1e-10, max_step=2e-4)
    return {"angle": sol.y[0], "speed": sol.y[1], "torque": law(np.asarray(t), sol.y)[0]}


def ripple(t, speed, torque, target: float) -> dict:
    """Over the last crank cycle (2π/target before the end): the mean speed (time average), the speed's
    peak to peak, and the torque's range."""
    last = t >= t[-1] - 2 * np.pi / target
    return {"mean": float(np.trapezoid(speed[last], t[last]) / (t[last][-1] - t[last][0])),
            "peak_to_peak": float(np.ptp(speed[last])),
            "torque_range": [float(torque[last].min()), float(torque[last].max())]}


def run_case(stiffness: float = 1.0, model: str | None = None, elements: int | None = None, sets=(), **solver):
    """The bundled case (solver overrides as keywords, any others as ``sets``; ``stiffness`` scales every
    link's E), run without its error estimate; the warnings it raised are in
    ``res.extra["warnings_raised"]``."""
    path = case_path("fourbar_pi_motor")
    sets = list(sets) + [f"solver.{k}={v!r}" for k, v in dict(solver, error_estimate="none").items()]
    sets += [f"links.{ln['name']}.youngs_modulus={ln['youngs_modulus'] * stiffness!r}" for ln in load_case(path)["links"]]
    case = load_case(path, overrides=sets)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = Prepared(case, elements_per_link=elements).run(model or case["solver"]["model"], estimate=False)
    res.extra["warnings_raised"] = [str(w.message) for w in caught]
    return res


def euler_ratios(case, speeds=(30.0, 40.0, 58.0, 120.0)) -> dict:
    """{speed: (coupler, follower) largest rigid-linkage compression over a cycle at that constant crank
    speed, as a multiple of each link's Euler load π² E I / L²}."""
    rig = RigidFourbar(case)
    euler = [np.pi ** 2 * rig.flex[n][0] * rig.flex[n][1] / rig.flex[n][2] ** 2 for n in ("coupler", "follower")]
    out = {}
    for w in speeds:
        n = np.array([rig.axial_forces(th, w) for th in np.linspace(0.0, 2 * np.pi, 361)])
        out[w] = tuple(float(-n[:, k].min() / euler[k]) for k in range(2))
    return out


def main() -> None:
    case = load_case(case_path("fourbar_pi_motor"))
    target = case["controllers"][0]["reference"]["final_speed"]
    print("rigid compression / Euler load (coupler, follower) at constant speed:", euler_ratios(case))
    stiff = run_case(stiffness=1e4)
    ode = rigid_closed_loop(case, stiff.t)
    print("rigid limit (E x 1e4) against the ODE: max |angle| difference",
          float(np.abs(stiff.columns["crank_angle"] - ode["angle"]).max()),
          "rad; max |speed| difference", float(np.abs(stiff.columns["motor_speed"] - ode["speed"]).max()), "rad/s")
    print("rigid ODE, last cycle:", ripple(stiff.t, ode["speed"], ode["torque"], target))
    for model in ("nonlinear", "coupled"):
        res = run_case(model=model)
        c = res.columns
        e = c["energy_kinetic"] + c["energy_potential"] - c["work_inputs"]
        print(f"{model}: motor (hub) speed", ripple(res.t, c["motor_speed"], c["control_motor_pi"], target),
              "| crank chord speed", ripple(res.t, c["crank_speed"], c["control_motor_pi"], target)["peak_to_peak"],
              "| largest |u|", float(np.abs(c["control_motor_pi"]).max()),
              "| energy balance", float(np.abs(e).max() / np.abs(c["work_inputs"]).max()),
              "| validity", res.extra["validity_overall"]["max_compression_over_euler"],
              res.extra["validity_overall"]["max_deflection_over_length"], "| warnings", res.extra["warnings_raised"])


if __name__ == "__main__":
    main()
