"""Guards in every run: validity of the small-deformation models and failure diagnosis (the third,
the time-step error estimate, is flexmech_py/checks/step_doubling.py).

- :class:`ValidityTracker` (every run, cheap, block by block; :func:`check_validity` for a run held
  in memory): per link the largest bending deflection from the chord over the link length, the
  largest extreme-fibre strain, the largest compressive axial force over the Euler load, and when
  each first passes its threshold (``THRESHOLDS``: deflection 2 % of L, compression 1 x the Euler
  load; a link's ``yield_strain`` when the case gives one).  Writes ``validity`` (per link),
  ``validity_overall`` and ``warnings`` into ``Result.extra``.
- :func:`failed` (a run that stopped): names the time, the quantity and the likely cause (step
  too large / physical instability / model outside its validity) from the run's own evidence —
  the shortest period of the elastic model, a short check at dt/2, the validity measures before
  the failure — and returns the SolverError that carries the partial result.
docs/stability.md ("Guards", "Validity warnings") documents the thresholds and messages.
"""

from __future__ import annotations

import copy
import time

import numpy as np

from ..models.constrained import coupled
from ..base import kernels, notices
from ..case import integrator_of
from ..base.errors import MechanismError, SolverError
from ..base.families import family, large_deflection_reference
from ..mechanism.control import loop_suspect
from ..models.superposition.model import squared_frequencies

__all__ = ["check_validity", "ValidityTracker", "failed", "frames_before", "fmt_time"]



def frames_before(fail_step: int, out_every: int) -> int:
    """Number of output frames the time loop stored before it failed at step ``fail_step`` (1-based):
    frames at steps 0, out_every, ... < fail_step."""
    return (int(fail_step) - 1) // int(out_every) + 1


def _first(t, mask) -> float | None:
    return float(t[int(np.argmax(mask))]) if np.any(mask) else None


def fmt_time(x) -> str:
    """A time [s] in messages."""
    return f"{x:.6g}"


# ----------------------------------------------------------------------------- validity
THRESHOLDS = {"compression_over_euler": 1.0, "displacement_over_length": 0.02}   # buckling; "a few per cent"


def deflection_over_length(res) -> np.ndarray:
    """(nlinks, nf) largest distance of a link's nodes from the chord through its end nodes, over its
    length: the bending deflection, whatever the model (total positions = rigid-body solution + u)."""
    fe = res.fe
    km = res.motion
    out = np.zeros((len(fe.case["links"]), res.t.size))
    for li, ln in enumerate(fe.case["links"]):
        if ln.get("rigid"):
            continue
        L = ln["length"]
        c, s = np.cos(km.phi[:, li]), np.sin(km.phi[:, li])
        pos = [np.array([km.ox[:, li] + f * L * c, km.oy[:, li] + f * L * s])
               + res.u[fe.trans_dof[fe.node_of[li][k]]] for k, f in enumerate(fe.node_frac[li])]
        chord = pos[-1] - pos[0]
        ell = np.hypot(chord[0], chord[1])
        for p in pos[1:-1]:
            d = p - pos[0]
            out[li] = np.maximum(out[li], np.abs(chord[0] * d[1] - chord[1] * d[0]) / ell / L)
    return out


def link_strains(res) -> np.ndarray:
    """(nlinks, nf) largest extreme-fibre strain of every link over its mesh nodes:
    c |kappa| + |N| / EA (bending strain of the outer fibre plus the axial strain of the adjacent
    elements), c the half depth."""
    fe = res.fe
    out = np.zeros((len(res.case["links"]), res.t.size))
    for li, ln in enumerate(res.case["links"]):
        if ln.get("rigid"):
            continue
        els = fe.link_elements(li)
        n = len(els)
        ea = ln["youngs_modulus"] * ln["area"]
        ax = np.abs(res.axial[els]) / ea if res.axial is not None else np.zeros((n, res.t.size))
        kap = np.abs(res.node_curvatures(li)) if res.curvature_of is not None else np.zeros((n + 1, res.t.size))
        eps_ax = np.empty((n + 1, res.t.size))              # the larger of the elements meeting at a node
        eps_ax[0], eps_ax[n] = ax[0], ax[n - 1]
        eps_ax[1:n] = np.maximum(ax[:n - 1], ax[1:])
        out[li] = np.max(ln["half_depth"] * kap + eps_ax, axis=0)
    return out


_FIRST_TIMES = {"deflection": "deflection_exceeds_at_s", "compression": "compression_exceeds_at_s",
                "strain": "strain_exceeds_yield_at_s"}


class ValidityTracker:
    """Validity measures of a run accumulated over its blocks of frames (:meth:`add` per block, in
    order; :meth:`finish` writes them into the run's Result): per flexible link the largest
    deflection over length, strain and compression over the Euler load and when each first passes its
    threshold, and the largest elastic displacement of all frames and of the last one (evidence of
    growth when a run stops)."""

    def __init__(self):
        self.links: dict[str, dict] = {}
        self.max_displacement = self.last_displacement = 0.0
        self.frames = 0
        self.speeds: dict[float, float] = {}     # time a limit is first passed -> first rigid coordinate's speed

    def add(self, block) -> None:
        if block.t.size == 0:
            return
        fe, t = block.fe, block.t
        per_link = coupled.validity(fe, block.axial, block.u)
        defl, strain = deflection_over_length(block), link_strains(block)
        for li, ln in enumerate(block.case["links"]):
            if ln.get("rigid"):
                continue
            new = per_link[ln["name"]]
            comp = np.maximum(0.0, -block.axial[fe.link_elements(li)].min(axis=0)) / new["euler_load_N"]
            new.update(max_deflection_over_length=float(defl[li].max()), max_strain=float(strain[li].max()),
                       yield_strain=ln.get("yield_strain"),
                       deflection_exceeds_at_s=_first(t, defl[li] > THRESHOLDS["displacement_over_length"]),
                       compression_exceeds_at_s=_first(t, comp > THRESHOLDS["compression_over_euler"]),
                       strain_exceeds_yield_at_s=(_first(t, strain[li] > ln["yield_strain"])
                                                  if ln.get("yield_strain") else None))
            old = self.links.get(ln["name"])
            if old is not None:
                for k, v in old.items():
                    if k.startswith("max_"):
                        new[k] = max(v, new[k])
                    elif k.endswith("_at_s") and v is not None:
                        new[k] = v
            self.links[ln["name"]] = new
            for key in _FIRST_TIMES.values():
                tk = new[key]
                if tk is not None and tk not in self.speeds and block.qd is not None and block.qd.size:
                    k = int(np.searchsorted(t, tk))
                    self.speeds[tk] = float(block.qd[min(k, t.size - 1), 0])
        tr = fe.trans_dof.ravel()
        amp = np.max(np.abs(block.u[tr]), axis=0)
        self.max_displacement = max(self.max_displacement, float(np.max(amp)))
        self.last_displacement = float(amp[-1])
        self.frames += int(t.size)

    def grew(self) -> bool:
        """Evidence of growth before a failure: at least 3 frames and the largest elastic displacement
        of the last frame is (within 10 %) the largest of the run, and not zero."""
        return self.frames >= 3 and 0 < self.last_displacement >= 0.9 * self.max_displacement

    def finish(self, res) -> dict:
        """``validity`` (per link), ``validity_overall`` and the validity ``warnings`` into res.extra;
        returns ``validity_overall``."""
        overall = {"thresholds": {"deflection_over_length": THRESHOLDS["displacement_over_length"],
                                  "compression_over_euler": THRESHOLDS["compression_over_euler"]},
                   "max_deflection_over_length": 0.0, "max_deflection_link": None, "max_strain": 0.0,
                   "max_strain_link": None, "max_compression_over_euler": 0.0, "max_compression_link": None,
                   "valid_until_s": None, "max_elastic_displacement_m": self.max_displacement,
                   "final_elastic_displacement_m": self.last_displacement}
        events = []   # (time, link, kind, measures)
        for name, v in self.links.items():
            for key, lk in (("max_deflection_over_length", "max_deflection_link"), ("max_strain", "max_strain_link"),
                            ("max_compression_over_euler", "max_compression_link")):
                if v[key] >= overall[key] and (v[key] > 0 or overall[lk] is None):
                    overall[key], overall[lk] = v[key], name
            for kind in ("compression", "deflection", "strain"):
                if v[_FIRST_TIMES[kind]] is not None:
                    events.append((v[_FIRST_TIMES[kind]], name, kind, v))
        events.sort(key=lambda e: e[0])
        model = res.model
        geo = res.extra.get("geometric_stiffness", {}).get("source", "none")
        # the nonlinear model follows large deflections and buckling: only yielding leaves its validity
        limiting = [e for e in events if not family(model).large_deflection or e[2] == "strain"]
        overall["valid_until_s"] = limiting[0][0] if limiting else None
        overall["first_limit"] = ({"link": limiting[0][1], "kind": limiting[0][2], "time_s": limiting[0][0]}
                                  if limiting else None)
        res.extra["validity"] = {k: dict(v) for k, v in self.links.items()}
        res.extra["validity_overall"] = overall
        res.extra["warnings"] = _validity_warnings(res, events, limiting, model, geo, self.speeds)
        res.extra["warning_kinds"] = notices.kinds_of(res.extra["warnings"], "validity")
        return overall


def check_validity(res) -> dict:
    """Validity measures of a run held in memory (or of its partial frames); fills ``res.extra`` and
    returns ``validity_overall``."""
    tracker = ValidityTracker()
    tracker.add(res)
    return tracker.finish(res)


def _advice(model: str, geo: str) -> str:
    ref = large_deflection_reference().name
    if family(model).superposition and geo == "none":
        return ("a linear model without geometric stiffness neither stiffens in tension nor buckles in compression; "
                f"use --model {ref}, or --set solver.geometric_stiffness=current")
    if not family(model).large_deflection:
        return f"use --model {ref}"
    return ""


def _first_coordinate(case) -> tuple[str, str]:
    """What q[:, 0] measures, in words, and its unit: the first drive's joint (else the first joint's);
    a joint to the ground is named by the body it turns ("crank")."""
    name = case["drives"][0]["joint"] if case["drives"] else case["joints"][0]["name"]
    joint = next(j for j in case["joints"] if j["name"] == name)
    a, b = (p.split(".")[0] for p in joint["connects"])
    unit = case.mechanism.joint(name).unit
    if "ground" in (a, b):
        return (b if a == "ground" else a), unit
    return f"joint {name}", unit


def _validity_warnings(res, events, limiting, model, geo, speeds: dict) -> list[str]:
    """The validity warnings; ``speeds`` {time: speed of the first rigid coordinate then}."""
    out = []
    if limiting:
        t0 = limiting[0][0]
        speed = ""
        if speeds.get(t0) is not None:
            who, unit = _first_coordinate(res.case)
            speed = f" ({who} speed {abs(speeds[t0]):.4g} {unit}/s)"
        if family(model).large_deflection:
            out.append(f"the {model} model's results after t = {fmt_time(t0)} s{speed} are outside its validity: "
                       "the material yields there and every flexmech model is elastic")
        else:
            adv = _advice(model, geo)
            buckles = " (a real link would buckle)" if any(e[2] == "compression" for e in limiting) else ""
            out.append(f"the {model} model's results after t = {fmt_time(t0)} s{speed} are outside its validity: "
                       f"{_limits_before(res, np.inf)}{buckles}{'; ' + adv if adv else ''}")
    for tk, name, kind, v in events:
        if kind == "compression":
            txt = (f"{name}: compressive axial force exceeds its Euler load ({v['euler_load_N']:.4g} N) from "
                   f"t = {fmt_time(tk)} s, up to {v['max_compression_over_euler']:.3g} times it")
            txt += ("; the link buckles there (the nonlinear model follows it)" if family(model).large_deflection else
                    f"; the {model} model's results after that time are outside its validity")
        elif kind == "deflection":
            txt = (f"{name}: elastic deflection exceeds 2 % of its length from t = {fmt_time(tk)} s, up to "
                   f"{100 * v['max_deflection_over_length']:.3g} %")
            txt += ("; beyond the range of the linear models (the nonlinear model remains valid while each "
                    "element's deflection stays small: refine the mesh to check)" if family(model).large_deflection else
                    "; beyond the small-deflection range of this model")
        else:
            txt = (f"{name}: strain exceeds its yield strain {v['yield_strain']:.3g} from t = {fmt_time(tk)} s, up to "
                   f"{v['max_strain']:.3g}; the material yields and the elastic results after that time are not physical")
        out.append(txt)
    return out


# ----------------------------------------------------------------------------- failures
def rigid_failure(res, exc: MechanismError) -> MechanismError:
    """The MechanismError of a run whose rigid motion reached a singular position or an assembly limit,
    carrying ``res`` (every frame before it) as its partial result."""
    res.failure = {"code": exc.code, "time_s": exc.time, "quantity": "the rigid-body motion",
                   "what": kernels.STATUS_WHAT.get(exc.code, "the rigid-body motion stopped"),
                   "likely_cause": "mechanism", "message": str(exc)}
    return MechanismError(str(exc), time=exc.time, code=exc.code, partial=res)


def _limits_before(res, t_fail: float) -> str:
    """The validity limits passed before t_fail, the earliest per kind, in time order."""
    words = {"compression": "the {} is compressed beyond its Euler load from t = {} s",
             "deflection": "the {}'s deflection passes 2 % of its length at t = {} s",
             "strain": "the {}'s strain passes its yield strain at t = {} s"}
    keys = {"compression": "compression_exceeds_at_s", "deflection": "deflection_exceeds_at_s",
            "strain": "strain_exceeds_yield_at_s"}
    parts = []
    for kind in ("compression", "deflection", "strain"):
        hits = [(v[keys[kind]], name) for name, v in res.extra["validity"].items()
                if v.get(keys[kind]) is not None and v[keys[kind]] <= t_fail]
        if hits:
            tk, name = min(hits)
            parts.append((tk, words[kind].format(name, fmt_time(tk))))
    return "; ".join(p for _, p in sorted(parts))


def _node_label(fe, node: int) -> str:
    for li, row in enumerate(fe.node_of):
        if node in row:
            k, n = row.index(node), len(row) - 1
            pos = {0: "start", n: "end"}.get(k, "mid" if 2 * k == n else f"{k / n:.3g}")
            return f"{fe.link_names[li]}.{pos}"
    return f"node {node}"


def _largest_displacement(res) -> tuple[str, dict]:
    """Largest elastic displacement at the last kept frame: text and summary entry."""
    fe, u = res.fe, res.u[:, -1]
    best = (-1.0, 0, 0.0)
    for li, ln in enumerate(res.case["links"]):
        for node in fe.node_of[li]:
            d = float(np.hypot(u[fe.trans_dof[node, 0]], u[fe.trans_dof[node, 1]]))
            if not np.isfinite(d):
                d = np.inf
            if d / ln["length"] > best[0]:
                best = (d / ln["length"], node, d)
    rel, node, d = best
    where = _node_label(fe, node)
    return (f"largest elastic displacement at t = {fmt_time(res.t[-1])} s: {d:.3g} m at {where} "
            f"({100 * rel:.3g} % of the link length)",
            {"quantity": "elastic displacement", "at": where, "value_m": d if np.isfinite(d) else None,
             "over_link_length": rel if np.isfinite(rel) else None,
             "frame_time_s": float(res.t[-1])})


def _grew(res) -> bool:
    """Evidence of growth before a failure: at least 3 frames and the largest elastic displacement
    of the last frame is (within 10 %) the largest of the run, and not zero."""
    ov = res.extra["validity_overall"]
    last, top = ov["final_elastic_displacement_m"], ov["max_elastic_displacement_m"]
    return bool(res.all_stats().frames >= 3 and last > 0 and last >= 0.9 * top)


def _shortest_period(prep, model: str, res, data) -> float | None:
    """Shortest natural period [s] of the elastic model linearized at the last kept frame (dense
    eigenproblem; None for models above 1500 free DOFs)."""
    try:
        if family(model).superposition:
            if prep.fe.nfree > 1500:
                return None
            lam = prep.fe.squared_frequencies(res.rig[:, :, -1], model)
        else:
            cm = data["cm"]
            if cm is None or int(cm.free_of.max()) > 1500:
                return None
            _, m, _, k, _ = cm.dense(data["q_last"], np.zeros(cm.ndof), np.zeros(cm.ndof), gravity=prep.gravity)
            lam = squared_frequencies(m, k)
    except Exception:   # a diagnosis must never hide the original failure
        return None
    lmax = float(np.max(lam))
    return 2 * np.pi / np.sqrt(lmax) if lmax > 0 else None


def _half_step_check(prep, model: str, geometric, t_fail: float, rerun) -> dict:
    """Rerun at dt/2 up to 1.5 t_fail (at least 20 steps past it): does the failure stay?  ``rerun``
    (case, dt, out_every, model, geometric) -> (its step, an iterator over its blocks): the run hands it
    to the check, which never builds a run itself."""
    case = copy.deepcopy(prep.case)
    t_check = min(case["solver"]["t_end"], 1.5 * t_fail + 20 * prep.dt)
    case["solver"]["t_end"] = t_check
    nsteps = max(2, int(np.ceil(t_check / (prep.dt / 2))))
    t0 = time.perf_counter()
    out = {"dt": None, "checked_until_s": t_check, "failed_at_s": None}
    try:
        out["dt"], blocks = rerun(case, prep.dt / 2, max(1, nsteps // 50), model, geometric)
        for _ in blocks:   # the frames are not needed: only whether it fails
            pass
    except SolverError as exc:
        out["failed_at_s"] = exc.time
    except Exception as exc:   # the check is evidence only; record why it is missing
        out["error"] = str(exc)
    out["wall_s"] = time.perf_counter() - t0
    return out


def _undamped_constraints(prep, model: str, data) -> bool:
    """A coupled/nonlinear run with rotation constraints (kinematic drive, clamped or locked joints)
    integrated without numerical dissipation (Newmark, gamma = 1/2): its multipliers are undamped."""
    sol = prep.case["solver"]
    cm = (data or {}).get("cm")
    integ = integrator_of(sol, model)
    return (family(model).constrained and integ["integrator"] == "newmark"
            and abs(integ.get("gamma", 0.5) - 0.5) < 1e-12 and cm is not None and len(cm.rows) > 0)


def failed(prep, model: str, geometric, exc: SolverError, diagnose: bool = True, rerun=None) -> SolverError:
    """The SolverError a failed run raises: one line naming the time, what stopped, the quantity
    and the likely cause; ``partial`` is marked failed and its summary carries the diagnosis.
    ``rerun``: the run's own function that reruns it on another case or step (see _half_step_check);
    without it there is no half-step evidence."""
    res, data, code, t_fail = exc.partial, exc.data or {}, exc.code, exc.time
    what = _what_stopped(prep, model, code, data)
    qtext, quantity = _stopping_quantity(res, model, code)
    evidence = _evidence(prep, model, geometric, res, data, code, t_fail, diagnose and rerun is not None, rerun)
    geo = data.get("geometric", "none")
    cause, ctext = _likely_cause(prep, model, res, data, code, t_fail, evidence, geo)
    loop = loop_suspect(prep.case, res.columns)
    if loop is not None:            # (docs/theory.md 23: an unstable loop stops through this diagnosis)
        cause, ctext = "unstable_control_loop", f"{loop} (the diagnosis without it: {ctext})"
    msg = (f"{model} run stopped at t = {fmt_time(t_fail)} s: {what}; {qtext}. Likely cause: {ctext}. "
           f"Partial results up to t = {fmt_time(res.t[-1])} s are kept.")
    failure = {"code": code, "step": exc.step, "what": what, "cause": cause, "message": msg,
               "quantity": quantity, "evidence": evidence}
    res.failure = dict(failure, time_s=t_fail)
    res.extra["error_estimate"] = {"method": "none", "reason": "the run failed"}
    return SolverError(msg, time=t_fail, code=code, step=exc.step, partial=res, failure=res.failure)


def _what_stopped(prep, model: str, code: int, data: dict) -> str:
    """What stopped the run, in words (the Newton limits and the coupled loop's last iteration)."""
    what = kernels.STATUS_WHAT.get(code, f"status {code}")
    if code == kernels.STATUS_NEWTON and family(model).superposition:
        return kernels.STATUS_WHAT_GEOMETRIC
    if code == kernels.STATUS_NEWTON:
        what += f" = {prep.case['solver']['newton_maxit']} (tolerance {prep.case['solver']['newton_tol']:g})"
        nw = data.get("newton")
        if nw is not None:       # the coupled/nonlinear loop's last iteration
            what += (f"; last iteration: residual norm {nw[0]:.3g}, acceleration correction {nw[1]:.3g} against "
                     f"accelerations of norm {nw[2]:.3g}")
    return what


def _stopping_quantity(res, model: str, code: int) -> tuple[str, dict]:
    """The largest displacement before the failure (and, for a linear model's failed axial-force
    iteration, the largest compression against the Euler load): text and numbers."""
    qtext, quantity = _largest_displacement(res)
    comp = res.extra["validity_overall"]
    if code == kernels.STATUS_NEWTON and family(model).superposition:
        quantity.update(max_compression_over_euler=comp["max_compression_over_euler"],
                        link=comp["max_compression_link"])
        qtext += (f"; largest compression {comp['max_compression_over_euler']:.3g} x the Euler load "
                  f"({comp['max_compression_link']})")
    return qtext, quantity


def _evidence(prep, model: str, geometric, res, data: dict, code: int, t_fail: float, diagnose: bool,
              rerun) -> dict:
    """The shortest elastic period against dt and (diagnose, a runtime failure) the run again at dt/2."""
    evidence = {}
    period = _shortest_period(prep, model, res, data)
    if period:
        evidence.update(shortest_period_s=period, dt_over_shortest_period=prep.dt / period)
    if diagnose and code in kernels.RUNTIME_FAILURES and code != kernels.STATUS_SINGULAR:
        evidence["half_step"] = _half_step_check(prep, model, geometric, t_fail, rerun)
    return evidence


def _likely_cause(prep, model: str, res, data: dict, code: int, t_fail: float, evidence: dict,
                  geo: str) -> tuple[str, str]:
    """(cause, its sentence) of a failure from its code and evidence (see failed)."""
    dt, hs = prep.dt, evidence.get("half_step")
    valid_until = res.extra["validity_overall"]["valid_until_s"]
    ratio = evidence.get("dt_over_shortest_period")
    res_txt = ""
    if ratio:
        part = f"{ratio:.3g} times" if ratio >= 1 else f"{ratio:.2g} of"
        res_txt = f" (dt = {dt:.3g} s is {part} the shortest elastic period {evidence['shortest_period_s']:.3g} s)"
    ran_at_half = bool(hs) and "error" not in hs
    if code in (kernels.STATUS_LAPACK_ARG, kernels.STATUS_BAD_INPUT):
        return "bug_or_input", kernels.STATUS_MESSAGES[code]
    if code == kernels.STATUS_SINGULAR:
        return "singular", kernels.STATUS_MESSAGES[code]
    if (_undamped_constraints(prep, model, data) and t_fail > 100 * dt and ran_at_half
            and hs["failed_at_s"] is not None):   # a slow growth over many steps, not a first-step failure
        return "undamped_integrator", (
            f"the average-acceleration rule adds no numerical damping, and the constraint (drive) torques of the "
            f"{model} model carry a period-2 dt oscillation that it lets grow (at dt/2 the run fails again at "
            f"t = {fmt_time(hs['failed_at_s'])} s); rerun with numerical dissipation: --integrator generalized-alpha "
            "--rho-inf 0.8 (theory.md §15)")
    if ran_at_half and (hs["failed_at_s"] is None or hs["failed_at_s"] > t_fail + max(0.1 * t_fail, 20 * dt)):
        passed = ("passes t = " + fmt_time(hs["checked_until_s"]) + " s" if hs["failed_at_s"] is None
                  else "fails only at t = " + fmt_time(hs["failed_at_s"]) + " s")
        return "step_too_large", f"the time step is too large: at dt/2 the run {passed}{res_txt}; reduce solver.dt"
    again = f"at dt/2 it fails again at t = {fmt_time(hs['failed_at_s'])} s" if hs and hs.get("failed_at_s") else ""
    if valid_until is not None and valid_until <= t_fail:
        adv = _advice(model, geo) or "the elastic model is past its range"
        return "outside_validity", (f"the model left its validity before the failure ({_limits_before(res, t_fail)}"
                                    f"{'; ' + again if again else ''}), so the growth is the model's, not the "
                                    f"structure's; {adv}")
    if hs is None and ratio is not None and ratio > 0.25:
        return "step_too_large", f"probably the time step{res_txt}; reduce solver.dt"
    grew = _grew(res)
    if code == kernels.STATUS_NEWTON and ratio is not None and ratio > 10 and not grew:
        return "step_too_large", (
            f"the time step is far above the shortest elastic period{res_txt}: the iteration cannot settle the "
            "unresolved stiff (axial) modes, also at dt/2; reduce solver.dt toward that period, use "
            "--integrator generalized-alpha, or fewer elements per link")
    if not grew and code == kernels.STATUS_NEWTON:
        return "solver_settings", (
            "the motion had not grown before the failure and it persists at dt/2: solver.newton_tol is below what "
            "the iteration can reach (round-off) or solver.newton_maxit is too small; raise them")
    if not grew:
        return "unknown", ("the motion had not grown before the failure and it persists at dt/2; check the case "
                           "(joints, masses, drive) and report it with the case file if it looks right")
    return "physical_instability", (f"a physical instability of the model ({again or 'the step is well resolved'}"
                                    f"{res_txt}), e.g. parametric resonance; for a constant-speed drive, "
                                    "`flexmech stability CASE` maps the unstable speeds")
