"""``flexmech modes``: natural frequencies and mode shapes of the elastic mechanism frozen at a
configuration of its rigid motion, and their course over one cycle of the drive (docs/cli.md,
docs/theory.md section 19).  The eigenproblems are in :mod:`flexmech_py.models.modal`.

Python::

    import flexmech_py as fm
    from flexmech_py.studies.modes import modes, frequencies_along
    ms = modes(fm.load_case("fourbar_constant_speed"), crank_angle=90.0, count=4)
    ms.hz, ms.omega, ms.rigid          # (n,) arrays: Hz, rad/s, rigid-body mode flags
    al = frequencies_along(fm.load_case("fourbar_constant_speed"), 36, count=3)
    al.x, al.hz, al.harmonics_hz(3)    # crank angle [deg], (36, 3) frequencies, k Omega / 2 pi
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..models import modal, shapes
from ..case import Case, study_model
from ..base.families import MODELS, family
from ..base.errors import CaseError
from ..base.sizes import check_count, format_count
from ..base.fileio import atomic_write, json_default
from ..base.version import versions
from ..run.simulate import time_grid
from ..models.superposition.model import FEModel
from ..models.constrained.coupled import CoupledModel
from ..models.superposition.loads import check_elastic_problem, elastic_torque_loads
from ..models.constrained.outputs import deviation
from ..case import with_elements
from ..run.simulate import motion_source

__all__ = ["ModeSet", "Along", "modes", "frequencies_along", "drive_joint", "turn_angle", "configuration_time",
           "cycle_times", "resonance_crossings", "DEFAULT_COUNT"]

DEFAULT_COUNT = 4
#: crank speed harmonics k Omega listed and drawn at most
MAX_HARMONICS = 20
#: memory of one position along the cycle [bytes]: its rigid motion sample and bookkeeping (besides
#: 16 bytes a mode)
POSITION_BYTES = 2_000


#: angles closer than this [deg] to a whole turn are on it (round-off of the assembly and the drive law)
TURN_ROUND_OFF_DEG = 1e-9


def turn_angle(deg: float) -> float:
    """An angle [deg] as the position on the turn, in [0, 360): a value within round-off of a whole
    turn is 0 (a crank drawn at 0 deg whose loop closure leaves it at -1e-14 rad is at 0 deg, not 360)."""
    a = deg % 360.0
    tol = TURN_ROUND_OFF_DEG * max(1.0, abs(deg) / 360.0)
    return 0.0 if a < tol or 360.0 - a < tol else a


def drive_joint(mech):
    """The joint whose coordinate is the crank angle: the first drive's joint, else the first primary
    coordinate's (None without either)."""
    if mech.drives:
        return mech.joint(mech.drives[0].joint)
    return None


def _revolute_drive(mech, what: str):
    j = drive_joint(mech)
    if j is None or not j.angular:
        raise CaseError(what, "needs a drive on a revolute joint (a crank); "
                              + ("this mechanism has no drive" if j is None else f"{j.name!r} is {j.kind}")
                              + ": give the instant with --at T instead")
    return j


def configuration_time(case: Case, source, at: float | None = None, crank_angle: float | None = None) -> float:
    """The instant [s] of the configuration: ``at`` (0 <= at <= solver.t_end), or the first instant at
    which the driven joint's angle reaches ``crank_angle`` [deg] (modulo 360), found on the case's
    output frames and refined by cubic Hermite interpolation of the angle and its rate; t = 0 when
    neither is given."""
    t_end = float(case["solver"]["t_end"])
    if at is not None and crank_angle is not None:
        raise CaseError("--at", "give the instant with --at T or with --crank-angle A, not both")
    if crank_angle is None:
        t = 0.0 if at is None else float(at)
        if not (math.isfinite(t) and 0.0 <= t <= t_end):
            raise CaseError("--at", f"must lie in the run, 0 <= T <= solver.t_end = {t_end:g} s, got {at!r} "
                                    "(raise it with --set solver.t_end=...)")
        return t
    if not math.isfinite(crank_angle):
        raise CaseError("--crank-angle", f"must be a number of degrees, got {crank_angle!r}")
    joint = _revolute_drive(case.mechanism, "--crank-angle")

    nsteps, _, every = time_grid(case)
    grid = np.linspace(0.0, t_end, nsteps // every + 1)
    jq = source(grid).joint(joint.name)
    f = (jq[:, 0] - math.radians(crank_angle)) / (2.0 * math.pi)
    exact = np.flatnonzero(np.abs(f - np.round(f)) < 1e-12)
    turn = np.floor(f)
    cross = np.flatnonzero(turn[1:] != turn[:-1])
    if exact.size and (not cross.size or exact[0] <= cross[0]):
        return float(grid[exact[0]])
    if not cross.size:
        lo, hi = np.degrees(jq[:, 0].min()), np.degrees(jq[:, 0].max())
        raise CaseError("--crank-angle", f"the angle of {joint.name!r} never reaches {crank_angle:g} deg (mod 360) in "
                                         f"the run (it spans {lo:.4g} .. {hi:.4g} deg up to t = {t_end:g} s); choose "
                                         "another angle or raise solver.t_end")
    k = int(cross[0])
    level = math.radians(crank_angle) + 2.0 * math.pi * max(turn[k], turn[k + 1])
    return _hermite_root(grid[k], grid[k + 1], jq[k], jq[k + 1], level)


def _hermite_root(t0, t1, j0, j1, level) -> float:
    """Root in [t0, t1] of the cubic Hermite interpolant of a coordinate (values and rates j0, j1)
    minus ``level``."""
    from scipy.optimize import brentq

    h = t1 - t0

    def g(t):
        s = (t - t0) / h
        h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
        return h00 * j0[0] + h10 * h * j0[1] + h01 * j1[0] + h11 * h * j1[1] - level

    if g(t0) * g(t1) > 0:       # the interpolant misses the sign change: the linear estimate
        return float(t0 + h * (level - j0[0]) / (j1[0] - j0[0]))
    return float(brentq(g, t0, t1, xtol=1e-14 * max(1.0, t1)))


def cycle_times(case: Case, positions: int) -> tuple[np.ndarray, str]:
    """(positions instants [s], what they span): one period 2 pi/|w| of a constant-speed crank (after
    the spin-up of a ``spinup`` law, at its final speed; 2 pi/frequency of a ``harmonic`` law), else
    the whole run [0, t_end] (tables, force drives, free motion) including both ends."""
    if not isinstance(positions, (int, np.integer)) or positions < 2:
        raise CaseError("--along-cycle", f"must be a whole number >= 2 of positions, got {positions!r}")
    mech, t_end = case.mechanism, float(case["solver"]["t_end"])
    j = drive_joint(mech)
    d = mech.drives[0] if mech.drives else None
    if j is not None and j.angular and d is not None:
        p = d.params
        law = {"constant_speed": ("speed", None), "spinup": ("final_speed", "spinup_time"),
               "harmonic": ("frequency", None)}.get(d.law)
        if law is not None and p.get(law[0]):
            period = 2.0 * math.pi / abs(float(p[law[0]]))
            t0 = float(p[law[1]]) if law[1] else 0.0
            what = (f"one crank period {period:.6g} s" + (f" after the spin-up ({t0:g} s)" if t0 else "")
                    if d.law != "harmonic" else f"one period {period:.6g} s of the harmonic drive")
            return t0 + period * np.arange(positions) / positions, what
    return np.linspace(0.0, t_end, positions), f"the run, 0 .. {t_end:g} s ({d.law if d else 'no'} drive)"


# ------------------------------------------------------------------------------ one model
class _Frozen:
    """A case's model made ready for frozen eigenproblems (the FE model or the coupled model, built
    once) at samples of a rigid motion."""

    def __init__(self, case: Case, model: str, geometric: str):
        if model not in MODELS:
            raise CaseError("--model", f"must be one of {', '.join(MODELS)}, got {model!r}")
        if geometric not in ("none", "current", "lagged", "quasi_static"):
            raise CaseError("--geometric", f"must be none or quasi_static, got {geometric!r}")
        self.case, self.model, self.gravity = case, model, case["loads"]["gravity"]
        self.geometric = family(model).superposition and geometric != "none"
        if family(model).superposition:
            self.fe, self.cm = FEModel.from_case(case), None
            node_frac = self.fe.node_frac
        else:
            self.fe, self.cm = None, CoupledModel.from_case(case, split=family(model).element_frames, hold_forced=True)
            node_frac = self.cm.mesh.node_frac
        self.bodies = shapes.body_points(case.mechanism, node_frac)
        self.dofs = self.fe.nfree if self.cm is None else self.cm.ndof
        self._checked = False

    def eigen(self, rm, i: int, count: int | None) -> modal.Eigen:
        if self.cm is not None:
            return modal.coupled_eigen(self.cm, rm, i, self.gravity, count)

        fe = self.fe
        rig = fe.rig_samples(rm, self.gravity, slice(i, i + 1))
        if not self._checked:
            check_elastic_problem(fe, rig, rm.setup.dof)
            self._checked = True
        nax = None
        if self.geometric:
            q_free, q_val = elastic_torque_loads(self.case, fe, rm.select(slice(i, i + 1)), rig)
            nax = modal.quasi_static_axial(fe, rig[:, :, 0], self.model, q_free, None if q_val is None else q_val[:, 0])
        return modal.superposition_eigen(fe, rig[:, :, 0], self.model, nax, count)

    def shapes(self, rm, i: int, ev: modal.Eigen) -> shapes.ShapeFrames:
        """The mode shapes of ev as ShapeFrames (key: frequency [Hz]); mass-normalized, each turned so
        that its largest displacement component is positive."""
        n = ev.lam.size
        rmi = rm.select(np.full(n, i))
        x = shapes.rigid_positions(self.case.mechanism, self.bodies, rmi)
        if self.cm is None:
            rig = self.fe.rig_samples(rmi, self.gravity)
            d, rot = shapes.superposition_displacements(self.fe, self.bodies, self.fe.expand(ev.x, rig), rmi)
        else:
            d, rot = self._coupled_shapes(rmi, ev)
        for k in range(n):
            flat = d[k].ravel()
            if flat.size and flat[np.argmax(np.abs(flat))] < 0:
                d[k], rot[k] = -d[k], -rot[k]
        return shapes.ShapeFrames(self.bodies, ev.omega / (2 * np.pi), x, d, rot)

    def _coupled_shapes(self, rmi, ev: modal.Eigen):
        """Node and body displacements of the coupled models' mode vectors by central differences of the
        model's own kinematics about the linearized state (exact to round-off for small steps)."""
        cm, n = self.cm, ev.lam.size
        dq = np.zeros((cm.ndof, n))
        free = modal.free_order(cm)
        dq[free] = ev.x
        eps = 1e-6 * self.case.mechanism.characteristic_length() / max(float(np.max(np.abs(dq))), 1e-300)
        out = []
        for sign in (1.0, -1.0):
            qf = ev.q[:, None] + sign * eps * dq
            out.append(shapes.coupled_displacements(cm, self.bodies, deviation(cm, qf, rmi.motion), qf, rmi))
        return (out[0][0] - out[1][0]) / (2 * eps), (out[0][1] - out[1][1]) / (2 * eps)


def _model_and_geometric(case, model, geometric):
    model = study_model(model, case)
    geometric = case["solver"]["geometric_stiffness"] if geometric is None else geometric
    return model, geometric


def _prepared_case(case, elements_per_link):
    case = case if isinstance(case, Case) else Case(case)
    return with_elements(case, elements_per_link) if elements_per_link is not None else case


# ------------------------------------------------------------------------------ one configuration
@dataclass
class ModeSet:
    """Natural frequencies and mode shapes at one configuration: ``t`` [s], the driven joint and its
    angle [deg] there (None without a revolute drive), ``omega`` (n,) [rad/s] (signed: < 0 a frozen
    instability), ``rigid`` (n,) rigid-body (mechanism) modes, ``rigid_fraction`` (n,), ``shapes``
    (ShapeFrames, one per mode, mass-normalized)."""

    case: Case
    model: str
    geometric: bool
    t: float
    joint: str | None
    crank_angle: float | None
    omega: np.ndarray
    rigid: np.ndarray
    rigid_fraction: np.ndarray
    shapes: shapes.ShapeFrames
    extra: dict = field(default_factory=dict)

    @property
    def hz(self) -> np.ndarray:
        return self.omega / (2.0 * np.pi)

    def summary(self) -> dict:

        return {"title": self.case["case"]["title"], "model": self.model,
                "geometric_stiffness": "quasi_static" if self.geometric else "none",
                "state": STATE[family(self.model).superposition], "t_s": self.t, "crank_joint": self.joint,
                "crank_angle_deg": self.crank_angle,
                "modes": [{"mode": k + 1, "kind": "rigid" if r else "elastic", "f_hz": float(f),
                           "omega_rad_s": float(w), "rigid_fraction": float(rf)}
                          for k, (f, w, r, rf) in enumerate(zip(self.hz, self.omega, self.rigid, self.rigid_fraction))],
                **self.extra, "versions": versions(), "input": self.case}

    def table(self) -> str:
        where = f"t = {self.t:.6g} s" + (f", {self.joint} at {self.crank_angle:.6g} deg" if self.joint else "")
        lines = [f"{self.case['case']['title']}  [model {self.model}"
                 + (", geometric stiffness (quasi-static)" if self.geometric else "") + f"]; {where}",
                 f"{'mode':>4}  {'f [Hz]':>12} {'omega [rad/s]':>14}  kind"]
        for k, (f, w, r) in enumerate(zip(self.hz, self.omega, self.rigid)):
            kind = "rigid (a free DOF of the mechanism)" if r else "elastic"
            lines.append(f"{k + 1:>4}  {f:>12.6g} {w:>14.6g}  {kind}")
        return "\n".join(lines)

    def write(self, out_dir) -> list[Path]:
        """modes.csv, mode_shapes.csv and modes.json in out_dir (created)."""

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        head = [f"flexmech modes; case {self.case['case']['title']!r}; model {self.model}; t = {self.t:.10g} s"
                + (f"; {self.joint} at {self.crank_angle:.10g} deg" if self.joint else "")]
        rows = [f"{k + 1},{f:.10g},{w:.10g},{'rigid' if r else 'elastic'},{rf:.6g}"
                for k, (f, w, r, rf) in enumerate(zip(self.hz, self.omega, self.rigid, self.rigid_fraction))]
        paths = [out / "modes.csv", out / "mode_shapes.csv", out / "modes.json"]
        atomic_write(paths[0], "\n".join([f"# {h}" for h in head] + ["mode,f_hz,omega_rad_s,kind,rigid_fraction"]
                                          + rows) + "\n")
        shapes.write_shape_csv(paths[1], self.shapes, head + [
            "one block per mode (index = mode - 1, f_hz its frequency): x, y the rigid position [m]; dx, dy, rot "
            "the mass-normalized mode shape (phi^T M phi = 1, M in kg and kg m^2: dx, dy in m/sqrt(kg m^2) = "
            "1/sqrt(kg), rot in rad/sqrt(kg m^2))"], key="f_hz")
        atomic_write(paths[2], json.dumps(self.summary(), indent=2, default=json_default) + "\n")
        return paths


STATE = {True: "the rigid configuration (K + K_c [+ K_sigma] against M at the rigid sample)",
         False: "the quasi-static state (elastic DOFs in equilibrium with the loads of the frozen rigid motion)"}


def modes(case, *, at: float | None = None, crank_angle: float | None = None, count: int = DEFAULT_COUNT,
          model: str | None = None, geometric: str | None = None, elements_per_link: int | None = None) -> ModeSet:
    """Natural frequencies and mode shapes of ``case`` frozen at the instant ``at`` [s] or at the first
    instant its driven joint reaches ``crank_angle`` [deg] (default t = 0): the ``count`` lowest elastic
    modes plus any rigid-body modes, with ``model`` (default: the case's solver.model) and ``geometric``
    (none | quasi_static; superposition models only; default: the case's solver.geometric_stiffness)."""
    if not isinstance(count, (int, np.integer)) or count < 1:
        raise CaseError("--count", f"must be a whole number >= 1, got {count!r}")
    case = _prepared_case(case, elements_per_link)
    model, geometric = _model_and_geometric(case, model, geometric)
    frozen = _Frozen(case, model, geometric)
    source = motion_source(case)
    t = configuration_time(case, source, at, crank_angle)
    rm = source(np.array([t]))
    ev = frozen.eigen(rm, 0, count)
    j = drive_joint(case.mechanism)
    ang = turn_angle(float(np.degrees(rm.joint(j.name)[0, 0]))) if j is not None and j.angular else None
    return ModeSet(case, model, frozen.geometric, t, j.name if ang is not None else None, ang, ev.omega, ev.rigid,
                   ev.rigid_fraction, frozen.shapes(rm, 0, ev))


# ------------------------------------------------------------------------------ along a cycle
@dataclass
class Along:
    """Frozen natural frequencies at K positions: ``t`` (K,) [s], ``x`` (K,) the abscissa (``xlabel``:
    crank angle [deg], unwrapped from the first position, or t [s]), ``omega`` (K, n) the n lowest
    elastic modes [rad/s] (k-th lowest at each position; modes are not tracked through crossings),
    ``speed`` (K,) the driven joint's speed |dtheta/dt| [rad/s] (None without a revolute drive),
    ``span`` what the positions cover, ``rigid_modes`` the number of rigid-body modes left out."""

    case: Case
    model: str
    geometric: bool
    t: np.ndarray
    x: np.ndarray
    xlabel: str
    omega: np.ndarray
    speed: np.ndarray | None
    joint: str | None
    span: str
    rigid_modes: int = 0
    angle: np.ndarray | None = None     # (K,) the driven joint's angle [deg] (None without a revolute drive)

    @property
    def hz(self) -> np.ndarray:
        return self.omega / (2.0 * np.pi)

    def harmonics(self) -> list[int]:
        """The harmonics k = 1, 2, ... whose k Omega / 2 pi reaches into the frequency range drawn
        (at most MAX_HARMONICS of them); none when the drive joint turns less than one revolution over
        a span that is not a cycle (a swinging arm: its speed's harmonics force nothing periodic)."""
        if self.speed is None or not np.any(self.speed > 0) or not self.turns():
            return []
        top = 1.05 * float(np.max(self.hz))
        kmax = int(top / (float(np.max(self.speed)) / (2 * np.pi)))
        return list(range(1, min(max(kmax, 1), MAX_HARMONICS) + 1))

    def turns(self) -> bool:
        """The drive joint turns: the span is one cycle, or the joint's angle covers a revolution."""
        return self.span.startswith("one") or (self.angle is not None and float(np.ptp(self.angle)) >= 360.0)

    def harmonics_hz(self, k: int) -> np.ndarray:
        """k Omega(t) / 2 pi [Hz] at the positions."""
        return k * self.speed / (2.0 * np.pi)

    def crossings(self) -> list[dict]:
        """Where a frequency meets a crank speed harmonic (:func:`resonance_crossings`)."""
        if self.speed is None:
            return []
        closed = self.xlabel.startswith("crank angle") and self.span.startswith("one")
        return resonance_crossings(self.t, self.x, self.hz, self.speed / (2 * np.pi), self.harmonics(), closed)

    def summary(self) -> dict:

        return {"title": self.case["case"]["title"], "model": self.model,
                "geometric_stiffness": "quasi_static" if self.geometric else "none", "positions": int(self.t.size),
                "span": self.span, "crank_joint": self.joint, "x": self.xlabel, "rigid_modes_left_out": self.rigid_modes,
                "band_hz": [{"mode": k + 1, "min": float(self.hz[:, k].min()), "max": float(self.hz[:, k].max())}
                            for k in range(self.hz.shape[1])],
                "harmonics": self.harmonics(), "crossings": self.crossings(), "versions": versions()}

    def write(self, out_dir) -> list[Path]:
        """frequencies_along.csv and frequencies_along.json in out_dir."""

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        n = self.hz.shape[1]
        cols = ["t"] + (["crank_angle_deg", "crank_speed_rad_s"] if self.speed is not None else []) \
            + [f"f{k + 1}_hz" for k in range(n)] + [f"omega{k + 1}_rad_s" for k in range(n)]
        data = [self.t] + ([self.angle, self.speed]
                           if self.speed is not None else []) + list(self.hz.T) + list(self.omega.T)
        head = [f"# flexmech modes --along-cycle; case {self.case['case']['title']!r}; model {self.model}; "
                f"{self.t.size} positions over {self.span}; the n lowest elastic modes at each position (not tracked)",
                ",".join(cols)]
        rows = [",".join(f"{v:.10g}" for v in row) for row in np.column_stack(data)]
        paths = [out / "frequencies_along.csv", out / "frequencies_along.json"]
        atomic_write(paths[0], "\n".join(head + rows) + "\n")
        atomic_write(paths[1], json.dumps(self.summary(), indent=2, default=json_default) + "\n")
        return paths


def resonance_crossings(t, x, hz: np.ndarray, speed_hz: np.ndarray, harmonics, closed: bool = False) -> list[dict]:
    """Where f_i(x) = k Omega(x) / 2 pi between two positions (linear interpolation): [{mode, harmonic,
    x, t, f_hz}], by mode, then position; ``closed``: the positions close a cycle (the last joins the
    first)."""
    out = []
    idx = list(range(len(t))) + ([0] if closed else [])
    for i in range(hz.shape[1]):
        for k in harmonics:
            g = hz[:, i] - k * speed_hz
            for a, b in zip(idx[:-1], idx[1:]):
                if g[a] == 0.0 or g[a] * g[b] < 0.0:
                    s = 0.0 if g[a] == 0.0 else g[a] / (g[a] - g[b])
                    xb = x[b] if b > a else x[a] + (x[1] - x[0])
                    tb = t[b] if b > a else t[a] + (t[1] - t[0])
                    out.append({"mode": i + 1, "harmonic": k, "x": float(x[a] + s * (xb - x[a])),
                                "t": float(t[a] + s * (tb - t[a])), "f_hz": float(hz[a, i] + s * (hz[b, i] - hz[a, i]))})
    return out


def frequencies_along(case, positions: int = 36, *, count: int = DEFAULT_COUNT, model: str | None = None,
                      geometric: str | None = None, elements_per_link: int | None = None) -> Along:
    """The ``count`` lowest elastic natural frequencies at ``positions`` instants over one cycle of the
    drive (:func:`cycle_times`)."""
    if not isinstance(count, (int, np.integer)) or count < 1:
        raise CaseError("--count", f"must be a whole number >= 1, got {count!r}")
    case = _prepared_case(case, elements_per_link)
    model, geometric = _model_and_geometric(case, model, geometric)
    if isinstance(positions, (int, np.integer)) and positions >= 2:   # before any array of the positions
        check_count(positions, POSITION_BYTES + 16 * min(count, 10 ** 6), "--along-cycle", "positions",
                    lambda n: f"use at most {format_count(n)} positions (e.g. --along-cycle {min(n, 360)})")
    frozen = _Frozen(case, model, geometric)
    count = min(count, frozen.dofs)       # no more modes than degrees of freedom
    t, span = cycle_times(case, positions)
    rm = motion_source(case)(t)
    omega = np.full((t.size, count), np.nan)
    nrigid = 0
    for i in range(t.size):
        ev = frozen.eigen(rm, i, count)
        w = ev.omega[~ev.rigid]
        omega[i, :w.size] = w
        nrigid = max(nrigid, int(np.sum(ev.rigid)))
    j = drive_joint(case.mechanism)
    speed, xlabel, x = None, "t [s]", t
    if j is not None and j.angular:
        jq = rm.joint(j.name)
        speed = np.abs(jq[:, 1])
        ang = np.degrees(jq[:, 0])
        d = case.mechanism.drives[0]
        if d.law in ("constant_speed", "spinup") and span.startswith("one"):
            x, xlabel = ang - (float(ang[0]) - turn_angle(float(ang[0]))), "crank angle [deg]"
    return Along(case, model, frozen.geometric, t, x, xlabel, omega, speed, None if speed is None else j.name, span,
                 nrigid, None if speed is None else np.degrees(rm.joint(j.name)[:, 0]))
