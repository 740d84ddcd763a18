"""Input shapers and rest-to-rest references (docs/theory.md, "Input shaping").

A shaper is a train of impulses (amplitudes A_i summing to 1 at times t_i, t_1 = 0); a reference
convolved with it, r_s(t) = sum_i A_i r(t - t_i), excites a mode of frequency w and damping ratio
zeta to the fraction V (the percentage residual vibration) of what r alone does:

    V = exp(-zeta w t_n) sqrt((sum A_i exp(zeta w t_i) cos(w_d t_i))^2 + (sum A_i exp(zeta w t_i) sin(w_d t_i))^2)

with w_d = w sqrt(1 - zeta^2).  Designs (half damped period T_d/2 = pi / w_d, K = exp(-zeta pi / sqrt(1 - zeta^2))):

- ZV: A = [1, K] / (1 + K), t = [0, T_d/2] (Singer and Seering 1990: V = 0 at the design frequency);
- ZVD: A = [1, 2K, K^2] / (1 + K)^2, t = [0, T_d/2, T_d] (also dV/dw = 0 there);
- EI (extra-insensitive, undamped design, Singhose, Seering and Singer 1994): A = [(1 + Vt)/4,
  (1 - Vt)/2, (1 + Vt)/4], t = [0, T/2, T], residual Vt (default 5 %) at the design frequency and
  below Vt over a wider band than ZVD's.

Rest-to-rest profiles of a joint coordinate over a duration T and a travel D, s = t/T in [0, 1]:
cycloidal D (s - sin(2 pi s)/(2 pi)), quintic D (10 s^3 - 15 s^4 + 6 s^5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import CaseError

__all__ = ["Shaper", "SHAPERS", "design", "residual_vibration", "RestToRest", "PROFILES"]

SHAPERS = ("zv", "zvd", "ei")
PROFILES = ("cycloidal", "quintic")


@dataclass(frozen=True)
class Shaper:
    """Impulses ``amplitudes`` (sum 1) at ``times`` [s], designed for ``frequency_hz`` and ``damping``."""

    kind: str
    amplitudes: np.ndarray
    times: np.ndarray
    frequency_hz: float
    damping: float

    @property
    def duration(self) -> float:
        """The delay the shaper adds to a move [s]."""
        return float(self.times[-1])

    def apply(self, reference):
        """The shaped reference: t -> sum_i A_i reference(t - t_i) (reference(t) for t < 0 is its
        value at 0); ``reference`` maps an array of times [s] to values."""
        def shaped(t):
            t = np.asarray(t, float)
            return sum(a * reference(np.maximum(t - ti, 0.0)) for a, ti in zip(self.amplitudes, self.times))
        return shaped

    def as_dict(self) -> dict:
        return {"kind": self.kind, "frequency_hz": self.frequency_hz, "damping": self.damping,
                "amplitudes": [float(a) for a in self.amplitudes], "times_s": [float(t) for t in self.times]}


def design(kind: str, frequency_hz: float, damping: float = 0.0, tolerance: float = 0.05) -> Shaper:
    """The ``kind`` (zv | zvd | ei) shaper for a mode of ``frequency_hz`` [Hz] and ``damping`` ratio;
    ``tolerance``: EI's residual vibration at the design frequency."""
    if kind not in SHAPERS:
        raise CaseError("shaper", f"must be one of {', '.join(SHAPERS)}, got {kind!r}")
    if not (math.isfinite(frequency_hz) and frequency_hz > 0):
        raise CaseError("shaper.frequency_hz", f"must be a positive finite frequency, got {frequency_hz!r}")
    if not (math.isfinite(damping) and 0.0 <= damping < 1.0):
        raise CaseError("shaper.damping", f"must be in [0, 1), got {damping!r}")
    if not 0.0 < tolerance < 1.0:
        raise CaseError("shaper.tolerance", f"must be in (0, 1), got {tolerance!r}")
    wd = 2 * math.pi * frequency_hz * math.sqrt(1 - damping ** 2)
    half = math.pi / wd
    k = math.exp(-damping * math.pi / math.sqrt(1 - damping ** 2))
    if kind == "zv":
        amps, times = np.array([1.0, k]) / (1 + k), np.array([0.0, half])
    elif kind == "zvd":
        amps, times = np.array([1.0, 2 * k, k * k]) / (1 + k) ** 2, np.array([0.0, half, 2 * half])
    else:
        v = tolerance
        amps, times = np.array([(1 + v) / 4, (1 - v) / 2, (1 + v) / 4]), np.array([0.0, half, 2 * half])
    return Shaper(kind, amps, times, float(frequency_hz), float(damping))


def residual_vibration(shaper: Shaper | None, frequency_hz, damping: float = 0.0) -> np.ndarray:
    """V (module docstring) of ``shaper`` (None: a single unit impulse, V = 1) for modes of
    ``frequency_hz`` (array) and ``damping``."""
    f = np.asarray(frequency_hz, float)
    if shaper is None:
        return np.ones_like(f)
    w = 2 * np.pi * f
    wd = w * math.sqrt(1 - damping ** 2)
    amps, times = shaper.amplitudes, shaper.times
    e = np.exp(damping * w[..., None] * times)
    c = np.sum(amps * e * np.cos(wd[..., None] * times), axis=-1)
    s = np.sum(amps * e * np.sin(wd[..., None] * times), axis=-1)
    return np.exp(-damping * w * times[-1]) * np.hypot(c, s)


@dataclass(frozen=True)
class RestToRest:
    """A rest-to-rest move of a joint coordinate from ``start`` by ``travel`` over ``duration`` [s]."""

    profile: str
    start: float
    travel: float
    duration: float

    def __post_init__(self):
        if self.profile not in PROFILES:
            raise CaseError("reference.profile", f"must be one of {', '.join(PROFILES)}, got {self.profile!r}")
        if not (math.isfinite(self.duration) and self.duration > 0):
            raise CaseError("reference.duration", f"must be a positive time [s], got {self.duration!r}")
        if not (math.isfinite(self.travel) and math.isfinite(self.start)):
            raise CaseError("reference.travel", "start and travel must be finite")

    def __call__(self, t):
        """(value, rate) at times t [s]."""
        s = np.clip(np.asarray(t, float) / self.duration, 0.0, 1.0)
        d, T = self.travel, self.duration
        if self.profile == "cycloidal":
            return (self.start + d * (s - np.sin(2 * np.pi * s) / (2 * np.pi)),
                    d / T * (1 - np.cos(2 * np.pi * s)))
        return (self.start + d * s ** 3 * (10 - 15 * s + 6 * s * s),
                d / T * 30 * s * s * (1 - s) ** 2)
