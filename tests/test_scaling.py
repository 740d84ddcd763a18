"""The exact model's cost linear in the elements on every mechanism (issue 30; docs/theory.md section
12.6, docs/performance.md "Scaling on every mechanism").  No clock: the operations of a Newton
step's factorization and solve as the kernel counts them from the structure it uses
(CoupledModel.structure), the ordering of the bordered saddle band, and the results of the
multi-loop mechanisms the same as before the bordered band (stored numbers) and as the whole band
with the multipliers' Schur complement (a different factorization of the same system)."""

import json
from pathlib import Path

import numpy as np
import pytest

import flexmech_py as fm
from flexmech_py.base import kernels
from flexmech_py.models.constrained.coupled import CoupledModel
from flexmech_py.models.constrained.ordering import bordered_numbering
from flexmech_py.run.simulate import Prepared

HERE = Path(__file__).resolve().parent
#: the bundled mechanisms and the tests' own: a ring of flexible links meeting no junction (rows to
#: two driven rigid arms), and a plate joining four flexible links with a slider and a welded cantilever
OWN = [HERE / "cases" / "ring_two_arms.toml", HERE / "cases" / "plate_slider_arm.toml"]
MODELS = [("coupled", "relative"), ("nonlinear", "relative"), ("nonlinear", "shared")]
BAND, SCHUR, AUTO, BORDERED = 0, 0, -1, 2


def _all_cases(cases_dir):
    return sorted(cases_dir.glob("*.toml")) + OWN


def _structure(path, model, angles, epl):
    case = fm.load_case(path, overrides=["solver.t_end=0.0002", f"solver.node_angles='{angles}'"])
    p = Prepared(case, elements_per_link=epl)
    cm = CoupledModel.from_case(p.case, split=model == "nonlinear")
    q, v = cm.initial_state(p.rm.select(slice(0, 1)))
    return cm.structure(q, v), int(sum(cm.n_el))


@pytest.mark.parametrize("model, angles", MODELS, ids=[f"{m}-{a}" for m, a in MODELS])
def test_the_step_costs_the_same_per_element_on_every_mesh(cases_dir, model, angles):
    """For every bundled mechanism and the tests' own, 32 and 128 elements per link: the operations of
    one factorization and of one solve per element grow by less than 15 % (a quadratic cost, as the
    dense Schur complement of the nonlinear model's weld rows on the multi-loop mechanisms was, grows
    fourfold), the band does not widen, the unknowns eliminated densely do not grow with the mesh,
    and the nonlinear model's band is that of one chain of elements (a single chain keeps the
    numbering it always had, whose saddle band has half width 7 or 8)."""
    for path in _all_cases(cases_dir):
        (coarse, n1), (fine, n2) = _structure(path, model, angles, 32), _structure(path, model, angles, 128)
        for key in ("flops_per_factorization", "flops_per_solve"):
            assert fine[key] / n2 <= 1.15 * coarse[key] / n1, (path.stem, key, coarse, fine)
        assert fine["band_half_width"] <= coarse["band_half_width"], (path.stem, coarse, fine)
        assert fine["dense_unknowns"] <= coarse["dense_unknowns"], (path.stem, coarse, fine)
        if model == "nonlinear":     # a single chain keeps its whole band, every other layout the bordered band
            assert fine["band_half_width"] <= 8, (path.stem, fine)
            assert fine["path"] == "bordered saddle band" or fine["dense_unknowns"] == 0 or "Schur" in fine["path"], \
                (path.stem, fine)


def test_multi_loop_costs_per_element_like_the_seed_fourbar(cases_dir):
    """The operations per element and factorization of the multi-loop mechanisms (the plate and the
    welded six-bar: two loops, a rigid plate joining three links, a junction of three chains) within
    1.25 of the seed four-bar's at 32 elements per link, nonlinear model (a single band of these
    topologies is twice as wide: four times the operations)."""
    seed = _structure(cases_dir / "fourbar_hac.toml", "nonlinear", "relative", 32)
    for name in ("sixbar_plate", "sixbar_welded"):
        st, n = _structure(cases_dir / f"{name}.toml", "nonlinear", "relative", 32)
        assert st["flops_per_factorization"] / n <= 1.25 * seed[0]["flops_per_factorization"] / seed[1], name


def _chain(nseg, first=0):
    """Segment DOF lists of a chain of nseg one-element segments: [xs ys xe ye th0 th1], shared end nodes."""
    cols, node = [], first
    for _ in range(nseg):
        cols.append([node, node + 1, node + 2, node + 3, node + 4, node + 5])
        node += 2
    return cols


def _renumber(cols, start):
    """Give every segment's angle DOFs their own numbers from start on (positions stay shared)."""
    out = []
    for c in cols:
        out.append(c[:4] + [start, start + 1])
        start += 2
    return out, start


def test_ordering_cuts_a_ring_and_puts_junctions_and_bodies_in_the_border():
    """bordered_numbering on synthetic layouts: a ring of segments (no junction) is cut at one node
    (its two DOFs go to the border) and numbered as one chain; three chains meeting at a node have
    that node in the border and every chain contiguous; a body's DOFs and every row touching them are
    border; the interior DOFs come first."""
    # a ring of 6 segments: node k = DOFs 2k, 2k+1 (k = 0..5), segment k from node k to node k+1 mod 6
    ring = [[2 * k, 2 * k + 1, 2 * ((k + 1) % 6), 2 * ((k + 1) % 6) + 1] for k in range(6)]
    ring, nd = _renumber([c + [0, 0] for c in ring], 12)
    free_of, nbd, rb = bordered_numbering(ring, [], [], np.ones(nd, bool))
    assert nbd == 2 and sorted(free_of) == list(range(1, nd + 1))
    border = np.flatnonzero(free_of > nd - nbd)
    assert border.size == 2 and border[0] // 2 == border[1] // 2 and border[0] % 2 == 0   # one node's x, y
    # three chains of 3 segments from a junction node J (DOFs 0, 1) and a body (DOFs 40..42) with a row to
    # chain 2's far end
    cols = []
    nxt = 2
    for _ in range(3):
        prev = [0, 1]
        for _ in range(3):
            cols.append(prev + [nxt, nxt + 1, 0, 0])
            prev = [nxt, nxt + 1]
            nxt += 2
    cols, nd = _renumber(cols, nxt)
    body = np.arange(nd, nd + 3)
    far = cols[5][2:4]                       # the end node of chain 2
    free_of, nbd, rb = bordered_numbering(cols, [body], [np.array(far + list(body))], np.ones(nd + 3, bool))
    assert nbd == 5 and rb.tolist() == [1]
    assert set(free_of[[0, 1]]) | set(free_of[body]) == set(range(nd + 3 - 4, nd + 4))
    for c in range(3):                       # each chain's DOFs contiguous
        dofs = {d for s in cols[3 * c:3 * c + 3] for d in s} - {0, 1}
        f = sorted(free_of[list(dofs)])
        assert f == list(range(f[0], f[0] + len(f)))


GOLDEN = json.loads((HERE / "golden_multiloop.json").read_text())


def _multiloop(cases_dir, name, angles, extra=()):
    case = fm.load_case(cases_dir / f"{name}.toml", overrides=[
        "solver.t_end=0.004", "solver.dt=1e-5", "solver.output_every=10", "mesh.elements_per_link=4",
        "solver.integrator='newmark'", f"solver.node_angles='{angles}'", "solver.error_estimate='none'", *extra])
    return fm.simulate(case, model="nonlinear")


FORCES = ("joint_c_force",)     # from the multipliers: the Newton tolerance's level, amplified


@pytest.mark.parametrize("name", ["sixbar_plate", "sixbar_welded"])
@pytest.mark.parametrize("angles", ["relative", "shared"])
def test_multi_loop_results_are_those_before_the_bordered_band(cases_dir, name, angles):
    """The multi-loop mechanisms' nonlinear runs (400 steps) against the numbers stored before the
    bordered saddle band (git 118de6d: the plate six-bar's multipliers by their dense Schur
    complement, the welded one's by the condensed segments): the same Newton iterations, the motion and
    strains to 1e-7 of each column's largest value (observed up to 3e-9: a different order of the same
    band elimination), the joint force to 1e-4 (observed 6e-6; the multipliers carry the Newton
    tolerance)."""
    res = _multiloop(cases_dir, name, angles)
    vals = GOLDEN["values"]
    assert int(np.sum(res.columns["newton_iterations"])) == vals[f"{name}/{angles}/newton_iterations"]
    for key, ref in vals.items():
        case, ang, col = key.split("/")
        if case != name or ang != angles or col == "newton_iterations":
            continue
        ref, now = np.array(ref), np.asarray(res[col], float)[::10]
        tol = 1e-4 if col in FORCES else 1e-7
        assert np.max(np.abs(now - ref)) <= tol * np.max(np.abs(ref)), col


def _forced(mode_solver, mode_mult, fn):
    assert kernels.cpl.cpl_set_solver(mode_solver) == 0 and kernels.cpl.cpl_set_multipliers(mode_mult) == 0
    try:
        return fn()
    finally:
        kernels.cpl.cpl_set_solver(AUTO)
        kernels.cpl.cpl_set_multipliers(AUTO)


@pytest.mark.parametrize("path", OWN, ids=[p.stem for p in OWN])
def test_bordered_band_equals_the_whole_band_on_the_tests_mechanisms(path):
    """On the tests' own mechanisms (the ring, the plate with slider and cantilever; 3 elements per
    link, 200 steps) the bordered saddle band and the whole band with the multipliers' dense Schur
    complement give the same Newton iterations, motion and strains to 1e-7 of each column's largest
    value and forces to 1e-4."""
    case = fm.load_case(path, overrides=["solver.t_end=0.002", "mesh.elements_per_link=3", "solver.error_estimate='none'"])
    new = _forced(BORDERED, AUTO, lambda: fm.simulate(case, model="nonlinear"))
    ref = _forced(BAND, SCHUR, lambda: fm.simulate(case, model="nonlinear"))
    assert new.extra["coupled"]["solver"]["path"] == "bordered saddle band"
    assert ref.extra["coupled"]["solver"]["path"].startswith("band, multipliers by their Schur")
    assert np.array_equal(ref.columns["newton_iterations"], new.columns["newton_iterations"])
    for key, col in ref.columns.items():
        col, other = np.asarray(col, float), np.asarray(new.columns[key], float)
        scale = np.max(np.abs(col))
        if scale > 0:
            tol = 1e-4 if "force" in key or "torque" in key else 1e-7
            assert np.max(np.abs(other - col)) <= tol * scale, key
