"""Drives on joint coordinates: kinematic laws (the coordinate as a function of time) and force laws
(a torque on a joint whose coordinate is an angle, a force on one whose coordinate is a slide).  Each law packs itself into the flat
layout of the Fortran flexmech_drivelaw module (its ``code`` and up to four parameters).

Kinematic laws (absolute joint coordinate f(t) [rad or m]; ``start`` defaults to the coordinate in
the assembly configuration, so the mechanism starts where it was drawn):

- ``constant_speed``: ``speed``; f = start + speed t.
- ``spinup``: ``final_speed``, ``spinup_time`` T; the smooth start from rest of Simo and Vu-Quoc,
  f = start + (w/T)(t^2/2 + (T/2 pi)^2 (cos(2 pi t/T) - 1)) up to T, then constant speed w.
- ``harmonic``: ``amplitude``, ``frequency`` [rad/s], ``phase`` [rad], ``mean`` (default: the
  assembly value minus amplitude sin(phase)); f = mean + amplitude sin(frequency t + phase).
- ``rest_to_rest``: ``travel``, ``duration`` T, ``profile`` (``"cycloidal"`` (default) or
  ``"quintic"``), ``start_time`` t0 (default 0); with s = (t - t0)/T clipped to [0, 1],
  f = start + travel (s - sin(2 pi s)/(2 pi)) or start + travel (10 s^3 - 15 s^4 + 6 s^5)
  (flexmech_py.base.shaping.rest_to_rest is the same profile in Python).
- ``table``: samples ``t`` [s] (increasing, from 0 at the latest) and ``value``, joined by a
  not-a-knot cubic spline (continuous accelerations).

Force law ``force``: tau = ``constant`` + sum_k sin_k sin(k theta) + cos_k cos(k theta) (harmonics of
the joint angle theta; revolute joints only) + sum_j a_j sin(w_j t + p_j) (``time_harmonics``
[[a, w, p], ...]) + a ``table`` {t = [...], value = [...]} in time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Drive", "KINEMATIC_LAWS", "LAW_CODES", "cubic_spline", "spinup", "constant_speed"]

LAW_CODES = {"constant_speed": 1, "spinup": 2, "harmonic": 3, "table": 4, "rest_to_rest": 5, "force": 11}
KINEMATIC_LAWS = ("constant_speed", "spinup", "harmonic", "table", "rest_to_rest")
REST_PROFILES = {"cycloidal": 5, "quintic": 6}     # the rest_to_rest law's codes in flexmech_drivelaw
#: parameters of each law: (required, optional with defaults)
LAW_PARAMS = {
    "constant_speed": ({"speed"}, {"start": None}),
    "spinup": ({"final_speed", "spinup_time"}, {"start": None}),
    "harmonic": ({"amplitude", "frequency"}, {"phase": 0.0, "mean": None}),
    "table": ({"t", "value"}, {}),
    "rest_to_rest": ({"travel", "duration"}, {"profile": "cycloidal", "start_time": 0.0, "start": None}),
    "force": (set(), {"constant": 0.0, "sin": [], "cos": [], "time_harmonics": [], "table": None}),
}


@dataclass
class Drive:
    """A drive on joint ``joint`` with law ``law`` (a key of LAW_CODES) and its ``params``."""

    joint: str
    law: str
    params: dict = field(default_factory=dict)

    @property
    def kinematic(self) -> bool:
        return self.law in KINEMATIC_LAWS

    @property
    def code(self) -> int:
        if self.law == "rest_to_rest":
            return REST_PROFILES[self.params.get("profile") or "cycloidal"]
        return LAW_CODES[self.law]

    def spec(self) -> dict:
        """The drive as a case-file table."""
        out = {"joint": self.joint, "law": self.law}
        for k, v in self.params.items():
            if v is None or (isinstance(v, list) and not v):
                continue
            out[k] = v
        return out

    def packed(self, start: float) -> dict:
        """The law for flexmech_drivelaw: ``par`` (4 numbers), ``sin`` and ``cos`` (harmonics of the
        joint coordinate), ``time_harmonics`` [[a, w, p], ...] and ``table`` ((t, coefficients (4, n))
        or None); ``start`` is the joint coordinate in the assembly configuration."""
        p = self.params
        out = {"par": [0.0] * 4, "sin": [], "cos": [], "time_harmonics": [], "table": None}
        if self.law == "constant_speed":
            out["par"] = [_or(p.get("start"), start), p["speed"], 0.0, 0.0]
        elif self.law == "spinup":
            out["par"] = [_or(p.get("start"), start), p["final_speed"], p["spinup_time"], 0.0]
        elif self.law == "harmonic":
            mean = _or(p.get("mean"), start - p["amplitude"] * math.sin(p["phase"]))
            out["par"] = [mean, p["amplitude"], p["frequency"], p["phase"]]
        elif self.law == "table":
            out["table"] = (np.asarray(p["t"], float), cubic_spline(p["t"], p["value"]))
        elif self.law == "rest_to_rest":
            out["par"] = [_or(p.get("start"), start), p["travel"], p["duration"], p.get("start_time") or 0.0]
        else:
            tab = p.get("table")
            out.update(par=[p["constant"], 0.0, 0.0, 0.0], sin=list(p["sin"]), cos=list(p["cos"]),
                       time_harmonics=[list(h) for h in p["time_harmonics"]],
                       table=None if tab is None else (np.asarray(tab["t"], float), cubic_spline(tab["t"], tab["value"])))
        return out

    def value_at_start(self, start: float) -> float:
        """The law's joint coordinate at t = 0 (kinematic laws)."""
        k = self.packed(start)
        if self.law == "table":
            return float(_spline_at(*k["table"], 0.0))
        par = k["par"]
        if self.law == "harmonic":
            return par[0] + par[1] * math.sin(par[3])
        if self.law == "rest_to_rest" and par[3] < 0.0:
            return par[0] + par[1] * min(1.0, -par[3] / par[2])    # (the quintic's endpoints are the same)
        return par[0]


def _spline_at(t, c, x: float) -> float:
    i = int(np.clip(np.searchsorted(t, x, side="right") - 1, 0, t.size - 2))
    s = x - t[i]
    return c[0, i] + s * (c[1, i] + s * (c[2, i] + s * c[3, i]))


def _or(value, default):
    return default if value is None else float(value)


def cubic_spline(t, y) -> np.ndarray:
    """Coefficients (4, n) of the not-a-knot cubic spline through (t_i, y_i) (natural for 3 points,
    the straight line for 2): on [t_i, t_i+1], y = c0 + c1 s + c2 s^2 + c3 s^3 with s = t - t_i."""
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    n = t.size
    h = np.diff(t)
    m = _spline_second_derivatives(t, y, h)
    c = np.zeros((4, n))
    c[0] = y
    c[2, :-1] = m[:-1] / 2.0
    c[3, :-1] = (m[1:] - m[:-1]) / (6.0 * h)
    c[1, :-1] = (y[1:] - y[:-1]) / h - h * (2.0 * m[:-1] + m[1:]) / 6.0
    return c


def _spline_second_derivatives(t, y, h) -> np.ndarray:
    n = t.size
    if n == 2:
        return np.zeros(2)
    a = np.zeros((n, n))
    r = np.zeros(n)
    for i in range(1, n - 1):
        a[i, i - 1:i + 2] = [h[i - 1], 2.0 * (h[i - 1] + h[i]), h[i]]
        r[i] = 6.0 * ((y[i + 1] - y[i]) / h[i] - (y[i] - y[i - 1]) / h[i - 1])
    if n == 3:                     # natural ends
        a[0, 0] = a[-1, -1] = 1.0
    else:                          # not-a-knot: the third derivative continuous at t_1 and t_n-2
        a[0, :3] = [h[1], -(h[0] + h[1]), h[0]]
        a[-1, -3:] = [h[-1], -(h[-2] + h[-1]), h[-2]]
    return _solve_banded(a, r)


def _solve_banded(a: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Solve the (nearly tridiagonal) spline system; dense for small tables, banded elimination beyond."""
    n = r.size
    if n <= 400:
        return np.linalg.solve(a, r)
    # Gaussian elimination within the band (half width 2 counting the not-a-knot rows), no pivoting:
    # the interior rows are diagonally dominant
    a = a.copy()
    r = r.copy()
    for i in range(n - 1):
        for k in range(i + 1, min(i + 3, n)):
            if a[k, i] != 0.0:
                f = a[k, i] / a[i, i]
                a[k, i:i + 3] -= f * a[i, i:i + 3]
                r[k] -= f * r[i]
    x = np.zeros(n)
    for i in range(n - 1, -1, -1):
        x[i] = (r[i] - a[i, i + 1:i + 3] @ x[i + 1:i + 3]) / a[i, i]
    return x


def constant_speed(t, start: float, speed: float):
    """(f, f', f'') of the constant-speed law on times t (for tests and analysis)."""
    t = np.asarray(t, float)
    return start + speed * t, np.full_like(t, speed), np.zeros_like(t)


def spinup(t, final_speed: float, spinup_time: float, start: float = 0.0):
    """(f, f', f'') of the spin-up law on times t (at rest for t < 0)."""
    t = np.maximum(np.asarray(t, float), 0.0)
    w, T = float(final_speed), float(spinup_time)
    k = 2 * np.pi / T
    ramp = t <= T
    f = np.where(ramp, w / T * (t * t / 2 + (np.cos(k * t) - 1) / k ** 2), w * (t - T / 2))
    fd = np.where(ramp, w / T * (t - np.sin(k * t) / k), w)
    fdd = np.where(ramp, w / T * (1 - np.cos(k * t)), 0.0)
    return start + f, fd, fdd
