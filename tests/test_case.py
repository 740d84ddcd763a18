"""Case files: validation messages name the field and the fix; overrides; every case file is valid."""

import copy

import pytest

import flexmech_py as fm
from flexmech_py.case import apply_overrides

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib


@pytest.fixture
def raw(cases_dir):
    return tomllib.loads((cases_dir / "fourbar_hac.toml").read_text())


def test_every_case_file_validates(cases_dir):
    files = sorted(cases_dir.glob("**/*.toml"))
    assert len(files) >= 4
    for f in files:
        case = fm.load_case(f)
        assert case["solver"]["t_end"] > 0


@pytest.mark.parametrize("mutate, field, hint", [
    (lambda r: r["links"][1].update(colour="red"), "links[1].colour", "unknown key"),
    (lambda r: r["links"][0].pop("length"), "links[0].length", "missing"),
    (lambda r: r["links"][0].update(length="long"), "links[0].length", "must be a number"),
    (lambda r: r["links"][2].update(area=0.0), "links[2].area", "> 0"),
    (lambda r: r["links"][2].update(youngs_modulus=-1.0), "links[2].youngs_modulus", "> 0"),
    (lambda r: r["solver"].update(dt=0.0), "solver.dt", "> 0"),
    (lambda r: r["solver"].update(dt=1.0), "solver.dt", "longer than the run"),
    (lambda r: r["solver"].update(output_every=10**9), "solver.output_every", "more than the run's"),
    (lambda r: r["solver"].update(gamma=0.4), "solver.gamma", ">= 0.5"),
    (lambda r: r["joints"].update(crank_pivot="weld"), "joints.crank_pivot", "one of"),
    (lambda r: r.update(solvr={}), "case file.solvr", "unknown key"),
    (lambda r: r["outputs"].update(x={"kind": "strain", "link": "conrod"}), "outputs.x.link", "one of"),
    (lambda r: r["outputs"].update(x={"kind": "speed"}), "outputs.x.kind", "one of"),
    (lambda r: r["outputs"].update(x={"kind": "position", "at": "coupler.end"}), "outputs.x.component", "missing"),
    (lambda r: r["point_masses"][0].update(at="crank.tip"), "point_masses[0].at", "start, mid, end"),
    (lambda r: r["drive"]["torques"][0].update(joint="elbow"), "drive.torques[0].joint", "one of"),
    (lambda r: r["initial"].update(angles=[0.0, 1.0]), "initial.angles", "list of 1"),
    (lambda r: r["mechanism"].update(type="slider"), "mechanism.type", "one of"),
    (lambda r: r["drive"].update(speed=10.0), "drive.speed", "does not apply"),
    (lambda r: r.update(drive={"type": "kinematic", "law": "constant_speed", "speed": 1.0}), "initial.speeds",
     "does not apply"),
    (lambda r: r["solver"].update(beta=0.2), "solver.beta", "conditionally stable"),
])
def test_bad_input_names_field(raw, mutate, field, hint):
    bad = copy.deepcopy(raw)
    mutate(bad)
    with pytest.raises(fm.CaseError) as exc:
        fm.validate_case(bad)
    assert exc.value.field == field
    assert hint in str(exc.value)


def test_node_not_on_mesh_is_rejected(cases_dir):
    case = fm.load_case(cases_dir / "fourbar_hac.toml",
                        overrides=['outputs.q = {kind = "displacement", at = "coupler.0.3", component = "x"}'])
    with pytest.raises(fm.CaseError, match=r"outputs.q.at.*not at a mesh node"):
        fm.simulate(case)


def test_linkage_that_cannot_assemble(cases_dir):
    """Caught when the case is read: the template cannot draw the linkage."""
    with pytest.raises(fm.MechanismError, match="cannot assemble"):
        fm.load_case(cases_dir / "fourbar_hac.toml", overrides=["links.crank.length=1.0"])


def test_zero_stiffness_elastic_problem_is_rejected(cases_dir):
    case = fm.load_case(cases_dir / "manipulator_bricout.toml", overrides=["joints.joint_2=pin", "solver.t_end=0.001"])
    with pytest.raises(fm.CaseError, match=r"joints.*zero-stiffness"):
        fm.simulate(case)


@pytest.mark.parametrize("n", [32, 96])
def test_zero_stiffness_check_on_fine_meshes(cases_dir, n):
    """The check compares squared natural frequencies (K x = w^2 M x), not K's own eigenvalues, whose
    axial-to-bending spread on short elements once made it reject the seed four-bar at 32 elements
    per link; a free crank pivot is still caught."""
    from flexmech_py.run.simulate import Prepared
    from flexmech_py.models.superposition.loads import check_elastic_problem

    ok = Prepared(fm.load_case(cases_dir / "fourbar_hac.toml", overrides=["solver.t_end=1e-4"]), elements_per_link=n)
    check_elastic_problem(ok.fe, ok.rig)
    free = Prepared(fm.load_case(cases_dir / "fourbar_hac.toml", overrides=["solver.t_end=1e-4", "joints.crank_pivot=pin"]),
                    elements_per_link=n)
    with pytest.raises(fm.CaseError, match=r"1 unintended zero-stiffness"):
        check_elastic_problem(free.fe, free.rig)


def test_overrides(raw):
    out = apply_overrides(raw, ["solver.dt=2e-5", "links.coupler.area=5e-5", "links.0.length=0.1",
                                'joints.follower_pivot="clamp"', "loads.gravity=[0, -9.81]", "case.title=hello world"])
    assert out["solver"]["dt"] == 2e-5
    assert out["links"][1]["area"] == 5e-5
    assert out["links"][0]["length"] == 0.1
    assert out["joints"]["follower_pivot"] == "clamp"
    assert out["loads"]["gravity"] == [0, -9.81]
    assert out["case"]["title"] == "hello world"
    assert raw["solver"]["dt"] == 1e-5  # the input is not modified
    with pytest.raises(fm.CaseError, match="no entry named 'rod'"):
        apply_overrides(raw, ["links.rod.area=1"])
    with pytest.raises(fm.CaseError, match="KEY.PATH=VALUE"):
        apply_overrides(raw, ["solver.dt"])


def test_rectangular_section_half_depth(cases_dir):
    case = fm.load_case(cases_dir / "fourbar_hac.toml")
    assert case["links"][1]["half_depth"] == pytest.approx(0.8e-3, rel=1e-3)  # 1.6 mm coupler


def test_an_empty_override_removes_the_key(cases_dir):
    """`--set KEY=` removes a key (issue 24): a drive switched from spinup to constant_speed loses the
    spinup's parameters, which validation would otherwise refuse; [[drives]] are also named by their
    joint.  Removing what is not there says what is."""
    from pathlib import Path

    watt = Path(__file__).parent / "data" / "watt_sixbar_spinup.toml"
    raw = tomllib.loads(watt.read_text())
    switch = ["drives.crank_pivot.law=constant_speed", "drives.crank_pivot.speed=60.0"]
    with pytest.raises(fm.CaseError, match="final_speed: unknown key"):
        fm.validate_case(apply_overrides(raw, switch))
    out = apply_overrides(raw, switch + ["drives.crank_pivot.final_speed=", "drives.0.spinup_time= "])
    assert out["drives"][0] == {"joint": "crank_pivot", "law": "constant_speed", "speed": 60.0}
    case = fm.validate_case(out)
    assert case.mechanism.drives[0].law == "constant_speed"
    assert apply_overrides(raw, ['case.title=""'])["case"]["title"] == ""          # an empty string, quoted
    assert "rotary_inertias" not in apply_overrides({"rotary_inertias": []}, ["rotary_inertias="])
    with pytest.raises(fm.CaseError, match=r"nothing to remove: drives\.0 has no key 'foo' \(its keys: final_speed"):
        apply_overrides(raw, ["drives.0.foo="])
    with pytest.raises(fm.CaseError, match="nothing to remove: loads is not in the case"):
        apply_overrides(raw, ["loads.gravity="])
    with pytest.raises(fm.CaseError, match="cannot remove a whole array element"):
        apply_overrides(raw, ["links.crank="])


@pytest.mark.parametrize("at, turns_with", [("coupler.0.25", None), ("coupler.0.75", "coupler"),
                                            ("crank.end", "coupler"), ("coupler.mid", None)])
def test_rotary_inertia_at_any_node_fraction(cases_dir, at, turns_with):
    """A rotary inertia at a fraction of a link that is a mesh node (0.25 with 4 elements) sits on that
    node's rotation of the link it turns with (it was refused: "link 'coupler' does not pass through
    'coupler.0.25'"), as at a named point; its J counts in the link's rigid inertia."""
    from flexmech_py.models.superposition.model import FEModel

    spec = f'{{at = "{at}", inertia = 2e-5' + (f', turns_with = "{turns_with}"}}' if turns_with else "}")
    case = fm.load_case(cases_dir / "fourbar_hac.toml",
                        overrides=["mesh.elements_per_link=4", f"rotary_inertias=[{spec}]"])
    fe = FEModel.from_case(case)
    _, node, _ = fe.node_ref(at, "at")
    carrier = fe.link_names.index(turns_with or at.split(".")[0])
    assert fe.ri_dof.tolist() == [fe.rot_dof[(node, carrier)] + 1] and fe.ri_prop.tolist() == [2e-5]
    assert [j for _, j in case.mechanism.links[carrier].hubs] == [2e-5]
