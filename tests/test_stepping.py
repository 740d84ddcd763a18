"""The Python stepping API (flexmech_py.run.stepping.Simulation): a run advanced step by step is the
batch run frame for frame, efforts act as the case's force laws do, and a saved state replays."""

import warnings

import numpy as np
import pytest

import flexmech_py as fm
from flexmech_py.case import Case
from flexmech_py.base.errors import CaseError
from flexmech_py.run.simulate import Prepared
from flexmech_py.run.stepping import Simulation, stepping_plan


def _short(name, steps, **solver):
    case = fm.load_case(name)
    sol = dict(case["solver"], error_estimate="none", **solver)
    sol["t_end"] = steps * sol["dt"]
    return Case(case, solver=sol)


def _batch(case, model):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Prepared(case).run(model, estimate=False)


def _csv(res, folder):
    return (res.write(folder)[0]).read_text().splitlines()[1:]    # the status line differs (frames count)


def test_stepping_plan_puts_every_frame_on_a_call_boundary_or_output():
    for i, n, oe in [(0, 25, 10), (3, 30, 10), (7, 3, 10), (10, 10, 10), (5, 1, 1)]:
        calls = stepping_plan(i, n, oe)
        assert sum(k for _, k, _ in calls) == n and calls[0][0] == i
        outputs = {i0 + j * e for i0, k, e in calls for j in range(k // e + 1)}
        assert {s for s in range(i, i + n + 1) if s % oe == 0} <= outputs


@pytest.mark.parametrize("model", fm.MODELS)
def test_one_step_per_call_is_the_batch_run_frame_for_frame(model, tmp_path):
    case = _short("fourbar_hac", 40, output_every=10, dt=2e-5)
    batch = _batch(case, model)
    sim = Simulation(case, model)
    for _ in range(sim.prep.nsteps):
        sim.advance()
    res = sim.result()
    assert res.t.size == batch.t.size == 5 and list(res.columns) == list(batch.columns)
    for k, y in batch.columns.items():
        np.testing.assert_array_equal(res.columns[k], y, err_msg=k)
    assert _csv(res, tmp_path / "s") == _csv(batch, tmp_path / "b")


@pytest.mark.parametrize("model", ["hac", "nonlinear"])
def test_outputs_read_between_steps_leave_the_run_whole_and_match_its_frames(model):
    """A Bricout arm with a free base joint (its deflection outputs measured from the rigid arm placed
    at the model's coordinates, solved frame after frame): outputs() read after every step agree with
    the run's frames, and reading them changes nothing the batch run gives (the deflection reference
    set-up is built once and started afresh for every evaluation).  The deflection outputs read between
    steps close the rigid arm's placement from the assembled start, the run's frames from the previous
    frame: they agree to the placement's tolerance (1e-12 of the arm's length), not to the bit."""
    case = _short("manipulator_bricout", 20, output_every=5)
    batch = _batch(case, model)
    sim = Simulation(case, model)
    read = []
    for _ in range(sim.prep.nsteps):
        values = sim.advance().outputs()
        assert values["tip_transverse_deflection"] == sim.output("tip_transverse_deflection")
        if sim.step % 5 == 0:
            read.append(values)
    res = sim.result()
    for k, y in batch.columns.items():
        np.testing.assert_array_equal(res.columns[k], y, err_msg=k)
        scale = max(float(np.max(np.abs(y))), 1e-300)
        tol = 1e-11 if k.endswith("deflection") else 1e-12 * scale       # [m] for the deflections
        np.testing.assert_allclose([r[k] for r in read], y[1:], rtol=0, atol=tol, err_msg=k)


@pytest.mark.parametrize("model", ["hac", "nonlinear"])
def test_efforts_act_as_the_force_laws_of_the_case(model):
    """The manipulator's step torques given as efforts on zero force laws reproduce its run (its rigid
    motion integrated from the restart at t = 0, the elastic loops with the same loads)."""
    case = _short("manipulator_bricout", 60, dt=5e-5)
    batch = _batch(case, model)
    zero = Case(case, drives=[dict(d, constant=0.0) for d in case["drives"]])
    sim = Simulation(zero, model)
    sim.advance(17, inputs={"base": 10.0, "joint_2": -10.0})
    sim.advance(to=case["solver"]["t_end"])
    res = sim.result()
    for k, y in batch.columns.items():
        np.testing.assert_allclose(res.columns[k], y, rtol=1e-9, atol=1e-12 * np.abs(y).max(), err_msg=k)
    assert sim.output("alpha") == pytest.approx(batch["alpha"][-1], rel=1e-9)
    assert sim.joint("base")[0] == pytest.approx(batch["alpha"][-1], rel=1e-6)


def test_a_restored_state_replays_the_same_steps_and_drops_later_frames():
    case = _short("manipulator_bricout", 80, dt=5e-5, output_every=4)
    sim = Simulation(case, "coupled")
    sim.advance(20, inputs={"base": 3.0})
    saved = sim.state()
    sim.advance(30, inputs={"base": -5.0})
    first = sim.outputs()
    sim.restore(saved)
    assert sim.step == 20 and sim.efforts["base"] == 3.0
    sim.advance(30, inputs={"base": -5.0})
    assert sim.outputs() == first
    sim.restore(saved).advance(30, inputs={"base": 5.0})
    assert sim.outputs()["alpha"] != first["alpha"]
    assert sim.result().t.size == 50 // 4 + 1


def test_bad_inputs_name_the_field_and_the_fix():
    sim = Simulation(_short("fourbar_constant_speed", 10), "hac")
    with pytest.raises(CaseError, match=r"inputs\.crank_pivot.*kinematic drive.*law 'force'"):
        sim.advance(inputs={"crank_pivot": 1.0})
    with pytest.raises(CaseError, match=r"inputs\.nowhere.*no force drive"):
        sim.advance(inputs={"nowhere": 1.0})
    sim2 = Simulation(_short("manipulator_bricout", 10), "hac")
    with pytest.raises(CaseError, match=r"inputs\.base.*finite"):
        sim2.advance(inputs={"base": float("nan")})
    with pytest.raises(ValueError, match="solver.t_end"):
        sim2.advance(11)
    sim2.advance(to=3.5 * sim2.dt)
    assert sim2.step == 4
