"""Compiled kernels (ked_run, ked_matrices, ked_loads) against the NumPy reference."""

import numpy as np
import pytest
from flexmech_py.models.superposition.reference import newmark, system

import flexmech_py as fm
from flexmech_py.run.simulate import Prepared


def _prep(cases_dir, name, t_end, dt, extra=()):
    case = fm.load_case(cases_dir / f"{name}.toml", overrides=[f"solver.t_end={t_end}", f"solver.dt={dt}",
                                                               "solver.output_every=1", *extra])
    return Prepared(case)


@pytest.mark.parametrize("name", ["fourbar_hac", "manipulator_bricout"])
@pytest.mark.parametrize("model", fm.SUPERPOSITION_MODELS)
def test_ked_run_matches_numpy(cases_dir, name, model):
    p = _prep(cases_dir, name, 0.004, 2e-5)
    uf, _, _ = p.fe.run(p.rig, model, p.dt)
    ref = newmark(p.fe, p.rig, model, p.dt)
    scale = np.max(np.abs(ref))
    assert scale > 0
    assert np.max(np.abs(uf - ref)) < 1e-12 * scale  # measured <= 8e-15


def test_ked_run_with_damping_and_applied_loads(cases_dir):
    """Rayleigh damping, Newmark (beta, gamma) != average acceleration, and applied generalized forces."""
    p = _prep(cases_dir, "fourbar_hac", 0.002, 2e-5)
    rng = np.random.default_rng(1)
    rows = np.array([1, 4], np.int32)  # free-DOF numbers (1-based)
    q_val = np.asfortranarray(rng.normal(size=(2, p.rig.shape[2])))
    ray = (30.0, 2e-5)
    uf, _, _ = p.fe.run(p.rig, "hac", p.dt, beta=0.3025, gamma=0.6, rayleigh=ray, q_free=rows, q_val=q_val)
    q_all = np.zeros((p.fe.ndof, p.rig.shape[2]))
    for r, qv in zip(rows, q_val):
        q_all[np.flatnonzero(p.fe.free_of == r)[0]] = qv
    ref = newmark(p.fe, p.rig, "hac", p.dt, beta=0.3025, gamma=0.6, rayleigh=ray, q_all=q_all)
    assert np.max(np.abs(uf - ref)) < 1e-9 * np.max(np.abs(ref))


@pytest.mark.parametrize("model", fm.SUPERPOSITION_MODELS)
def test_ked_matrices_and_loads_match_numpy(cases_dir, model):
    p = _prep(cases_dir, "manipulator_bricout", 0.01, 1e-3)
    rig = p.rig[:, :, 5]
    mm, cm, km, f = p.fe.matrices(rig, model, rayleigh=(3.0, 1e-4))
    M, C, K, F = system(p.fe, rig, model, rayleigh=(3.0, 1e-4))
    free = np.flatnonzero(p.fe.free_of > 0)
    free = free[np.argsort(p.fe.free_of[free])]
    ix = np.ix_(free, free)
    for a, b in ((mm, M[ix]), (cm, C[ix]), (km, K[ix])):
        assert np.allclose(a, b, rtol=1e-12, atol=1e-12 * np.max(np.abs(b)))
    assert np.allclose(f, F, rtol=1e-12, atol=1e-12 * np.max(np.abs(F)))
    loads = p.fe.loads(p.rig[:, :, 3:6], model)
    assert np.allclose(loads[:, 2], F, rtol=1e-12, atol=1e-12 * np.max(np.abs(F)))


def test_kernel_status_becomes_solver_error(cases_dir):
    """A zero-mass system is singular: the compiled status code surfaces as SolverError naming the time."""
    p = _prep(cases_dir, "fourbar_hac", 0.001, 1e-4)
    fe = p.fe
    saved = fe.el_prop.copy()
    try:
        fe.el_prop[2, :] = 0.0       # rho*A = 0: no mass at all
        fe.lm_prop[0, :] = 0.0
        with pytest.raises(fm.SolverError, match=r"singular.*") as exc:
            fe.run(p.rig, "hac", p.dt)
        assert exc.value.code == 1 and exc.value.time == 0.0
    finally:
        fe.el_prop[:] = saved
