"""`flexmech accuracy`: observed orders, Richardson extrapolation only in the asymptotic range,
the files it writes, failed runs as data points, and resuming from the cache.

Reduced sizes throughout (a spinning cantilever of a few elements, a few hundred steps).
"""

import csv
import json
import math

import numpy as np
import pytest

from flexmech_py.studies.accuracy import accuracy_study, parse_integrators, richardson, successive_orders
from flexmech_py.case import CaseError
from flexmech_py.cli import main

# A cantilever spun up smoothly from rest (kinematic drive, no rigid ODE): smooth in time,
# so the time ladder is asymptotic at a few hundred steps.  Midspan strain and tip deflection.
SPIN = """
[mechanism]
type = "serial"
[[links]]
name = "arm"
length = 0.5
area = 4.0e-5
second_moment = 1.3333e-9
youngs_modulus = 7.0e10
density = 2700.0
[mesh]
elements_per_link = 2
[drive]
type = "kinematic"
law = "spinup"
final_speed = 20.0
spinup_time = 0.05
[solver]
t_end = 0.05
dt = 1.0e-4
[outputs]
strain_mid = { kind = "strain", link = "arm", at = 0.5 }
tip = { kind = "displacement", at = "arm.end", component = "transverse" }
hub = { kind = "joint_angle", joint = "base" }
"""


@pytest.fixture
def spin_case(tmp_path):
    p = tmp_path / "spin.toml"
    p.write_text(SPIN)
    return p


def _orders(study, **match):
    return [o["order"] for o in study.orders if all(o[k] == v for k, v in match.items())]


# ----------------------------------------------------------------------------- Richardson
def _family(h0, p, n=4, noise=None):
    t = np.linspace(0.0, 1.0, 101)
    exact = np.sin(3 * t)
    out = []
    for i in range(n):
        h = h0 * 2 ** i
        y = exact + 0.3 * h ** p * np.cos(5 * t) + 0.05 * h ** (p + 2) * t
        if noise is not None:
            y = y + noise[i] * np.cos(17 * t)
        out.append(y)
    return exact, out


def test_richardson_extrapolates_a_consistent_family():
    exact, levels = _family(0.05, 2.0)
    r = richardson(levels)
    assert r["applied"] and r["reason"] == ""
    assert abs(r["orders"][0] - 2) < 0.05 and abs(r["orders"][1] - 2) < 0.05
    err_fine = np.max(np.abs(levels[0] - exact))
    err_rich = np.max(np.abs(levels[0] + r["correction"] - exact))
    assert err_rich < 0.05 * err_fine                       # the h^2 term is removed
    assert r["uncertainty"] < err_fine


def test_richardson_refuses_an_inconsistent_family():
    # differences of successive levels that do not shrink at one rate (a pre-asymptotic mix)
    exact, levels = _family(0.05, 2.0, noise=[1e-3, 1.5e-3, 1e-4, 3e-2])
    r = richardson(levels)
    assert not r["applied"]
    assert np.all(r["correction"] == 0.0)
    assert "differ by more than" in r["reason"] or "asymptotic" in r["reason"]
    assert r["uncertainty"] == pytest.approx(np.max(np.abs(levels[0] - levels[1])))
    # a column that does not depend on the refinement: nothing to extrapolate
    same = [exact.copy() for _ in range(4)]
    r = richardson(same)
    assert not r["applied"] and "round-off" in r["reason"] and r["uncertainty"] == 0.0
    # three levels cannot check the order
    assert not richardson(levels[:3])["applied"]


def test_successive_orders_of_a_known_rate():
    _, levels = _family(0.02, 3.0, n=4)
    assert np.allclose(successive_orders(levels), 3.0, atol=0.05)


# ----------------------------------------------------------------------------- the study
def test_orders_files_and_resume(spin_case, tmp_path):
    out = tmp_path / "acc"
    kw = dict(dt_levels=4, elements=(2, 4, 8), jobs=1, out_dir=out, progress=False)
    st = accuracy_study(spin_case, **kw)
    assert st.columns == ["strain_mid", "tip"]               # the strain and displacement outputs by default
    assert st.batch["failed"] == 0

    # time order of Newmark average acceleration: 2, from successive differences along the dt ladder
    for c in st.columns:
        p = _orders(st, direction="time", source="successive differences", column=c)
        assert len(p) == 2 and 1.7 < p[0] < 2.3 and 1.7 < p[1] < 2.3, (c, p)
    # space order of the midspan strain (second derivative of the cubic Hermite field): about 2
    p = _orders(st, direction="space", source="reference family", column="strain_mid")
    assert 1.7 < p[0] < 2.6, p
    ref = st.reference["hac"]["columns"]["strain_mid"]
    assert ref["space"]["applied"] == (abs(ref["space"]["orders"][0] - ref["space"]["orders"][1]) <= 0.3)
    assert ref["uncertainty_rel"] < 1e-3
    # mesh ladder errors against the reference fall with the mesh; the time ladder at 2 elements is
    # stuck at the space error (the space error dominates)
    rows = {(r["ladders"], r["dt_over_case_dt"], r["elements_per_link"]): r for r in st.rows}
    e_space = [r["err_strain_mid"] for r in st.rows if "space" in r["ladders"]]
    assert len(e_space) == 3 and e_space[0] < e_space[1] < e_space[2]     # finest mesh first
    e_time = [r["err_strain_mid"] for r in st.rows if r["ladders"] in ("time", "time;space")]
    assert max(e_time) < 1.05 * min(e_time) and min(e_time) > 0.01

    # files: accuracy.csv one row per run, orders.csv, accuracy.json, report.md, accuracy.png
    with open(out / "accuracy.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert len(table) == st.batch["runs"] == len(st.rows)
    for r in table:
        assert r["status"] == "ok" and float(r["kernel_s"]) > 0 and math.isfinite(float(r["err_worst"]))
        assert float(r["time_s"]) == float(r["kernel_cpu_s"]) and float(r["kernel_cpu_s"]) <= float(r["run_cpu_s"])
        assert float(r["err_worst"]) == pytest.approx(max(float(r["err_strain_mid"]), float(r["err_tip"])), rel=1e-5)
    with open(out / "orders.csv", newline="") as fh:
        assert {"model", "integrator", "direction", "source", "column", "levels", "order"} <= set(csv.DictReader(fh).fieldnames)
    doc = json.loads((out / "accuracy.json").read_text())
    assert set(doc) == {"settings", "batch", "reference", "orders", "cheapest"}
    assert "Cheapest run" in (out / "report.md").read_text()
    png = (out / "accuracy.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    import matplotlib.image

    img = matplotlib.image.imread(out / "accuracy.png")
    assert img.shape[0] > 300 and img.shape[1] > 500 and img[..., :3].std() > 0.05   # not blank

    # cheapest run per tolerance: it meets the tolerance, and no cheaper run does
    for e in st.cheapest:
        if "integrator" in e:
            assert e["error"] <= e["tolerance"]
            col = "err_worst" if e["column"] == "worst" else f"err_{e['column']}"
            cheaper = [r for r in st.rows if r["ladders"] != "reference" and r["time_s"] < e["time_s"]]
            assert all(r[col] > e["tolerance"] for r in cheaper)

    # resume: nothing is recomputed; a removed result is recomputed alone; same errors
    st2 = accuracy_study(spin_case, **kw)
    assert (st2.batch["computed"], st2.batch["cached"]) == (0, st.batch["runs"])
    cached = sorted((out / "cache").glob("*.json"))
    assert len(cached) == st.batch["runs"]
    cached[0].unlink()
    st3 = accuracy_study(spin_case, **kw)
    assert st3.batch["computed"] == 1
    assert [r["err_worst"] for r in st3.rows] == pytest.approx([r["err_worst"] for r in st.rows], rel=1e-12)


def test_a_failing_run_is_a_row_not_a_crash(spin_case, tmp_path):
    # a tip output "arm.mid" needs a node at midspan: the 1-element mesh cannot provide it
    text = spin_case.read_text().replace('tip = { kind = "displacement", at = "arm.end"',
                                         'tip = { kind = "displacement", at = "arm.mid"')
    spin_case.write_text(text)
    st = accuracy_study(spin_case, dt_levels=2, elements=(1, 2), ref_elements=8, columns=["tip"], jobs=1,
                        out_dir=tmp_path / "acc", progress=False, plots=False)
    failed = [r for r in st.rows if r["status"] == "failed"]
    # the mesh ladder's 1-element run and the coarsest run of the reference mesh family (8, 4, 2, 1)
    assert sorted(r["ladders"] for r in failed) == ["reference", "space"]
    assert all(r["elements_per_link"] == 1 and "outputs.tip.at" in r["error_message"] for r in failed)
    assert st.batch["failed"] == 2
    space = st.reference["hac"]["columns"]["tip"]["space"]
    assert not space["applied"] and "failed" in space["reason"]
    assert all(math.isfinite(r["err_tip"]) for r in st.rows if r["status"] == "ok")
    assert "Failed runs" in (tmp_path / "acc" / "report.md").read_text()


def test_bad_options_name_the_option(spin_case, tmp_path):
    for kw, field in [({"models": ["hac", "bogus"]}, "--models"), ({"columns": ["nope"]}, "--columns"),
                      ({"ref_dt_factor": 3}, "--ref-dt-factor"), ({"ref_elements": 12}, "--ref-elements"),
                      ({"integrators": ["rk4"]}, "--integrators")]:
        with pytest.raises(CaseError) as exc:
            accuracy_study(spin_case, out_dir=tmp_path / "x", progress=False, **kw)
        assert exc.value.field == field


def test_cli_accuracy(spin_case, tmp_path, capsys):
    rc = main(["accuracy", str(spin_case), "--dt-levels", "2", "--elements", "2,4", "--ref-elements", "8",
               "--jobs", "1", "--quiet", "--no-plots", "--out", str(tmp_path / "cli")])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "cheapest hac to 0.1" in out and (tmp_path / "cli" / "accuracy.csv").is_file()
    assert not (tmp_path / "cli" / "accuracy.png").exists()
    rc = main(["accuracy", str(spin_case), "--models", "bogus", "--out", str(tmp_path / "cli")])
    assert rc == 2 and "--models" in capsys.readouterr().err


def test_integrators(spin_case, tmp_path):
    """Every integrator the build has, on one time ladder: second order in time."""
    raw = {"mechanism": {"type": "serial"}, "links": [{"name": "a", "length": 1.0, "area": 1e-4, "second_moment": 1e-9,
           "youngs_modulus": 2e11, "density": 7800.0}], "drive": {"type": "kinematic", "law": "constant_speed",
           "speed": 0.0}, "solver": {"t_end": 0.01, "dt": 1e-4},
           "outputs": {"x": {"kind": "displacement", "at": "a.end", "component": "transverse"}}}
    try:
        its = parse_integrators(["newmark", "hht:0.1", "generalized-alpha:0.8"], raw)
    except CaseError as exc:
        assert "only newmark" in str(exc)                      # this build predates solver.integrator
        its = parse_integrators(["newmark"], raw)
    labels = [i.label for i in its]
    st = accuracy_study(spin_case, integrators=[{"newmark": "newmark", "hht": "hht:0.1",
                                                 "generalized-alpha": "generalized-alpha:0.8"}[lb.split("(")[0]]
                                                for lb in labels],
                        dt_levels=4, elements=(2, 4), ref_elements=8, columns=["tip"], jobs=1,
                        out_dir=tmp_path / "acc", progress=False, plots=False)
    assert st.settings["integrators"] == labels
    for lb in labels:
        p = _orders(st, integrator=lb, direction="time", source="successive differences", column="tip")
        assert 1.75 < p[0] < 2.3, (lb, p)


def test_coupled_model_on_a_refined_mesh_is_timed(spin_case, tmp_path):
    """The one-pass coupled model over a mesh ladder: every run succeeds and its kernel CPU time is
    measured (inside the compiled Newton-Newmark loop, so at most the run's whole CPU time)."""
    st = accuracy_study(spin_case, models=["coupled"], dt_levels=2, elements=(2, 4), ref_elements=8, columns=["tip"],
                        jobs=1, out_dir=tmp_path / "acc", progress=False, plots=False)
    assert st.batch["failed"] == 0
    for r in st.rows:
        assert 0 < r["kernel_cpu_s"] <= r["run_cpu_s"] * 1.001 + 1e-4
    e = {r["elements_per_link"]: r["err_tip"] for r in st.rows if "space" in r["ladders"]}
    assert e[4] < e[2]
