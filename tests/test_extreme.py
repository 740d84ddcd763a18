"""The stability suite (cases/extreme/, docs/stability.md "Extreme cases") at reduced size: each test
checks the physics claim its row of the table makes.  Full size: python -m flexmech_py.studies.extreme."""

import math

import numpy as np
import pytest

import flexmech_py as fm
from flexmech_py.studies import extreme as ex


def by(rows, key, value):
    return [r for r in rows if r[key] == value]


# ------------------------------------------------------------------------------------------ 1
@pytest.fixture(scope="module")
def stiff():
    # full size: one crank cycle, 524 steps, cheap
    return ex.stiff_study(integrators=("newmark", "galpha-0.8", "galpha-0.5", "galpha-0.0", "hht-0.05"))[0]


def test_stiff_step_far_above_highest_period(stiff):
    r = stiff[0]
    # the step is hundreds of highest periods and about half the first period: nothing is resolved
    assert r["dt"] * r["w_max"] / (2 * math.pi) > 100 and r["dt"] * r["w1_min"] / (2 * math.pi) > 0.3


def test_stiff_average_acceleration_bounded_but_rings(stiff):
    nm = by(stiff, "integrator", ex.LABEL["newmark"])[0]
    ga0 = by(stiff, "integrator", ex.LABEL["galpha-0.0"])[0]
    # bounded (unconditionally stable): no more than a few times the dissipative run's peak ...
    assert nm["peak_strain"] < 5 * ga0["peak_strain"]
    # ... but the unresolved start-up ringing stays as a period-2-step sawtooth of the response's size
    assert nm["sawtooth_strain"] > 0.2 and nm["sawtooth_axial"] > 0.1


def test_stiff_numerical_dissipation_removes_the_sawtooth(stiff):
    for lab, limit in (("galpha-0.0", 1e-3), ("galpha-0.5", 1e-3), ("galpha-0.8", 0.05), ("hht-0.05", 1e-2)):
        r = by(stiff, "integrator", ex.LABEL[lab])[0]
        assert r["sawtooth_strain"] < limit, lab
    nm = by(stiff, "integrator", ex.LABEL["newmark"])[0]
    ga8 = by(stiff, "integrator", ex.LABEL["galpha-0.8"])[0]
    assert ga8["sawtooth_strain"] < 0.1 * nm["sawtooth_strain"]


# ------------------------------------------------------------------------------------------ 2
def test_flexible_links_leave_the_linear_range():
    rows, _ = ex.flexible_study(models=("hac", "nonlinear"), t_end=0.005, windows=(0.002, 0.005))
    hac, nl = by(rows, "model", "hac")[0], by(rows, "model", "nonlinear")[0]
    for r in (hac, nl):
        assert r["deflection_over_length"] > 0.02          # beyond a few per cent of the link length
        assert r["compression_over_euler"] > 1.0          # compressive forces beyond the Euler load
        assert r["warnings"], r["model"]                  # and the run says so
    assert hac["t_deflection_2pc"] < 0.005 and nl["t_deflection_2pc"] < 0.005
    assert hac["strain_error_vs_nonlinear"][0.005] > 0.2  # the linear model no longer follows


# ------------------------------------------------------------------------------------------ 3
@pytest.fixture(scope="module")
def critical():
    return ex.critical_study(speeds=(120.0, 140.0, 280.0, 560.0), cycles=12, dt=5e-5)[1]


def test_critical_speed_bands(critical):
    p = {x["speed"]: x for x in critical}
    assert ex.classify_speed(p[120.0]) == ""
    assert "forced k=2 (ω1)" in ex.classify_speed(p[140.0])
    assert "parametric k=1 (ω1+ω1)" in ex.classify_speed(p[560.0])


def test_critical_speeds_growth(critical):
    p = {x["speed"]: x for x in critical}
    # away from every band: the response is bounded, damped or not
    assert p[120.0]["undamped"]["growth"] < 1.5 and p[120.0]["damped"]["growth"] < 1.5
    # crank speed at the first natural frequency: grows undamped
    assert p[280.0]["undamped"]["growth"] > 5
    # principal parametric resonance (crank speed = 2 w1): exponential growth that 1 % damping does not stop
    assert p[560.0]["damped"]["growth"] > 1e3
    # the time runs' growth per cycle is the largest Floquet multiplier where it dominates
    for lab in ("undamped", "damped"):
        assert p[560.0][lab]["per_cycle"] == pytest.approx(p[560.0][lab]["mu"], rel=0.05)
    assert p[280.0]["undamped"]["floquet_unstable"] and p[560.0]["damped"]["floquet_unstable"]
    assert not p[120.0]["undamped"]["floquet_unstable"] and not p[120.0]["damped"]["floquet_unstable"]
    assert p[120.0]["kind"] == "bounded" and p[560.0]["kind"] == "unstable"


# ------------------------------------------------------------------------------------------ 4
@pytest.fixture(scope="module")
def toggle():
    return ex.toggle_study(deltas=(20.0, 1.0), dt=4e-5)


def test_toggle_design():
    # the closed-form design puts the transmission angle at 180 - delta at crank angle pi
    from closed_forms import fourbar_angles

    d = ex.toggle_ground_length(3.0)
    case = fm.load_case(ex.case_path("toggle_fourbar"))
    assert case["mechanism"]["template"]["ground_length"] == pytest.approx(d, abs=1e-6)
    th3, th4 = fourbar_angles(0.10795, 0.2794, 0.2794, d, math.pi)
    mu = math.degrees(abs(math.remainder(th4 - th3, 2 * math.pi)))
    assert mu == pytest.approx(177.0, abs=1e-6)


def test_toggle_rigid_acceleration_grows_like_one_over_delta(toggle):
    _, pts = toggle
    a, b = pts[0], pts[1]        # delta 20 and 1 deg
    assert b["alpha4_max"] / a["alpha4_max"] > 10          # ~ 1/delta (20 / 1)
    assert b["omega4_max"] / a["omega4_max"] < 1.5         # while the velocity ratio stays bounded
    assert b["w1_min"] < 0.7 * a["w1_min"]                 # the elastic linkage softens at the toggle
    assert b["w1_max"] == pytest.approx(a["w1_max"], rel=0.05)
    for p in pts:
        assert np.isfinite(p["strain_max"]) and np.isfinite(p["axial_max"])


def test_toggle_passing_through_raises_mechanism_error(toggle):
    """Past the change point the driven crank cannot turn fully: the run stops at the assembly limit,
    names the time and the drive coordinate, and keeps every frame before it."""
    rows, _ = toggle
    err = rows[-1]["error"]
    assert err and "t = " in err and "crank_pivot = " in err and "cannot assemble" in err
    with pytest.raises(fm.MechanismError, match=r"at t = .* s: the mechanism cannot assemble") as info:
        fm.simulate(ex.load("toggle_fourbar", [f"mechanism.ground_length={ex.toggle_ground_length(0) + 1e-3}"]))
    part = info.value.partial
    assert part is not None and part.status == "failed" and 0 < part.t[-1] < info.value.time
    assert np.all(np.isfinite(part["strain_coupler_mid"]))


# ------------------------------------------------------------------------------------------ 5
@pytest.fixture(scope="module")
def spinup():
    configs = [c for c in ex.SPINUP_CONFIGS if c[:3:2] != ("nonlinear", "newmark")]
    return ex.spinup_study(rates=(6.0,), t_end=20.0, dt=2e-3, elements=4, configs=configs)


def test_spinup_first_frequency():
    case = ex.load("spinup_beam")
    ln = case["links"][0]
    assert ln["youngs_modulus"] * ln["area"] == pytest.approx(2.8e7)
    assert ln["youngs_modulus"] * ln["second_moment"] == pytest.approx(1.4e4)
    assert ln["density"] * ln["area"] == pytest.approx(1.2)
    assert ex.spinup_first_frequency(case) == pytest.approx(3.797, abs=1e-3)


def test_spinup_without_stiffening_diverges(spinup):
    rows, series = spinup
    none = by(rows, "model", "classic/none")[0]
    ref = by(rows, "model", ex.SPINUP_REFERENCE)[0]
    assert not ref["error"] and ref["t_last"] == pytest.approx(20.0)
    # it grows past the beam length, or stops on the divergence guard ...
    if none["error"]:
        assert "divergence" in none["error"]
    else:
        assert none["peak"] > 10 * ref["peak"]
    # ... after the spin rate passed the first bending frequency
    assert none.get("t_past_L", none["t_last"]) > none["t_rate_w1"]


def test_spinup_stiffened_follows_nonlinear(spinup):
    rows, _ = spinup
    ref = by(rows, "model", ex.SPINUP_REFERENCE)[0]
    assert ref["late"] < 0.02 * ref["peak"]            # returns to a small steady value after the spin-up
    for key in ("classic/current", "classic/quasi_static"):
        r = by(rows, "model", key)[0]
        assert r["peak_ratio_vs_nonlinear"] == pytest.approx(1.0, abs=0.05), key
        assert r["error_vs_nonlinear"] < 0.1, key
        assert r["late"] < 0.05 * r["peak"], key


# ------------------------------------------------------------------------------------------ 6
def test_long_run_amplitude_and_energy():
    rows, series = ex.long_run_study(integrators=("newmark", "galpha-0.8"), cycles=12, coupled_cycles=20, dt=2e-4,
                                     coupled_dt=1e-4)
    hac = {r["integrator"]: r for r in rows if r["model"] == "hac"}
    cpl = {r["integrator"]: r for r in rows if r["model"] == "coupled"}
    nm, ga = hac[ex.LABEL["newmark"]], hac[ex.LABEL["galpha-0.8"]]
    # average acceleration: the free vibration of the start-up transient is kept (no decay) ...
    assert nm["change_last"] > 0.5 * nm["change_cycle2"]
    # ... and generalized-alpha at w1 dt ~ 0.06 keeps it too (its dissipation acts at w dt ~ 1)
    assert ga["change_last"] > 0.8 * nm["change_last"]
    assert ga["amp_last"] == pytest.approx(nm["amp_last"], rel=0.05)
    # coupled model: the drive constraint's period-2-step mode grows under average acceleration ...
    cn, cg = cpl[ex.LABEL["newmark"]], cpl[ex.LABEL["galpha-0.8"]]
    assert cn["drive_saw_last"] > 3 * cn["drive_saw_first"]
    # ... and stays down under generalized-alpha, which only removes energy
    assert cg["drive_saw_last"] < 1.5 * cg["drive_saw_first"] and cg["drive_saw_last"] < 0.3 * cn["drive_saw_last"]
    assert cg["energy_final"] < 0 and cg["energy_drift"] < 0.01


# ------------------------------------------------------------------------------------------ 7
def test_torque_step_high_frequency_content():
    rows, _ = ex.torque_step_study(integrators=("newmark", "galpha-0.5"), models=("coupled",), dts=(1e-3,))
    nm, ga = rows[0], rows[1]
    # the step leaves the axial chord-stretch modes ringing, aliased to the step frequency when unresolved
    assert nm["hf_axial"] > 0.5 and nm["sawtooth_axial"] > 0.3
    # generalized-alpha (rho_inf 0.5) removes it and halves the axial-force peak ...
    assert ga["hf_axial"] < 0.5 * nm["hf_axial"] and ga["sawtooth_axial"] < 0.1 * nm["sawtooth_axial"]
    assert ga["peak_axial"] < 0.6 * nm["peak_axial"]
    # ... while the bending response stays within 10 %
    assert abs(ga["peak_tip_dy"] / nm["peak_tip_dy"] - 1) < 0.1


def test_every_extreme_case_has_a_header():
    for name in ("stiff_fourbar", "flexible_fourbar", "critical_fourbar", "toggle_fourbar", "spinup_beam",
                 "long_run_fourbar", "manipulator_torque_step"):
        text = ex.case_path(name).read_text()
        assert text.startswith("# Stability suite, case")
        assert "Where the numbers come from" in text or "Source:" in text
        assert "Expect" in text
