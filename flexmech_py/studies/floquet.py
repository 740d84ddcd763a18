"""Periodic steady state and Floquet stability of constant-speed drives (docs/theory.md section 15).

With the crank at constant speed Omega the superposition models are linear in the elastic
state x = (u, v) with T-periodic coefficients, T = 2 pi / Omega.  The Fortran time loop
(average-acceleration Newmark, an integer number N of steps per period) is an affine
one-period map

    x(T) = Phi x(0) + x_p,

Phi the (discrete) monodromy matrix and x_p the response over one period from rest.  By
linearity Phi e_i = x(T; e_i) - x(T; 0), so 2 n + 1 whole-period runs of the compiled loop
give Phi (n free elastic DOFs).  The Floquet multipliers mu are its eigenvalues
(|mu| > 1: a physical parametric instability, the integrator adds no damping); the periodic
steady state is x* = (I - Phi)^{-1} x_p, and one period from x* is the steady-state response.

Python only launches whole-period runs (:func:`_period_run`, the one call into the time
loop); every step stays in Fortran.
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ..base import notices
from ..case import SUPERPOSITION_MODELS, Case, study_model
from ..base.errors import CaseError
from .regions import default_resolution, multiplier_type, refinement_speeds
from ..base.sizes import check_points
from ..run.simulate import Prepared
from ..models.superposition.loads import check_elastic_problem
from ..base.fileio import atomic_write
from ..models.modal import superposition_frequencies
from ..run.parallel import run_tasks

__all__ = ["PeriodicCase", "FloquetResult", "floquet", "steady_state", "frozen_frequencies", "stability_point",
           "STABLE_RATE", "ILL_CONDITIONED", "stability_chart", "ChartRuns", "REFINE_ROUNDS",
           "write_stability_csv", "parse_range"]

#: growth rate ln|mu| / T [1/s] above which a speed is reported unstable (an e-folding time of 10 s or
#: less).  The discrete map of the time-varying equations is not exactly symplectic: undamped, its
#: multipliers leave the unit circle by O(dt^2) (about 1e-4 per period, 2e-3 1/s, on the seed four-bar
#: at dt = 1e-5 s); this threshold sits well above that floor (docs/stability.md).
STABLE_RATE = 0.1
#: condition number of the balanced I - Phi above which the periodic steady state is reported
#: ill-defined (resonance: a multiplier near 1)
ILL_CONDITIONED = 1e6
#: crank positions per cycle at which the frozen natural frequencies are evaluated
FROZEN_SAMPLES = 48

_REFUSED = {
    "current": "the axial forces of 'current' come from the unknown displacements at every step: the equations "
               "are nonlinear in u and have no monodromy matrix",
    "lagged": "'lagged' takes the axial forces from the previous step's displacements: the step map is "
              "nonlinear in u and has no monodromy matrix",
}


class PeriodicCase:
    """One crank period of a constant-speed case, made ready for whole-period runs.

    ``speed`` [rad/s] overrides ``drive.speed``; ``geometric`` overrides
    ``solver.geometric_stiffness`` (``none`` or ``quasi_static``).  The time step is
    the case's ``solver.dt`` shortened to an integer number of steps per period
    (a multiple of ``solver.output_every``); the integrator is average-acceleration
    Newmark whatever the case says (no numerical damping: |mu| > 1 is physical).
    """

    def __init__(self, case: dict, model: str | None = None, *, speed: float | None = None,
                 geometric: str | None = None, dt: float | None = None, elements_per_link: int | None = None):
        case = case if isinstance(case, Case) else Case(case)   # a resolved case that travelled as a plain dict
        model = study_model(model, case)
        geometric = case["solver"]["geometric_stiffness"] if geometric is None else geometric
        i = self.check(case, model, geometric)
        speed = case["drives"][i]["speed"] if speed is None else float(speed)
        if not (math.isfinite(speed) and speed != 0.0):
            raise CaseError(f"drives[{i}].speed", f"the crank speed must be finite and nonzero for a period, got {speed}")
        c = copy.deepcopy(case)
        c["drives"][i]["speed"] = speed
        self.period = 2.0 * math.pi / abs(speed)
        sol = c["solver"]
        # the monodromy is always average-acceleration Newmark (no numerical damping; theory.md §16)
        for key in ("hht_alpha", "rho_inf"):
            sol.pop(key, None)
        sol.update(t_end=self.period, integrator="newmark", beta=0.25, gamma=0.5, geometric_stiffness=geometric,
                   model=model, error_estimate="none")
        self.case_integrator = case["solver"].get("integrator", "newmark")
        self.speed, self.model, self.geometric = speed, model, geometric
        self.prep = Prepared(c, dt=dt, elements_per_link=elements_per_link)
        self.case = self.prep.case
        self.fe = self.prep.fe
        self.nsteps, self.dt = self.prep.nsteps, self.prep.dt
        if self.prep.setup.mode != "kinematic":
            raise CaseError("drives", f"the mechanism has {self.prep.setup.dof} degrees of freedom and one drive: its motion "
                                      "is not periodic; drive every degree of freedom")
        check_elastic_problem(self.fe, self.prep.rig, self.prep.setup.dof)
        self.prep.elastic_checked = True

    @staticmethod
    def check(case: dict, model: str, geometric: str) -> int:
        """CaseError unless the case has one drive, constant-speed on a revolute joint, and a model linear in
        the elastic state; returns the drive's index."""
        drives, mech = case["drives"], case.mechanism
        laws = ", ".join(f"{d['joint']}: {d['law']!r}" for d in drives) or "none"
        if len(drives) != 1 or drives[0]["law"] != "constant_speed" or not mech.joint(drives[0]["joint"]).angular:
            raise CaseError("drives", "the periodic steady state and Floquet multipliers need one kinematic drive with "
                                      "law = 'constant_speed' on a revolute joint (periodic coefficients); this case has "
                                      f"{laws}")
        if model not in SUPERPOSITION_MODELS:
            raise CaseError("model", f"Floquet analysis needs a model linear in the elastic state: one of "
                                     f"{', '.join(SUPERPOSITION_MODELS)}, not {model!r} (its equations are nonlinear)")
        if geometric in _REFUSED:
            raise CaseError("solver.geometric_stiffness", f"{_REFUSED[geometric]}; use 'none' or 'quasi_static' "
                                                          "(axial forces from the rigid-body loads, still linear in u)")
        if geometric not in ("none", "quasi_static"):
            raise CaseError("solver.geometric_stiffness", f"must be 'none' or 'quasi_static' here, got {geometric!r}")
        return 0

    @property
    def n(self) -> int:
        """Free elastic DOFs (the state has 2 n entries)."""
        return self.fe.nfree

    def period_run(self, u0=None, v0=None, out_every: int | None = None):
        """One period from (u0, v0): (uf, vf, nf) frames over the free DOFs and element axial forces."""
        return _period_run(self.prep, self.model, self.geometric, u0, v0,
                           self.nsteps if out_every is None else out_every)


def _period_run(prep: Prepared, model: str, geometric: str, u0, v0, out_every: int):
    """The one call into the compiled time loop: one whole period from (u0, v0), average acceleration,
    consistent initial acceleration (computed in Fortran, geometric stiffness included).  The
    divergence guard is off: the map is linear and its columns start from unit states."""
    sol = prep.case["solver"]
    uf, vf, _af, nf, _it = prep.fe.run(prep.rig, model, prep.dt, beta=0.25, gamma=0.5, out_every=out_every,
                                       rayleigh=sol["rayleigh"], q_free=prep.q_free, q_val=prep.q_val, u0=u0, v0=v0,
                                       geometric=geometric, div_limit=math.inf, full=True)
    return uf, vf, nf


class FloquetResult:
    """Monodromy matrix ``phi`` (2n, 2n) on x = (u, v), multipliers ``mu`` (sorted by decreasing |mu|),
    the response from rest ``x_p``, the periodic state ``x_star`` and diagnostics."""

    def __init__(self, pc: PeriodicCase, phi, x_p, wall_s, nf_rest):
        self.pc, self.phi, self.x_p, self.wall_s = pc, phi, x_p, wall_s
        self.nf_rest = nf_rest
        mu = np.linalg.eigvals(phi)
        self.mu = mu[np.argsort(-np.abs(mu), kind="stable")]
        # u [m, rad] and v [m/s, rad/s] differ in scale by the frequencies: balance Phi by a diagonal
        # similarity D^-1 Phi D (same multipliers) before judging and solving I - Phi
        b, (d, _) = scipy.linalg.matrix_balance(phi, permute=False, separate=True)
        a = np.eye(phi.shape[0]) - b
        self.cond = float(np.linalg.cond(a))
        self.resonance_margin = float(np.min(np.abs(1.0 - self.mu)))   # distance of the multipliers from 1
        try:
            self.x_star = d * np.linalg.solve(a, x_p / d)
        except np.linalg.LinAlgError:
            self.x_star = np.full_like(x_p, np.nan)

    @property
    def max_abs_mu(self) -> float:
        return float(np.abs(self.mu[0]))

    @property
    def growth_rate(self) -> float:
        """ln max|mu| / T [1/s]: the e-folding rate of the fastest-growing Floquet solution."""
        return float(np.log(self.max_abs_mu) / self.pc.period)

    @property
    def stable(self) -> bool:
        return self.growth_rate <= STABLE_RATE

    def warnings(self) -> list[str]:
        out = []
        if not self.stable:
            out.append(f"unstable at crank speed {self.pc.speed:g} rad/s: largest Floquet multiplier |mu| = "
                       f"{self.max_abs_mu:.6g} (growth rate {self.growth_rate:.3g} 1/s; parametric resonance or buckling): the periodic state exists but a transient "
                       f"grows by that factor every period and never settles on it")
        if self.cond > ILL_CONDITIONED:
            out.append(f"I - Phi is ill-conditioned (condition number {self.cond:.3g}) at crank speed "
                       f"{self.pc.speed:g} rad/s: a multiplier is near 1 (resonance, a natural frequency near a "
                       f"multiple of the crank speed); there is no meaningful periodic steady state")
        return out

    def summary(self) -> dict:
        """Multipliers and diagnostics for summary.json."""
        mu = self.mu
        return {"speed_rad_s": self.pc.speed, "period_s": self.pc.period, "steps_per_period": self.pc.nsteps,
                "dt": self.pc.dt, "integrator": "Newmark average acceleration (beta = 1/4, gamma = 1/2)",
                "geometric_stiffness": self.pc.geometric, "rayleigh": list(self.pc.case["solver"]["rayleigh"]),
                "state_size": int(self.phi.shape[0]), "max_abs_multiplier": self.max_abs_mu,
                "growth_rate_per_s": self.growth_rate, "stable": self.stable,
                "cond_I_minus_Phi": self.cond, "resonance_margin": self.resonance_margin,
                "multipliers": [{"re": float(m.real), "im": float(m.imag), "abs": float(abs(m))} for m in mu],
                "monodromy_wall_s": self.wall_s, "warnings": self.warnings()}


def floquet(pc: PeriodicCase, *, out_every: int | None = None) -> FloquetResult:
    """Monodromy matrix from 2 n + 1 whole-period runs, multipliers and the periodic state.

    The run from rest keeps frames every ``out_every`` steps (default: the case's
    ``solver.output_every``): its element axial forces feed the frozen frequencies.
    """
    t0 = time.perf_counter()
    n = pc.n
    z = np.zeros(n)
    uf, vf, nf = pc.period_run(z, z, out_every=pc.prep.out_every if out_every is None else out_every)
    x_p = np.concatenate([uf[:, -1], vf[:, -1]])
    phi = np.empty((2 * n, 2 * n))
    for i in range(2 * n):
        e = np.zeros(2 * n)
        e[i] = 1.0
        ue, ve, _ = pc.period_run(e[:n], e[n:])
        phi[:, i] = np.concatenate([ue[:, -1], ve[:, -1]]) - x_p
    return FloquetResult(pc, phi, x_p, time.perf_counter() - t0, nf)


def steady_state(pc: PeriodicCase, fr: FloquetResult | None = None):
    """One period of the periodic steady state as a :class:`~flexmech_py.run.results.Result`
    (the usual outputs of ``flexmech run``), with the multipliers in ``extra["floquet"]``."""
    fr = floquet(pc) if fr is None else fr
    n = pc.n
    with notices.silenced():      # its warnings are issued with the Floquet ones below
        res = pc.prep.run(pc.model, pc.geometric, u0=fr.x_star[:n], v0=fr.x_star[n:], estimate=False)
    x_end = np.concatenate([pc.fe.restrict(res.u[:, -1]), pc.fe.restrict(res.v[:, -1])])
    scale = max(float(np.max(np.abs(fr.x_star[:n]))), 1e-300)
    info = fr.summary()
    info["periodicity_residual"] = float(np.max(np.abs(x_end[:n] - fr.x_star[:n])) / scale)
    res.extra["floquet"] = info
    for m in info["warnings"]:                                   # validity, then Floquet
        notices.add(res.extra, m, "stability")
    notices.issue(res.extra)
    return res


def frozen_frequencies(pc: PeriodicCase, fr: FloquetResult, nmodes: int = 4, samples: int = FROZEN_SAMPLES):
    """(samples, nmodes) natural frequencies [rad/s] of the frozen configuration at ``samples`` crank
    positions over the cycle: sqrt of the eigenvalues of (K + Kc [+ Kg], M) at that instant (the
    stiffness the model uses there, centrifugal and geometric terms included; gyroscopic and damping
    terms left out), lowest first (flexmech_py.models.modal.superposition_frequencies)."""
    nfr = fr.nf_rest.shape[1]                    # frames of the run from rest over one period
    frames = np.unique(np.linspace(0, nfr - 1, samples, endpoint=False).round().astype(int))
    steps = frames * (pc.nsteps // (nfr - 1))
    nax = fr.nf_rest[:, frames] if pc.geometric == "quasi_static" else None
    return superposition_frequencies(pc.fe, pc.prep.rig[:, :, steps], pc.model, nmodes, nax)


def stability_point(task: dict) -> dict:
    """Worker of ``flexmech stability``: one crank speed.  ``task``: {"case": resolved case,
    "model", "geometric", "speed", "nmodes"}.  Returns multipliers and frozen-frequency bands."""
    pc = PeriodicCase(task["case"], task["model"], speed=task["speed"], geometric=task["geometric"])
    t0 = time.perf_counter()
    fr = floquet(pc)
    freqs = frozen_frequencies(pc, fr, nmodes=task.get("nmodes", 4))
    out = fr.summary()
    out.pop("warnings")
    out["multipliers"] = out["multipliers"][:8]
    out["freq_min"] = [float(x) for x in freqs.min(axis=0)]
    out["freq_max"] = [float(x) for x in freqs.max(axis=0)]
    out["wall_s"] = time.perf_counter() - t0
    return out


def parse_range(text: str, where: str) -> list[float]:
    """``START:STOP:N`` (N evenly spaced values, ends included) or ``a,b,c``."""
    try:
        if ":" in text:
            a, b, n = text.split(":")
            a, b, n = float(a), float(b), int(n)
            if n < 1:
                raise ValueError
        else:
            return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise CaseError(where, f"{text!r} must be START:STOP:N (N >= 1 points) or a list a,b,c") from None
    check_points(n, where, lambda k: f"give at most {k:,} speeds, e.g. {where} {a:g}:{b:g}:{min(k, 1000)}")
    return [float(x) for x in np.linspace(a, b, n)]


STABILITY_COLUMNS = ["speed", "max_abs_mu", "growth_rate", "stable", "mu_re", "mu_im", "multiplier", "round",
                     "resonance_margin", "steps_per_period", "wall_s"]
#: refinement rounds after the user's grid (``flexmech stability --refine-rounds``)
REFINE_ROUNDS = 8


@dataclass
class ChartRuns:
    """What a chart cost: speeds computed and taken from the cache, wall time, worker processes (or the
    Dask ``executor``), tasks re-run after a lost worker, and the refinement (``rounds`` run after the
    user's grid, ``added`` speeds, ``resolution`` [rad/s])."""

    computed: int = 0
    cached: int = 0
    wall_s: float = 0.0
    jobs: int = 1
    retries: int = 0
    executor: str = ""
    rounds: int = 0
    added: int = 0
    resolution: float | None = None


def _chart_row(speed: float, r: dict, round_: int) -> dict:
    if "error" in r:
        return {"speed": speed, "round": round_, "error": r["error"]}
    mu = r["multipliers"][0]
    row = {"speed": speed, "max_abs_mu": r["max_abs_multiplier"], "growth_rate": r["growth_rate_per_s"],
           "stable": int(r["stable"]), "mu_re": mu["re"], "mu_im": mu["im"],
           "multiplier": multiplier_type(mu["re"], mu["im"]), "round": round_,
           "resonance_margin": r["resonance_margin"], "steps_per_period": r["steps_per_period"], "wall_s": r["wall_s"]}
    for k, (lo, hi) in enumerate(zip(r["freq_min"], r["freq_max"]), start=1):
        row[f"omega{k}_min"], row[f"omega{k}_max"] = lo, hi
    return row


def stability_chart(case: dict, speeds, *, model: str | None = None, geometric: str | None = None, nmodes: int = 4,
                    jobs: int | None = None, cache_dir=None, progress: bool = True, resolution: float | None = None,
                    refine_rounds: int = REFINE_ROUNDS, scheduler=None):
    """Floquet analysis at every crank speed, in parallel (:func:`~flexmech_py.run.parallel.run_tasks`: the
    local pool of ``jobs`` processes, or the Dask ``scheduler``), then up to ``refine_rounds`` further
    rounds on the speeds :func:`~flexmech_py.studies.regions.refinement_speeds` picks (region edges, extrema of
    |mu| that may hide a pocket) until no interval wider than ``resolution`` [rad/s] (default:
    :func:`~flexmech_py.studies.regions.default_resolution`) is left to split.  Returns (rows, runs): one dict
    per speed, sorted by speed (an ``error`` entry for a failed one; ``round`` 0 for the user's speeds;
    ``worker`` where it ran), and a :class:`ChartRuns`."""
    model = study_model(model, case)
    geometric = case["solver"]["geometric_stiffness"] if geometric is None else geometric
    PeriodicCase.check(case, model, geometric)
    speeds = sorted({float(s) for s in speeds})
    if not speeds or any(not math.isfinite(s) or s <= 0 for s in speeds):
        raise CaseError("--speed", f"crank speeds must be finite and > 0 rad/s, got {speeds}")
    resolution = default_resolution(speeds) if resolution is None else float(resolution)
    if resolution is not None and not (math.isfinite(resolution) and resolution > 0):
        raise CaseError("--resolution", f"must be a finite speed > 0 rad/s, got {resolution}")
    c = copy.deepcopy(case)
    c["case"].pop("path", None)   # the cache key depends on the case's content, not on where it was read
    rows, runs = [], ChartRuns(resolution=resolution)
    todo, round_ = speeds, 0
    while todo:
        tasks = [{"case": c, "model": model, "geometric": geometric, "speed": s, "nmodes": nmodes} for s in todo]
        batch = run_tasks(stability_point, tasks, jobs=jobs, cache_dir=cache_dir, progress=progress,
                          label="speeds" if round_ == 0 else f"refinement {round_}", scheduler=scheduler)
        rows += [dict(_chart_row(s, r, round_), worker=w) for s, r, w in zip(todo, batch.results, batch.task_worker)]
        runs.computed, runs.cached = runs.computed + batch.computed, runs.cached + batch.cached
        runs.wall_s, runs.jobs = runs.wall_s + batch.wall_s, max(runs.jobs, batch.jobs)
        runs.retries, runs.executor = runs.retries + batch.retries, batch.executor
        if round_ >= refine_rounds or resolution is None:
            break
        done = {r["speed"] for r in rows}
        todo = [s for s in refinement_speeds(rows, resolution) if s not in done]
        round_ += 1
        if todo:
            runs.rounds, runs.added = round_, runs.added + len(todo)
    return sorted(rows, key=lambda r: r["speed"]), runs


def write_stability_csv(rows: list, path, header: str = "") -> None:
    """stability.csv: one row per speed (units in the second comment line)."""

    names = list(STABILITY_COLUMNS)
    for r in rows:
        names += [k for k in r if k not in names and k != "error"]
    names.append("error")
    units = {"speed": "rad/s", "max_abs_mu": "1", "growth_rate": "1/s", "stable": "1", "mu_re": "1", "mu_im": "1",
             "multiplier": "", "round": "1", "resonance_margin": "1", "steps_per_period": "1", "wall_s": "s",
             "worker": "", "error": ""}
    lines = [f"# {header}" if header else "# flexmech stability",
             "# units: " + ",".join(units.get(n, "rad/s") for n in names), ",".join(names)]
    for r in rows:
        cells = []
        for n in names:
            v = r.get(n, "")
            cells.append(f"{v:.10g}" if isinstance(v, float) else ('"' + str(v).replace('"', "'") + '"' if n == "error" and v else str(v)))
        lines.append(",".join(cells))
    atomic_write(path, "\n".join(lines) + "\n")
