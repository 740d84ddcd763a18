"""The eigenvalues of a feedback loop closed around a flexible mechanism (docs/theory.md section 23.5):
the case's coupled or nonlinear model linearized about its state at t = 0 (the frozen eigenproblem of
:mod:`flexmech_py.models.modal`, with its damping matrix), one of its controllers added as feedback of
the measured signal through the generalized force of its force drive, the first-order state matrix
A(kp, kd, ki) and its eigenvalues; the gain where the loop loses stability (the largest real part of
the eigenvalues crossing zero along a ray of gains, found by scipy's brentq).

Python::

    from flexmech_py.studies.control_eigen import linearize_loop, critical_gain
    loop = linearize_loop(case, "hub_pid")    # the controller's measured signal and drive
    loop.abscissa(kp=2.0, kd=0.3)             # max Re lambda [1/s]
    critical_gain(loop, tau=0.15)             # the kp of the law kp (e + tau e') where max Re = 0

The law is the continuous one (sample_time = delay = 0: docs/theory.md 23.1), linearized about rest:
its output limits are not active there, its reference and feedforward do not change the eigenvalues.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from scipy.optimize import brentq

from ..base.errors import CaseError
from ..base.families import family
from ..case import Case, study_model, with_elements
from ..models import modal
from ..models.constrained.coupled import CoupledModel
from ..models.constrained.layout import Row
from ..run.simulate import motion_source

__all__ = ["Loop", "linearize_loop", "critical_gain", "GAIN_RANGE", "TOUCH", "MARGINAL"]

#: a mode whose actuator participation or measurement is below this fraction of the largest is one the
#: loop does not touch (its eigenvalue stays the open loop's: e.g. the axial modes of a link under a
#: hub torque)
TOUCH = 1e-9
#: the gains scanned for the first loss of stability (kp [u/rad or u/m]), log-spaced
GAIN_RANGE = (1e-3, 1e4)
SCAN_POINTS = 141
#: real parts within this fraction of the largest open-loop frequency of zero are zero (marginal: the
#: eigenvalues' round-off, measured at 1e-17..2e-17 of it on 2..8 elements per link)
MARGINAL = 1e-13


@dataclass
class Loop:
    """A controller's loop linearized in the open loop's modal coordinates eta (x = Phi eta, Phi
    mass-normalized): eta'' + D eta' + diag(omega^2) eta = p u,  y = o . eta,  u = -kp y - kd y' - ki I,
    I' = y (the error's integral about rest).  ``omega`` (n,) [rad/s] the modes the loop touches
    (rigid-body modes at 0), ``p`` (n,) the actuator's participation (Phi^T b), ``o`` (n,) the
    measurement's (c Phi), ``d`` (n, n) the modal damping (Rayleigh damping, gyroscopic terms);
    ``untouched_hz`` the modes the loop leaves alone (their eigenvalues those of the open loop) and
    ``untouched_re`` the largest real part among them [1/s]; ``controller``, ``measure`` (joint | the
    point and direction), ``model``, ``elements_per_link``."""

    omega: np.ndarray
    p: np.ndarray
    o: np.ndarray
    d: np.ndarray
    untouched_hz: np.ndarray
    untouched_re: float
    controller: str
    measure: str
    model: str
    elements_per_link: int

    def state_matrix(self, kp: float, kd: float = 0.0, ki: float = 0.0) -> np.ndarray:
        """A of the closed loop, state [eta, eta', I] (I only with ki > 0)."""
        n = self.omega.size
        po = np.outer(self.p, self.o)
        ni = 1 if ki > 0 else 0
        a = np.zeros((2 * n + ni, 2 * n + ni))
        a[:n, n:2 * n] = np.eye(n)
        a[n:2 * n, :n] = -np.diag(self.omega ** 2) - kp * po
        a[n:2 * n, n:2 * n] = -self.d - kd * po
        if ni:
            a[n:2 * n, 2 * n] = -ki * self.p
            a[2 * n, :n] = self.o
        return a

    def eigenvalues(self, kp: float, kd: float = 0.0, ki: float = 0.0) -> np.ndarray:
        """The closed loop's eigenvalues [1/s] of the touched modes, by descending real part."""
        lam = np.linalg.eigvals(self.state_matrix(kp, kd, ki))
        return lam[np.argsort(-lam.real, kind="stable")]

    @property
    def round_off(self) -> float:
        """|Re lambda| [1/s] below which a real part is zero (MARGINAL x the largest open-loop rate)."""
        return MARGINAL * max(float(np.max(np.abs(self.omega))), float(np.max(np.abs(self.d), initial=0.0)), 1.0)

    def abscissa(self, kp: float, kd: float = 0.0, ki: float = 0.0) -> float:
        """max Re lambda [1/s] of the modes the loop touches (< 0: the loop is stable)."""
        return float(self.eigenvalues(kp, kd, ki)[0].real)

    def leading(self, kp: float, kd: float = 0.0, ki: float = 0.0) -> dict:
        """The eigenvalue of largest real part: growth rate [1/s], frequency [Hz], damping ratio."""
        lam = self.eigenvalues(kp, kd, ki)[0]
        mag = abs(lam)
        return {"re_per_s": float(lam.real), "f_hz": float(abs(lam.imag) / (2 * math.pi)),
                "damping_ratio": float(-lam.real / mag) if mag > 0 else 0.0}

    def slope_at_zero(self, tau: float) -> np.ndarray:
        """d Re lambda_i / d kp at kp = 0 along kd = tau kp, per touched elastic mode (first-order
        perturbation of an undamped, simple mode: lambda = i w - kp p_i o_i (tau / 2 + 1 / (2 i w)))."""
        return -0.5 * tau * self.p * self.o


def _controller(case, name):
    ctls = case.get("controllers", [])
    if not ctls:
        raise CaseError("controllers", "the case has no controller to close a loop with; add a [[controllers]] table")
    c = next((c for c in ctls if c["name"] == name), None) if name is not None else ctls[0]
    if c is None:
        raise CaseError("--controller", f"no controller named {name!r}; the case has {', '.join(x['name'] for x in ctls)}")
    if c.get("sample_time", 0.0) > 0 or c.get("delay", 0.0) > 0:
        raise CaseError(f"controllers.{c['name']}.sample_time", "the eigenvalue analysis is of the continuous "
                                                               "law; set sample_time = 0 and delay = 0")
    return c


def _rows(cm, c) -> tuple[Row, Row]:
    """(the force drive's coordinate row, the measured row) of controller c in the model."""
    drive = next(row for row, d in cm.forces if d.joint == c["joint"])
    if c["measure"] == "joint":
        return drive, drive
    kind, a, b, d = cm.layout.control_rows[c["name"]]
    return drive, Row(kind, a, b, d=d)


def _gradients(cm, q, rows) -> np.ndarray:
    """(len(rows), nfree) the rows' gradients over the free DOFs at configuration q: their rates at the
    unit velocities (the model's own kinematics, cpl_post; a rate is linear in the velocities)."""
    nd = cm.ndof
    out = cm.post(np.repeat(q[:, None], nd, axis=1), np.eye(nd), np.zeros((nd, nd)), np.zeros((1, nd)),
                  np.zeros(nd), list(rows))
    return out["measures"][1][:, modal.free_order(cm)]


def _actuator(cm, q, joint) -> np.ndarray:
    """(nfree,) the generalized force of a unit effort of the force drive on ``joint`` at q: the change
    of the model's residual (cpl_dense) between the drive's constant set to 1 and to 0 (then back to
    the case's)."""
    zero = np.zeros(cm.ndof)
    res = []
    for value in (0.0, 1.0):
        cm.set_force_constants({joint: value})
        res.append(cm.dense(q, zero, zero)[0])
    drive = next(d for _, d in cm.forces if d.joint == joint)
    cm.set_force_constants({joint: float(drive.params.get("constant", 0.0))})
    return -(res[1] - res[0])[modal.free_order(cm)]


def _open_loop_modes(lz: modal.Linearized):
    """(omega (n,), Phi (nfree, n) mass-normalized, modal damping (n, n)) of the linearized model on
    the motions its constraints allow."""
    n = lz.n
    mr = n.T @ (0.5 * (lz.m + lz.m.T)) @ n
    kr = n.T @ (0.5 * (lz.k + lz.k.T)) @ n
    lam, y = scipy.linalg.eigh(kr, mr)
    lam[np.abs(lam) < modal.ZERO_STIFFNESS * np.max(np.abs(lam))] = 0.0
    phi = n @ y
    return modal.signed_sqrt(lam), phi, phi.T @ lz.c @ phi


def linearize_loop(case, controller: str | None = None, *, model: str | None = None,
                   elements_per_link: int | None = None) -> Loop:
    """The loop of ``controller`` (default: the case's first) linearized about the case's state at
    t = 0, in ``model`` (coupled or nonlinear; default the case's) with its mesh or
    ``elements_per_link``.  The modes the loop does not touch (participation or measurement below
    TOUCH of the largest, modal damping uncoupled) are set apart."""
    case = case if isinstance(case, Case) else Case(case)
    if elements_per_link is not None:
        case = with_elements(case, elements_per_link)
    model = study_model(model, case)
    if family(model).superposition:
        raise CaseError("--model", f"{model!r} cannot close a loop (theory.md 23.3); use coupled or nonlinear")
    c = _controller(case, controller)
    cm = CoupledModel.from_case(case, split=family(model).element_frames)
    rm = motion_source(case)(np.array([0.0]))
    lz = modal.coupled_linearized(cm, rm, 0, case["loads"]["gravity"], case["solver"]["rayleigh"])
    omega, phi, d = _open_loop_modes(lz)
    drive_row, measured_row = _rows(cm, c)
    grads = _gradients(cm, lz.q, (measured_row,))
    p, o = phi.T @ _actuator(cm, lz.q, c["joint"]), grads[0] @ phi
    touched = (np.abs(p) > TOUCH * np.abs(p).max()) & (np.abs(o) > TOUCH * np.abs(o).max())
    off = d - np.diag(np.diag(d))
    if np.any(np.abs(off[np.ix_(touched, ~touched)]) > TOUCH * max(np.abs(d).max(), 1e-300)):
        touched[:] = True                # damping couples them: keep every mode
    du = np.diag(d)[~touched]
    wu = omega[~touched]
    re = -0.5 * du + np.where(du ** 2 > 4 * wu ** 2, 0.5 * np.sqrt(np.maximum(du ** 2 - 4 * wu ** 2, 0.0)), 0.0)
    measure = "joint" if c["measure"] == "joint" else f"{c['measure']['point']} along {list(c['measure']['direction'])}"
    return Loop(omega[touched], p[touched], o[touched], d[np.ix_(touched, touched)], wu / (2 * math.pi),
                float(re.max()) if re.size else -math.inf, c["name"], measure, model,
                int(case["mesh"]["elements_per_link"]))


def critical_gain(loop: Loop, tau: float, ti: float | None = None, gains=GAIN_RANGE) -> dict:
    """The smallest kp of the law kp (e + tau e' [+ I / ti]) in ``gains`` at which the loop loses
    stability (max Re lambda rises above its round-off, Loop.round_off), by a log scan and brentq:
    ``kp`` (0.0 when it is unstable already at the smallest gain: unstable for every positive gain when
    the open loop is stable or marginal; None when it is stable or marginal over the whole range), the
    unstable mode there (``f_hz``), and ``scanned``, ``abscissa_at_ends`` [1/s]."""
    lo, hi = gains
    tol = loop.round_off

    def law(k):
        return k, tau * k, (k / ti if ti else 0.0)

    def excess(k):
        return loop.abscissa(*law(k)) - tol

    ks = np.geomspace(lo, hi, SCAN_POINTS)
    s = np.array([excess(k) for k in ks])
    out = {"tau_s": tau, "scanned": [lo, hi], "abscissa_at_ends": [float(s[0] + tol), float(s[-1] + tol)]}
    if s[0] > 0.0:
        return {**out, "kp": 0.0, "f_hz": loop.leading(*law(lo))["f_hz"],
                "slope_at_zero_per_s": float((s[0] + tol) / lo)}
    up = np.flatnonzero((s[:-1] <= 0.0) & (s[1:] > 0.0))
    if not up.size:
        return {**out, "kp": None}
    i = int(up[0])
    k = brentq(excess, ks[i], ks[i + 1], xtol=1e-12 * ks[i], rtol=1e-12)
    return {**out, "kp": float(k), "f_hz": loop.leading(*law(k))["f_hz"]}
