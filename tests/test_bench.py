"""flexmech bench (no timing is asserted: the benchmark reports numbers), chunked runs, and the
NumPy reference the benchmark times against."""

import csv
import math
import shutil

import numpy as np
import pytest

import flexmech_py as fm
from flexmech_py.studies import bench, bench_exudyn
from flexmech_py.models.superposition import reference
from flexmech_py.cli import main
from flexmech_py.run.simulate import Prepared


def _runnable_cases(src, dst):
    """A copy of the bundled cases."""
    dst.mkdir()
    for p in src.glob("*.toml"):
        shutil.copy(p, dst / p.name)
    return dst


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_bench_quick_writes_wellformed_csv_and_png(tmp_path, cases_dir, capsys):
    cases_dir = _runnable_cases(cases_dir, tmp_path / "cases")
    assert main(["bench", "--quick", "--out", str(tmp_path), "--cases", str(cases_dir)]) == 0
    out = capsys.readouterr().out
    assert "mesh ladder" in out and "summary" in out
    ladder = _rows(tmp_path / "bench_ladder.csv")
    assert {r["model"] for r in ladder} == set(bench.MODELS)
    for r in ladder:
        steps, us, dofs = int(r["steps"]), float(r["us_per_step"]), int(r["dofs"])
        assert steps > 0 and dofs > 0 and us > 0 and math.isfinite(us)
        assert float(r["ns_per_dof_step"]) == pytest.approx(1e3 * us / dofs, rel=1e-4)
        assert 0 < float(r["peak_fraction"]) and float(r["flops_per_step"]) > 0
    # more elements: more DOFs (the ladder really refines the mesh)
    hac = [r for r in ladder if r["model"] == "hac"]
    assert [int(r["dofs"]) for r in hac] == sorted(int(r["dofs"]) for r in hac)
    solves = _rows(tmp_path / "bench_solves.csv")
    assert all(float(r["banded_us"]) > 0 for r in solves)
    if bench_exudyn.unavailable() is None:      # the side by side ran for both seed mechanisms
        assert "side by side with Exudyn (seed manipulator" in out
        (row,) = _rows(tmp_path / "bench_exudyn_manipulator.csv")
        assert float(row["speedup"]) > 0 and math.isfinite(float(row["strain_link1_diff_300hz"]))
    summary = {r["metric"]: r for r in _rows(tmp_path / "bench_summary.csv")}
    for key in ("import", "flexmech_run_no_plots", "scalar_peak", "reference.ratio_reference_to_fortran",
                "reference.max_relative_difference"):
        assert math.isfinite(float(summary[key]["value"])), key
    # the reference solved the identical equations
    assert float(summary["reference.max_relative_difference"]["value"]) < 1e-9
    assert float(summary["matplotlib_imported_by_import"]["value"]) == 0
    seeds = _rows(tmp_path / "bench_seed.csv")
    assert {r["case"] for r in seeds} == {p.stem for p in cases_dir.glob("*.toml")}
    mem = [r for k, r in summary.items() if k.startswith("memory.") and k.endswith("tracemalloc_peak_MB")]
    assert len(mem) == 2
    side = tmp_path / "bench_exudyn.csv"
    if bench_exudyn.unavailable() is None:      # Exudyn installed: the side-by-side rows
        rows = _rows(side)
        assert {r["model"] for r in rows} == {"nonlinear", "coupled"}
        for r in rows:
            assert float(r["speedup"]) == pytest.approx(float(r["exudyn_cpu_s"]) / float(r["flexmech_cpu_s"]), rel=1e-3)
            assert math.isfinite(float(r["strain_coupler_diff"])) and float(r["newton_per_step"]) >= 1
        # the multi-loop side by side: in its file and in the summary, both node-angle forms
        multi = _rows(tmp_path / "bench_exudyn_mechanism.csv")
        assert {r["node_angles"] for r in multi} == {"relative", "shared"}
        for r in multi:
            key = f"exudyn.{r['case']}.{r['node_angles']}.{r['elements_per_link']}_per_link.speedup"
            assert float(summary[key]["value"]) == pytest.approx(float(r["speedup"]), rel=1e-4)
    else:                                       # one line says why, no file
        assert not side.exists() and "Exudyn is not installed (pip install exudyn" in out
    png = tmp_path / "bench.png"
    if png.exists():   # matplotlib installed
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("case_name, geometric", [("fourbar_hac.toml", "none"), ("manipulator_bricout.toml", "lagged"),
                                                  ("fourbar_constant_speed.toml", "none")])
def test_chunked_run_equals_unchunked(cases_dir, case_name, geometric):
    case = fm.load_case(cases_dir / case_name, overrides=["solver.t_end=0.02", f"solver.geometric_stiffness='{geometric}'"])
    whole = Prepared(case, chunk_steps=10 ** 9).run()
    parts = Prepared(case, chunk_steps=130)   # 130 steps rounded up to a multiple of output_every
    assert parts.chunk_steps % parts.out_every == 0 and parts.chunk_steps < parts.nsteps
    chunked = parts.run()
    for k in whole.columns:
        scale = max(np.max(np.abs(whole[k])), 1e-300)
        assert np.max(np.abs(chunked[k] - whole[k])) <= 1e-12 * scale, k
    assert np.max(np.abs(chunked.u - whole.u)) <= 1e-12 * np.max(np.abs(whole.u))


def test_rigid_source_samples_equal_the_whole_grid(cases_dir):
    """The dense rigid solution sampled chunk by chunk equals it sampled on the whole grid."""
    p = Prepared(fm.load_case(cases_dir / "fourbar_hac.toml", overrides=["solver.t_end=0.01"]))
    t = p.t
    a = p.source(t[:400]).q
    b = p.source(t[399:]).q
    full = p.source(t).q
    assert np.array_equal(np.vstack([a, b[1:]]), full)


def test_reference_matches_fortran_on_seed(cases_dir):
    """The NumPy reference the benchmark times solves the same equations: same solution."""
    p = Prepared(fm.load_case(cases_dir / "fourbar_hac.toml", overrides=["solver.t_end=2e-4"]))
    uf, _, _ = p.fe.run(p.rig, "hac", p.dt)
    ur = reference.newmark(p.fe, p.rig, "hac", p.dt)
    assert np.max(np.abs(uf - ur)) <= 1e-9 * np.max(np.abs(ur))


def test_flop_model_and_exponent_fit():
    # banded LU 2 n kl (kl + ku) with kl = ku: doubling n doubles it, doubling kb quadruples it
    f1 = bench.flops_superposition(6, 3, 100, 5)["factorization"]
    assert bench.flops_superposition(12, 3, 200, 5)["factorization"] == 2 * f1
    assert bench.flops_superposition(6, 3, 100, 10)["factorization"] == 4 * f1
    x = np.array([16, 32, 64, 128.0])
    assert bench.fit_exponent(x, 3 * x ** 1.5) == pytest.approx(1.5)
    assert math.isnan(bench.fit_exponent([1.0], [2.0]))


def test_side_by_side_with_exudyn_follows_the_same_mechanism(cases_dir):
    """The Exudyn model of the side-by-side benchmark is the seed four-bar: over its first 0.05 s (4
    elements per link) the crank turns by the same angle in both (within 1 %), and the coupler's
    midspan strain has the same sign and order at the end."""
    pytest.importorskip("exudyn")
    r = bench_exudyn.side_by_side(cases_dir / "fourbar_hac.toml", epl=4, dt=1.25e-5, t_end=0.05)
    fx, ex = r["flexmech"], r["exudyn"]
    assert abs(ex["crank_angle"][-1] - fx["crank_angle"][-1]) < 0.01 * abs(fx["crank_angle"][-1])
    a, b = fx["strain_coupler_mid"][-1], np.interp(fx["t"][-1], ex["t"], ex["strain_coupler_mid"])
    assert a * b > 0 and 0.5 < b / a < 2


def test_nonlinear_model_and_exudyn_agree_over_the_first_revolution(cases_dir):
    """Issue 12's criterion: the seed four-bar at 16 el/link, generalized-alpha 0.8, dt = 1.25e-5 s;
    the midspan strains of flexmech's nonlinear model and Exudyn's ANCF cable differ by less than 1 %
    of flexmech's peak over the crank's first revolution (measured 0.03 % coupler, 0.013 % follower,
    Exudyn's curvature at the midspan node the mean of its two elements as flexmech reads it;
    3.3 % over 50 ms before the shallow-arch strain of docs/theory.md 12.4)."""
    pytest.importorskip("exudyn")
    r = bench_exudyn.side_by_side(cases_dir / "fourbar_hac.toml", epl=16, dt=1.25e-5, t_end=0.135)
    assert r["first_revolution_s"] == pytest.approx(0.131, abs=2e-3)
    d = r["strain_difference_revolution"]
    assert d["strain_coupler_mid"] < 0.01 and d["strain_follower_mid"] < 0.01


def test_manipulator_agrees_with_exudyn(cases_dir):
    """The seed manipulator (step torques at base and elbow, elbow mass and hub, payload), nonlinear,
    8 el/link, generalized-alpha 0.8, dt = 1.25e-5 s, 0.1 s, frames at every step: the midspan strains
    of flexmech and of Exudyn's ANCF cable low-passed at 300 Hz differ by less than 1 % of flexmech's
    peak (measured over 0.25 s: 0.08 % link 1, 0.02 % link 2; at 1 kHz 1.4 % and 0.7 %).  With frames
    at every 10th step they seemed to differ by 10-20 %: the torque steps ring up to tens of kHz, and
    the decimated frames fold that into the low band, differently for the two elements' high modes."""
    pytest.importorskip("exudyn")
    r = bench_exudyn.manipulator_side_by_side(cases_dir / "manipulator_bricout.toml", epl=8, t_end=0.1,
                                              cutoffs=(300.0,))
    d = r["strain_difference"][300.0]
    assert d["strain_link1_mid"] < 0.01 and d["strain_link2_mid"] < 0.01
