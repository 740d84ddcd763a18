"""From a run to a design decision: stress envelopes, bearing loads and fatigue life of one run.

:class:`DesignAnalysis` watches a run block by block (an observer of
:func:`flexmech_py.run.runner.execute`; or :meth:`DesignAnalysis.add` of one whole Result, e.g. the
periodic steady state) and, when it ends, gives the stress envelope of every flexible link
(:mod:`flexmech_py.strength.stress`), the load envelope of every joint (:mod:`flexmech_py.strength.joint_loads`) and,
when asked, the fatigue life (:mod:`flexmech_py.strength.fatigue`) over a repeating history: the steady
state's period or a run window of whole crank cycles.  It writes stress.csv, joint_loads.csv and
design.json, puts the critical values in ``Result.extra["design"]`` (summary.json) and in the printed
table, and reports its own cost against the run's.
"""

from __future__ import annotations

import json
import math
import time

from . import fatigue as fat
from ..base.errors import CaseError
from .joint_loads import JointLoads
from ..run.results import csv_rows
from .stress import StressEnvelope

__all__ = ["DesignAnalysis", "crank_period", "parse_window", "stress_errors", "design_lines"]


def crank_period(case) -> float | None:
    """The period [s] of a case whose one drive turns a revolute joint at constant speed; else None."""
    drives = case["drives"]
    if len(drives) != 1 or drives[0]["law"] != "constant_speed":
        return None
    if not case.mechanism.joint(drives[0]["joint"]).angular or not drives[0].get("speed"):
        return None
    return 2.0 * math.pi / abs(float(drives[0]["speed"]))


def parse_window(text: str | None, t_end: float) -> tuple[float, float] | None:
    """``T0:T1`` [s] (either end may be left out: the run's start or end) as (t0, t1); None for None."""
    if text is None:
        return None
    parts = text.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        t0 = float(parts[0]) if parts[0].strip() else 0.0
        t1 = float(parts[1]) if parts[1].strip() else t_end
    except ValueError:
        raise CaseError("--window", f"{text!r} must be T0:T1 in seconds, e.g. 0.2:0.2617994") from None
    if not 0.0 <= t0 < t1 <= t_end * (1 + 1e-9):
        raise CaseError("--window", f"{text!r} must satisfy 0 <= T0 < T1 <= t_end = {t_end:g} s")
    return t0, t1


def fatigue_window(case, window, steady: bool) -> tuple[float | None, float]:
    """(crank period or None, history length [s]) of a fatigue request, or CaseError saying why the run
    has no repeating history to count: a run with no window, or a window shorter than a crank cycle."""
    period = crank_period(case)
    if steady:
        return period, period
    if window is None:
        raise CaseError("--fatigue", "a run's start is a transient, not a repeating history: give --window T0:T1 over "
                                     "whole crank cycles of the part that repeats, or use `flexmech steady CASE "
                                     "--fatigue` for the periodic steady state")
    span = window[1] - window[0]
    if period is not None and span < period * (1.0 - 1e-6):
        raise CaseError("--window", f"spans {span:.6g} s, less than one crank cycle ({period:.6g} s): the fatigue count "
                                    "needs at least one whole cycle; widen the window or lengthen solver.t_end")
    return period, span


def stress_errors(res, links) -> dict:
    """{link: the stress error as a fraction of its peak} from the run's error budget (per output:
    the largest over its strain, curvature and axial-force outputs; else the run's worst column), or
    from its step-doubling estimate; None where the run estimated none."""
    budget = res.extra.get("error_budget") or {}
    est = res.extra.get("error_estimate") or {}
    cols = {n: c.get("total") for n, c in (budget.get("columns") or {}).items()} or \
        {n: c.get("relative") for n, c in (est.get("columns") or {}).items()}
    worst = budget.get("worst_total", est.get("worst_relative"))
    out = {}
    for name in links:
        own = [cols[o] for o, sp in res.case["outputs"].items() if sp.get("link") == name and o in cols and
               sp["kind"] in ("strain", "curvature", "axial_force") and cols[o] is not None and math.isfinite(cols[o])]
        out[name] = max(own) if own else worst
    return out


class DesignAnalysis:
    """Stress, joint loads (``joint_loads``: the optimizer asks for them only when a quantity is a joint's
    load, as they cost a reaction solve per frame) and (``correction`` not None) fatigue of one run's frames
    inside ``window``."""

    def __init__(self, prep_case, fe=None, *, window=None, correction: str | None = None, steady: bool = False,
                 joint_loads: bool = True):
        self.case, self.window, self.correction = prep_case, window, correction
        if correction is not None:
            fat.require_rainflow()
            if correction not in fat.CORRECTIONS:
                raise CaseError("--fatigue", f"must be one of {', '.join(fat.CORRECTIONS)}, got {correction!r}")
            self.period, self.history_s = fatigue_window(prep_case, window, steady)
        else:
            self.period, self.history_s = crank_period(prep_case), None
        self.stress = StressEnvelope(prep_case, fe, window, keep_history=correction is not None)
        self.loads = JointLoads(prep_case, window) if joint_loads else None
        self.cpu_s = 0.0
        self.cpu_start = time.process_time()   # the run's CPU time is this process's since, less cpu_s
        self.report: dict | None = None

    def add(self, block) -> None:
        t0 = time.process_time()
        self.stress.add(block)
        if self.loads is not None:
            self.loads.add(block)
        self.cpu_s += time.process_time() - t0

    def finish(self, res) -> dict:
        """The design summary (also ``res.extra["design"]``); warnings join the run's."""
        t0 = time.process_time()
        rep = {"window_s": list(self.window) if self.window else None, "stress": self.stress.summary(),
               "joint_loads": self.loads.summary(self.case) if self.loads is not None else {}}
        if self.correction is not None:
            rep["fatigue"] = self._fatigue(res)
        t1 = time.process_time()
        self.cpu_s += t1 - t0
        run_cpu = t1 - self.cpu_start - self.cpu_s
        rep["cost"] = {"post_processing_cpu_s": self.cpu_s, "run_cpu_s": run_cpu,
                       "fraction_of_run": self.cpu_s / run_cpu if run_cpu > 0 else None}
        res.extra["design"] = rep
        self.report = rep
        return rep

    def _fatigue(self, res) -> dict:
        t, hist = self.stress.histories()
        if t.size < 3:
            raise CaseError("--window", f"holds {t.size} frame(s): too few to count cycles; widen it or lower "
                                        "solver.output_every")
        per_link = {}
        for env in self.stress.links:
            st = env.st
            r = fat.link_fatigue(st.name, st.length, st.fractions, hist[st.name], t, st.material, self.correction)
            per_link[st.name] = r
        summary, warnings = fat.fatigue_summary(per_link, self.history_s, self.period,
                                                stress_errors(res, list(per_link)))
        summary["correction"] = self.correction
        summary["frames"] = int(t.size)
        for w in warnings:
            res.extra.setdefault("warnings", []).append(w)
        return summary

    def write(self, folder) -> list:
        """stress.csv, joint_loads.csv and design.json in ``folder`` (a result folder's staging folder: the
        files are whole when it commits); their paths."""
        rows = self.stress.station_rows()
        keys = list(rows[0]) if rows else []
        head = "# flexmech stress envelope: per station of every flexible link, the largest and smallest outer-fibre " \
               "stress [Pa] over the frames" + (f" in {self.window[0]:g}..{self.window[1]:g} s" if self.window else "")
        body = "\n".join([head, ",".join(keys)] + [",".join(_cell(r[k]) for k in keys) for r in rows]) + "\n"
        paths = [folder / "stress.csv", folder / "joint_loads.csv", folder / "design.json"]
        paths[0].write_text(body, encoding="utf-8")
        cols, data = self.loads.cycle_rows()
        lhead = "# flexmech joint loads: the force body a exerts on body b in the frame of the joint's link " \
                "(axial along it, normal across) [N], its magnitude and the joint moment [N m]\n"
        paths[1].write_text(lhead + ",".join(cols) + "\n" + csv_rows(data[:, 0], dict(zip(cols[1:], data[:, 1:].T)))
                            if data.shape[0] else lhead, encoding="utf-8")
        paths[2].write_text(json.dumps(self.report, indent=1, default=_plain) + "\n", encoding="utf-8")
        return paths


def _plain(o):
    """JSON for numpy scalars and arrays."""
    return o.tolist() if hasattr(o, "tolist") else str(o)


def _cell(x) -> str:
    return f"{x:.9g}" if isinstance(x, float) else str(x)


def design_lines(rep: dict) -> list[str]:
    """The critical values for the printed table."""
    out = []
    for name, s in rep["stress"].items():
        c = s["critical_station"]
        sf = s["safety_factor"]
        sf_txt = f"safety factor {sf:.3g} against yield {s['yield_strength_Pa'] / 1e6:.0f} MPa" if sf is not None \
            else "no yield strength (give the link a material)"
        out.append(f"stress {name}: peak {c['stress_Pa'] / 1e6:+.4g} MPa at {c['fraction']:.3g} L ({c['fibre']} fibre, "
                   f"t = {c['t_s']:.6g} s); {sf_txt}")
    for name, j in rep["joint_loads"].items():
        out.append(f"joint {name}: load max {j['max_N']:.4g} N (t = {j['t_max_s']:.6g} s), min {j['min_N']:.4g} N, "
                   f"rms {j['rms_N']:.4g} N ({j['source']} reactions, frame of {j['frame']})")
    fat_rep = rep.get("fatigue")
    if fat_rep:
        for name, f in fat_rep["links"].items():
            c = f["critical_station"]
            cyc = f"{f['life_cycles']:.3g} crank cycles, " if f["life_cycles"] is not None else ""
            span = f.get("life_hours_interval")
            span_txt = f" [{span[0]:.3g}..{span[1]:.3g} h]" if span else ""
            life = (f"{cyc}{f['life_hours']:.3g} h{span_txt}" if f["damage_per_history"] != float("inf") else
                    "none: a cycle's mean stress reaches the ultimate strength")
            out.append(f"fatigue {name} ({fat_rep['correction']}): life {life} at "
                       f"{c['fraction']:.3g} L ({c['fibre']} fibre); damage {f['damage_per_history']:.3g} per "
                       f"{fat_rep['history_s']:.4g} s")
    cost = rep["cost"]
    if cost.get("fraction_of_run") is not None:
        out.append(f"design post-processing: {cost['post_processing_cpu_s']:.3g} s CPU, "
                   f"{cost['fraction_of_run']:.1%} of the run")
    return out

