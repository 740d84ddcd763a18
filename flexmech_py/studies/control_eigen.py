"""The eigenvalues of feedback loops closed around a flexible mechanism (docs/theory.md section 23.5):
the case's coupled or nonlinear model linearized about its state at t = 0 (the frozen eigenproblem of
:mod:`flexmech_py.models.modal`, with its damping matrix), its controllers added as feedback of their
measured signals through the generalized forces of their force drives, the first-order state matrix
A(kp, kd, ki) and its eigenvalues; the gain where the loops lose stability (the largest real part of
the eigenvalues crossing zero along a ray of gains, found by scipy's brentq); the files of
``flexmech modes --closed-loop``.

Python::

    from flexmech_py.studies.control_eigen import linearize_loop, critical_gain
    loop = linearize_loop(case, "hub_pid")    # the controller's measured signal and drive
    loop.abscissa(kp=2.0, kd=0.3)             # max Re lambda [1/s]
    critical_gain(loop, tau=0.15)             # the kp of the law kp (e + tau e') where max Re = 0

The laws are the continuous ones (sample_time = delay = 0: docs/theory.md 23.1), linearized about
rest: their output limits are not active there, their references and feedforwards do not change the
eigenvalues.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.linalg
from scipy.optimize import brentq

from ..base.errors import CaseError
from ..base.fileio import atomic_write, json_default
from ..base.version import versions
from ..base.families import family
from ..case import Case, study_model, with_elements
from ..models import modal
from ..models.constrained.coupled import CoupledModel
from ..models.constrained.layout import Row
from ..run.simulate import motion_source

__all__ = ["Loop", "describe", "linearize_loop", "critical_gain", "critical_scale", "GAIN_RANGE", "TOUCH",
           "MARGINAL", "closed_loop_modes", "closed_loop_summary", "closed_loop_table", "write_closed_loop"]

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
    """The case's controllers' loops linearized in the open loop's modal coordinates eta (x = Phi eta,
    Phi mass-normalized): eta'' + D eta' + diag(omega^2) eta = P u,  y = O eta,  u_j = -kp_j y_j -
    kd_j y_j' - ki_j I_j,  I' = y (the errors' integrals about rest).  ``omega`` (n,) [rad/s] the modes
    the loops touch (rigid-body modes at 0), ``p`` (n, m) the actuators' participations (Phi^T b_j),
    ``o`` (m, n) the measurements' (c_j Phi), ``d`` (n, n) the modal damping (Rayleigh damping,
    gyroscopic terms); ``untouched_hz`` the modes no loop moves (their eigenvalues the open loop's) and
    ``untouched_re`` the largest real part among them [1/s]; ``controllers`` their names, ``measures``
    (joint | the point and direction), ``gains`` (3, m) the case's kp, kd, ki; ``model``,
    ``elements_per_link``.  Gains given to the methods are scalars (every controller) or (m,) arrays."""

    omega: np.ndarray
    p: np.ndarray
    o: np.ndarray
    d: np.ndarray
    untouched_hz: np.ndarray
    untouched_re: float
    controllers: list
    measures: list
    gains: np.ndarray
    model: str
    elements_per_link: int

    def state_matrix(self, kp, kd=0.0, ki=0.0) -> np.ndarray:
        """A of the closed loop, state [eta, eta', I] (the integrals of the controllers with ki > 0)."""
        n, m = self.p.shape
        kp, kd, ki = (np.broadcast_to(np.asarray(g, float), (m,)) for g in (kp, kd, ki))
        integ = np.flatnonzero(ki > 0)
        a = np.zeros((2 * n + integ.size, 2 * n + integ.size))
        a[:n, n:2 * n] = np.eye(n)
        a[n:2 * n, :n] = -np.diag(self.omega ** 2) - (self.p * kp) @ self.o
        a[n:2 * n, n:2 * n] = -self.d - (self.p * kd) @ self.o
        a[n:2 * n, 2 * n:] = -self.p[:, integ] * ki[integ]
        a[2 * n:, :n] = self.o[integ]
        return a

    def eigenvalues(self, kp, kd=0.0, ki=0.0) -> np.ndarray:
        """The closed loop's eigenvalues [1/s] of the touched modes, by descending real part."""
        lam = np.linalg.eigvals(self.state_matrix(kp, kd, ki))
        return lam[np.argsort(-lam.real, kind="stable")]

    @property
    def round_off(self) -> float:
        """|Re lambda| [1/s] below which a real part is zero (MARGINAL x the largest open-loop rate)."""
        return MARGINAL * max(float(np.max(np.abs(self.omega))), float(np.max(np.abs(self.d), initial=0.0)), 1.0)

    def abscissa(self, kp, kd=0.0, ki=0.0) -> float:
        """max Re lambda [1/s] of the modes the loops touch (< 0: the loops are stable)."""
        return float(self.eigenvalues(kp, kd, ki)[0].real)

    def leading(self, kp, kd=0.0, ki=0.0) -> dict:
        """The eigenvalue of largest real part: growth rate [1/s], frequency [Hz], damping ratio."""
        return describe(self.eigenvalues(kp, kd, ki)[0])

    def slope_at_zero(self, tau: float) -> np.ndarray:
        """d Re lambda_i / d k at k = 0 of the law k (e + tau e') on every controller, per touched mode
        (first-order perturbation of an undamped, simple mode: lambda = i w - k g_i (tau / 2 - i / (2 w)),
        g_i = (P O)_ii)."""
        return -0.5 * tau * np.einsum("ij,ji->i", self.p, self.o)


def describe(lam: complex) -> dict:
    """An eigenvalue as growth rate [1/s], frequency [Hz] and damping ratio."""
    mag = abs(lam)
    return {"re_per_s": float(lam.real), "f_hz": float(abs(lam.imag) / (2 * math.pi)),
            "damping_ratio": float(-lam.real / mag) if mag > 0 else 0.0}


def _controllers(case, names):
    ctls = case.get("controllers", [])
    if not ctls:
        raise CaseError("controllers", "the case has no controller to close a loop with; add a [[controllers]] table")
    names = [names] if isinstance(names, str) else names
    missing = [n for n in names or [] if n not in {c["name"] for c in ctls}]
    if missing:
        raise CaseError("--controller", f"no controller named {missing[0]!r}; the case has "
                                        f"{', '.join(x['name'] for x in ctls)}")
    chosen = [c for c in ctls if names is None or c["name"] in names]
    for c in chosen:
        if c.get("sample_time", 0.0) > 0 or c.get("delay", 0.0) > 0:
            raise CaseError(f"controllers.{c['name']}.sample_time", "the eigenvalue analysis is of the continuous "
                                                                   "law; set sample_time = 0 and delay = 0")
    return chosen


def _measured_row(cm, c) -> Row:
    """The row controller c measures in the model: its force drive's coordinate (collocated) or its
    own row (the layout's control_rows: a projection, or a strain's relative node rotation)."""
    if c["measure"] == "joint":
        return next(row for row, d in cm.forces if d.joint == c["joint"])
    kind, a, b, d = cm.layout.control_rows[c["name"]]
    return Row(kind, a, b, d=d)


def _measure_text(m) -> str:
    """A controller's measured signal in words: joint, a point along a direction, a strain gauge."""
    if m == "joint":
        return "joint"
    if "strain" in m:
        return f"strain of {m['strain']} at {m['at']:g}"
    return f"{m['point']} along {list(m['direction'])}"


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


def linearize_loop(case, controllers=None, *, model: str | None = None,
                   elements_per_link: int | None = None) -> Loop:
    """The loops of ``controllers`` (a name or a list; default: all the case's) linearized about the
    case's state at t = 0, in ``model`` (coupled or nonlinear; default the case's) with its mesh or
    ``elements_per_link``.  The modes no loop touches (every actuator participation or every
    measurement below TOUCH of the largest, modal damping uncoupled) are set apart."""
    case = case if isinstance(case, Case) else Case(case)
    if elements_per_link is not None:
        case = with_elements(case, elements_per_link)
    chosen = _controllers(case, controllers)
    model = study_model(model, case)
    if family(model).superposition:
        raise CaseError("--model", f"the closed-loop eigenvalues linearize a finite-element model with its "
                                   f"elastic coordinates; {model!r} superposes them on a rigid motion computed "
                                   "first (theory.md 23.3): use coupled or nonlinear")
    cm = CoupledModel.from_case(case, split=family(model).element_frames)
    rm = motion_source(case)(np.array([0.0]))
    lz = modal.coupled_linearized(cm, rm, 0, case["loads"]["gravity"], case["solver"]["rayleigh"])
    omega, phi, d = _open_loop_modes(lz)
    b = {j: _actuator(cm, lz.q, j) for j in {c["joint"] for c in chosen}}
    p = np.column_stack([phi.T @ b[c["joint"]] for c in chosen])
    o = _gradients(cm, lz.q, [_measured_row(cm, c) for c in chosen]) @ phi
    o *= np.array([cm.layout.control_scales.get(c["name"], 1.0) for c in chosen])[:, None]   # a strain: c/span
    touched = (np.abs(p).max(axis=1) > TOUCH * np.abs(p).max()) & (np.abs(o).max(axis=0) > TOUCH * np.abs(o).max())
    off = d - np.diag(np.diag(d))
    if np.any(np.abs(off[np.ix_(touched, ~touched)]) > TOUCH * max(np.abs(d).max(), 1e-300)):
        touched[:] = True                # damping couples them: keep every mode
    nu = int((~touched).sum())
    a_u = np.block([[np.zeros((nu, nu)), np.eye(nu)], [-np.diag(omega[~touched] ** 2), -d[np.ix_(~touched, ~touched)]]])
    re = np.linalg.eigvals(a_u).real
    measures = [_measure_text(c["measure"]) for c in chosen]
    gains = np.array([[c[k] for c in chosen] for k in ("kp", "kd", "ki")], float)
    return Loop(omega[touched], p[touched], o[:, touched], d[np.ix_(touched, touched)], omega[~touched] / (2 * math.pi),
                float(re.max()) if re.size else -math.inf, [c["name"] for c in chosen], measures, gains, model,
                int(case["mesh"]["elements_per_link"]))


def critical_scale(loop: Loop, kp, kd=0.0, ki=0.0, scales=GAIN_RANGE) -> dict:
    """The smallest factor s in ``scales`` on the gains (kp, kd, ki) (scalars or (m,) arrays) at which
    the loops lose stability (max Re lambda rises above its round-off, Loop.round_off), by a log scan
    (SCAN_POINTS) and brentq: ``scale`` (0.0 when they are unstable already at the smallest factor:
    unstable for every positive gain when the open loop is stable or marginal; None when stable or
    marginal over the whole range), the unstable mode there (``f_hz``, with ``slope_at_zero_per_s``,
    max Re lambda / s at the smallest factor, when 0), ``scanned`` and ``abscissa_at_ends`` [1/s]."""
    lo, hi = scales
    tol = loop.round_off
    base = [np.asarray(g, float) for g in (kp, kd, ki)]

    def excess(f):
        return loop.abscissa(*(f * g for g in base)) - tol

    fs = np.geomspace(lo, hi, SCAN_POINTS)
    s = np.array([excess(f) for f in fs])
    out = {"scanned": [lo, hi], "abscissa_at_ends": [float(s[0] + tol), float(s[-1] + tol)]}
    if s[0] > 0.0:
        return {**out, "scale": 0.0, "f_hz": loop.leading(*(lo * g for g in base))["f_hz"],
                "slope_at_zero_per_s": float((s[0] + tol) / lo)}
    up = np.flatnonzero((s[:-1] <= 0.0) & (s[1:] > 0.0))
    if not up.size:
        return {**out, "scale": None}
    i = int(up[0])
    f = brentq(excess, fs[i], fs[i + 1], xtol=1e-12 * fs[i], rtol=1e-12)
    return {**out, "scale": float(f), "f_hz": loop.leading(*(f * g for g in base))["f_hz"]}


def critical_gain(loop: Loop, tau: float, ti: float | None = None, gains=GAIN_RANGE) -> dict:
    """The smallest kp in ``gains`` of the law kp (e + tau e' [+ I / ti]) on every controller at which
    the loops lose stability (:func:`critical_scale`; ``kp`` 0.0: unstable at every positive gain, None:
    stable or marginal over the range), with ``tau_s``."""
    out = critical_scale(loop, 1.0, tau, 1.0 / ti if ti else 0.0, gains)
    return {"tau_s": tau, "kp": out.pop("scale"), **out}


# ------------------------------------------------------------------------------ flexmech modes --closed-loop
def closed_loop_modes(loop: Loop, count: int) -> list[dict]:
    """The closed loop's eigenvalues at the case's gains, one per conjugate pair (Im >= 0), the ``count``
    lowest in |lambda|, by frequency, each described (:func:`describe`)."""
    lam = loop.eigenvalues(*loop.gains)
    lam = lam[lam.imag >= -1e-12 * np.abs(lam).max(initial=1.0)]
    lam = lam[np.argsort(np.abs(lam), kind="stable")][:count]
    return sorted((describe(x) for x in lam), key=lambda r: (r["f_hz"], -r["re_per_s"]))


def closed_loop_summary(loop: Loop, count: int, title: str) -> dict:
    """The JSON of ``flexmech modes --closed-loop``."""
    crit = critical_scale(loop, *loop.gains)
    return {"title": title, "model": loop.model, "elements_per_link": loop.elements_per_link,
            "state": "linearized about the state at t = 0; the continuous law about rest (docs/theory.md 23.5)",
            "controllers": [{"name": n, "measure": m, "kp": g[0], "kd": g[1], "ki": g[2]}
                            for n, m, g in zip(loop.controllers, loop.measures, loop.gains.T.tolist())],
            "leading": loop.leading(*loop.gains), "max_re_per_s": loop.abscissa(*loop.gains),
            "round_off_per_s": loop.round_off,
            "modes": closed_loop_modes(loop, count), "untouched_hz": loop.untouched_hz.tolist(),
            "untouched_max_re_per_s": loop.untouched_re,
            "critical_gain_factor": crit}


def closed_loop_table(summary: dict) -> str:
    """The printed table of ``flexmech modes --closed-loop``."""
    ctl = ", ".join(f"{c['name']} (kp {c['kp']:g}, kd {c['kd']:g}, ki {c['ki']:g}; {c['measure']})"
                    for c in summary["controllers"])
    lines = [f"{summary['title']}  [model {summary['model']}, closed loop: {ctl}]; linearized at t = 0",
             f"{'mode':>4}  {'f [Hz]':>12} {'Re [1/s]':>12} {'damping':>9}"]
    lines += [f"{k + 1:>4}  {m['f_hz']:>12.6g} {m['re_per_s']:>12.4g} {m['damping_ratio']:>9.4g}"
              for k, m in enumerate(summary["modes"])]
    stable = summary["max_re_per_s"] <= summary["round_off_per_s"]
    lines.append(f"max Re lambda = {summary['max_re_per_s']:.4g} 1/s (at {summary['leading']['f_hz']:.6g} Hz): "
                 + ("stable" if stable else "UNSTABLE"))
    crit = summary["critical_gain_factor"]
    if crit["scale"] is None:
        lines.append(f"stable for every factor {crit['scanned'][0]:g} .. {crit['scanned'][1]:g} on these gains")
    elif crit["scale"] == 0.0:
        lines.append(f"unstable at every positive factor on these gains (the {crit['f_hz']:.4g} Hz mode)")
    else:
        lines.append(f"loses stability at {crit['scale']:.6g} x these gains (the {crit['f_hz']:.4g} Hz mode)")
    if summary["untouched_hz"]:
        lines.append(f"{len(summary['untouched_hz'])} modes no loop moves (from {min(summary['untouched_hz']):.4g} Hz; "
                     f"max Re {summary['untouched_max_re_per_s']:.3g} 1/s)")
    return "\n".join(lines)


def write_closed_loop(summary: dict, out_dir) -> list[Path]:
    """closed_loop.csv (the modes) and closed_loop.json (the summary) in out_dir."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "closed_loop.csv", out / "closed_loop.json"]
    rows = [f"{k + 1},{m['f_hz']:.10g},{m['re_per_s']:.10g},{m['damping_ratio']:.10g}"
            for k, m in enumerate(summary["modes"])]
    atomic_write(paths[0], f"# flexmech modes --closed-loop; case {summary['title']!r}; model {summary['model']}\n"
                 + "mode,f_hz,re_per_s,damping_ratio\n" + "\n".join(rows) + "\n")
    atomic_write(paths[1], json.dumps({**summary, "versions": versions()}, indent=2, default=json_default) + "\n")
    return paths
