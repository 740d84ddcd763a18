"""A run advanced from Python, step by step: :class:`Simulation` (docs/api.md, "Stepping").

A controller, an estimator or a learning agent written in Python builds a simulation from a case (or
a mechanism built in Python), advances it by steps or to a time with the actuator efforts of named
joints, reads its outputs and its state, changes the efforts and goes on; it saves and restores the
state for rollouts.  The time loops are the compiled ones of every model family, continued from the
state the last call left: a simulation advanced with no efforts is the case's run, frame for frame.

An effort (torque [N m] on a revolute joint, force [N] on a prismatic one) is added to the
``constant`` of the joint's force drive and held over the steps of the call (zero-order hold: the
discrete equations at both ends of each step see it).  Only joints with a force drive take efforts
(give a joint the law ``force`` with ``constant = 0`` to actuate it); a kinematically driven joint
is refused.  Where the rigid-body motion is integrated (a mechanism with a free degree of freedom),
a change of effort restarts its integration at the current step.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from pathlib import Path

import numpy as np

from ..models.constrained import outputs as cpl_out
from ..case import Case, integrator_coefficients, integrator_of, load_case
from ..models.constrained.coupled import CoupledModel
from ..base.errors import CaseError
from ..base.families import SUPERPOSITION_MODELS, family
from ..mechanism import Mechanism, MotionSource
from ..mechanism.motion import RigidMotion
from ..mechanism.packing import force_constant_positions
from ..models.superposition.outputs import DeflectionReference
from .results import Result
from ..mechanism.control import refuse_superposition
from .blocks import Accumulated
from .simulate import Prepared
from ..models.superposition.loads import check_elastic_problem, elastic_torque_loads
from ..base.sizes import check_mesh

__all__ = ["Simulation", "SimulationState", "RigidBuffer", "stepping_plan"]

#: steps of rigid motion sampled ahead at a time (the samples do not depend on the chunking)
RIGID_AHEAD = 256


def stepping_plan(i: int, n: int, oe: int) -> list[tuple[int, int, int]]:
    """The compiled calls (first step, steps, output spacing) that advance n steps from step i with the
    run's frames (every oe-th step) among their outputs: up to the next frame, whole frames, the rest."""
    calls = []
    head = min(n, (-i) % oe)
    if head:
        calls.append((i, head, head))
    body = oe * ((n - head) // oe)
    if body:
        calls.append((i + head, body, oe))
    tail = n - head - body
    if tail:
        calls.append((i + head + body, tail, tail))
    return calls


class RigidChunk:
    """Consecutive samples of the rigid-body motion from step ``i0`` on, with what a model derives from
    them (:meth:`derived`: computed once per chunk, as the batch run does per chunk)."""

    def __init__(self, i0: int, rm: RigidMotion):
        self.i0, self.rm, self._derived = i0, rm, {}

    def derived(self, key: str, fn):
        if key not in self._derived:
            self._derived[key] = fn(self.rm)
        return self._derived[key]

    def frames(self, idx) -> RigidMotion:
        """The samples at the chunk's positions ``idx``."""
        return self.rm.select(np.asarray(idx, int))


def _own_description(setup):
    """The motion set-up with a copy of its packed description's reals (the force laws' constants a
    stepped run changes), the rest shared."""
    return dataclasses.replace(setup, packed=dataclasses.replace(setup.packed, rspec=setup.packed.rspec.copy()))


class RigidBuffer:
    """The rigid-body motion of a simulation, sampled ahead in chunks from a MotionSource of its own
    (with a description of its own, whose force laws the efforts change)."""

    def __init__(self, prep: Prepared):
        self.prep = prep
        self.setup = _own_description(prep.setup)
        sol = prep.case["solver"]
        self.source = MotionSource(self.setup, rtol=sol["rigid_rtol"], atol=sol["rigid_atol"], hmax=sol["t_end"],
                                   controls=prep.source.controls)
        self.positions = force_constant_positions(self.setup.packed)
        self.current = None
        self.ahead = RIGID_AHEAD        # steps sampled ahead: from one after a change of effort, doubling

    def chunk(self, i: int, k: int) -> tuple[RigidChunk, int]:
        """(chunk, position of step i in it) of a chunk holding steps i..i+k."""
        c = self.current
        if c is None or i < c.i0 or i + k > c.i0 + c.rm.t.size - 1:
            end = min(self.prep.nsteps, max(i + k, i + self.ahead))
            c = self.current = RigidChunk(i, self.source(self.prep.times(i, end)))
            self.ahead = min(2 * self.ahead, RIGID_AHEAD)
        return c, i - c.i0

    def set_constants(self, values: dict, i: int) -> None:
        """Force-law constants {joint: value} from step i on (the rigid integration restarts there)."""
        c, a = self.chunk(i, 0)
        for joint, value in values.items():
            self.setup.packed.rspec[self.positions[joint]] = float(value)
        self.source.restart_at(float(c.rm.t[a]), c.rm.z[a], c.rm.zd[a],
                               (c.rm.integral[a], c.rm.work[a]) if self.source.controls is not None else None)
        self.current, self.ahead = None, 1

    def copy(self) -> "RigidBuffer":
        """An independent buffer at the same point, with a description of its own (a later effort set
        on one does not reach the other's force laws)."""
        other = copy.copy(self)
        other.setup = _own_description(self.setup)
        other.source = self.source.fork()
        other.source.setup = other.setup
        return other


@dataclasses.dataclass(frozen=True)
class SimulationState:
    """A saved point of a :class:`Simulation` (for :meth:`Simulation.restore`): the step, the efforts,
    the model's state and the rigid motion's; opaque otherwise."""

    step: int
    efforts: dict
    model_state: dict
    rigid: RigidBuffer
    recorded: int


class Simulation:
    """A case advanced from Python; see the module's docstring and docs/api.md.

    ``case``: a resolved case, a case file's path (or a bundled case's name), or a
    :class:`~flexmech_py.Mechanism` (then ``case_kw`` go to :meth:`~flexmech_py.Case.from_mechanism`);
    ``model``: a model family (default: the case's ``solver.model``); ``dt`` [s],
    ``elements_per_link`` override the case.  The run's frames (every ``solver.output_every``-th
    step) are kept for :meth:`result` unless ``record=False``."""

    def __init__(self, case, model: str | None = None, *, dt: float | None = None,
                 elements_per_link: int | None = None, record: bool = True, **case_kw):
        if isinstance(case, Mechanism):
            case = Case.from_mechanism(case, **case_kw)
        elif isinstance(case, (str, Path)):
            case = load_case(case)
        self.prep = Prepared(case, dt=dt, elements_per_link=elements_per_link)
        self.case = self.prep.case
        self.model = self.case["solver"]["model"] if model is None else model
        self.rigid = RigidBuffer(self.prep)
        mech = self.case.mechanism
        self.base = {d.joint: float(d.params.get("constant", 0.0)) for d in mech.drives if not d.kinematic}
        self.kinematic = {d.joint for d in mech.drives if d.kinematic}
        self.efforts = dict.fromkeys(self.base, 0.0)
        stepper = SuperpositionStepper if self.model in SUPERPOSITION_MODELS else CoupledStepper
        self.stepper = stepper(self.prep, self.model, self.rigid)
        self.record = record
        self.step = 0
        self._current = None

    # ------------------------------------------------------------------ time
    @property
    def dt(self) -> float:
        """The step [s]."""
        return self.prep.dt

    @property
    def t(self) -> float:
        """The current time [s]."""
        return float(self.prep.times(self.step, self.step)[0])

    @property
    def t_end(self) -> float:
        """The last time the simulation reaches [s] (the case's ``solver.t_end``)."""
        return float(self.case["solver"]["t_end"])

    def advance(self, steps: int | None = None, *, to: float | None = None, inputs: dict | None = None) -> "Simulation":
        """Advance by ``steps`` steps (default 1), or ``to`` the first step time at or after ``to`` [s],
        with the efforts ``inputs`` {joint: N m or N} held over them (joints not named keep theirs).
        Returns the simulation.  Raises SolverError when the model's loop stops (the state stays at
        the last completed call)."""
        n = self._steps_to(steps, to)
        if inputs:
            self._set_efforts(inputs)
        if n == 0:
            return self
        keep = (self.step if self.step == 0 else self.step + 1) if self.record else None
        for i0, k, every in stepping_plan(self.step, n, self.prep.out_every):
            self.stepper.advance(i0, k, every, keep)
            self.step = i0 + k
        self._current = None
        return self

    def _steps_to(self, steps, to) -> int:
        if steps is not None and to is not None:
            raise ValueError("advance: give steps or to, not both")
        if to is not None:
            if not math.isfinite(to):
                raise ValueError(f"advance: to must be a finite time [s], got {to!r}")
            n = max(0, math.ceil((float(to) - self.t) / self.dt - 1e-9))
        else:
            n = 1 if steps is None else steps
            if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
                raise ValueError(f"advance: steps must be a whole number >= 0, got {steps!r}")
        if self.step + n > self.prep.nsteps:
            raise ValueError(f"advance: {n} steps from t = {self.t:.6g} s pass solver.t_end = {self.t_end:.6g} s: "
                             "build the simulation from a case with a later solver.t_end")
        return int(n)

    def _set_efforts(self, inputs: dict) -> None:
        new = dict(self.efforts)
        for joint, value in inputs.items():
            if joint in self.kinematic:
                raise CaseError(f"inputs.{joint}", "is prescribed by a kinematic drive: an effort cannot act on it; "
                                                   "give the joint the law 'force' in the case to actuate it")
            if joint not in self.base:
                raise CaseError(f"inputs.{joint}", f"has no force drive; joints that take efforts: "
                                                   f"{', '.join(self.base) or 'none'} (give the joint a drive with "
                                                   "law = 'force' and constant = 0 to actuate it)")
            if not math.isfinite(float(value)):
                raise CaseError(f"inputs.{joint}", f"must be a finite effort (N m or N), got {value!r}")
            new[joint] = float(value)
        changed = {j: self.base[j] + v for j, v in new.items() if v != self.efforts[j]}
        if changed:
            self.rigid.set_constants(changed, self.step)
            self.stepper.set_constants(changed)
            self.efforts = new

    # ------------------------------------------------------------------ reading
    def outputs(self) -> dict:
        """{output: value} of the case's outputs at the current time (evaluated once per step)."""
        if self._current is None:
            block = self.stepper.current_block(self.step)
            self._current = {k: float(y[-1]) for k, y in block.columns.items()}
        return dict(self._current)

    def output(self, name: str) -> float:
        """The value of one of the case's outputs at the current time."""
        values = self.outputs()
        if name not in values:
            raise KeyError(f"no output {name!r}; the case's outputs: {', '.join(values)}")
        return values[name]

    def joint(self, name: str) -> tuple[float, float]:
        """(coordinate, rate) [rad or m, per s] of a joint at the current time, in the model's own
        motion (cheap: no output evaluation)."""
        return self.stepper.joint(name, self.step)

    def state(self) -> SimulationState:
        """The current point (see :meth:`restore`)."""
        return SimulationState(self.step, dict(self.efforts), self.stepper.save(), self.rigid.copy(),
                               self.stepper.recorded())

    def restore(self, state: SimulationState) -> "Simulation":
        """Go back (or forward) to a saved point: later advances repeat the steps from there exactly;
        recorded frames after it are dropped."""
        self.step = state.step
        changed = {j: self.base[j] + v for j, v in state.efforts.items()}
        self.efforts = dict(state.efforts)
        self.rigid = state.rigid.copy()
        self.stepper.rigid = self.rigid
        self.stepper.set_constants(changed)
        self.stepper.load(state.model_state, state.recorded)
        self._current = None
        return self

    def result(self) -> Result:
        """The recorded frames as a Result (as a run's: ``res.write(folder)`` gives timeseries.csv)."""
        if not self.record:
            raise ValueError("this simulation keeps no frames (record=False)")
        return self.stepper.result(self.step)


def _grouped(frames, idx: int):
    """The rigid samples of recorded frames [(chunk, position, ...)] as one RigidMotion (one selection
    per chunk) and the other entries from position ``idx`` on."""
    parts, group = [], []
    for f in frames:
        if group and f[0] is not group[0][0]:
            parts.append(group[0][0].frames([g[1] for g in group]))
            group = []
        group.append(f)
    parts.append(group[0][0].frames([g[1] for g in group]))
    return RigidMotion.concat(parts), [f[idx:] for f in frames]


class RecordedFrames:
    """What both families' steppers share: the recorded frames (``frames``) and the current one
    (``current()``) evaluated into Results by the family's ``_block``."""

    frames: list
    prep: Prepared

    @property
    def deflection(self) -> DeflectionReference:
        """The deflection outputs' reference, built once (a fresh start of it per evaluation)."""
        if getattr(self, "_deflection", None) is None:
            self._deflection = DeflectionReference(self.prep.case, self.prep.setup)
        return self._deflection

    def recorded(self) -> int:
        return len(self.frames)

    def current_block(self, step: int) -> Result:
        return self._block([self.current()], step, step)

    def result(self, step: int) -> Result:
        if not self.frames:
            raise ValueError("no frame recorded yet: advance the simulation first")
        return self._block(self.frames, step, 0)


class SuperpositionStepper(RecordedFrames):
    """The superposition models' elastic loop (flexmech_ked) continued call by call."""

    def __init__(self, prep: Prepared, model: str, rigid: RigidBuffer):
        refuse_superposition(prep.case, model)
        self.prep, self.model, self.rigid = prep, model, rigid
        self.fe = prep.fe
        sol = self.sol = dict(prep.case["solver"])
        integ = integrator_of(sol, model)
        self.coef = integrator_coefficients(integ["integrator"], integ)
        self.state = {"u0": None, "v0": None}
        self.frames, self.last = [], None
        self.checked = False

    def set_constants(self, values: dict) -> None:
        """The elastic loads come from the rigid motion's drive values: nothing to change here."""

    def _samples(self, rm: RigidMotion):
        rig = self.fe.rig_samples(rm, self.prep.gravity)
        return (rig,) + elastic_torque_loads(self.prep.case, self.fe, rm, rig)

    def advance(self, i0: int, k: int, every: int, keep_from: int | None):
        """k steps from step i0 with outputs every ``every`` steps; the outputs at steps >= keep_from
        that are the run's frames are recorded (None: none)."""
        fe, prep, sol = self.fe, self.prep, self.sol
        c, a = self.rigid.chunk(i0, k)
        rig, q_free, q_val = c.derived("superposition", self._samples)
        rig = rig[:, :, a:a + k + 1]
        q_val = None if q_val is None else q_val[:, a:a + k + 1]
        if not self.checked:
            check_elastic_problem(fe, rig[:, :, :1], prep.setup.dof)
            self.checked = True
        am, af, beta, gamma = self.coef
        out = fe.run(rig, self.model, prep.dt, alpha_m=am, alpha_f=af, beta=beta, gamma=gamma, out_every=every,
                     rayleigh=sol["rayleigh"], q_free=q_free, q_val=q_val, t0=i0 * prep.dt,
                     geometric=sol["geometric_stiffness"], geo_tol=sol["geometric_tol"],
                     geo_maxit=sol["geometric_maxit"], div_limit=sol.get("divergence_limit"), full=True, **self.state)
        lr = fe.last_run
        self.state = {"u0": lr["u"], "v0": lr["v"], "a0": lr["a"], "p0": lr["p"]}
        oe = prep.out_every
        for j in range(out[0].shape[1]):
            step = i0 + j * every
            if keep_from is not None and step >= keep_from and step % oe == 0 and (j > 0 or step == 0):
                self.frames.append((c, a + j * every, tuple(x[:, j] for x in out[:4])))
        self.last = (c, a + k, tuple(x[:, -1] for x in out[:4]))

    def save(self) -> dict:
        return {"state": dict(self.state), "last": self.last}

    def load(self, saved: dict, recorded: int) -> None:
        self.state, self.last = dict(saved["state"]), saved["last"]
        del self.frames[recorded:]

    def current(self):
        """(chunk, position, frame) at the current step; before the first step, a zero-step call of the
        loop (the loop's own start is left to the first step)."""
        if self.last is None:
            state = self.state
            self.advance(0, 0, 1, None)
            self.state = state
        return self.last

    def joint(self, name: str, step: int) -> tuple[float, float]:
        c, a, _ = self.current()
        q = c.rm.joint(name)[a]
        return float(q[0]), float(q[1])

    def _block(self, items, step: int, i0: int) -> Result:
        rm, rest = _grouped(items, 2)
        cols = [np.stack([r[0][k] for r in rest], axis=1) for k in range(4)]
        acc = Accumulated()
        acc.deflection = self.deflection.fresh()
        return self.prep.superposition_block(self.model, self.sol, rm, i0, cols, None, acc, step, every=1)



class CoupledStepper(RecordedFrames):
    """The coupled and nonlinear models' loop (flexmech_coupled_run) continued call by call.  A frame's
    Newton iterations and multiplier alternation are the largest since the run's previous frame,
    over the calls between them, as in a batch run."""

    def __init__(self, prep: Prepared, model: str, rigid: RigidBuffer):
        self.prep, self.model, self.rigid = prep, model, rigid
        check_mesh(prep.case, model)
        self.cm = CoupledModel.from_case(prep.case, split=family(model).element_frames)
        sol = self.sol = prep.case["solver"]
        integ = integrator_of(sol, model)
        self.coef = integrator_coefficients(integ["integrator"], integ)
        self.kin = self.cm.kernel_inputs(prep.dt, prep.gravity, sol["rayleigh"], sol.get("divergence_limit"))
        self.first = None
        self.state, self.iters = None, 0
        self.frames, self.last = [], None
        self.since = (0.0, 0.0)           # the largest Newton iterations and alternation since the last frame

    def set_constants(self, values: dict) -> None:
        self.cm.set_force_constants(values)
        self.kin.set_force_constants(values)

    def advance(self, i0: int, k: int, every: int, keep_from: int | None):
        """As :meth:`SuperpositionStepper.advance`."""
        cm, prep, sol = self.cm, self.prep, self.sol
        c, a = self.rigid.chunk(i0, k)
        if self.first is None:
            self.first = c.rm.select(slice(a, a + 1))
        cval = c.derived("cval", self._constraint_values)[:, :, a:a + k + 1]
        q0, v0 = cm.initial_state(self.first) if self.state is None else (None, None)
        am, af, beta, gamma = self.coef
        out = cm.run(q0, v0, c.rm.t[a:a + k + 1], cval, prep.dt, alpha_m=am, alpha_f=af, beta=beta, gamma=gamma,
                     out_every=every, tol=sol["newton_tol"], maxit=sol["newton_maxit"], state=self.state,
                     inputs=self.kin)
        self.state = cm.last_run
        self.iters += int(out[5])
        la, oe = cm.last_run["la"], prep.out_every
        for j in range(out[0].shape[1]):
            step = i0 + j * every
            if j > 0 or step == 0:
                its, alt = max(self.since[0], out[4][3, j]), np.maximum(self.since[1], la[:, j])
                self.since = (its, alt)
                if keep_from is not None and step >= keep_from and step % oe == 0:
                    frame = tuple(x[:, j] for x in out[:5])
                    ef = frame[4].copy()
                    ef[3] = its          # (the controllers' outputs ride behind the energies)
                    ef = np.concatenate([ef, [u[j] for u in cm.last_run["controls"].values()]])
                    self.frames.append((c, a + j * every, cval[:, :, j * every], frame[:4] + (ef,), alt))
                if step % oe == 0:
                    self.since = (0.0, 0.0)
        self.last = (c, a + k, cval[:, :, -1], tuple(x[:, -1] for x in out[:5]), la[:, -1])

    def _constraint_values(self, rm: RigidMotion) -> np.ndarray:
        return self.cm.constraint_values(rm, self.first)

    def save(self) -> dict:
        return {"state": self.state, "iters": self.iters, "last": self.last, "first": self.first, "since": self.since}

    def load(self, saved: dict, recorded: int) -> None:
        self.state, self.iters, self.last = saved["state"], saved["iters"], saved["last"]
        self.first, self.since = saved["first"], saved["since"]
        del self.frames[recorded:]

    def current(self):
        """(chunk, position, cval, frame, alternation) at the current step (before the first step as
        the superposition stepper's)."""
        if self.last is None:
            saved = self.save()
            self.advance(0, 0, 1, None)
            self.load(dict(saved, last=self.last), len(self.frames))
        return self.last

    def joint(self, name: str, step: int) -> tuple[float, float]:
        c, a, _, cols, _ = self.current()
        rm = c.frames([a])
        fr = cpl_out.model_frames(self.cm, *(x[:, None] for x in cols[:4]), rm.t, self.prep.gravity,
                                  self.sol["rayleigh"])
        value = cpl_out.joint_output(self.cm, fr, rm, name)
        return float(value[0][0]), float(value[1][0])

    def _block(self, items, step: int, i0: int) -> Result:
        rm, rest = _grouped(items, 2)
        cval = np.stack([r[0] for r in rest], axis=2)
        cols = tuple(np.stack([r[1][k] for r in rest], axis=1) for k in range(5))
        la = np.stack([r[2] for r in rest], axis=1)
        acc = Accumulated()
        acc.deflection = self.deflection.fresh()
        diag = cpl_out.Diagnostics(self.cm)
        controls = cols[4][4:]
        cols = cols[:4] + (cols[4][:4],)
        self.cm.last_run = dict(self.cm.last_run, controls=dict(zip(self.cm.last_run["controls"], controls)))
        return self.prep.coupled_block(self.cm, self.model, rm, np.asfortranarray(cval), i0, cols, self.iters, None,
                                       diag, acc, step, every=1, alternating=la)

