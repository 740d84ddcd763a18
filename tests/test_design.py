"""Sections, materials, stresses, joint loads and fatigue (issue 28; docs/validation.md "Stress and
fatigue"): section properties against handbook formulas, stresses against the closed forms of a
rotating cantilever and a pinned-pinned link under their own inertia, the strain and axial-force
outputs at the named stations, rainflow counts of the ASTM E1049 example, Miner's sum of a
constant-amplitude history, and the command line's files and bad-input messages."""

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flexmech_py.case import load_case, validate_case
from flexmech_py.strength.analysis import DesignAnalysis
from flexmech_py.base.errors import CaseError
from flexmech_py.strength.fatigue import cycle_damage, equivalent_amplitude, rainflow_cycles
from flexmech_py.mechanism.materials import MATERIALS, material_values
from flexmech_py.run.runner import MemorySink, execute
from flexmech_py.mechanism.sections import section_properties
from flexmech_py.run.simulate import Prepared
from flexmech_py.strength.stress import link_stations, station_values

DATA = Path(__file__).parent / "data"
BEAM = Path(__file__).parent / "data" / "rotating_beam.toml"
FLEXMECH = [sys.executable, "-m", "flexmech_py"]

PINNED = """
[case]
title = "pinned-pinned coupler"
[mechanism]
type = "fourbar"
ground_length = 0.254
assembly = "open"
[[links]]
name = "crank"
length = 0.06
rigid = true
mass = 0.05
inertia = 2e-5
[[links]]
name = "coupler"
length = 0.28
section = { shape = "rectangle", width = 0.02, height = 0.01 }
material = "structural-steel"
[[links]]
name = "follower"
length = 0.27
rigid = true
mass = 0.1
inertia = 1e-3
[mesh]
elements_per_link = 8
[joints]
crank_pivot = "clamp"
crank_coupler = "pin"
coupler_follower = "pin"
follower_pivot = "pin"
[drive]
type = "kinematic"
law = "spinup"
final_speed = 40.0
spinup_time = 0.5
[initial]
angles = [0.0]
[solver]
t_end = 0.5
dt = 2.0e-4
output_every = 5
model = "hac"
error_estimate = "none"
[outputs]
mid_strain = { kind = "strain", link = "coupler", at = 0.5 }
mid_axial = { kind = "axial_force", link = "coupler", at = 0.5 }
"""


# ----------------------------------------------------------------------------- sections and materials
@pytest.mark.parametrize("spec, area, inertia, c", [
    # Roark's Formulas for Stress and Strain, Table A.1 (cases 1, 15, 16 and the I-section as two flanges and a web)
    ({"shape": "rectangle", "width": 0.0254, "height": 0.0016}, 0.0254 * 0.0016, 0.0254 * 0.0016 ** 3 / 12, 0.0008),
    ({"shape": "circle", "diameter": 0.02}, math.pi * 1e-4, math.pi * 0.02 ** 4 / 64, 0.01),
    ({"shape": "tube", "outer_diameter": 0.02, "wall": 0.002}, math.pi * (0.02 ** 2 - 0.016 ** 2) / 4,
     math.pi * (0.02 ** 4 - 0.016 ** 4) / 64, 0.01),
    ({"shape": "hollow_rectangle", "width": 0.02, "height": 0.04, "wall": 0.002}, 0.02 * 0.04 - 0.016 * 0.036,
     (0.02 * 0.04 ** 3 - 0.016 * 0.036 ** 3) / 12, 0.02),
    ({"shape": "i_section", "width": 0.05, "height": 0.1, "flange": 0.008, "web": 0.005},
     2 * 0.05 * 0.008 + 0.084 * 0.005, 0.005 * 0.084 ** 3 / 12 + 2 * (0.05 * 0.008 ** 3 / 12 + 0.05 * 0.008 * 0.046 ** 2),
     0.05),
])
def test_section_properties_match_handbook_formulas(spec, area, inertia, c):
    _, p = section_properties(spec, "s")
    assert p.area == pytest.approx(area, rel=1e-12)
    assert p.second_moment == pytest.approx(inertia, rel=1e-12)
    assert p.half_depth == pytest.approx(c, rel=1e-12)


def test_the_seed_strip_gives_the_seed_numbers_and_a_written_case_keeps_its_section(tmp_path):
    case = load_case("fourbar_design")
    cp = case["links"][1]
    assert cp["area"] == pytest.approx(0.406e-4, rel=1e-3) and cp["second_moment"] == pytest.approx(8.67e-12, rel=1e-3)
    assert cp["youngs_modulus"] == MATERIALS["6061-T6"]["youngs_modulus"]
    assert cp["yield_strain"] == pytest.approx(276e6 / 68.9e9)
    text = case.write(tmp_path / "c.toml").read_text()
    assert "section = {shape = \"rectangle\"" in text and "second_moment = 8.6" not in text.split("coupler")[1]
    again = load_case(tmp_path / "c.toml", ["links.coupler.section.height=2e-3"])
    assert again["links"][1]["second_moment"] == pytest.approx(0.0254 * 0.002 ** 3 / 12)


def test_basquin_lines_pass_through_their_published_points():
    for name, m in MATERIALS.items():
        s = lambda n: m["basquin_coefficient"] * n ** m["basquin_exponent"]   # noqa: E731
        assert s(1e3) == pytest.approx(0.9 * m["ultimate_strength"], rel=1e-12), name
        assert s(m["fatigue_cycles"]) == pytest.approx(m["fatigue_strength"], rel=1e-12), name
    assert material_values({"name": "7075-T6", "yield_strength": 450e6}, "m")["yield_strength"] == 450e6


@pytest.mark.parametrize("override, field, words", [
    ("links.coupler.section.shape=oval", "links[1].section.shape", "'rectangle', 'circle', 'tube'"),
    ("links.coupler.section={shape='tube', outer_diameter=0.01, wall=0.006}", "links[1].section.wall",
     "thinner than its radius"),
    ("links.coupler.section.height=-0.001", "links[1].section.height", "must be > 0"),
    ("links.coupler.material=unobtainium", "links[1].material", "structural-steel, 6061-T6"),
    ("links.coupler.area=1e-5", "links[1].area", "remove area or remove section"),
    ("links.coupler.material={youngs_modulus=7e10, density=2700, yield_strength=5e8, ultimate_strength=3e8}",
     "links[1].material.yield_strength", "exceeds ultimate_strength"),
    ("links.coupler.section={shape='i_section', width=0.01, height=0.01, flange=0.006, web=0.002}",
     "links[1].section.flange", "two flanges"),
])
def test_bad_sections_and_materials_name_the_field_and_the_fix(override, field, words):
    with pytest.raises(CaseError) as err:
        load_case("fourbar_design", [override])
    assert str(err.value).startswith(field) and words in str(err.value)


# ----------------------------------------------------------------------------- stress
def _quasi_static_cantilever(res, st):
    ln = res.case["links"][st.index]
    w, al = res.motion.omega[:, st.index], res.motion.alpha[:, st.index]
    rho_a, L = ln["density"] * ln["area"], ln["length"]
    return rho_a * w ** 2 * L ** 2 / 2, -rho_a * al * L ** 3 / 3      # N(0), M(0)


def test_rotating_cantilever_stress_matches_its_closed_form_and_converges():
    errs = {}
    for n in (8, 16):
        res = Prepared(load_case(BEAM, [f"mesh.elements_per_link={n}"])).run()
        st = link_stations(res.case, res.fe)[0]
        nst, kap, sig = station_values(res, st)
        n0, m0 = _quasi_static_cantilever(res, st)
        s_ax, s_b = n0 / st.area, m0 * st.half_depth / res.case["links"][0]["second_moment"]
        errs[n] = (np.max(np.abs(nst[0] / st.area - s_ax)) / np.max(np.abs(s_ax)),
                   np.max(np.abs(sig[0, 0] - s_ax - s_b)) / np.max(np.abs(s_ax + s_b)))
        # stress / E at the named station is the strain output, the axial part the axial_force output
        assert np.max(np.abs((sig[0, 0] - nst[0] / st.area) / st.youngs_modulus - res["root_strain"])) <= \
            1e-10 * np.max(np.abs(res["root_strain"]))
        assert np.max(np.abs(nst[0] - res["root_axial_force"])) <= 1e-10 * np.max(np.abs(nst[0]))
        k = int(np.argmin(np.abs(st.fractions - 0.5)))
        assert np.max(np.abs((sig[0, k] - nst[k] / st.area) / st.youngs_modulus - res["mid_strain"])) <= \
            1e-10 * np.max(np.abs(res["mid_strain"]))
    assert errs[16][0] < 3e-3 and errs[16][1] < 6e-3        # element-mean axial force: (h/L)^2 / 3 = 0.13 %
    assert errs[16][0] < 0.5 * errs[8][0]                   # converging with the mesh


def test_pinned_pinned_link_bending_stress_matches_the_simply_supported_beam(tmp_path):
    path = tmp_path / "pp.toml"
    path.write_text(PINNED)
    res = Prepared(load_case(path)).run()
    st = link_stations(res.case, res.fe)[0]
    nst, kap, sig = station_values(res, st)
    ln, li, m = res.case["links"][st.index], st.index, res.motion
    c, s = np.cos(m.phi[:, li]), np.sin(m.phi[:, li])
    a0y = -s * m.ax[:, li] + c * m.ay[:, li]
    q0, q1 = -ln["density"] * ln["area"] * a0y, -ln["density"] * ln["area"] * m.alpha[:, li]
    x, L = st.fractions[:, None] * ln["length"], ln["length"]
    moment = q0 * x * (x - L) / 2 + q1 * (x ** 3 - L ** 2 * x) / 6          # M'' = q, M(0) = M(L) = 0
    bending = sig[0] - nst / st.area
    closed = moment * st.half_depth / ln["second_moment"]
    assert np.max(np.abs(bending - closed)) < 0.02 * np.max(np.abs(closed))
    k = int(np.argmin(np.abs(st.fractions - 0.5)))
    assert np.max(np.abs(nst[k] - res["mid_axial"])) <= 1e-10 * np.max(np.abs(nst[k]))


@pytest.mark.parametrize("model", ["classic", "coupled", "nonlinear"])
def test_every_model_family_gives_stresses_consistent_with_its_strain_output(model):
    res = Prepared(load_case(BEAM, ["solver.t_end=0.2", "mesh.elements_per_link=4"])).run(model)
    st = link_stations(res.case, res.fe)[0]
    nst, _, sig = station_values(res, st)
    ref = res["root_strain"]
    assert np.max(np.abs((sig[0, 0] - nst[0] / st.area) / st.youngs_modulus - ref)) <= 1e-10 * np.max(np.abs(ref))


@pytest.mark.parametrize("model", ["classic", "nonlinear"])
def test_without_a_mesh_the_stations_are_those_of_the_model_that_runs(model):
    """`flexmech run --stress` under model = auto does not know the family before the run starts: the
    envelope takes the mesh of the first block (the coupled mesh under nonlinear)."""
    prep = Prepared(load_case(BEAM, ["solver.t_end=0.2", "mesh.elements_per_link=4"]))
    da = DesignAnalysis(prep.case)
    res = execute(prep, model, MemorySink(prep.frames), observers=[da])
    rep = da.finish(res)
    st = link_stations(res.case, res.fe)[0]
    assert np.array_equal(da.stress.links[0].st.fractions, st.fractions)
    _, _, sig = station_values(res, st)
    assert rep["stress"]["bar"]["peak_abs_stress_Pa"] == pytest.approx(np.max(np.abs(sig)), rel=1e-12)


def test_envelope_safety_factor_and_joint_loads_of_a_run():
    prep = Prepared(load_case(BEAM))
    da = DesignAnalysis(prep.case, prep.fe)
    res = execute(prep, None, MemorySink(prep.frames), observers=[da])
    rep = da.finish(res)
    s = rep["stress"]["bar"]
    st = link_stations(res.case, res.fe)[0]
    _, _, sig = station_values(res, st)
    assert s["peak_abs_stress_Pa"] == pytest.approx(np.max(np.abs(sig)), rel=1e-12)
    assert s["safety_factor"] == pytest.approx(355e6 / s["peak_abs_stress_Pa"])
    assert s["critical_station"]["fraction"] == 0.0           # a cantilever's root
    j = rep["joint_loads"]["base"]
    assert j["source"] == "model" and j["max_N"] >= j["rms_N"] >= j["min_N"] >= 0
    # the hub carries the bar's inertia: at the end of the spin-up the centripetal force rho A w^2 L^2 / 2
    ln = res.case["links"][0]
    assert j["max_N"] == pytest.approx(ln["density"] * ln["area"] * 20.0 ** 2 * 0.5 ** 2 / 2, rel=0.02)


# ----------------------------------------------------------------------------- fatigue
def test_rainflow_counts_the_astm_e1049_example():
    # ASTM E1049-85 (2017) section 5.4.4 and its Table 4: history -2 1 -3 5 -1 3 -4 4 -2
    cyc = rainflow_cycles(np.array([-2, 1, -3, 5, -1, 3, -4, 4, -2.0]), repeating=False)
    counts = {}
    for rng, _mean, count, _i in cyc:
        counts[rng] = counts.get(rng, 0.0) + count
    assert counts == {3.0: 0.5, 4.0: 1.5, 6.0: 0.5, 8.0: 1.0, 9.0: 0.5}


def test_a_repeating_history_closes_every_cycle():
    y = np.array([0.0, 5, -1, 3, -4, 4, -2, 1, -3, 0])
    cyc = rainflow_cycles(y[:-1])
    totals = {}
    for rng, _mean, count, _i in cyc:
        totals[rng] = totals.get(rng, 0.0) + count
    assert all(float(v).is_integer() for v in totals.values())      # no half cycle left over
    assert totals[9.0] == 1.0


def test_miner_damage_of_a_constant_amplitude_history_is_the_hand_formula():
    m = MATERIALS["6061-T6"]
    t = np.linspace(0, 10, 2001)
    amp, mean = 80e6, 40e6
    cyc = rainflow_cycles(mean + amp * np.sin(2 * np.pi * t)[:-1])
    assert cyc[:, 2].sum() == pytest.approx(10.0)
    n_none = (amp / m["basquin_coefficient"]) ** (1 / m["basquin_exponent"])
    assert cycle_damage(cyc, m, "none").sum() == pytest.approx(10 / n_none, rel=1e-6)
    s_g = amp / (1 - mean / m["ultimate_strength"])                      # Goodman
    n_g = (s_g / m["basquin_coefficient"]) ** (1 / m["basquin_exponent"])
    assert cycle_damage(cyc, m, "goodman").sum() == pytest.approx(10 / n_g, rel=1e-6)
    assert equivalent_amplitude(np.array([amp]), np.array([mean]), m["ultimate_strength"], "gerber")[0] == \
        pytest.approx(amp / (1 - (mean / m["ultimate_strength"]) ** 2))
    steel = MATERIALS["structural-steel"]                                  # below the endurance limit: no damage
    assert cycle_damage(cyc, steel, "none").sum() == 0.0


# ----------------------------------------------------------------------------- command line
def _cli(*args, cwd=None):
    return subprocess.run(FLEXMECH + list(args), capture_output=True, text=True, cwd=cwd)


def test_run_stress_fatigue_writes_the_files_and_the_critical_values(tmp_path):
    out = tmp_path / "r"
    p = _cli("run", str(BEAM), "--stress", "--fatigue", "goodman", "--window", "0:", "--set",
             "drive.law=constant_speed", "--set", "drive.speed=20.0", "--set", "drive.final_speed=",
             "--set", "drive.spinup_time=", "--set", "solver.t_end=0.31415927", "--out", str(out), "--no-plots")
    assert p.returncode == 0, p.stderr
    assert "stress bar: peak" in p.stdout and "fatigue bar (goodman): life" in p.stdout
    for name in ("stress.csv", "joint_loads.csv", "design.json", "summary.json"):
        assert (out / name).is_file()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["design"]["fatigue"]["critical_link"] == "bar"
    assert "design.json" in summary["files"]


@pytest.mark.parametrize("args, words", [
    (["--fatigue", "goodman"], "--fatigue: a run's start is a transient"),
    (["--fatigue", "goodman", "--window", "0:0.1", "--set", "drive.law=constant_speed", "--set", "drive.speed=20.0",
      "--set", "drive.final_speed=", "--set", "drive.spinup_time="], "less than one crank cycle"),
    (["--stress", "--window", "0.5:0.2"], "--window: '0.5:0.2' must satisfy"),
])
def test_fatigue_without_a_repeating_history_is_refused(tmp_path, args, words):
    p = _cli("run", str(BEAM), "--out", str(tmp_path / "r"), *args)
    assert p.returncode == 2 and words in p.stderr and p.stderr.count("\n") == 1
    assert not (tmp_path / "r" / "stress.csv").exists()


def test_seed_cases_keep_their_raw_numbers():
    raw_only = validate_case({**load_case("fourbar_hac"), "case": {"title": "x"}})
    assert all("section" not in ln and "material" not in ln for ln in raw_only["links"])
