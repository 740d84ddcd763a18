"""Comparisons of like with like (issue 24, docs/theory.md section 8.1): a kinematically driven joint
reads its law in every model, a link angle is its chord in every model, ``displacement`` is measured
from the rigid-body solution and ``deflection`` from the rigid mechanism at the model's own joint
coordinates; ``compare --models`` says where a column's two curves are not the same quantity."""

import json

import numpy as np
import pytest

import flexmech_py as fm
from flexmech_py.base.errors import CaseError
from flexmech_py.cli import main
from flexmech_py.definitions import definition_notes
from flexmech_py.run.simulate import Prepared

SLOW = ["drive.speed=20.0", "solver.t_end=0.1", "mesh.elements_per_link=4", "solver.output_every=10",
        "solver.rayleigh=[0.0, 2e-5]", "solver.error_estimate=none",
        'outputs.crank={kind = "joint_angle", joint = "crank_pivot"}',
        'outputs.crank_speed={kind = "joint_speed", joint = "crank_pivot"}',
        'outputs.pivot={kind = "joint_angle", joint = "follower_pivot"}',
        'outputs.follower={kind = "link_angle", link = "follower"}',
        'outputs.coupler={kind = "link_angle", link = "coupler"}',
        'outputs.d_mid={kind = "displacement", at = "coupler.mid", component = "transverse"}',
        'outputs.f_mid={kind = "deflection", at = "coupler.mid", component = "transverse"}']


@pytest.fixture(scope="module")
def slow_fourbar():
    """The seed four-bar at a constant 20 rad/s, inside the small-deflection range (0.6 % of a link's
    length): every model family valid, the rigid-body solution on the same grid."""
    case = fm.load_case("fourbar_constant_speed", overrides=SLOW)
    prep = Prepared(case)
    runs = {m: prep.run(m) for m in ("classic", "coupled", "nonlinear")}
    return runs, prep.source(runs["classic"].t)


def test_a_driven_joint_reads_its_drive_law_in_every_model(slow_fourbar):
    """The crank's joint angle is the prescribed one in every family (the coupled and nonlinear models
    reported the flexible crank's chord, 0.19 rad off the law at 120 rad/s)."""
    runs, _ = slow_fourbar
    for m, r in runs.items():
        np.testing.assert_allclose(r["crank"], 20.0 * r.t, atol=1e-12, err_msg=m)
        np.testing.assert_allclose(r["crank_speed"], 20.0, rtol=1e-5, err_msg=m)


def test_a_links_angle_is_its_chord_in_both_families(slow_fourbar):
    """A link angle is the link's chord, in the superposition models as in the coupled one: their
    elastic parts (the value minus the rigid-body solution's) agree within 5 % of their peaks (in the
    superposition models it was the rigid frame, with no elastic part).  A joint that no kinematic
    drive moves stays the model's rigid coordinate (the frames against the chords: compare marks it)."""
    runs, rm = slow_fourbar
    c, k = runs["classic"], runs["coupled"]
    rigid = {"follower": np.unwrap(rm.motion.phi[:, 2]), "coupler": np.unwrap(rm.motion.phi[:, 1])}
    for col, ref in rigid.items():
        ec, ek = c[col] - ref, k[col] - ref
        peak = np.max(np.abs(ek))
        assert peak > 1e-3, col                                     # an elastic part worth comparing
        assert np.max(np.abs(ec - ek)) < 0.05 * peak, (col, np.max(np.abs(ec - ek)) / peak)
    np.testing.assert_allclose(c["pivot"], rm.joint("follower_pivot")[:, 0], atol=1e-9)   # the rigid frames
    np.testing.assert_allclose(k["pivot"] - k["pivot"][0], k["follower"] - k["follower"][0], atol=1e-12)  # chord


def test_deflection_is_the_displacement_when_every_dof_is_driven(slow_fourbar):
    runs, _ = slow_fourbar
    for m, r in runs.items():
        np.testing.assert_array_equal(r["f_mid"], r["d_mid"], err_msg=m)


@pytest.fixture(scope="module")
def torque_fourbar():
    """The torque-driven seed four-bar over 0.1 s, 4 elements per link: a free degree of freedom, whose
    coupled rigid motion drifts from the rigid-body solution."""
    case = fm.load_case("fourbar_hac", overrides=[
        "solver.t_end=0.1", "mesh.elements_per_link=4", "solver.error_estimate=none",
        'outputs.d_a={kind = "displacement", at = "crank.end", component = "transverse"}',
        'outputs.f_a={kind = "deflection", at = "crank.end", component = "transverse"}',
        'outputs.f_mid={kind = "deflection", at = "coupler.mid", component = "rotation"}'])
    prep = Prepared(case)
    return {m: prep.run(m) for m in ("classic", "coupled")}


def test_deflection_leaves_out_the_drift_of_the_models_rigid_motion(torque_fourbar):
    """The crank tip of the torque-driven four-bar: measured from the rigid-body solution, the coupled
    model's crank tip moves 6.9 times as far as the superposition model's crank bends (its crank angle
    drifts from the rigid one); measured from the rigid mechanism at its own crank angle, it deflects
    as the superposition model's does (within 30 %, the two models' different physics).  In the
    superposition model (the crank clamped at its hub) the two measures are one."""
    c, k = torque_fourbar["classic"], torque_fourbar["coupled"]
    np.testing.assert_allclose(c["f_a"], c["d_a"], rtol=0, atol=1e-10)    # the loop closure's tolerance
    peak = {m: {col: np.max(np.abs(r[col])) for col in ("d_a", "f_a")} for m, r in torque_fourbar.items()}
    assert peak["coupled"]["d_a"] > 5 * peak["classic"]["d_a"]
    assert 0.7 < peak["coupled"]["f_a"] / peak["classic"]["f_a"] < 1.3, peak
    assert np.all(np.isfinite(k["f_mid"])) and np.max(np.abs(k["f_mid"])) < 0.1


def test_compare_models_marks_columns_that_are_not_the_same_quantity(cases_dir, tmp_path, capsys):
    case = fm.load_case("fourbar_hac", overrides=[
        'outputs.d_mid={kind = "displacement", at = "coupler.mid", component = "y"}',
        'outputs.f_mid={kind = "deflection", at = "coupler.mid", component = "y"}',
        'outputs.load_c={kind = "inertia_load", at = "coupler.mid", component = "y", model = "classic"}'])
    notes = definition_notes(case, "hac", "coupled", free_motion=True)
    assert set(notes) == {"d_mid", "load_coupler_mid_x", "load_coupler_mid_y", "load_joint_a_x", "load_joint_a_y",
                          "load_joint_b_x", "load_joint_b_y", "load_norm", "crank_angle", "crank_speed"}
    assert "drift" in notes["d_mid"] and "deflection" in notes["d_mid"] and "link_angle" in notes["crank_angle"]
    driven = fm.load_case("fourbar_constant_speed", overrides=['outputs.crank={kind = "joint_angle", joint = '
                                                               '"crank_pivot"}'])
    assert "crank" not in definition_notes(driven, "hac", "coupled", free_motion=False)   # reads its law
    assert "d_mid" not in definition_notes(case, "hac", "coupled", free_motion=False)      # every DOF driven
    assert "d_mid" not in definition_notes(case, "coupled", "nonlinear", free_motion=True)  # one family
    assert not any(k.startswith("load") for k in definition_notes(case, "classic", "nonlinear", True))
    rc = main(["compare", "--models", str(cases_dir / "fourbar_hac.toml"), "--set", "solver.t_end=0.01",
               "--set", 'outputs.d_mid={kind = "displacement", at = "coupler.mid", component = "y"}',
               "--set", 'outputs.f_mid={kind = "deflection", at = "coupler.mid", component = "y"}',
               "--model-list", "hac", "--reference-model", "coupled", "--out", str(tmp_path / "c")])
    out = capsys.readouterr().out
    assert rc == 0 and "d_mid*" in out and "f_mid*" not in out and "* d_mid: not the same quantity" in out
    js = json.loads((tmp_path / "c" / "hac" / "compare.json").read_text())
    assert "drift" in js["columns"]["d_mid"]["definition_note"] and "definition_note" not in js["columns"]["f_mid"]


def test_a_joint_output_measured_at_the_joint_is_one_quantity_in_every_family():
    """``measure = "joint"``: the tangents at the joint (the hub) in every model, so compare --models does
    not mark it where the default (the model's frames: chords against the rigid-body solution) is
    marked; an unknown measure is refused naming the field."""
    hub = 'outputs.hub={kind = "joint_speed", joint = "crank_pivot", measure = "joint"}'
    notes = definition_notes(fm.load_case("fourbar_hac", overrides=[hub]), "hac", "coupled", free_motion=True)
    assert "crank_speed" in notes and "hub" not in notes
    assert 'measure = "joint"' in notes["crank_speed"]
    with pytest.raises(CaseError, match="outputs.hub.measure"):
        fm.load_case("fourbar_hac", overrides=[hub.replace('"joint"}', '"hub"}')])
