"""The condensed solve of the coupled and nonlinear models (theory.md §11, "The solve"): every
segment's elastic DOFs eliminated onto the shared end positions must give the same runs as the
factorization of the whole band matrix, to the round-off the Newton iteration carries."""

import numpy as np
import pytest

import flexmech_py as fm
from flexmech_py.base import kernels
from flexmech_py.mechanism.rows import ROW_KINDS

BAND, CONDENSED, AUTO = 0, 1, -1

# uneven meshes (6/4/8 and 6/4 elements per link): segments of different sizes share joints
CASES = [("fourbar_hac", ["links.0.elements=6", "links.1.elements=4", "links.2.elements=8"]),
         ("manipulator_bricout", ["links.0.elements=6", "links.1.elements=4"]),
         ("fourbar_constant_speed", ["links.0.elements=4", "links.1.elements=8", "links.2.elements=6"])]


def _run(cases_dir, name, extra, model, mode):
    assert kernels.cpl.cpl_set_solver(mode) == 0
    try:
        case = fm.load_case(cases_dir / f"{name}.toml",
                            overrides=["solver.t_end=0.003", "solver.dt=1e-5", "solver.output_every=10"] + extra)
        return fm.simulate(case, model=model)
    finally:
        kernels.cpl.cpl_set_solver(AUTO)


@pytest.mark.parametrize("model", ["coupled", "nonlinear"])
@pytest.mark.parametrize("name, extra", CASES, ids=[c[0] for c in CASES])
def test_condensed_solve_equals_band_solve(cases_dir, name, extra, model):
    """300 steps (torque drive; kinematic drive for fourbar_constant_speed, i.e. with the Lagrange
    multiplier's X = S^-1 G solves): every output column agrees between the two solves to 1e-6 of its
    largest value (observed: up to 8e-9; the old and the new assembly of the same band solve differ
    by as much, the stiff chord terms amplify the round-off), with the same Newton iterations."""
    ref = _run(cases_dir, name, extra, model, BAND)
    new = _run(cases_dir, name, extra, model, CONDENSED)
    assert np.array_equal(ref.columns["newton_iterations"], new.columns["newton_iterations"])
    worst = 0.0
    for key, col in ref.columns.items():
        col, other = np.asarray(col, float), np.asarray(new.columns[key], float)
        scale = np.max(np.abs(col))
        if scale > 0:
            worst = max(worst, np.max(np.abs(other - col)) / scale)
    print(f"\n{name} {model}: largest relative difference {worst:.2e}")
    assert worst < 1e-6
    # and the energy balance of the condensed run holds like the reference's
    e_ref = ref["energy_kinetic"] + ref["energy_potential"] - ref["work_inputs"]
    e_new = new["energy_kinetic"] + new["energy_potential"] - new["work_inputs"]
    assert np.max(np.abs(e_new - e_ref)) <= 1e-6 * max(np.max(np.abs(ref["energy_kinetic"])), 1e-30)


SCHUR, SADDLE = 0, 1

# many rows (the nonlinear model's weld per interior node with relative angles: 21, 9, 6 + joints),
# force and kinematic drives, rigid bodies (the plate six-bar)
SADDLE_CASES = [("fourbar_hac", 8, []), ("fourbar_constant_speed", 4, []), ("manipulator_bricout", 4, []),
                ("sixbar_plate", 3, [])]


def _run_multipliers(cases_dir, name, epl, model, mode, solver=BAND):
    """The run with the given solver (the whole band unless said) and multiplier modes."""
    assert kernels.cpl.cpl_set_multipliers(mode) == 0 and kernels.cpl.cpl_set_solver(solver) == 0
    try:
        case = fm.load_case(cases_dir / f"{name}.toml",
                            overrides=["solver.t_end=0.004", "solver.dt=1e-5", "solver.output_every=10",
                                       f"mesh.elements_per_link={epl}", "solver.error_estimate='none'"])
        return fm.simulate(case, model=model)
    finally:
        kernels.cpl.cpl_set_multipliers(AUTO)
        kernels.cpl.cpl_set_solver(AUTO)


BORDERED = 2


@pytest.mark.parametrize("solver", ["saddle", "bordered"])
@pytest.mark.parametrize("name, epl, extra", SADDLE_CASES, ids=[c[0] for c in SADDLE_CASES])
def test_saddle_band_equals_schur_complement(cases_dir, name, epl, extra, solver):
    """The multipliers by the band LU of the whole saddle-point system (flexmech_saddle_band: over
    the whole free-DOF band, or the nonlinear model's bordered saddle band, theory.md 12.6) against
    their dense Schur complement over the whole band, nonlinear model, 400 steps: the motion
    (angles, displacements, strains) and the energies agree to 1e-7 of each column's largest value,
    with the same Newton iterations; constraint forces to 1e-4 (observed 2e-5 on the seed four-bar's
    joint loads at the default Newton tolerance, shrinking with it: the iteration accepts on the
    accelerations, and the multipliers carry the iteration's error amplified)."""
    ref = _run_multipliers(cases_dir, name, epl, "nonlinear", SCHUR)
    new = (_run_multipliers(cases_dir, name, epl, "nonlinear", SADDLE) if solver == "saddle" else
           _run_multipliers(cases_dir, name, epl, "nonlinear", AUTO, BORDERED))
    assert ref.extra["coupled"]["solver"]["path"].startswith("band, multipliers by their Schur")
    assert new.extra["coupled"]["solver"]["path"] == ("saddle band" if solver == "saddle" else "bordered saddle band")
    assert np.array_equal(ref.columns["newton_iterations"], new.columns["newton_iterations"])
    forces = {k for k in ref.columns if k.startswith(("load_", "drive_")) or "force" in k or "torque" in k}
    for key, col in ref.columns.items():
        col, other = np.asarray(col, float), np.asarray(new.columns[key], float)
        scale = np.max(np.abs(col))
        if scale > 0:
            assert np.max(np.abs(other - col)) <= (1e-4 if key in forces else 1e-7) * scale, key


def test_set_multipliers_rejects_unknown_mode():
    assert kernels.cpl.cpl_set_multipliers(2) == 4
    assert kernels.cpl.cpl_set_multipliers(AUTO) == 0


def test_set_solver_rejects_unknown_mode():
    assert kernels.cpl.cpl_set_solver(7) == 4
    assert kernels.cpl.cpl_set_solver(3) == 4
    assert kernels.cpl.cpl_set_solver(AUTO) == 0


def test_kernel_rejects_a_corrupted_flat_description(cases_dir):
    """coupled_build checks the flat description before it builds anything: a wrong length of
    either array, an element count out of range, a marker or a DOF index out of range each give
    status 4 (bad input) and no residual; the intact description builds (status 0)."""
    from flexmech_py.base import kernels
    from flexmech_py.run.simulate import Prepared

    case = fm.load_case(cases_dir / "slider_crank.toml", overrides=["solver.t_end=0.001"])
    p = Prepared(case, elements_per_link=2)
    p.run("coupled")
    cm = p.coupled["coupled"]
    st = cm.last_run
    ispec, rspec = cm._spec(p.gravity, (0.0, 0.0))
    q = np.asfortranarray(st["q"][:, None])

    def status(isp, rsp):
        res, code = kernels.cpl.cpl_residuals(np.asarray(isp, dtype=np.int32), rsp, q, st["v"], st["a"], 0.0)
        return code, res

    code, res = status(ispec, rspec)
    assert code == 0 and np.abs(res).max() > 0
    header = 12                                   # COUPLED_NSPEC_HEADER
    nseg, nrb, ndof, maxn = ispec[:4]
    ld0 = header + nseg                            # first entry of ld
    con0 = header + nseg * (1 + 3 * maxn + 3) + 3 * nrb + ndof + 2 * ispec[4] + 2 * ispec[5] + 3 * ispec[6]
    bad = {"ispec one short": (ispec[:-1], rspec), "rspec one long": (ispec, np.append(rspec, 0.0)),
           "no elements in a segment": (np.where(np.arange(ispec.size) == header, 0, ispec), rspec),
           "DOF index past ndof": (np.where(np.arange(ispec.size) == ld0, ndof + 1, ispec), rspec),
           "marker index past nmk": (np.where(np.arange(ispec.size) == con0 + 1, ispec[6] + 1, ispec), rspec),
           "row kind past the table (flexmech_markers NCON)":
               (np.where(np.arange(ispec.size) == con0, max(ROW_KINDS) + 1, ispec), rspec),
           "row kind 0": (np.where(np.arange(ispec.size) == con0, 0, ispec), rspec)}
    assert ispec[7] > 0                            # the slider-crank has constraint rows
    for what, (isp, rsp) in bad.items():
        code, res = status(isp, rsp)
        assert code == 4, what
        assert not res.any(), what
