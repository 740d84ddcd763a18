"""Run a case: rigid-body motion first, then the superposition KED model in Fortran."""

from __future__ import annotations

import copy
import math
import time

import numpy as np

from .case import MODELS, SUPERPOSITION_MODELS, Case, integrator_coefficients
from .errors import CaseError, MechanismError, SolverError
from . import coupled, guards
from . import coupled_outputs as cpl_out
from .coupled import CoupledModel
from .mechanism import MotionSource, prepare_motion
from .mechanism.motion import LinkMotion, RigidMotion
from .model import FEModel
from .outputs import evaluate_outputs, link_curvature, output_unit
from .reactions import ModelReactions
from .results import Result

__all__ = ["simulate", "simulate_models", "Prepared", "motion_source", "rigid_motion", "time_grid", "RigidMotion"]


def motion_source(case: dict) -> MotionSource:
    """The rigid-body motion of a resolved case as a function of time (flexmech_py.mechanism.motion)."""
    setup = prepare_motion(case.mechanism, case["loads"]["gravity"])
    sol = case["solver"]
    return MotionSource(setup, rtol=sol["rigid_rtol"], atol=sol["rigid_atol"], hmax=sol["t_end"])


def rigid_motion(case: dict, t: np.ndarray) -> RigidMotion:
    """The rigid-body motion of a case on the grid t [s]."""
    return motion_source(case)(np.asarray(t, float))


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


def elastic_torque_loads(case: dict, fe: FEModel, rm: RigidMotion, rig: np.ndarray | None = None):
    """The force drives' torques and forces as generalized forces on the free elastic DOFs: (q_free,
    q_val) or (None, None); ``rig`` the samples of rm (fe.rig_samples) when the model has slave relations.

    A torque on a revolute joint acts on the elastic rotation of its body b at the joint, its reaction
    on body a's; a force on a prismatic joint acts on the joint's along DOF (the elastic slide: the
    force on b and its reaction on a at the contact point do the work F ds).  Assembled over all DOFs
    (constrained ones included), projected onto the masters of slaved DOFs and restricted to the free
    DOFs; rows that vanish identically (torques on clamped DOFs, or action and reaction on one locked
    rotation) are dropped, so they cost nothing.
    """
    mech = case.mechanism
    forced = [d.joint for d in mech.drives if not d.kinematic]
    if not forced:
        return None, None
    q_all = drive_loads(fe, rm, forced)
    if fe.slaving is not None:
        q_all = fe.slaving.project(q_all, fe.rig_samples(rm, case["loads"]["gravity"]) if rig is None else rig)
    qf = fe.restrict(q_all)
    rows = np.flatnonzero(np.any(qf != 0.0, axis=1))
    if rows.size == 0:
        return None, None
    return (rows + 1).astype(np.int32), np.asfortranarray(qf[rows])


def drive_loads(fe: FEModel, rm: RigidMotion, joints) -> np.ndarray:
    """(ndof, N) the generalized forces of the drives of ``joints`` over all DOFs: a torque on the
    elastic rotations of its joint's bodies (+ on b, - on a), a force on its joint's along DOF."""
    mech = fe.case.mechanism
    slides = {sl.joint.name: sl for sl in fe.slides}
    q_all = np.zeros((fe.ndof, rm.t.size))
    for name in joints:
        f = rm.drive_force(name)
        if name in slides:
            q_all[slides[name].dof] += f
            continue
        a, b = mech.joint_points(mech.joint(name))
        db, da = fe.rotation_dof(b), fe.rotation_dof(a)
        if db is not None:
            q_all[db] += f
        if da is not None:
            q_all[da] -= f
    return q_all


def check_elastic_problem(fe: FEModel, rig0: np.ndarray, dof: int | None = None) -> None:
    """Reject an elastic problem with zero-stiffness modes (an unconstrained mechanism motion);
    ``dof`` the mechanism's degrees of freedom (at most that many joints can be left free with
    'torque' on purpose)."""
    if fe.nfree > 1500:  # a dense eigenvalue check would cost more than the run; skipped
        return
    # squared natural frequencies of M and the elastic K alone (the rigid sample's angle only): a
    # zero-stiffness mode sits at round-off (~1e-16 of the largest), a real mode above (w_1/w_max)^2
    # ~ 1e-10 even at 256 elements per link; K's own eigenvalues spread far more (axial vs bending)
    try:
        ev = fe.squared_frequencies(rig0[:, :, 0] * np.array([1, 0, 0, 0, 0])[:, None])
    except np.linalg.LinAlgError:
        turning = [p.name for p in fe.parts.values() if p.inertia == 0.0 and fe.free_of[p.dofs[2]] > 0]
        if turning:
            raise CaseError(f"bodies.{turning[0]}.inertia", "is 0 but the body can turn in the elastic problem of "
                                                           "the superposition models (its joints leave its rotation "
                                                           "free): give its rotary inertia about its centre of mass") from None
        raise CaseError("links", "the mass matrix is not positive definite: every link needs density > 0 and area > 0") from None
    scale = np.max(np.abs(ev))
    nzero = int(np.sum(np.abs(ev) < 1e-13 * scale))
    # a joint left free with 'torque' (a prismatic one with 'force') turns the mechanism's own degree of
    # freedom into a zero-stiffness mode of the elastic problem, on purpose (theory.md section 14)
    mech = fe.case.mechanism
    released = sum(1 for j in mech.joints if mech.condition(j) in ("torque", "force"))
    allowed = min(released, released if dof is None else dof)
    if nzero > allowed:
        raise CaseError("joints", f"the elastic problem has {nzero - allowed} unintended zero-stiffness mode(s): the joints leave the "
                                  "mechanism free to move elastically; clamp the driven ground joint "
                                  "(crank_pivot/base = 'clamp') or lock a joint")


class Prepared:
    """A case made ready to run: FE model, time grid and rigid motion (shared by every model).

    The superposition models run in chunks of ``chunk_steps`` steps (rounded up to a multiple of the
    output decimation): the rigid motion is sampled and the kernel called per chunk, continuing from
    the last state, so memory is O(frames), not O(steps).  ``rm``, ``rig``, ``q_free`` and ``q_val``
    (the rigid motion on the whole grid) are computed when first used (the coupled models use them)."""

    CHUNK_STEPS = 10_000

    def __init__(self, case: dict, *, dt: float | None = None, elements_per_link: int | None = None,
                 out_every: int | None = None, chunk_steps: int | None = None):
        t_start = time.perf_counter()
        case = case if isinstance(case, Case) else Case(case)   # a resolved case that travelled as a plain dict
        if elements_per_link is not None:
            case = _with_elements(case, elements_per_link)
        self.case = case
        self.nsteps, self.dt, self.out_every = time_grid(case, dt, out_every)
        self._t = None
        chunk = self.CHUNK_STEPS if chunk_steps is None else int(chunk_steps)
        self.chunk_steps = self.out_every * max(1, math.ceil(chunk / self.out_every))
        self._fe = None
        t0, c0 = time.perf_counter(), time.thread_time()
        self.source = motion_source(case)
        self.setup = self.source.setup
        self.rigid_failure = None
        try:
            self.rm_frames = self.source(self.times(0, self.nsteps, self.out_every))   # the motion at the output frames
        except MechanismError as exc:
            self._stop_at(exc)
        self.t_rigid, self.t_rigid_cpu = time.perf_counter() - t0, time.thread_time() - c0
        self.gravity = case["loads"]["gravity"]
        self._checked = False
        self._full = None
        self._rm = None
        self.coupled = {}
        self.t_prepare = time.perf_counter() - t_start

    def _stop_at(self, exc: MechanismError) -> None:
        """The rigid motion reached a singular position or an assembly limit: keep the grid up to the last
        output frame before it (every model runs that far and its result is marked partial), or re-raise
        when not even two frames are left."""
        frames = exc.partial
        if frames is None or frames.t.size < 2:
            exc.partial = None
            raise exc
        n_new = (frames.t.size - 1) * self.out_every
        t_new = float(self.times(n_new, n_new)[0])
        self.case = Case(self.case, solver=dict(self.case["solver"], t_end=t_new))
        self.nsteps, self.rm_frames, self.rigid_failure = n_new, frames, exc
        exc.partial = None

    def times(self, i0: int, i1: int, every: int = 1) -> np.ndarray:
        """Step times t_i = i t_end/N [s] for i = i0, i0 + every, ..., i1 (bit-equal to
        linspace(0, t_end, N + 1)[i0:i1 + 1:every]) without holding the whole grid."""
        t_end = float(self.case["solver"]["t_end"])
        i = np.arange(i0, i1 + 1, every)
        t = i * (t_end / self.nsteps)
        if i.size and i[-1] == self.nsteps:
            t[-1] = t_end
        return t

    @property
    def t(self) -> np.ndarray:
        """(N+1,) step times [s] (computed on first use)."""
        if self._t is None:
            self._t = np.linspace(0.0, self.case["solver"]["t_end"], self.nsteps + 1)
        return self._t

    @property
    def fe(self) -> FEModel:
        """The superposition models' FE model (built on first use; the coupled models build their own)."""
        if self._fe is None:
            fe = FEModel.from_case(self.case)
            for name, sp in self.case["outputs"].items():  # node references must fall on the mesh
                if isinstance(sp.get("at"), str):
                    fe.point_ref(sp["at"], f"outputs.{name}.at")
            self._fe = fe
        return self._fe

    def _full_grid(self):
        if self._full is None:
            rm = self.rm
            rig = self.fe.rig_samples(rm, self.gravity)
            self._full = (rm, rig) + elastic_torque_loads(self.case, self.fe, rm, rig)
        return self._full

    @property
    def rm(self) -> RigidMotion:
        """Rigid motion on the whole time grid (computed on first use)."""
        if self._full is not None:
            return self._full[0]
        if self._rm is None:
            self._rm = self.source(self.t)
        return self._rm

    @property
    def rig(self) -> np.ndarray:
        """Kernel samples (5, nlinks, nsteps+1) on the whole grid (computed on first use)."""
        return self._full_grid()[1]

    @rig.setter
    def rig(self, value) -> None:
        """Replace the kernel samples on the whole grid (e.g. a frozen configuration in a test);
        every later superposition run uses them."""
        rm, _, qf, qv = self._full_grid()
        self._full = (rm, np.asfortranarray(value, float), qf, qv)

    @property
    def q_free(self):
        return self._full_grid()[2]

    @property
    def q_val(self):
        return self._full_grid()[3]

    def _chunk(self, i0: int, i1: int):
        """(rig, q_free, q_val) of steps i0..i1 (grid samples i0..i1 inclusive)."""
        if self._full is not None or (i0 == 0 and i1 == self.nsteps):
            _, rig, qf, qv = self._full_grid()
            if qv is not None:
                qv = np.asfortranarray(qv[:, i0:i1 + 1])
            return np.asfortranarray(rig[:, :, i0:i1 + 1]), qf, qv
        rm = self.source(self.times(i0, i1))
        rig = self.fe.rig_samples(rm, self.gravity)
        return (rig,) + elastic_torque_loads(self.case, self.fe, rm, rig)

    def coarsened(self):
        """This case on every second step of its grid (the same rigid solution), for the step-doubling
        error estimate: output frames on this run's frames (every frame when out_every is even, every
        second one when it is odd; the grid then ends at the last frame both share).  None when the
        coarse grid would have fewer than two frames."""
        oe, n = self.out_every, self.nsteps
        if oe % 2 == 0:
            oc, nc = oe // 2, n // 2
        else:
            oc, nc = oe, oe * (n // (2 * oe))
        if nc < oc or nc < 1:
            return None
        pc = copy.copy(self)
        if 2 * nc != n:   # the grid ends earlier: at the fine grid's step 2 nc
            pc.case = Case(self.case, solver=dict(self.case["solver"], t_end=float(self.times(2 * nc, 2 * nc)[0])))
        pc.nsteps, pc.dt, pc.out_every = nc, 2.0 * self.dt, oc
        pc.chunk_steps = oc * max(1, math.ceil(self.chunk_steps / 2 / oc))
        pc._t, pc._full, pc._rm = None, None, None
        if oe % 2 == 0:
            pc.rm_frames = self.rm_frames
        else:
            sel = slice(0, 2 * (nc // oc) + 1, 2)   # coarse frame k is fine frame 2 k
            pc.rm_frames = self.rm_frames.select(sel)
        return pc

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
        self._report_mechanism(res)
        if estimate is None:
            estimate = self.case["solver"].get("error_estimate", "time") != "none"
        res.extra["error_estimate"] = guards.error_estimate(self, res, geometric) if estimate else {"method": "none"}
        if self.rigid_failure is not None:
            raise guards.rigid_failure(res, self.rigid_failure)
        return res

    def _report_mechanism(self, res: Result) -> None:
        """summary.json's ``mechanism`` entry (degrees of freedom, mode, the joints of q, how far the
        assembly moved the drawn points) and the mechanism's own warnings beside the validity ones."""
        st = self.setup
        floor = 1e-12 * st.packed.lref            # the assembly's own tolerance: below it, nothing moved
        point, moved = st.max_moved
        if moved <= floor:
            point, moved = "", 0.0
        res.extra["mechanism"] = {"degrees_of_freedom": st.dof, "rigid_motion": st.mode, "coordinates": st.primary,
                                  "assembly": {"max_moved_m": moved, "point": point,
                                               "moved_m": {k: v for k, v in st.moved.items() if v > floor}},
                                  "rigid_steps": self.source.stats.get("steps", 0)}
        res.extra["warnings"] = list(st.warnings) + list(res.extra.get("warnings", []))

    def _run_raw(self, model: str, geometric: str | None, u0=None, v0=None) -> Result:
        t_start = time.perf_counter()
        if model in ("coupled", "nonlinear"):
            if u0 is not None or v0 is not None:
                raise CaseError("model", f"an initial elastic state needs a superposition model, not {model!r}")
            return self._run_coupled(t_start, model)
        case, fe = self.case, self.fe
        if not self._checked:
            check_elastic_problem(fe, fe.rig_samples(self.rm_frames, self.gravity, slice(0, 1)), self.setup.dof)
            self._checked = True
        sol = dict(case["solver"])
        if geometric is not None:
            sol["geometric_stiffness"] = geometric
        am, af_, beta, gamma = integrator_coefficients(sol.get("integrator", "newmark"), sol)
        oe, nfr = self.out_every, self.nsteps // self.out_every + 1
        uf, vf, af = (np.empty((fe.nfree, nfr), order="F") for _ in range(3))
        nf, geo_iters = np.zeros((fe.nel, nfr), order="F"), 0
        u, v, a, p = u0, v0, None, None
        t_kernel = t_samples = c_kernel = 0.0
        failure, nvalid = None, nfr
        for i0 in range(0, self.nsteps, self.chunk_steps):
            i1 = min(i0 + self.chunk_steps, self.nsteps)
            ts = time.perf_counter()
            rig, q_free, q_val = self._chunk(i0, i1)
            t0, c0 = time.perf_counter(), time.thread_time()
            f0 = i0 // oe                       # a chunk's first frame is the previous chunk's last
            try:
                out = fe.run(rig, model, self.dt, alpha_m=am, alpha_f=af_, beta=beta, gamma=gamma, out_every=oe,
                             rayleigh=sol["rayleigh"], q_free=q_free, q_val=q_val, u0=u, v0=v, a0=a, p0=p,
                             t0=i0 * self.dt, geometric=sol["geometric_stiffness"], geo_tol=sol["geometric_tol"],
                             geo_maxit=sol["geometric_maxit"], div_limit=sol.get("divergence_limit"), full=True)
            except SolverError as exc:   # keep the frames before the failed step
                if exc.data is None or exc.step is None or exc.step < 1:
                    raise
                k = guards.frames_before(exc.step, oe)
                for arr, name in ((uf, "uf"), (vf, "vf"), (af, "af"), (nf, "nf")):
                    arr[:, f0:f0 + k] = exc.data[name][:, :k]
                geo_iters += int(exc.data["geo_iters"])
                exc.step += i0                  # the chunk's step -> the run's step (exc.time is already global)
                failure, nvalid = exc, f0 + k
                break
            finally:
                t_kernel += time.perf_counter() - t0
                c_kernel += time.thread_time() - c0
                t_samples += t0 - ts
            f = slice(f0, i1 // oe + 1)
            uf[:, f], vf[:, f], af[:, f], nf[:, f] = out[:4]
            geo_iters += int(out[4])
            lr = fe.last_run                    # the state at step i1: continue from it
            u, v, a, p = lr["u"], lr["v"], lr["a"], lr["p"]
        if nvalid < nfr:
            uf, vf, af, nf = uf[:, :nvalid], vf[:, :nvalid], af[:, :nvalid], nf[:, :nvalid]
        sel = slice(0, nvalid)
        rmf = self.rm_frames
        motion_f = rmf.motion.select(sel)
        rig_f = fe.rig_samples(rmf, self.gravity, sel)
        u_all, v_all, a_all = fe.expand_state(uf, vf, af, rig_f)
        if sol["geometric_stiffness"] == "none":   # the axial forces of the linear solution, for outputs
            nf = np.array([[fe.el_prop[3, e] / fe.el_prop[0, e]] for e in range(fe.nel)]) * _axial_stretch(fe, u_all, motion_f)
        rm_f = rmf.select(sel)
        reactions = ModelReactions(fe, model, rm_f, rig_f, (u_all, v_all, a_all), sol, nf)
        columns = evaluate_outputs(fe, case["outputs"], u_all, motion_f, rig_f, model, rm=rm_f, axial=nf,
                                   rates=(v_all, a_all), reactions=reactions)
        units = {name: output_unit(sp, case) for name, sp in case["outputs"].items()}
        self.last_cpu = {"rigid_cpu_s": self.t_rigid_cpu, "kernel_cpu_s": c_kernel, "rigid_samples_s": t_samples}
        timing = {"rigid_s": self.t_rigid, "kernel_s": t_kernel,
                  "total_s": self.t_prepare + time.perf_counter() - t_start}
        extra = {"integrator": integrator_summary(sol), "validity": coupled.validity(fe, nf, u_all)}
        if sol["geometric_stiffness"] != "none":
            extra["geometric_stiffness"] = {"source": sol["geometric_stiffness"], "iterations": int(geo_iters),
                                            "mean_per_step": geo_iters / self.nsteps}
        if reactions.checked:
            extra["reactions"] = reactions.summary()
        res = Result(case=case, model=model, t=rmf.t[sel], columns=columns, units=units, fe=fe,
                     q=rmf.q[sel], qd=rmf.qd[sel], qdd=rmf.qdd[sel], u=u_all, v=v_all,
                     a=a_all, rig=rig_f, nsteps=self.nsteps, dt=self.dt, timing=timing, extra=extra,
                     axial=nf, motion=motion_f)
        res.reactions = reactions
        res.curvature = lambda li, frac: link_curvature(fe, u_all, motion_f.phi[:, li], li, frac)
        return guards.partial_or(res, failure, sol["geometric_stiffness"])


    def _run_coupled(self, t_start: float, model: str) -> Result:
        """The one-pass coupled model (one chord frame per flexible link) or the nonlinear co-rotational
        model (one per element); the rigid-body solution on the grid is their reference."""
        case, sol = self.case, self.case["solver"]
        if model not in self.coupled:
            self.coupled[model] = CoupledModel.from_case(case, split=(model == "nonlinear"))
        cm = self.coupled[model]
        q0, v0 = cm.initial_state(self.rm.select(slice(0, 1)))
        cval = cm.constraint_values(self.rm)
        am, af_, beta, gamma = integrator_coefficients(sol.get("integrator", "newmark"), sol)
        t0, c0 = time.perf_counter(), time.thread_time()
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
        t_kernel, c_kernel = time.perf_counter() - t0, time.thread_time() - c0
        idx = slice(0, self.out_every * (qf.shape[1] - 1) + 1, self.out_every)
        rmf = self.rm.select(idx)
        ref = rmf.motion
        fr = cpl_out.model_frames(cm, qf, vf, af, lf, self.t[idx], self.gravity, sol["rayleigh"])
        u_dev = cpl_out.deviation(cm, qf, ref)
        axial = cpl_out.axial_forces(cm, qf)
        columns = cpl_out.evaluate(cm, case["outputs"], fr, rmf, ref, u_dev, axial, superposition_fe=lambda: self.fe)
        units = {name: output_unit(sp, case) for name, sp in case["outputs"].items()}
        energy = {"energy_kinetic": ef[0], "energy_potential": ef[1], "work_inputs": ef[2]}
        for k, y in energy.items():
            columns[k], units[k] = y, "J"
        columns["newton_iterations"], units["newton_iterations"] = ef[3], "1"
        columns.update(_drive_columns(cm, fr, units))
        self.last_cpu = {"rigid_cpu_s": self.t_rigid_cpu, "kernel_cpu_s": c_kernel, "rigid_samples_s": 0.0}
        timing = {"rigid_s": self.t_rigid, "kernel_s": t_kernel,
                  "total_s": self.t_prepare + time.perf_counter() - t_start}
        extra = {"integrator": integrator_summary(sol),
                 "coupled": cpl_out.diagnostics(cm, fr, ef, rmf, iters, self.nsteps, cval[:, :, idx]),
                 "validity": coupled.validity(cm.mesh, axial, u_dev)}
        rig_chord = np.asfortranarray(np.stack([fr.chord.phi, fr.chord.omega, fr.chord.alpha,
                                                fr.chord.ax - self.gravity[0],
                                                fr.chord.ay - self.gravity[1]]).transpose(0, 2, 1))
        res = Result(case=case, model=model, t=self.t[idx], columns=columns, units=units, fe=cm.mesh,
                     q=rmf.q, qd=rmf.qd, qdd=rmf.qdd, u=u_dev, v=np.zeros_like(u_dev),
                     a=np.zeros_like(u_dev), rig=rig_chord, nsteps=self.nsteps, dt=self.dt, timing=timing, extra=extra,
                     axial=axial, motion=ref)
        res.curvature = lambda li, frac: cpl_out.curvature(cm, qf, li, frac)
        return guards.partial_or(res, failure, "coupled", cm=cm)


def _drive_columns(cm, fr, units: dict) -> dict:
    """The kinematic drives' torque (force on a prismatic joint) from the model's multipliers, as extra
    columns: ``drive_torque`` (``drive_force``) for a single drive, ``drive_torque_<joint>`` for
    several; a name the case's outputs already use is left to them."""
    kin = [d for d in cm.case.mechanism.drives if d.kinematic]
    out = {}
    for d in kin:
        angular = cm.case.mechanism.joint(d.joint).angular
        name = ("drive_torque" if angular else "drive_force") + ("" if len(kin) == 1 else f"_{d.joint}")
        if name in cm.case["outputs"]:
            continue
        out[name] = cpl_out.drive_force(cm, fr, d.joint)
        units[name] = "N m" if angular else "N"
    return out


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
        if not ln.get("rigid"):
            ln["elements"] = int(n)
    return c
