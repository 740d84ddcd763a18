"""Model families and joint kinds as protocols (docs/architecture.md): the registry's entries, the one
mesh rule of every family, the joint kinds' declarations, and the checks handed a rerun function."""

from __future__ import annotations

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib

import numpy as np
import pytest

import flexmech_py as fm
from flexmech_py.checks import guards
from flexmech_py.case import integrator_of
from flexmech_py.base.families import FAMILIES, MODELS, SUPERPOSITION_MODELS, family, large_deflection_reference, names
from flexmech_py.mechanism.joints import JOINT_KINDS
from flexmech_py.mechanism.packing import drawn_coordinates, joint_pose
from flexmech_py.mechanism.rows import ROW_KINDS
from flexmech_py.run.simulate import Prepared


def test_the_registry_is_the_one_list_of_models():
    assert fm.MODELS == MODELS == tuple(FAMILIES) and fm.SUPERPOSITION_MODELS == SUPERPOSITION_MODELS
    assert names(superposition=True) == SUPERPOSITION_MODELS
    assert set(names(superposition=False)) == set(MODELS) - set(SUPERPOSITION_MODELS)
    assert len({f.label for f in FAMILIES.values()}) == len(FAMILIES)
    assert large_deflection_reference().name == "nonlinear"
    with pytest.raises(KeyError, match="choose from"):
        family("linear")


@pytest.mark.parametrize("name", MODELS)
def test_a_family_declares_what_it_is(name):
    f = family(name)
    assert f is family(f)
    # superposition families feed the ked kernels a load model; constrained ones run the coupled loop
    assert (f.load_code is not None) == f.superposition == (f.load_mass is not None)
    assert f.constrained == (not f.superposition) == (f.dof2_bytes > 0 or f.element_bytes > 0)
    assert f.inertia_loads in SUPERPOSITION_MODELS
    assert integrator_of({}, name) == f.default_integrator
    assert f.guides_on_flexible_links == f.constrained


def test_the_load_codes_are_the_kernels_and_distinct():
    codes = [family(m).load_code for m in SUPERPOSITION_MODELS]
    assert sorted(codes) == [1, 2, 3]


def _welded_sixbar(elements: int, t_end: float = 2e-4):
    return fm.load_case("sixbar_welded", overrides=[f"mesh.elements_per_link={elements}", f"solver.t_end={t_end}"])


def test_one_mesh_rule_a_joint_at_the_middle_of_an_odd_mesh_in_every_family():
    """The welded six-bar joins its arm at the coupler's middle: with 3 elements per link every family
    puts a node there (the superposition mesher always did; the coupled one refused the case)."""
    case = _welded_sixbar(3)
    prep = Prepared(case)
    li = prep.fe.link_names.index("coupler")
    assert np.any(np.isclose(prep.fe.node_frac[li], 0.5))
    strains = {}
    for model in MODELS:
        res = prep.run(model, estimate=False)
        assert np.all(np.isfinite(res.columns["strain_rocker_mid"])), model
        strains[model] = res.columns["strain_rocker_mid"]
        nodes = res.fe.node_frac[li]
        assert np.allclose(nodes, prep.fe.node_frac[li]), model     # one mesh in every family
    # the same mesh: the coupled model follows the superposition models to small differences
    peak = np.max(np.abs(strains["classic"]))
    assert peak > 0 and np.max(np.abs(strains["coupled"] - strains["classic"])) < 0.2 * peak


def test_the_mesh_rule_keeps_a_mesh_that_already_has_the_joint_node():
    """With 4 elements the coupler's middle is a node already: the rule adds nothing (golden meshes)."""
    prep = Prepared(_welded_sixbar(4))
    li = prep.fe.link_names.index("coupler")
    assert np.allclose(prep.fe.node_frac[li], np.linspace(0, 1, 5))


@pytest.mark.parametrize("kind", sorted(JOINT_KINDS))
def test_a_joint_kind_declares_its_behaviour(kind):
    cls = JOINT_KINDS[kind]
    assert cls.kind == kind and cls.rows > 0
    assert cls.conditions and cls.driven_default in cls.conditions and set(cls.released) <= set(cls.conditions)
    assert set(cls.holding) <= set(cls.conditions)
    assert cls.coupled_rows and set(cls.coupled_rows) <= {"point", "normal", "angle", "own"}
    assert cls.coupled_coordinate == ("slide" if cls.guided else "angle")
    assert (cls.unit == "m") == cls.guided
    assert cls.has_coordinate == bool(cls.released)
    assert ("point" in cls.coupled_rows) == cls.shares_point
    assert ("angle" in cls.coupled_rows or "own" in cls.coupled_rows) == cls.ties_rotation


def test_a_joint_kind_names_its_rows_from_the_one_vocabulary():
    """Every kind's rigid rows and coordinate are rows of the Fortran table (mechanism.rows), as many
    as it declares; no kind needs a solver branch of its own."""
    case = fm.load_case("quick_return")
    mech = case.mechanism
    for j in mech.joints:
        pose = joint_pose(mech, j, drawn_coordinates(mech))
        rows = j.rigid_rows(pose)
        assert len(rows) == j.rows and all(r[0] in ROW_KINDS for r in rows)
        assert j.coordinate_row(pose.axis)[0] in ROW_KINDS


def test_a_kind_field_on_another_kind_is_refused_naming_the_kinds_that_take_it():
    spec = tomllib.loads(fm.case_path("slider_crank").read_text())
    spec["joints"][0]["axis"] = [1.0, 0.0]
    with pytest.raises(fm.CaseError,
                       match=r"joints\[0\]\.axis.*applies to prismatic and slot joints only, not to a revolute"):
        fm.validate_case(spec)


def test_the_half_step_check_reruns_through_the_function_it_is_handed():
    """guards never builds a run: the evidence of a failure comes from the run's own rerun function."""
    prep = Prepared(fm.load_case("fourbar_hac", overrides=["solver.t_end=0.001"]))
    calls = []

    def rerun(case, dt, out_every, model, geometric):
        calls.append((case["solver"]["t_end"], dt, model))
        return prep.rerun(case, dt, out_every, model, geometric)

    out = guards._half_step_check(prep, "hac", None, 5e-4, rerun)
    assert calls and calls[0][1] == pytest.approx(prep.dt / 2) and calls[0][2] == "hac"
    assert out["failed_at_s"] is None and 0.9 * prep.dt / 2 < out["dt"] <= prep.dt / 2   # the step fitted to t_end
