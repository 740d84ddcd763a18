"""Input shapers (flexmech_py.base.shaping) against their defining properties, and shaping at work on the
manipulator under PD joint control closed through the stepping API (flexmech_py.studies.shaping_study)."""

import numpy as np
import pytest

from flexmech_py.base.errors import CaseError
from flexmech_py.base.shaping import RestToRest, design, residual_vibration
from flexmech_py.studies.shaping_study import manipulator, pd_move, residual
from flexmech_py.studies.modes import modes


@pytest.mark.parametrize("zeta", [0.0, 0.05])
def test_zv_and_zvd_cancel_the_design_mode_and_zvd_is_flat_there(zeta):
    f = 7.5
    zv, zvd = design("zv", f, zeta), design("zvd", f, zeta)
    for sh in (zv, zvd):
        assert sh.amplitudes.sum() == pytest.approx(1.0) and sh.times[0] == 0.0
        assert residual_vibration(sh, f, zeta) == pytest.approx(0.0, abs=1e-12)
    h = 1e-4 * f
    slope = lambda sh: (residual_vibration(sh, f + h, zeta) - residual_vibration(sh, f - h, zeta)) / (2 * h)
    assert abs(slope(zvd)) < 1e-3 * abs(slope(zv))
    assert zv.duration == pytest.approx(0.5 / (f * np.sqrt(1 - zeta ** 2)))
    # the classic insensitivities at +-20 % frequency error (undamped): ZV 31 %, ZVD 10 %
    if zeta == 0.0:
        assert residual_vibration(zv, 1.2 * f) == pytest.approx(abs(np.cos(0.6 * np.pi)), rel=1e-9)
        assert residual_vibration(zvd, 1.2 * f) == pytest.approx(np.cos(0.6 * np.pi) ** 2, rel=1e-9)


def test_ei_leaves_its_tolerance_at_the_design_frequency_and_stays_below_it_on_a_wider_band():
    f = 10.0
    ei, zvd = design("ei", f, tolerance=0.05), design("zvd", f)
    assert residual_vibration(ei, f) == pytest.approx(0.05, rel=1e-9)
    r = np.linspace(0.6, 1.4, 801)
    band = lambda sh: np.ptp(r[residual_vibration(sh, r * f) <= 0.05])
    assert band(ei) > 1.3 * band(zvd)


def test_rest_to_rest_profiles_start_and_end_at_rest():
    for profile in ("cycloidal", "quintic"):
        m = RestToRest(profile, 0.2, 0.5, 0.3)
        (x0, v0), (x1, v1) = m(0.0), m(0.3)
        assert (x0, v0, v1) == pytest.approx((0.2, 0.0, 0.0), abs=1e-15) and x1 == pytest.approx(0.7)
        t = np.linspace(0, 0.3, 3001)
        x, v = m(t)
        assert np.allclose(np.gradient(x, t), v, atol=1e-3 * v.max())
    with pytest.raises(CaseError, match="reference.profile"):
        RestToRest("trapezoid", 0, 1, 1)
    with pytest.raises(CaseError, match="shaper.frequency_hz"):
        design("zv", -1.0)


def test_zv_shaping_of_a_pd_move_leaves_a_fraction_of_the_unshaped_residual_vibration():
    """A short cycloidal base move of the manipulator (superposition model, coarse step): the ZV
    shaper designed from the frozen first mode cuts the tip's residual vibration to a few per cent."""
    case = manipulator(t_end=0.65, dt=2e-4)
    f1 = float(modes(case, at=0.0, count=1).hz[0])
    move = RestToRest("cycloidal", 0.0, 0.3, 0.15)
    zv = design("zv", f1)

    def shaped(t):
        parts = [(a, move(max(t - ti, 0.0))) for a, ti in zip(zv.amplitudes, zv.times)]
        return sum(a * p[0] for a, p in parts), sum(a * p[1] for a, p in parts)

    plain, with_zv = pd_move(case, move), pd_move(case, shaped)
    # after the PD loop's own settling (0.2 s past the move's end): the mode's ringing
    r_plain, r_zv = residual(plain, 0.35, 0.3), residual(with_zv, 0.35 + zv.duration, 0.3 - zv.duration)
    assert r_plain > 1e-2 and r_zv < 0.15 * r_plain
