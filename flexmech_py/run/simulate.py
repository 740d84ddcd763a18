"""Run a case: rigid-body motion first, then the superposition KED model in Fortran."""

from __future__ import annotations

import copy
import functools
import math
import time

import numpy as np

from ..case import Case, integrator_coefficients, integrator_of, with_elements
from ..base.families import AUTO, MODELS, SUPERPOSITION_MODELS, family
from ..base.errors import CaseError, MechanismError, SolverError
from ..checks import guards, step_doubling
from ..base import notices
from ..models.constrained import outputs as cpl_out
from ..mechanism.control import refuse_superposition, rigid_pack
from ..models.constrained.coupled import CoupledModel
from ..mechanism import MotionSource, prepare_motion
from ..mechanism.motion import RigidMotion
from ..models.superposition.model import FEModel
from ..models.motion_tap import MotionTap
from ..models.superposition.outputs import DeflectionReference, evaluate_outputs, joint_at_joint, output_unit
from ..models.superposition.reactions import ModelReactions
from .blocks import (Accumulated, add_control_columns, after_first, coupled_curvature, drive_column_joints,
                     drive_columns, integrator_summary, last_values)
from ..models.superposition.loads import (axial_stretch, check_elastic_problem, elastic_torque_loads,
                                          superposition_curvature, superposition_node_curvatures)
from .results import Result
from ..base.sizes import check_mesh, check_steps

__all__ = ["simulate", "simulate_models", "Prepared", "motion_source", "rigid_motion", "time_grid", "RigidMotion"]


def motion_source(case: dict) -> MotionSource:
    """The rigid-body motion of a resolved case as a function of time (flexmech_py.mechanism.motion)."""
    setup = prepare_motion(case.mechanism, case["loads"]["gravity"])
    sol = case["solver"]
    return MotionSource(setup, rtol=sol["rigid_rtol"], atol=sol["rigid_atol"], hmax=sol["t_end"],
                        controls=rigid_pack(case, setup.packed, sol["dt"]))


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
    check_steps(nsteps, sol["t_end"], dt)
    return nsteps, sol["t_end"] / nsteps, out_every


#: floats of frame data one chunk may hold (about 32 MB): bounds a chunk's frames on fine meshes
FRAME_BUDGET = 4_000_000
#: steps of a run's first chunk; every next chunk has twice the steps of the last, up to chunk_steps
FIRST_CHUNK_STEPS = 256
#: chunks of rigid motion and kernel samples a Prepared remembers (shared by runs advanced in step)
MEMO_CHUNKS = 2


class Prepared:
    """A case made ready to run: time grid, rigid-motion source and, on first use, FE model.

    A run goes chunk by chunk (:meth:`blocks`): per chunk the rigid motion is sampled, the Fortran
    loop continues from the state the last chunk left and the frames are evaluated into a *block*
    (a Result over those frames), so a run of any length holds one chunk at a time.  The first chunk
    has FIRST_CHUNK_STEPS steps and each next one twice the last, up to CHUNK_STEPS (rounded up to a
    multiple of the output decimation; at most FRAME_BUDGET floats of frames); a ``chunk_steps``
    given fixes every chunk at that size.  The results do not depend on the chunking.  :meth:`run` keeps every frame (a Result in memory), :meth:`stream`
    writes them to files as they come (:mod:`flexmech_py.run.runner`).  ``rm``, ``rig``, ``q_free`` and
    ``q_val`` (the rigid motion on the whole grid) and ``rm_frames`` (at the output frames) are
    computed when first used, for the studies that need them."""

    CHUNK_STEPS = 10_000

    def __init__(self, case: dict, *, dt: float | None = None, elements_per_link: int | None = None,
                 out_every: int | None = None, chunk_steps: int | None = None):
        t_start = time.perf_counter()
        case = case if isinstance(case, Case) else Case(case)   # a resolved case that travelled as a plain dict
        if elements_per_link is not None:
            case = with_elements(case, elements_per_link)
        self.case = case
        self.nsteps, self.dt, self.out_every = time_grid(case, dt, out_every)
        self._t = None
        chunk = self.CHUNK_STEPS if chunk_steps is None else int(chunk_steps)
        self.chunk_steps = self.out_every * max(1, math.ceil(chunk / self.out_every))
        self.first_chunk_steps = FIRST_CHUNK_STEPS if chunk_steps is None else self.chunk_steps
        self._fe = None
        self.source = motion_source(case)
        self.setup = self.source.setup
        self.gravity = case["loads"]["gravity"]
        self.elastic_checked = False
        self._full = None
        self._rm = None
        self._rm_frames = None
        self.coupled = {}
        self.last_cpu = {}
        self._memo = {}
        self.taps: list = []          # MotionTaps fed with this run's rigid motion (share_motion)
        self.tap = None               # the MotionTap this run takes its rigid motion from
        self.t_prepare = time.perf_counter() - t_start

    @property
    def frames(self) -> int:
        """Number of output frames of a run that completes."""
        return self.nsteps // self.out_every + 1

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
    def rm_frames(self) -> RigidMotion:
        """Rigid motion at the output frames (computed on first use)."""
        if self._rm_frames is None:
            self._rm_frames = self.source(self.times(0, self.nsteps, self.out_every))
        return self._rm_frames

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

    def coarsened(self):
        """This case on every second step of its grid (the same rigid solution, followed by a source of
        its own), for the step-doubling error estimate: output frames on this run's frames (every frame
        when out_every is even, every second one when it is odd; the grid then ends at the last frame
        both share).  None when the coarse grid would have fewer than two frames."""
        nc, oc = step_doubling.coarse_grid(self.nsteps, self.out_every)
        if nc < oc or nc < 1:
            return None
        pc = copy.copy(self)
        if 2 * nc != self.nsteps:   # the grid ends earlier: at the fine grid's step 2 nc
            pc.case = Case(self.case, solver=dict(self.case["solver"], t_end=float(self.times(2 * nc, 2 * nc)[0])))
        pc.nsteps, pc.dt, pc.out_every = nc, 2.0 * self.dt, oc
        pc.chunk_steps = oc * max(1, math.ceil(self.chunk_steps / 2 / oc))
        pc._t, pc._full, pc._rm, pc._rm_frames = None, None, None, None
        pc.source = self.source.fork()
        pc.coupled, pc._memo, pc.taps, pc.tap = {}, {}, [], None
        return pc

    def thinned(self, k: int):
        """This case with an output frame at every k-th of this grid's frames (the grid ends at the last of
        them), for a run that is compared at fewer frames (the error budget's probes)."""
        oe = self.out_every * int(k)
        n = oe * (self.nsteps // oe)
        if k <= 1 or n < oe:
            return self
        pt = copy.copy(self)
        if n != self.nsteps:
            pt.case = Case(self.case, solver=dict(self.case["solver"], t_end=float(self.times(n, n)[0])))
        pt.nsteps, pt.out_every = n, oe
        pt.chunk_steps = oe * max(1, math.ceil(self.chunk_steps / oe))
        pt._t, pt._full, pt._rm, pt._rm_frames = None, None, None, None
        pt.source = self.source.fork()
        pt.coupled, pt._memo, pt.taps, pt.tap = {}, {}, [], None
        return pt

    def remeshed(self, case):
        """This prepared run (the same time grid, its own rigid-motion source) on the mesh of ``case``,
        a copy of this run's case with other element counts (the error budget's probe mesh); the
        mechanism's elastic problem was checked on this run's mesh."""
        pm = copy.copy(self)
        pm.case = case
        pm._fe, pm._full, pm._rm, pm._rm_frames = None, None, None, None
        pm.source = self.source.fork()
        pm.coupled, pm._memo, pm.taps, pm.tap = {}, {}, [], None
        pm._checked = True
        return pm

    def share_motion(self, other, ratio: int) -> None:
        """Let ``other`` (this case on every ``ratio``-th step of this grid, not started: a step-doubling
        or probe run) take its rigid motion from the chunks this run samples instead of computing it
        again (:mod:`flexmech_py.models.motion_tap`): its blocks then yield None while it waits for this run."""
        other.tap = MotionTap(ratio)
        self.taps.append(other.tap)

    def end_shared_motion(self) -> None:
        """This run samples no more: the runs that take their motion from it stop where it stopped."""
        for tap in self.taps:
            tap.closed = True
        self.taps = []

    def rerun(self, case: dict, dt: float, out_every: int, model: str, geometric: str | None = None):
        """(its step, its blocks): ``model`` run on another ``case`` (the same mechanism) or step, as
        the checks ask for evidence (guards: the failure again at dt/2); the run hands the checks this
        function so that they never build a run themselves."""
        other = Prepared(case, dt=dt, out_every=out_every)
        return other.dt, other.blocks(model, geometric)

    # ------------------------------------------------------------------ runs
    def run(self, model: str | None = None, geometric: str | None = None, *, estimate: bool | None = None,
            diagnose: bool = True, u0=None, v0=None) -> Result:
        """Integrate the elastic equations with one model and keep every frame (``geometric`` overrides
        ``solver.geometric_stiffness`` for a superposition model; ``u0``, ``v0`` (nfree,) an
        initial elastic state other than rest, superposition models only).

        Every run gets the validity report and warnings (:mod:`flexmech_py.checks.guards`), issued as Python
        warnings of the classes of :mod:`flexmech_py.base.notices` (``fm.ValidityWarning``, ...);
        ``estimate`` (default: ``solver.error_estimate != "none"``) adds the step-doubling error
        estimate (the run at 2 dt, made alongside).  A failed run raises SolverError carrying the partial
        result and, with ``diagnose``, the likely cause (which may cost a short run at dt/2); a run
        whose rigid motion reaches a singular position raises MechanismError carrying the frames before
        it.  A run whose frames would not fit in memory is refused (CaseError naming
        ``solver.output_every``): :meth:`stream` writes any length to files."""
        from .runner import MemorySink, execute  # start-up: the runner and its checks load with the first run

        res = execute(self, model, MemorySink(self.frames), geometric=geometric, estimate=estimate,
                      diagnose=diagnose, u0=u0, v0=v0)
        notices.issue(res.extra)      # as Python warnings of their kind (flexmech_py.base.notices)
        return res

    def stream(self, out_dir, model: str | None = None, geometric: str | None = None, *,
               estimate: bool | None = None, diagnose: bool = True, progress=None, force: bool = False) -> Result:
        """Run one model writing its frames to ``out_dir``/timeseries.csv as they come and its summary to
        summary.json (memory does not grow with the run's length).  Returns a Result holding the last
        block's frames, the statistics of all (``stats``) and the frames to draw (``plot_view()``);
        failures raise as in :meth:`run`, after the files are written (marked partial); Ctrl-C raises
        :class:`~flexmech_py.base.errors.Interrupted` after writing the frames so far.  The files replace
        an earlier run's in ``out_dir`` only when the run completes (:func:`flexmech_py.run.runner.stream_to_folder`).
        A run whose CSV would not fit on the disk is refused (CaseError) unless ``force``.
        ``progress``: called as progress(done, total) [steps] after every block."""
        from .runner import stream_to_folder  # start-up: the runner and its checks load with the first run

        res = stream_to_folder(self, out_dir, model, force=force, geometric=geometric, estimate=estimate,
                               diagnose=diagnose, progress=progress)
        notices.issue(res.extra)
        return res

    def blocks(self, model: str | None = None, geometric: str | None = None, *, u0=None, v0=None):
        """The run of one model as blocks of frames: Results over consecutive frames, the first from
        t = 0, each with its frames' ``steps`` and the run-level entries (timing, ``extra``) accumulated
        so far.  A failed step raises SolverError whose ``partial`` is the block of the frames before it
        (maybe none) and ``data`` the state; a rigid motion that stops raises MechanismError after the
        block that ends at the last output frame before the singular position."""
        model = self.case["solver"]["model"] if model is None else model
        if model == AUTO:
            raise CaseError("model", "'auto' is chosen by a run (Prepared.run, Prepared.stream: flexmech_py.checks.auto_model); "
                                     "name one of " + ", ".join(MODELS) + " for the blocks of a run")
        if model not in MODELS:
            raise CaseError("model", f"must be one of {', '.join(MODELS)}, got {model!r}")
        if family(model).constrained:
            if u0 is not None or v0 is not None:
                raise CaseError("model", f"an initial elastic state needs a superposition model, not {model!r}")
            return self._coupled_blocks(model)
        return self._superposition_blocks(model, geometric, u0, v0)

    def _chunks(self, floats_per_frame: int, clock: dict):
        """(i0, i1, rm): step ranges [i0, i1] (at multiples of out_every) and their rigid motion.  When the
        rigid motion stops inside a chunk, the chunk ends at the last output frame before it and the
        MechanismError follows it (at once when not even the chunk's first frame can be kept after
        its start)."""
        oe = self.out_every
        cap = min(self.chunk_steps, oe * max(1, FRAME_BUDGET // max(1, floats_per_frame)))
        size = min(cap, oe * max(1, self.first_chunk_steps // oe))
        i0 = 0
        while i0 < self.nsteps:
            i1 = min(i0 + size, self.nsteps)
            if self.tap is not None and self.tap.available() < i1:   # the run it follows is not there yet
                if not self.tap.closed:
                    yield None             # wait: a whole chunk later (per-chunk costs stay those of a run)
                    continue
                i1 = oe * (self.tap.available() // oe)
                if i1 <= i0:
                    raise MechanismError("the run this one follows stopped", time=i0 * self.dt)
            t0, c0 = time.perf_counter(), time.thread_time()
            rm, stop = self._rigid_chunk(i0, i1)
            clock["rigid_s"] += time.perf_counter() - t0
            clock["rigid_cpu_s"] += time.thread_time() - c0
            if stop is not None:
                i1 = i0 + oe * ((rm.t.size - 1) // oe)
                stop.partial = None
                if i1 == i0:
                    raise stop
                rm = rm.select(slice(0, i1 - i0 + 1))
            yield i0, i1, rm
            if stop is not None:
                raise stop
            i0, size = i1, min(2 * size, cap)

    def _rigid_chunk(self, i0: int, i1: int):
        """(rm, None) the rigid motion of steps i0..i1, or (rm up to the stop, MechanismError).  The last
        chunks sampled are remembered: several runs of this Prepared advanced in step (the error
        budget's probes) share them instead of sampling the motion again (or restarting its source)."""
        stop, rm = None, self._memo.get(("rigid", i0, i1))
        if rm is not None:
            pass
        elif self._full is not None:
            rm = self._full[0].select(slice(i0, i1 + 1))
        elif self.tap is not None:
            rm = self.tap.take(i0, i1)
        else:
            try:
                rm = self.source(self.times(i0, i1))
            except MechanismError as exc:
                if exc.partial is None or exc.partial.t.size == 0:
                    self.end_shared_motion()
                    raise
                rm, stop = exc.partial, exc
        for tap in self.taps:
            tap.offer(i0, rm)
        if stop is None and ("rigid", i0, i1) not in self._memo:
            self._remember(("rigid", i0, i1), rm)
        return rm, stop

    def _remember(self, key, value) -> None:
        """Keep the last MEMO_CHUNKS chunks of each kind (rigid motion, kernel samples)."""
        same = [k for k in self._memo if k[0] == key[0]]
        for k in same[:max(0, len(same) - MEMO_CHUNKS + 1)]:
            del self._memo[k]
        self._memo[key] = value

    def _loads(self, i0: int, i1: int, rm: RigidMotion):
        """(rig, q_free, q_val) of steps i0..i1: kernel samples and the force drives' elastic loads."""
        if self._full is not None:
            _, rig, qf, qv = self._full
            if qv is not None:
                qv = np.asfortranarray(qv[:, i0:i1 + 1])
            return np.asfortranarray(rig[:, :, i0:i1 + 1]), qf, qv
        if ("loads", i0, i1) in self._memo:
            return self._memo[("loads", i0, i1)]
        rig = self.fe.rig_samples(rm, self.gravity)
        out = (rig,) + elastic_torque_loads(self.case, self.fe, rm, rig)
        self._remember(("loads", i0, i1), out)
        return out

    def _superposition_blocks(self, model: str, geometric: str | None, u0, v0):
        refuse_superposition(self.case, model)
        fe, oe = self.fe, self.out_every
        sol = dict(self.case["solver"])
        if geometric is not None:
            sol["geometric_stiffness"] = geometric
        integ = integrator_of(sol, model)
        am, af_, beta, gamma = integrator_coefficients(integ["integrator"], integ)
        acc = Accumulated()
        state, prev = {"u0": u0, "v0": v0}, None
        acc.deflection = DeflectionReference(self.case, self.setup)
        for chunk in self._chunks(3 * fe.nfree + 4 * fe.ndof + fe.nel, acc.clock):
            if chunk is None:                  # waiting for the run whose rigid motion this one takes
                yield None
                continue
            i0, i1, rm = chunk
            ts, cs = time.perf_counter(), time.thread_time()
            rig, q_free, q_val = self._loads(i0, i1, rm)
            if not self.elastic_checked:
                check_elastic_problem(fe, rig[:, :, :1], self.setup.dof)
                self.elastic_checked = True
            acc.add_time("samples", ts, cs)
            t0, c0 = time.perf_counter(), time.thread_time()
            try:
                out = fe.run(rig, model, self.dt, alpha_m=am, alpha_f=af_, beta=beta, gamma=gamma, out_every=oe,
                             rayleigh=sol["rayleigh"], q_free=q_free, q_val=q_val, t0=i0 * self.dt,
                             geometric=sol["geometric_stiffness"], geo_tol=sol["geometric_tol"],
                             geo_maxit=sol["geometric_maxit"], div_limit=sol.get("divergence_limit"), full=True, **state)
            except SolverError as exc:   # keep the frames before the failed step
                acc.add_time("kernel", t0, c0)
                if exc.data is None or exc.step is None or exc.step < 1:
                    raise
                k, d = guards.frames_before(exc.step, oe), exc.data
                acc.geo_iters += int(d["geo_iters"])
                exc.partial = self.superposition_block(model, sol, rm, i0, [d[n][:, :k] for n in ("uf", "vf", "af", "nf")],
                                                        prev, acc, i0 + exc.step)
                exc.step += i0                  # the chunk's step -> the run's step (exc.time is already global)
                exc.data = dict(d, cm=None, geometric=sol["geometric_stiffness"])
                raise
            acc.add_time("kernel", t0, c0)
            acc.geo_iters += int(out[4])
            block = self.superposition_block(model, sol, rm, i0, out[:4], prev, acc, i1)
            lr = fe.last_run                    # the state at step i1: the next chunk continues from it
            state = {"u0": lr["u"], "v0": lr["v"], "a0": lr["a"], "p0": lr["p"]}
            prev = last_values(block, prev)
            self.last_cpu = acc.cpu()
            yield block

    def superposition_block(self, model: str, sol: dict, rm: RigidMotion, i0: int, frames, prev, acc, steps_done,
                            every: int | None = None):
        """The block of a chunk's frames (uf, vf, af, nf over the free DOFs; frame 0 at step i0, the
        previous block's last frame when i0 > 0, evaluated again for the continuity of angles and dropped);
        ``rm`` the rigid motion at every ``every``-th of its samples per frame (default: at every step,
        ``every = out_every``; 1 when rm holds the frames only)."""
        fe, case, oe = self.fe, self.case, self.out_every
        uf, vf, af, nf = frames
        every = oe if every is None else every
        sel = slice(0, every * (uf.shape[1] - 1) + 1, every)
        rmf = rm.select(sel)
        motion_f = rmf.motion
        rig_f = fe.rig_samples(rm, self.gravity, sel)
        u_all, v_all, a_all = fe.expand_state(uf, vf, af, rig_f)
        if sol["geometric_stiffness"] == "none":   # the axial forces of the linear solution, for outputs
            nf = (fe.el_prop[3] / fe.el_prop[0])[:, None] * axial_stretch(fe, u_all, motion_f)
        reactions = ModelReactions(fe, model, rmf, rig_f, (u_all, v_all, a_all), sol, nf)
        z_ref = acc.deflection(rmf.t, lambda p: joint_at_joint(fe, rmf, p, 0, u_all))
        columns = evaluate_outputs(fe, case["outputs"], u_all, motion_f, rig_f, model, rm=rmf, axial=nf,
                                   rates=(v_all, a_all), reactions=reactions, z_ref=z_ref)
        units = {name: output_unit(sp, case) for name, sp in case["outputs"].items()}
        if self.source.controls is not None:     # the controllers closed in the rigid-body integration
            add_control_columns(case, dict(zip(self.source.controls.names, rmf.control.T)), columns, units)
            columns["work_inputs"], units["work_inputs"] = rmf.work, "J"     # on the rigid-body motion
        extra = {"integrator": integrator_summary(sol, model)}
        if sol["geometric_stiffness"] != "none":
            extra["geometric_stiffness"] = {"source": sol["geometric_stiffness"], "iterations": acc.geo_iters,
                                            "mean_per_step": acc.geo_iters / max(steps_done, 1)}
        if reactions.checked:
            acc.reaction_residual = max(acc.reaction_residual, reactions.residual)
            extra["reactions"] = dict(reactions.summary(), equilibrium_residual=acc.reaction_residual)
        res = Result(case=case, model=model, t=rmf.t, columns=columns, units=units, fe=fe,
                     q=rmf.q, qd=rmf.qd, qdd=rmf.qdd, u=u_all, v=v_all, a=a_all, rig=rig_f, nsteps=self.nsteps,
                     dt=self.dt, timing=acc.timing(), extra=extra, axial=nf, motion=motion_f, rigid=rmf,
                     steps=i0 + oe * np.arange(uf.shape[1]), curvature_of=superposition_curvature,
                     node_curvatures_of=superposition_node_curvatures,
                     reactions=reactions)
        return after_first(res, prev)

    def _coupled_blocks(self, model: str):
        """The one-pass coupled model (one chord frame per flexible link) or the nonlinear co-rotational
        model (one per element); the rigid-body solution on the grid is their reference."""
        case, sol, oe = self.case, self.case["solver"], self.out_every
        if model not in self.coupled:
            check_mesh(case, model)      # the model's own arrays (Family.element_bytes, dof2_bytes)
            self.coupled[model] = CoupledModel.from_case(case, split=family(model).element_frames)
        cm = self.coupled[model]
        integ = integrator_of(sol, model)
        am, af_, beta, gamma = integrator_coefficients(integ["integrator"], integ)
        acc, diag = Accumulated(), cpl_out.Diagnostics(cm)
        state, prev, first = None, None, None
        acc.deflection = DeflectionReference(case, self.setup)
        for chunk in self._chunks(6 * cm.ndof + 3 * len(cm.markers), acc.clock):
            if chunk is None:                  # waiting for the run whose rigid motion this one takes
                yield None
                continue
            i0, i1, rm = chunk
            first = rm.select(slice(0, 1)) if first is None else first
            cval = cm.constraint_values(rm, first)
            q0, v0 = cm.initial_state(rm.select(slice(0, 1))) if state is None else (None, None)
            t0, c0 = time.perf_counter(), time.thread_time()
            try:
                qf, vf, af, lf, ef, iters = cm.run(q0, v0, rm.t, cval, self.dt, alpha_m=am, alpha_f=af_, beta=beta,
                                                   gamma=gamma, out_every=oe, tol=sol["newton_tol"],
                                                   maxit=sol["newton_maxit"], gravity=self.gravity,
                                                   rayleigh=sol["rayleigh"], div_limit=sol.get("divergence_limit"),
                                                   state=state)
            except SolverError as exc:   # keep the frames before the failed step
                acc.add_time("kernel", t0, c0)
                if exc.data is None or exc.step is None or exc.step < 1:
                    raise
                k, d = guards.frames_before(exc.step, oe), exc.data
                frames = [d[n][:, :k] for n in ("qf", "vf", "af", "lf", "ef")]
                exc.partial = self.coupled_block(cm, model, rm, cval, i0, frames, d["iters"], prev, diag, acc,
                                                  i0 + exc.step)
                exc.data = dict(d, cm=cm, geometric="coupled", q_last=frames[0][:, -1])
                exc.step += i0
                raise
            acc.add_time("kernel", t0, c0)
            block = self.coupled_block(cm, model, rm, cval, i0, (qf, vf, af, lf, ef), iters, prev, diag, acc, i1)
            state, prev = cm.last_run, last_values(block, prev)
            self.last_cpu = acc.cpu()
            yield block

    def coupled_block(self, cm, model: str, rm: RigidMotion, cval, i0: int, frames, iters: int, prev, diag, acc,
                      steps_done: int, every: int | None = None, alternating=None):
        """The block of a chunk's frames of the coupled or nonlinear model (frame 0, ``rm`` and ``every`` as
        in :meth:`superposition_block`, ``cval`` on rm's samples; ``alternating`` the multipliers'
        alternating part per frame, default the last run's)."""
        case, sol, oe = self.case, self.case["solver"], self.out_every
        qf, vf, af, lf, ef = frames
        every = oe if every is None else every
        idx = slice(0, every * (qf.shape[1] - 1) + 1, every)
        alternating = cm.last_run["la"][:, :qf.shape[1]] if alternating is None else alternating
        rmf = rm.select(idx)
        ref = rmf.motion
        fr = cpl_out.model_frames(cm, qf, vf, af, lf, rmf.t, self.gravity, sol["rayleigh"])
        u_dev = cpl_out.deviation(cm, qf, ref)
        axial = cpl_out.axial_forces(cm, qf)
        z_ref = acc.deflection(rmf.t, lambda p: cpl_out.joint_at_joint(cm, fr, rmf, p)[0])
        columns = cpl_out.evaluate(cm, case["outputs"], fr, rmf, ref, u_dev, axial, superposition_fe=lambda: self.fe,
                                   z_ref=z_ref, run_loads=family(model).inertia_loads)
        units = {name: output_unit(sp, case) for name, sp in case["outputs"].items()}
        for k, y in {"energy_kinetic": ef[0], "energy_potential": ef[1], "work_inputs": ef[2]}.items():
            columns[k], units[k] = y, "J"
        columns["newton_iterations"], units["newton_iterations"] = ef[3], "1"
        columns.update(drive_columns(cm, fr, units))
        add_control_columns(case, cm.control_outputs(qf.shape[1]), columns, units)
        diag.add(fr, ef, rmf, iters, cval[:, :, idx])
        extra = {"integrator": integrator_summary(sol, model), "coupled": diag.summary(steps_done),
                 "step_alternation": cpl_out.multiplier_alternation(cm, alternating, lf,
                                                                    rmf.t, drive_column_joints(cm))}
        rig_chord = np.asfortranarray(np.stack([fr.chord.phi, fr.chord.omega, fr.chord.alpha,
                                                fr.chord.ax - self.gravity[0],
                                                fr.chord.ay - self.gravity[1]]).transpose(0, 2, 1))
        own = [cpl_out.joint_output(cm, fr, rmf, name) for name in self.setup.primary]
        q, qd, qdd = (np.stack([o[k] for o in own], axis=1) if own else x for k, x in enumerate((rmf.q, rmf.qd, rmf.qdd)))
        res = Result(case=case, model=model, t=rmf.t, columns=columns, units=units, fe=cm.mesh,
                     q=q, qd=qd, qdd=qdd, u=u_dev, v=np.zeros_like(u_dev), a=np.zeros_like(u_dev),
                     rig=rig_chord, nsteps=self.nsteps, dt=self.dt, timing=acc.timing(), extra=extra, axial=axial,
                     motion=ref, rigid=rmf, steps=i0 + oe * np.arange(qf.shape[1]), state=qf,
                     curvature_of=functools.partial(coupled_curvature, cm),
                     reactions=cpl_out.FrameReactions(cm, fr))
        return after_first(res, prev)

    def report_mechanism(self, res: Result) -> None:
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
        res.extra["warning_kinds"] = {**notices.kinds_of(st.warnings, "mechanism"), **res.extra.get("warning_kinds", {})}


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
