"""Unstable regions of a stability chart (flexmech_py/studies/regions.py): the multiplier type of known
parametric resonances (Mathieu equations integrated here with SciPy, independent of flexmech's
kernels), and the adaptive refinement of the speed grid on a synthetic chart."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from flexmech_py.studies.floquet import STABLE_RATE
from flexmech_py.studies.regions import (PEAK_PROMINENCE, default_resolution, describe_region, multiplier_type,
                                 refinement_speeds, unstable_regions)


def _monodromy(omega2, eps, coupling, speed):
    """Monodromy of x'' + (diag(omega2) + eps cos(speed t) coupling) x = 0 over T = 2 pi / speed."""
    n = len(omega2)
    T = 2 * np.pi / speed

    def rhs(t, y):
        x, v = y[:n], y[n:]
        return np.concatenate([v, -(np.diag(omega2) + eps * np.cos(speed * t) * coupling) @ x])

    cols = [solve_ivp(rhs, (0, T), e, rtol=1e-11, atol=1e-13).y[:, -1] for e in np.eye(2 * n)]
    return np.array(cols).T


def _dominant(phi):
    mu = np.linalg.eigvals(phi)
    return mu[np.argmax(np.abs(mu))]


def test_mathieu_principal_resonance_is_real_negative_and_the_second_real_positive():
    # x'' + w^2 (1 + eps cos(Omega t)) x = 0: the principal region Omega = 2 w has the response at
    # Omega / 2 (period doubling: mu on the -1 side), the second region Omega ~ w period T (+1 side)
    w = 1.0
    mu = _dominant(_monodromy([w ** 2], 0.3, np.array([[w ** 2]]), 2.0 * w))
    assert abs(mu) > 1.05 and multiplier_type(mu.real, mu.imag) == "real-"
    second = [_dominant(_monodromy([w ** 2], 0.6, np.array([[w ** 2]]), s)) for s in np.linspace(0.9, 1.0, 6)]
    top = max(second, key=abs)
    assert abs(top) > 1.01 and multiplier_type(top.real, top.imag) == "real+"
    stable = _dominant(_monodromy([w ** 2], 0.3, np.array([[w ** 2]]), 1.4 * w))
    assert abs(abs(stable) - 1) < 1e-8 and multiplier_type(stable.real, stable.imag) == "complex"


def test_combination_resonance_is_a_complex_pair_at_the_modes_angle():
    # two modes w1 = 1, w2 = 1.7 coupled parametrically, driven at Omega = w1 + w2: the pair leaves the unit
    # circle where the multipliers of both modes meet, exp(+-i w1 T) = exp(-+i w2 T)
    w1, w2 = 1.0, 1.7
    speed = w1 + w2
    mu = _dominant(_monodromy([w1 ** 2, w2 ** 2], 0.3, np.array([[0.0, 1.0], [1.0, 0.0]]), speed))
    assert abs(mu) > 1.02 and multiplier_type(mu.real, mu.imag) == "complex"
    expected = math.degrees(w1 * 2 * np.pi / speed) % 360
    assert abs(abs(math.degrees(np.angle(mu))) - min(expected, 360 - expected)) < 2.0


def _synthetic_rows(speeds, centre=232.75):
    """A damped chart: ln|mu| per period -0.15 away from a tongue (real +1 side) rising linearly to 0.03 at
    ``centre`` over 11.5 rad/s on either side, unstable over about 3.5 rad/s only, and a small bump at
    170 rad/s that stays far below the threshold."""
    rows = []
    for s in speeds:
        T = 2 * np.pi / s
        lnmu = -0.15 + 0.18 * max(0.0, 1 - abs(s - centre) / 11.5) + 0.002 * math.exp(-((s - 170) / 5) ** 2)
        amu = math.exp(lnmu)
        rows.append({"speed": s, "max_abs_mu": amu, "growth_rate": lnmu / T, "stable": int(lnmu / T <= STABLE_RATE),
                     "mu_re": amu, "mu_im": 0.0})
    return rows


def _refine(speeds, resolution, rounds=8):
    rows = _synthetic_rows(speeds)
    for _ in range(rounds):
        new = [s for s in refinement_speeds(rows, resolution) if s not in {r["speed"] for r in rows}]
        if not new:
            break
        rows += _synthetic_rows(new)
    return rows


def test_refinement_finds_a_narrow_pocket_the_coarse_grid_misses_and_its_edges():
    grid = list(np.arange(20.0, 601.0, 10.0))
    assert unstable_regions(_synthetic_rows(grid)) == []            # 230 and 240 are both stable
    res = default_resolution(grid)
    assert res == pytest.approx(10 / 16)
    rows = _refine(grid, res)
    regions = unstable_regions(rows)
    assert len(regions) == 1
    reg = regions[0]
    # the exact edges: where the growth rate crosses the threshold
    fine = _synthetic_rows(list(np.linspace(225, 240, 15001)))
    unst = [r["speed"] for r in fine if not r["stable"]]
    assert reg["below"] < unst[0] <= reg["from"] and reg["to"] <= unst[-1] < reg["above"]
    assert reg["from"] - reg["below"] <= res and reg["above"] - reg["to"] <= res
    assert reg["parts"][0]["type"] == "real+" and "real +1 side" in describe_region(reg)
    # the refinement stayed near the pocket and the bump at 170 (prominence above PEAK_PROMINENCE, stable)
    added = sorted({r["speed"] for r in rows} - set(grid))
    assert all(160 < s < 180 or 220 < s < 250 for s in added), added
    assert len(added) < 40


def test_no_refinement_on_a_flat_floor_and_none_below_the_resolution():
    flat = [{"speed": s, "max_abs_mu": 1 + 1e-4 + 1e-7 * math.sin(s), "growth_rate": 1e-3, "stable": 1,
             "mu_re": 0.0, "mu_im": 1.0} for s in np.arange(20.0, 200.0, 4.0)]
    assert PEAK_PROMINENCE > 1e-6 and refinement_speeds(flat, 0.25) == []
    rows = _synthetic_rows([230.0, 230.5, 231.0])
    assert refinement_speeds(rows, 0.5) == []       # every interval is at the resolution already


def test_a_region_of_one_sample_is_not_labelled_with_zero_width():
    """One unstable speed between stable neighbours (124 rad/s on the seed four-bar's chart) is said to be
    one sample inside its stable neighbours, not '124.00-124.00 rad/s'; a one-sample part likewise."""
    def row(speed, mu, stable, re=None, im=0.0):
        return {"speed": speed, "max_abs_mu": mu, "growth_rate": 0.3 if not stable else -1.0, "stable": stable,
                "mu_re": -mu if re is None else re, "mu_im": im}

    rows = [row(123.75, 0.99, True), row(124.0, 1.018, False, re=-0.94, im=0.39), row(124.25, 0.99, True),
            row(190.75, 0.99, True), row(191.0, 1.2, False), row(191.25, 1.1, False, re=-1.0, im=0.4),
            row(191.5, 0.99, True)]
    regs = unstable_regions(rows)
    one = describe_region(regs[0], 2)
    assert "124.00-124.00" not in one and one.startswith("124.00 rad/s (one unstable sample")
    assert "inside 123.75-124.25" in one
    two = describe_region(regs[1], 2)
    assert "191.25-191.25" not in two and "191.00-191.25 rad/s" in two and two.endswith("191.25")
