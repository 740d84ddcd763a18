"""Floquet multipliers and the periodic steady state of constant-speed drives (flexmech_py/studies/floquet.py).

Reduced size: the seed four-bar (2 elements per link, 18 free DOFs) at speeds whose period
is short.  Physics checked: the multipliers of a time-invariant problem are those of the FE
natural frequencies under the average-acceleration rule; the undamped discrete map keeps the
multipliers on the unit circle up to an O(dt^2) defect; the directly computed steady state is
where a long damped transient ends; the instabilities of the chart lie where a parametric
resonance condition holds.
"""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from flexmech_py import load_case
from flexmech_py.cli import main
from flexmech_py.base.errors import CaseError
from flexmech_py.studies.floquet import (PeriodicCase, floquet, frozen_frequencies, stability_chart, stability_point,
                                 steady_state)
from flexmech_py.run.simulate import simulate

from conftest import CASES

SEED = CASES / "fourbar_constant_speed.toml"


@pytest.fixture(scope="module")
def seed():
    return load_case(SEED)


def _match(mu, expected):
    """Largest distance from each computed multiplier to the nearest expected one (and back)."""
    d = np.abs(mu[:, None] - expected[None, :])
    return max(d.min(axis=1).max(), d.min(axis=0).max())


def test_time_invariant_multipliers_are_the_natural_frequencies(seed):
    # the linkage frozen at one configuration, not moving (omega = alpha = 0, no loads): constant
    # coefficients, so every period map is exp(A T) discretized by the trapezoidal (Cayley) rule
    pc = PeriodicCase(seed, "hac", speed=600.0)
    rig0 = pc.prep.rig[:, :, 0].copy()
    rig0[1:] = 0.0
    pc.prep.rig = np.asfortranarray(np.repeat(rig0[:, :, None], pc.nsteps + 1, axis=2))
    fr = floquet(pc)
    m, _, k, _ = pc.fe.matrices(rig0, "hac")
    w = np.sqrt(np.sort(np.linalg.eigvals(np.linalg.solve(m, k)).real))
    h, n = pc.dt, pc.nsteps
    # average acceleration: one step turns a mode of frequency w by 2 atan(w h / 2), exactly, no decay
    theta = n * 2.0 * np.arctan(w * h / 2.0)
    expected = np.concatenate([np.exp(1j * theta), np.exp(-1j * theta)])
    assert _match(fr.mu, expected) < 1e-9
    assert np.max(np.abs(np.abs(fr.mu) - 1.0)) < 1e-10          # on the unit circle to round-off
    assert np.allclose(fr.x_p, 0.0)                              # no load, no response
    # the continuous multipliers exp(+-i w T) of the lowest modes, up to the rule's period error
    low = np.concatenate([np.exp(1j * w[:3] * pc.period), np.exp(-1j * w[:3] * pc.period)])
    d = np.abs(fr.mu[:, None] - low[None, :]).min(axis=0)
    assert d.max() < 2e-3
    err_theory = n * (w[:3] * h) ** 3 / 12.0                      # period error of the trapezoidal rule
    assert np.all(d[:3] < 2 * err_theory + 1e-9)


def test_undamped_multipliers_leave_the_unit_circle_only_by_O_dt2(seed):
    # time-varying coefficients: the discrete map is not exactly symplectic, the defect shrinks as dt^2
    defect = []
    for dt in (2e-5, 1e-5):
        fr = floquet(PeriodicCase(seed, "hac", speed=120.0, dt=dt))
        defect.append(np.max(np.abs(np.abs(fr.mu) - 1.0)))
        assert fr.stable
    assert defect[1] < 1e-3
    assert 3.0 < defect[0] / defect[1] < 5.0


def test_steady_state_is_the_end_of_a_damped_transient(seed):
    c = load_case(SEED, overrides=["solver.rayleigh=[200.0, 0.0]"])
    pc = PeriodicCase(c, "hac", speed=120.0)
    fr = floquet(pc)
    assert fr.stable and not fr.warnings()
    steady = steady_state(pc, fr)
    assert steady.extra["floquet"]["periodicity_residual"] < 1e-8
    # a transient from rest over 6 periods on the same time grid: decays as exp(-100 t), e^-31 here
    c6 = load_case(SEED, overrides=["solver.rayleigh=[200.0, 0.0]", f"solver.t_end={6 * pc.period!r}",
                                    "solver.beta=0.25", "solver.gamma=0.5"])
    tr = simulate(c6, "hac", dt=pc.dt * (1 + 1e-12))
    assert tr.nsteps == 6 * pc.nsteps
    nf = steady.t.size
    for name in ("strain_coupler_mid", "strain_follower_mid"):
        last = tr[name][-nf:]
        ref = steady[name]
        assert np.max(np.abs(last - ref)) < 1e-7 * np.max(np.abs(ref))
    assert np.allclose(tr["crank_angle"][-nf:] - 10 * np.pi, steady["crank_angle"], atol=1e-9)


def test_geometric_stiffness_quasi_static_is_linear_and_buckles_the_seed_links(seed):
    # quasi_static axial forces come from the rigid-body loads only: still linear, so the steady state
    # closes on itself; at 120 rad/s the coupler and follower carry several times their Euler load in
    # compression, so the frozen stiffness loses definiteness and the multiplier is real and large
    pc = PeriodicCase(seed, "hac", speed=120.0, geometric="quasi_static")
    fr = floquet(pc)
    res = steady_state(pc, fr)
    assert res.extra["floquet"]["periodicity_residual"] < 1e-8
    assert not fr.stable and abs(fr.mu[0].imag) < 1e-9 * abs(fr.mu[0])
    assert np.min(frozen_frequencies(pc, fr, nmodes=1)) < 1.0
    # without it the same speed is stable and the lowest frozen frequency is the linkage's 260-300 rad/s
    pc0 = PeriodicCase(seed, "hac", speed=120.0)
    f0 = frozen_frequencies(pc0, floquet(pc0), nmodes=1)
    assert 240 < f0.min() < f0.max() < 310


@pytest.mark.parametrize("change,field", [
    (dict(geometric="current"), "geometric_stiffness"),
    (dict(geometric="lagged"), "geometric_stiffness"),
    (dict(model="coupled"), "model"),
    (dict(speed=0.0), r"drives\[0\].speed"),
])
def test_refuses_what_has_no_monodromy(seed, change, field):
    kw = dict(model="hac")
    kw.update(change)
    with pytest.raises(CaseError, match=field):
        PeriodicCase(seed, **kw)


def test_refuses_a_torque_drive():
    with pytest.raises(CaseError, match="constant_speed"):
        PeriodicCase(load_case(CASES / "fourbar_hac.toml"))


def test_resonance_warns_about_the_steady_state(seed):
    # forced resonance: a frozen linkage whose period is a whole number of periods of its first mode
    pc = PeriodicCase(seed, "hac", speed=600.0)
    rig0 = pc.prep.rig[:, :, 0].copy()
    rig0[1:3] = 0.0
    m, _, k, _ = pc.fe.matrices(rig0, "hac")
    w1 = np.sqrt(np.sort(np.linalg.eigvals(np.linalg.solve(m, k)).real))[0]
    n = 2000
    h = 2.0 * np.tan(np.pi / n) / w1          # one step turns mode 1 by 2 atan(w1 h / 2) = 2 pi / n exactly
    pc.prep.rig = np.asfortranarray(np.repeat(rig0[:, :, None], n + 1, axis=2))
    pc.nsteps, pc.prep.dt = n, h
    fr = floquet(pc, out_every=n)
    assert fr.resonance_margin < 1e-8
    assert fr.cond > 1e6
    assert any("ill-conditioned" in w for w in fr.warnings())


def test_stability_chart_instabilities_are_parametric_resonances(seed, tmp_path):
    # three speeds, two workers: 200 and 600 rad/s unstable, 400 rad/s stable (undamped, geometric none)
    speeds = [200.0, 400.0, 600.0]
    rows, batch = stability_chart(seed, speeds, model="hac", jobs=2, cache_dir=tmp_path / "cache", progress=False,
                                  refine_rounds=0)
    assert batch.jobs == 2 and batch.computed == 3
    by = {r["speed"]: r for r in rows}
    assert [bool(by[s]["stable"]) for s in speeds] == [False, True, False]
    for s in speeds:
        r = by[s]
        nm = 3
        lo = [r[f"omega{k}_min"] for k in range(1, nm + 1)]
        hi = [r[f"omega{k}_max"] for k in range(1, nm + 1)]
        hit = [(i, j, k) for k in range(1, 5) for i in range(nm) for j in range(i, nm)
               if lo[i] + lo[j] <= k * s <= hi[i] + hi[j]]
        if not r["stable"]:
            assert hit, f"unstable at {s} rad/s without a resonance condition"
    # the cached chart is returned unchanged
    rows2, batch2 = stability_chart(seed, speeds, model="hac", jobs=1, cache_dir=tmp_path / "cache", progress=False,
                                    refine_rounds=0)
    assert batch2.cached == 3 and rows2 == rows
    # one point computed in-process agrees with the workers'
    one = stability_point({"case": {**seed, "case": {k: v for k, v in seed["case"].items() if k != "path"}},
                           "model": "hac", "geometric": "none", "speed": 600.0, "nmodes": 4})
    assert one["max_abs_multiplier"] == pytest.approx(by[600.0]["max_abs_mu"], rel=1e-12)


def test_cli_stability_and_steady(tmp_path, capsys):
    out = tmp_path / "st"
    assert main(["stability", str(SEED), "--speed", "560:600:2", "--jobs", "1", "--out", str(out)]) == 0
    with open(out / "stability.csv") as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    assert [float(r["speed"]) for r in rows] == [560.0, 600.0]
    assert all(float(r["max_abs_mu"]) > 1.0 for r in rows)
    from flexmech_py.figures.plots import have_matplotlib
    if have_matplotlib():
        assert (out / "stability.png").stat().st_size > 10000
    sd = tmp_path / "sd"
    capsys.readouterr()
    assert main(["steady", str(SEED), "--set", "solver.rayleigh=[200.0, 0.0]", "--out", str(sd), "--no-plots"]) == 0
    import json
    s = json.loads((sd / "summary.json").read_text())
    # the steady state's validity is reported like a run's: its coupler bends by far more than 2 % of its length
    err = capsys.readouterr().err.splitlines()
    assert s["validity_overall"]["max_deflection_over_length"] > 0.02
    assert "flexmech: warning: the hac model's results after t = 0 s" in err[0] and len(err) == len(s["warnings"])
    assert any("deflection exceeds 2 % of its length" in w for w in s["warnings"])
    assert s["floquet"]["stable"] and len(s["floquet"]["multipliers"]) == 36
    assert s["t_end"] == pytest.approx(2 * math.pi / 120.0)
    head = (sd / "timeseries.csv").read_text().splitlines()[3].split(",")
    assert head[:3] == ["t", "crank_angle", "crank_speed"]
    assert main(["steady", str(CASES / "fourbar_hac.toml"), "--out", str(tmp_path / "x")]) == 2
    assert "constant_speed" in capsys.readouterr().err


def test_principal_parametric_resonance_has_a_real_negative_multiplier(seed):
    # at 480 rad/s the lowest frozen frequency (229-299 rad/s along the cycle) meets 2 omega_1 = Omega: the
    # principal region of a Mathieu-like equation, whose multiplier leaves the unit circle at -1
    pc = PeriodicCase(seed, "hac", speed=480.0)
    fr = floquet(pc)
    w1 = frozen_frequencies(pc, fr, nmodes=1)[:, 0]
    assert 2 * w1.min() < 480.0 < 2 * w1.max()
    assert fr.mu[0].real < -1.5 and fr.mu[0].imag == 0.0
    from flexmech_py.studies.regions import multiplier_type
    assert multiplier_type(fr.mu[0].real, fr.mu[0].imag) == "real-"


def test_refinement_finds_the_damped_pocket_a_coarse_grid_misses(seed):
    # with Rayleigh damping (zeta_1 about 1.6 %) a pocket of the real +1 tongue stays unstable near 231-234 rad/s;
    # a 10 rad/s grid sees 230 and 240 rad/s stable, its refinement (bisection of the peak at 230) finds it
    # (dt = 2e-5 s for speed; the multipliers agree with dt = 1e-5 s to 1e-3)
    c = load_case(SEED, overrides=["solver.rayleigh=[5.0, 5e-5]", "solver.dt=2e-5"])
    grid = [220.0, 230.0, 240.0, 250.0]
    rows, runs = stability_chart(c, grid, model="hac", jobs=1, progress=False, resolution=1.0, refine_rounds=0)
    assert runs.rounds == 0 and all(r["stable"] for r in rows)
    from flexmech_py.studies.regions import unstable_regions
    rows, runs = stability_chart(c, grid, model="hac", jobs=1, progress=False, resolution=1.0)
    assert 0 < runs.rounds <= 8 and runs.added == len(rows) - 4 and runs.added < 20
    assert [r["round"] for r in rows if r["speed"] in grid] == [0, 0, 0, 0]
    (reg,) = unstable_regions(rows)
    assert 230.0 < reg["below"] < reg["from"] <= 232.0 and 234.0 <= reg["to"] < reg["above"] < 236.0
    assert reg["from"] - reg["below"] <= 1.0 and reg["above"] - reg["to"] <= 1.0
    assert 1.02 < reg["max_abs_mu"] < 1.04 and reg["parts"][0]["type"] == "real+"


def pocket_growth(speed=232.5, dt=1e-5, cycles=80):
    """(Floquet growth rate, growth rate of a time run) [1/s] at ``speed`` with the damping of docs/stability.md:
    the time run starts from rest and its distance from the periodic steady state (coupler strain, max
    over each cycle) is fitted by exp(rate t) over the second half of the cycles."""
    ov = ["solver.rayleigh=[5.0, 5e-5]", f"drive.speed={speed}", "solver.divergence_limit=1e12",
          "solver.error_estimate='none'", "solver.output_every=1", f"solver.dt={dt}"]
    pc = PeriodicCase(load_case(SEED, overrides=ov), "hac")
    fr = floquet(pc)
    ys = steady_state(pc, fr)["strain_coupler_mid"]
    run = simulate(load_case(SEED, overrides=ov + [f"solver.t_end={cycles * pc.period!r}"]), "hac",
                   dt=pc.dt * (1 + 1e-12))
    n = pc.nsteps
    y = run["strain_coupler_mid"]
    dist = np.array([np.max(np.abs(y[k * n:(k + 1) * n + 1] - ys)) for k in range(cycles)])
    k = np.arange(cycles // 2, cycles)
    return fr.growth_rate, float(np.polyfit(k * pc.period, np.log(dist[k]), 1)[0])


def test_damped_pocket_grows_in_a_time_run():
    # the pocket's multiplier is the growth of a plain time run away from the periodic state: the real +1
    # multiplier 1.029 per period (1.06 1/s; 40 cycles at dt = 2e-5 s here, 80 at 1e-5 s in docs/stability.md)
    floquet_rate, time_rate = pocket_growth(dt=2e-5, cycles=40)
    assert 0.9 < floquet_rate < 1.2
    assert time_rate == pytest.approx(floquet_rate, rel=0.02)


def _point_failing_at_600(task):
    from flexmech_py.base.errors import SolverError

    if task["speed"] == 600.0:
        raise SolverError("made to fail for the test", time=0.0, code=2)
    return stability_point(task)   # the real one, imported before the test replaces it


def test_cli_stability_names_regions_exits_3_on_failed_speeds_and_writes_nothing_when_rejected(tmp_path, capsys,
                                                                                               monkeypatch):
    out = tmp_path / "st"
    assert main(["stability", str(SEED), "--speed", "440,460", "--jobs", "1", "--refine-rounds", "0",
                 "--out", str(out), "--no-plots"]) == 0
    text = capsys.readouterr().out
    assert "unstable (growth rate ln max|mu| / T > 0.1 1/s): 1 region(s)" in text
    assert "440.0-460.0 rad/s" in text and "real -1 side, period doubling" in text
    with open(out / "stability_regions.csv") as f:
        reg = list(csv.DictReader(line for line in f if not line.startswith("#")))
    assert len(reg) == 1 and reg[0]["multiplier"] == "real-" and float(reg[0]["speed_from"]) == 440.0
    with open(out / "stability.csv") as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    assert [r["multiplier"] for r in rows] == ["real-", "real-"] and float(rows[0]["mu_re"]) < -1
    # rejected: a torque-driven case, or a bad speed: one line, exit 2, no output folder
    for case, speed in ((CASES / "fourbar_hac.toml", "100:200:3"), (SEED, "0:10:3")):
        bad = tmp_path / "rejected"
        assert main(["stability", str(case), "--speed", speed, "--out", str(bad)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("flexmech: error: ") and not bad.exists()
    # a speed that fails: listed, the chart written, exit 3
    import flexmech_py.studies.floquet as fq
    monkeypatch.setattr(fq, "stability_point", _point_failing_at_600)
    assert main(["stability", str(SEED), "--speed", "560,600", "--jobs", "1", "--refine-rounds", "0",
                 "--out", str(tmp_path / "f"), "--no-plots"]) == 3
    cap = capsys.readouterr()
    assert [ln for ln in cap.err.splitlines() if ln.startswith("flexmech:")] == [
        "flexmech: error: 1 of 2 speeds failed (the others are kept):"]
    assert "1 x made to fail for the test (speeds 600 rad/s)" in cap.err
    assert "made to fail" in (tmp_path / "f" / "stability.csv").read_text()


if __name__ == "__main__":   # the time-run check of the damped pocket quoted in docs/stability.md
    f, t = pocket_growth()
    print(f"232.5 rad/s, Rayleigh [5, 5e-5], dt 1e-5 s: Floquet growth {f:.4f} 1/s, 80-cycle time run {t:.4f} 1/s")
