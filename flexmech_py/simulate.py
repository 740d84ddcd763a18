"""Run a case: rigid-body motion first, then the superposition KED model in Fortran."""

from __future__ import annotations

import copy
import math
import time

import numpy as np

from . import rigid
from .case import MODELS, SUPERPOSITION_MODELS, integrator_coefficients
from .errors import CaseError, SolverError
from . import coupled, guards
from .coupled import CoupledModel
from .model import FEModel
from .outputs import evaluate_outputs, link_curvature, output_unit
from .results import Result

__all__ = ["simulate", "simulate_models", "Prepared", "build_mechanism", "link_masses", "rigid_motion", "time_grid", "RigidMotion"]


def build_mechanism(case: dict):
    """The rigid mechanism (rigid.FourBar or rigid.SerialChain) of a resolved case."""
    L = [ln["length"] for ln in case["links"]]
    mech = case["mechanism"]
    if mech["type"] == "fourbar":
        q0 = case["initial"]["angles"][0]
        fb = rigid.FourBar.open_assembly(L[0], L[1], L[2], mech["ground_length"], q0)
        if mech["assembly"] == "crossed":
            fb = rigid.FourBar(L[0], L[1], L[2], mech["ground_length"], branch=-fb.branch)
        return fb
    return rigid.SerialChain(L, base=tuple(mech["base"]))


def link_masses(case: dict, fe: FEModel) -> list:
    """Rigid mass properties per link, equal to those of the FE model (bars + lumped inertias)."""
    masses = [rigid.LinkMass.from_bar(ln["density"] * ln["area"], ln["length"]) for ln in case["links"]]
    for i, pm in enumerate(case["point_masses"]):
        li, _, zeta = fe.node_ref(pm["at"], f"point_masses[{i}].at")
        masses[li].add_point_mass(pm["mass"], zeta)
    for r in case["rotary_inertias"]:
        masses[fe.link_names.index(r["turns_with"])].add_rotary_inertia(r["inertia"])
    return masses


def torque_value(tq: dict, theta):
    """Joint torque law tau(theta) = constant + sum_k sin_k sin(k theta) + cos_k cos(k theta) [N m]."""
    tau = tq["constant"] + 0.0 * theta
    for k, a in enumerate(tq["sin"], start=1):
        tau = tau + a * np.sin(k * theta)
    for k, b in enumerate(tq["cos"], start=1):
        tau = tau + b * np.cos(k * theta)
    return tau


def time_grid(case: dict, dt: float | None = None, out_every: int | None = None):
    """(nsteps, dt_eff, out_every): nsteps a multiple of out_every and dt_eff = t_end / nsteps <= dt."""
    sol = case["solver"]
    dt = sol["dt"] if dt is None else dt
    out_every = sol["output_every"] if out_every is None else out_every
    if not dt > 0 or dt > sol["t_end"]:
        raise CaseError("solver.dt", f"must satisfy 0 < dt <= t_end = {sol['t_end']} s, got {dt}")
    nsteps = max(1, math.ceil(sol["t_end"] / dt - 1e-9))
    nsteps = out_every * math.ceil(nsteps / out_every)
    return nsteps, sol["t_end"] / nsteps, out_every


class RigidMotion:
    """Rigid-body motion sampled on a time grid: q, qd, qdd (N, ndof) and the link motion."""

    def __init__(self, t, q, qd, qdd, motion):
        self.t, self.q, self.qd, self.qdd, self.motion = t, q, qd, qdd, motion

    def kernel_samples(self, gravity, idx=slice(None)) -> np.ndarray:
        """(5, nlinks, N) array [phi, omega, alpha, a_Ox - g_x, a_Oy - g_y] for the kernels."""
        m = self.motion
        rig = np.stack([m.phi[idx], m.omega[idx], m.alpha[idx], m.ax[idx] - gravity[0], m.ay[idx] - gravity[1]])
        return np.asfortranarray(rig.transpose(0, 2, 1))


def rigid_motion(case: dict, fe: FEModel, t: np.ndarray, mech=None) -> RigidMotion:
    """Rigid-body motion on the grid t: kinematic drive, or torque-driven forward dynamics."""
    mech = build_mechanism(case) if mech is None else mech
    drive = case["drive"]
    q0 = np.array(case["initial"]["angles"], float)
    qd0 = np.array(case["initial"]["speeds"], float)
    if drive["type"] == "kinematic":
        if drive["law"] == "constant_speed":
            q, qd, qdd = rigid.constant_speed(t, q0[0], drive["speed"])
        else:
            q, qd, qdd = rigid.spinup(t, drive["final_speed"], drive["spinup_time"], q0=q0[0])
        if isinstance(mech, rigid.FourBar):
            rigid.check_motion(mech, q, t)
    else:
        masses = link_masses(case, fe)
        torques = [(tq, fe.joint(tq["joint"])) for tq in drive["torques"]]

        def gen_force(_t, q, qd):
            km, jac = rigid.motion_and_jacobian(mech, q, qd, strict=False)  # angles and d(phi)/dq (cached)
            Q = np.zeros_like(q)
            for tq, j in torques:
                theta = km.phi[:, j.outboard] - (km.phi[:, j.inboard] if j.inboard is not None else 0.0)
                dphi = jac[:, j.outboard, 2, :] - (jac[:, j.inboard, 2, :] if j.inboard is not None else 0.0)
                Q += torque_value(tq, theta)[:, None] * dphi
            return Q

        q, qd, qdd = rigid.integrate(mech, masses, q0, qd0, t, gen_force, gravity=tuple(case["loads"]["gravity"]),
                                     rtol=case["solver"]["rigid_rtol"], atol=case["solver"]["rigid_atol"])
    return RigidMotion(t, q, qd, qdd, mech.kinematics(q, qd, qdd))


def elastic_torque_loads(case: dict, fe: FEModel, rm: RigidMotion):
    """Applied joint torques as generalized forces on the free elastic DOFs: (q_free, q_val) or (None, None).

    Assembled over all DOFs (constrained ones included) and restricted to the free
    DOFs; rows that vanish identically (torques on clamped DOFs, or action and
    reaction on one locked rotation) are dropped, so they cost nothing.
    """
    drive = case["drive"]
    if drive["type"] != "torque":
        return None, None
    q_all = np.zeros((fe.ndof, rm.t.size))
    for tq in drive["torques"]:
        j = fe.joint(tq["joint"])
        theta = rm.motion.phi[:, j.outboard] - (rm.motion.phi[:, j.inboard] if j.inboard is not None else 0.0)
        tau = torque_value(tq, theta)
        node = fe.node_of[j.outboard][0 if j.outboard_end == "start" else -1]
        q_all[fe.rot_dof[(node, j.outboard)]] += tau
        if j.inboard is not None:
            q_all[fe.rot_dof[(node, j.inboard)]] -= tau
    qf = fe.restrict(q_all)
    rows = np.flatnonzero(np.any(qf != 0.0, axis=1))
    if rows.size == 0:
        return None, None
    return (rows + 1).astype(np.int32), np.asfortranarray(qf[rows])


def check_elastic_problem(fe: FEModel, rig0: np.ndarray) -> None:
    """Reject an elastic problem with zero-stiffness modes (an unconstrained mechanism motion)."""
    if fe.nfree > 1500:  # a dense eigenvalue check would cost more than the run; skipped
        return
    _, _, k, _ = fe.matrices(rig0[:, :, 0] * np.array([1, 0, 0, 0, 0])[:, None])  # elastic K only
    ev = np.linalg.eigvalsh(0.5 * (k + k.T))
    scale = np.max(np.abs(ev))
    nzero = int(np.sum(np.abs(ev) < 1e-10 * scale))
    # a joint left free with 'torque' turns the mechanism's own degree of freedom into a zero-stiffness
    # mode of the elastic problem, on purpose (theory.md section 14)
    allowed = min(sum(1 for j in fe.joints if j.elastic == "torque"), len(fe.case["initial"]["angles"]))
    if nzero > allowed:
        raise CaseError("joints", f"the elastic problem has {nzero - allowed} unintended zero-stiffness mode(s): the joints leave the "
                                  "mechanism free to move elastically; clamp the driven ground joint "
                                  "(crank_pivot/base = 'clamp') or lock a joint")


class Prepared:
    """A case made ready to run: FE model, time grid and rigid motion (shared by every model)."""

    def __init__(self, case: dict, *, dt: float | None = None, elements_per_link: int | None = None,
                 out_every: int | None = None):
        t_start = time.perf_counter()
        if elements_per_link is not None:
            case = _with_elements(case, elements_per_link)
        self.case = case
        self.nsteps, self.dt, self.out_every = time_grid(case, dt, out_every)
        self.t = np.linspace(0.0, case["solver"]["t_end"], self.nsteps + 1)
        self.fe = FEModel.from_case(case)
        for name, sp in case["outputs"].items():  # node references must fall on the mesh: check before running
            if isinstance(sp.get("at"), str):
                self.fe.node_ref(sp["at"], f"outputs.{name}.at")
        t0 = time.perf_counter()
        self.rm = rigid_motion(case, self.fe, self.t)
        self.t_rigid = time.perf_counter() - t0
        self.gravity = case["loads"]["gravity"]
        self.rig = self.rm.kernel_samples(self.gravity)
        self._checked = False
        self.q_free, self.q_val = elastic_torque_loads(case, self.fe, self.rm)
        self.coupled = {}
        self.mech = build_mechanism(case)
        self.t_prepare = time.perf_counter() - t_start

    def run(self, model: str | None = None, geometric: str | None = None, *, estimate: bool | None = None,
            diagnose: bool = True, u0=None, v0=None) -> Result:
        """Integrate the elastic equations with one model (``geometric`` overrides
        ``solver.geometric_stiffness`` for a superposition model; ``u0``, ``v0`` (nfree,) an
        initial elastic state other than rest, superposition models only).

        Every run gets the validity report and warnings (:mod:`flexmech_py.guards`);
        ``estimate`` (default: ``solver.error_estimate != "none"``) adds the step-doubling error
        estimate (one more run at 2 dt).  A failed run raises SolverError carrying the partial
        result and, with ``diagnose``, the likely cause (which may cost a short run at dt/2)."""
        model = self.case["solver"]["model"] if model is None else model
        if model not in MODELS:
            raise CaseError("model", f"must be one of {', '.join(MODELS)}, got {model!r}")
        try:
            res = self._run_raw(model, geometric, u0=u0, v0=v0)
        except SolverError as exc:
            if exc.partial is None:
                raise
            guards.check_validity(exc.partial)
            raise guards.failed(self, model, geometric, exc, diagnose=diagnose) from None
        guards.check_validity(res)
        if estimate is None:
            estimate = self.case["solver"].get("error_estimate", "time") != "none"
        res.extra["error_estimate"] = guards.error_estimate(self, res, geometric) if estimate else {"method": "none"}
        return res

    def _run_raw(self, model: str, geometric: str | None, u0=None, v0=None) -> Result:
        t_start = time.perf_counter()
        case, fe = self.case, self.fe
        if model in ("coupled", "nonlinear"):
            if u0 is not None or v0 is not None:
                raise CaseError("model", f"an initial elastic state needs a superposition model, not {model!r}")
            return self._run_coupled(t_start, model)
        if not self._checked:
            check_elastic_problem(fe, self.rig)
            self._checked = True
        sol = dict(case["solver"])
        if geometric is not None:
            sol["geometric_stiffness"] = geometric
        t0 = time.perf_counter()
        am, af_, beta, gamma = integrator_coefficients(sol.get("integrator", "newmark"), sol)
        failure = None
        try:
            uf, vf, af, nf, geo_iters = fe.run(self.rig, model, self.dt, alpha_m=am, alpha_f=af_, beta=beta,
                                               gamma=gamma, out_every=self.out_every, rayleigh=sol["rayleigh"],
                                               q_free=self.q_free, q_val=self.q_val, geometric=sol["geometric_stiffness"],
                                               geo_tol=sol["geometric_tol"], geo_maxit=sol["geometric_maxit"],
                                               div_limit=sol.get("divergence_limit"), full=True,
                                               u0=u0, v0=v0)
        except SolverError as exc:   # keep the frames before the failed step
            if exc.data is None or exc.step is None or exc.step < 1:
                raise
            failure, k = exc, guards.frames_before(exc.step, self.out_every)
            uf, vf, af, nf = (exc.data[n][:, :k] for n in ("uf", "vf", "af", "nf"))
            geo_iters = exc.data["geo_iters"]
        t_kernel = time.perf_counter() - t0
        idx = slice(0, self.out_every * (uf.shape[1] - 1) + 1, self.out_every)
        motion_f = rigid.LinkMotion(**{k: getattr(self.rm.motion, k)[idx]
                                       for k in rigid.LinkMotion.__dataclass_fields__})
        rig_f = self.rm.kernel_samples(self.gravity, idx)
        u_all = fe.expand(uf)
        if sol["geometric_stiffness"] == "none":   # the axial forces of the linear solution, for outputs
            nf = np.array([[fe.el_prop[3, e] / fe.el_prop[0, e]] for e in range(fe.nel)]) * _axial_stretch(fe, u_all, motion_f)
        columns = evaluate_outputs(fe, case["outputs"], u_all, motion_f, self.rm.q[idx], self.rm.qd[idx],
                                   self.rm.qdd[idx], rig_f, model, axial=nf)
        units = {name: output_unit(sp) for name, sp in case["outputs"].items()}
        timing = {"rigid_s": self.t_rigid, "kernel_s": t_kernel,
                  "total_s": self.t_prepare + time.perf_counter() - t_start}
        extra = {"integrator": integrator_summary(sol), "validity": coupled.validity(fe, nf, u_all)}
        if sol["geometric_stiffness"] != "none":
            extra["geometric_stiffness"] = {"source": sol["geometric_stiffness"], "iterations": int(geo_iters),
                                            "mean_per_step": geo_iters / self.nsteps}
        res = Result(case=case, model=model, t=self.t[idx], columns=columns, units=units, fe=fe,
                     q=self.rm.q[idx], qd=self.rm.qd[idx], qdd=self.rm.qdd[idx], u=u_all, v=fe.expand(vf),
                     a=fe.expand(af), rig=rig_f, nsteps=self.nsteps, dt=self.dt, timing=timing, extra=extra,
                     axial=nf)
        res.curvature = lambda li, frac: link_curvature(fe, u_all, motion_f.phi[:, li], li, frac)
        return guards.partial_or(res, failure, sol["geometric_stiffness"])


    def _run_coupled(self, t_start: float, model: str) -> Result:
        """The one-pass coupled model (one chord frame per link) or the nonlinear co-rotational model
        (one per element); the rigid-body solution on the grid is their reference."""
        case, fe, sol = self.case, self.fe, self.case["solver"]
        if model not in self.coupled:
            self.coupled[model] = CoupledModel.from_case(case, fe, split=(model == "nonlinear"))
        cm = self.coupled[model]
        q0, v0 = cm.initial_state(self.rm.q[0], self.rm.qd[0], self.mech)
        cval = cm.constraint_values(self.t, self.rm.q, self.rm.qd, self.rm.qdd, self.mech)
        am, af_, beta, gamma = integrator_coefficients(sol.get("integrator", "newmark"), sol)
        t0 = time.perf_counter()
        failure = None
        try:
            qf, vf, af, lf, ef, iters = cm.run(q0, v0, self.t, cval, self.dt, alpha_m=am, alpha_f=af_, beta=beta,
                                               gamma=gamma, out_every=self.out_every, tol=sol["newton_tol"],
                                               maxit=sol["newton_maxit"], gravity=self.gravity, rayleigh=sol["rayleigh"],
                                               div_limit=sol.get("divergence_limit"))
        except SolverError as exc:   # keep the frames before the failed step
            if exc.data is None or exc.step is None or exc.step < 1:
                raise
            failure, k = exc, guards.frames_before(exc.step, self.out_every)
            qf, vf, af, lf, ef = (exc.data[n][:, :k] for n in ("qf", "vf", "af", "lf", "ef"))
            iters = exc.data["iters"]
        t_kernel = time.perf_counter() - t0
        idx = slice(0, self.out_every * (qf.shape[1] - 1) + 1, self.out_every)
        ref = rigid.LinkMotion(**{k: getattr(self.rm.motion, k)[idx] for k in rigid.LinkMotion.__dataclass_fields__})
        chord = coupled.chord_motion(cm, qf, vf, af)
        u_dev = coupled.deviation(cm, qf, ref)
        rig_chord = np.asfortranarray(np.stack([chord.phi, chord.omega, chord.alpha, chord.ax - self.gravity[0],
                                                chord.ay - self.gravity[1]]).transpose(0, 2, 1))
        columns = evaluate_outputs(fe, case["outputs"], u_dev, ref, self.rm.q[idx], self.rm.qd[idx], self.rm.qdd[idx],
                                   rig_chord, "classic", joint_motion=chord,
                                   curvature=lambda li, frac: coupled.curvature(cm, qf, li, frac),
                                   axial=(axial := coupled.axial_forces(cm, qf)))
        units = {name: output_unit(sp) for name, sp in case["outputs"].items()}
        energy = {"energy_kinetic": ef[0], "energy_potential": ef[1], "work_inputs": ef[2]}
        for k, y in energy.items():
            columns[k], units[k] = y, "J"
        columns["newton_iterations"], units["newton_iterations"] = ef[3], "1"
        for (_, _, kind, _), lam in zip(cm.constraints, lf):
            if kind == "drive":   # the torque the kinematic drive applies (the constraint torque is -lambda)
                columns["drive_torque"], units["drive_torque"] = -lam, "N m"
        timing = {"rigid_s": self.t_rigid, "kernel_s": t_kernel,
                  "total_s": self.t_prepare + time.perf_counter() - t_start}
        extra = {"integrator": integrator_summary(sol),
                 "coupled": coupled.diagnostics(cm, qf, ef, chord, ref, iters, self.nsteps),
                 "validity": coupled.validity(fe, axial, u_dev)}
        res = Result(case=case, model=model, t=self.t[idx], columns=columns, units=units, fe=fe,
                     q=self.rm.q[idx], qd=self.rm.qd[idx], qdd=self.rm.qdd[idx], u=u_dev, v=np.zeros_like(u_dev),
                     a=np.zeros_like(u_dev), rig=rig_chord, nsteps=self.nsteps, dt=self.dt, timing=timing, extra=extra,
                     axial=axial)
        res.curvature = lambda li, frac: coupled.curvature(cm, qf, li, frac)
        return guards.partial_or(res, failure, "coupled", cm=cm)


def integrator_summary(sol: dict) -> dict:
    """summary.json's ``integrator`` entry: the name, its case parameter(s) and the kernel's
    (am, af, beta, gamma), and the divergence limit [m]."""
    name = sol.get("integrator", "newmark")
    am, af, beta, gamma = integrator_coefficients(name, sol)
    params = {k: sol[k] for k in ("hht_alpha", "rho_inf") if k in sol}
    return {"name": name, **params, "am": am, "af": af, "beta": beta, "gamma": gamma,
            "divergence_limit_m": sol.get("divergence_limit")}


def _axial_stretch(fe, u_all, motion) -> np.ndarray:
    """(nel, nf) elongation p2 - p1 [m] of every element in its link frame."""
    out = np.empty((fe.nel, u_all.shape[1]))
    for e in range(fe.nel):
        li = fe.el_link[e] - 1
        c, s = np.cos(motion.phi[:, li]), np.sin(motion.phi[:, li])
        d = u_all[fe.el_dof[:, e] - 1]
        out[e] = (c * d[3] + s * d[4]) - (c * d[0] + s * d[1])
    return out


def simulate(case: dict, model: str | None = None, *, dt: float | None = None,
             elements_per_link: int | None = None, out_every: int | None = None) -> Result:
    """Run one case with one superposition model and return a :class:`Result`.

    ``case`` is a resolved case (:func:`flexmech_py.load_case`); ``model`` one of
    ``hac``, ``classic``, ``classic-translational`` (default: the case's
    ``solver.model``); ``dt`` [s], ``elements_per_link`` and ``out_every`` override the case.
    """
    return Prepared(case, dt=dt, elements_per_link=elements_per_link, out_every=out_every).run(model)


def simulate_models(case: dict, models=SUPERPOSITION_MODELS, **kw) -> dict:
    """Run several models of one case on one shared rigid motion: {model: Result}."""
    prep = Prepared(case, **kw)
    return {m: prep.run(m) for m in models}


def _with_elements(case: dict, n: int) -> dict:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise CaseError("elements_per_link", f"must be a whole number >= 1, got {n!r}")
    c = copy.deepcopy(case)
    c["mesh"]["elements_per_link"] = int(n)
    for ln in c["links"]:
        ln["elements"] = int(n)
    return c
