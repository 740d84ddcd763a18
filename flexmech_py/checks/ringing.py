"""Why a step-doubling estimate does not shrink with the step: undamped elastic ringing
(docs/stability.md, "Error estimate").

An elastic mode excited at the start (or by a sudden load) and left undamped rings for the whole run.
The runs at dt and 2 dt hold its amplitude but not its phase: the phase error grows with the number of
cycles, and once it is of order one radian the difference between the runs is as large as the
ringing itself, whatever the step, so the observed order falls to about zero.  A smaller step does
not settle it at any reasonable cost; damping does: physical damping (``solver.rayleigh``) removes the
ringing if it is not of interest, numerical dissipation (``--integrator generalized-alpha
--rho-inf``) removes the modes the step does not resolve (omega dt above about 1).

:class:`DifferenceFrequency` follows, per output column, the rms frequency of the difference
y_dt - y_2dt over the compared frames (sqrt of sum (d')^2 / sum d^2, the derivative by differences of
consecutive compared frames; a frequency above the frames' Nyquist frequency is seen aliased, lower).
:func:`ringing_cause` calls the difference ringing when the observed order is at most ORDER_RINGING
and the difference oscillates at least CYCLES_RINGING times over the compared span, and says what
would damp it.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["DifferenceFrequency", "ringing_cause", "ORDER_RINGING", "CYCLES_RINGING", "ZETA"]

#: observed order at or below which a step-doubling difference is not a converging discretization error
ORDER_RINGING = 1.0
#: cycles over the compared span from which the difference is a vibration, not a drift of the motion
CYCLES_RINGING = 20.0
#: damping ratio the suggested stiffness-proportional coefficient gives at the ringing frequency
ZETA = 0.02
#: omega dt from which generalized-alpha's numerical dissipation damps a mode appreciably
#: (docs/theory.md section 15.2: rho(omega dt = 1) = 0.989 for rho_inf = 0.5)
OMEGA_DT_DISSIPATED = 1.0


class DifferenceFrequency:
    """Per column, the mean of d^2 and of (d')^2 of the difference d between two runs over the frames
    both have (fed in time order, block by block, :meth:`add`), and the span of those frames."""

    def __init__(self):
        self.sums: dict = {}        # name -> [sum d^2, frames, sum (d')^2, differences]
        self.last, self.t0, self.t1 = {}, {}, {}

    def add(self, name: str, t: np.ndarray, d: np.ndarray) -> None:
        if t.size == 0:
            return
        prev = self.last.get(name)
        tt, dd = (t, d) if prev is None else (np.r_[prev[0], t], np.r_[prev[1], d])
        h = np.diff(tt)
        ok = h > 0.0
        s = self.sums.setdefault(name, [0.0, 0, 0.0, 0])
        s[0] += float(np.sum(d * d))
        s[1] += int(d.size)
        s[2] += float(np.sum((np.diff(dd)[ok] / h[ok]) ** 2))
        s[3] += int(np.count_nonzero(ok))
        self.last[name] = (float(t[-1]), float(d[-1]))
        self.t0.setdefault(name, float(tt[0]))
        self.t1[name] = float(t[-1])

    def frequency(self, name: str) -> float | None:
        """rms frequency [Hz] of the difference of column ``name`` (None: no difference, or one frame)."""
        s = self.sums.get(name)
        if s is None or not s[0] > 0.0 or s[3] == 0:
            return None
        return math.sqrt((s[2] / s[3]) / (s[0] / s[1])) / (2.0 * math.pi)

    def span(self, name: str) -> float:
        return self.t1.get(name, 0.0) - self.t0.get(name, 0.0)


def ringing_cause(name: str, freq: float | None, span: float, order: float | None, dt: float) -> dict | None:
    """The cause and advice of a step-doubling estimate past its threshold when the difference of column
    ``name`` is undamped ringing (see the module's docstring), else None.  ``freq`` [Hz] and ``span``
    [s] from :class:`DifferenceFrequency`, ``order`` the observed order, ``dt`` the run's step [s]."""
    if order is None or freq is None or order > ORDER_RINGING or freq * span < CYCLES_RINGING:
        return None
    w = 2.0 * math.pi * freq
    a_k = 2.0 * ZETA / w
    f_nd = OMEGA_DT_DISSIPATED / (2.0 * math.pi * dt)
    text = (f"the difference between the runs at dt and 2 dt is a vibration at about {freq:.3g} Hz "
            f"({freq * span:.0f} cycles over the run; observed order {order:.2g}): undamped elastic ringing, whose "
            "phase the step does not hold over so many cycles, not an error a smaller step would settle; ")
    damp = (f"if the ringing is not of interest, damp it: solver.rayleigh = [0, {a_k:.2g}] gives {100 * ZETA:g} % of "
            f"critical damping at {freq:.3g} Hz (--set 'solver.rayleigh=[0,{a_k:.2g}]')")
    if freq >= 0.3 * f_nd:
        advice = (f"numerical dissipation removes the modes the step does not resolve (above about {f_nd:.3g} Hz): "
                  "--integrator generalized-alpha --rho-inf 0.5; or " + damp)
    else:
        advice = (damp + f"; numerical dissipation (--integrator generalized-alpha --rho-inf) acts only above about "
                         f"{f_nd:.3g} Hz at this step and would not remove it")
    return {"cause": "ringing", "frequency_hz": freq, "cycles": freq * span, "suggested_rayleigh": [0.0, a_k],
            "message": text + advice}
