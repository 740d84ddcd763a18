"""The words of the error budget: its warning (the worst column, the part that dominates and the
setting that cuts it), the lines of the printed table, the choice of ``model = "auto"``, and numbers
quoted to the digits their error allows (docs/cli.md "Error budget").  Pure formatting of the
``error_budget`` and ``model_choice`` entries of summary.json."""

from __future__ import annotations

import math

from . import mesh_error, model_error
from ..definitions import rigid_in_superposition
from ..base.families import family, large_deflection_reference

__all__ = ["budget_warning", "unchecked_model_warning", "budget_lines", "choice_lines", "pct", "significant_digits", "quote"]

PART_NAMES = {"time": "time-step", "mesh": "mesh", "model": "model"}


def pct(x, floor: float = 1e-5) -> str:
    """A fraction as a percentage with two significant digits ('–' when unknown, '<0.001 %' below
    ``floor``)."""
    if x is None or not math.isfinite(x):
        return "–"
    if x == 0:
        return "0 %"
    if abs(x) < floor:
        return f"<{100 * floor:g} %"
    text = quote(100 * x, None, most=2)
    return f"{100 * x:g} %" if float(text) == 100 * x else f"{text} %"


def significant_digits(value: float, relative_error: float | None, most: int = 4) -> int:
    """Significant digits of ``value`` whose last one sits at the leading digit of its error
    (relative_error x |value|): 1.68 with 16 % error -> 2 digits (1.7).  At least 1, at most ``most``."""
    if relative_error is None or not math.isfinite(relative_error) or relative_error <= 0 or value == 0:
        return most
    lead_v = math.floor(math.log10(abs(value)))
    lead_e = math.floor(math.log10(abs(value) * relative_error))
    return max(1, min(most, lead_v - lead_e + 1))


def quote(value: float, relative_error: float | None, most: int = 4) -> str:
    """``value`` rounded to the digits its relative error allows (see :func:`significant_digits`), in
    positional notation: 1.684 +- 16 % -> "1.7", 51 +- 30 % -> "50"."""
    if value == 0 or not math.isfinite(value):
        return f"{value:g}"
    decimals = significant_digits(value, relative_error, most) - 1 - math.floor(math.log10(abs(value)))
    if decimals >= 0:
        return f"{value:.{decimals}f}"
    return f"{round(value, decimals):.0f}"


def _parts_text(c: dict) -> str:
    return ", ".join(f"{PART_NAMES[k]} {pct(c[k])}" for k in ("model", "mesh", "time") if c.get(k) is not None)


def _remedy(part: str, name: str, c: dict, out: dict, est: dict, prep, model: str, geometric) -> str | None:
    tol = out["tolerance"]
    if part == "mesh":
        n = max(ln["elements"] for ln in prep.case["links"] if not ln.get("rigid"))
        m = mesh_error.elements_for(n, c["mesh"], tol)
        return (f"a finer mesh cuts it (the spatial error falls as h^{mesh_error.MESH_ORDER}): --elements-per-link {m} "
                f"or mesh.elements_per_link = {m} instead of {n}")
    if part == "model":
        better = f"--model {large_deflection_reference().name} (the exact model)"
        if family(model).superposition and rigid_in_superposition(prep.case, name):
            return (f"{name} is the rigid-body solution's drive force in {model_error.label(model, geometric)} (docs/theory.md section 18.5), "
                    f"which no geometric stiffness changes; {better} includes the links' elasticity in it")
        if family(model).superposition and geometric in (None, "none"):
            better = ("the geometric stiffness of the axial forces (--set solver.geometric_stiffness=lagged) or "
                      + better)
        return (f"a better model than {model_error.label(model, geometric)} cuts it: {better}, or --model auto "
                "(the cheapest model within solver.tolerance)")
    if est.get("warning"):            # step doubling has warned already, with its own remedy
        return None
    if est.get("remedy"):             # a diagnosis of the time error's cause (e.g. undamped ringing)
        return est["remedy"]
    dt = prep.dt
    new = dt * (0.5 * tol / c["time"]) ** 0.5
    return f"a smaller step cuts it: --dt {new:.2g} or solver.dt = {new:.2g} instead of {dt:.3g} s"


def budget_warning(out: dict, est: dict, prep, model: str, geometric) -> dict | None:
    """The warning of a budget whose worst column passes the tolerance, or None."""
    w = out["worst_column"]
    if w is None or not out["worst_total"] > out["tolerance"]:
        return None
    c = out["columns"][w]
    remedy = _remedy(c["dominant"], w, c, out, est, prep, model, geometric)
    if remedy is None:
        return None
    over = sum(1 for n, x in out["columns"].items()
               if "negligible" not in x and math.isfinite(x["total"]) and x["total"] > out["tolerance"])
    more = f" ({over} outputs above it)" if over > 1 else ""
    msg = (f"error budget: {w} may be off by about {pct(c['total'])} of its peak ({_parts_text(c)}), above the "
           f"tolerance of {pct(out['tolerance'])} (solver.tolerance){more}; the {PART_NAMES[c['dominant']]} error "
           f"dominates: {remedy}")
    return {"column": w, "dominant": c["dominant"], "remedy": remedy, "message": msg}


def unchecked_model_warning(out: dict, t_end: float, model: str) -> str | None:
    """The warning of a budget whose model error covers less than 90 % of the run (a probe run stopped):
    beyond that time the run's answer is unchecked against the exact model; None otherwise."""
    if not any("model" in c.get("lower_bound", ()) for c in out["columns"].values() if "negligible" not in c):
        return None
    runs = [r for r in out["probes"].get("runs", []) if r["role"] in ("model", "reference")
            and r.get("stopped_at_s") is not None]
    if not runs or min(r["stopped_at_s"] for r in runs) >= 0.9 * t_end:
        return None
    r = min(runs, key=lambda r: r["stopped_at_s"])
    exact = large_deflection_reference().name
    return (f"error budget: the model error of {model} is checked only over [0, {r['stopped_at_s']:.3g}] s of "
            f"{t_end:.3g} s (its probe run of {r['model']} at dt {r['dt']:.3g} s stopped there), so the table's "
            f"model column is a lower bound: the answer may be off by more; compare with --model {exact}, at a "
            "smaller --dt if it stops")


def _probe_words(b: dict) -> str:
    pr = b.get("probes", {})
    if not pr.get("made"):
        return f"; no mesh or model estimate: {pr['reason']}" if pr.get("reason") and len(b["parts"]) > 1 else ""
    els = "/".join(map(str, sorted(set(pr["elements"].values()))))
    runs = {r["role"]: r for r in pr["runs"]}
    out = ""
    if "mesh" in runs:
        out += f"; mesh: against {els} elements per link (dt {runs['mesh']['dt']:.3g} s)"
    if "reference" in runs:
        r = runs["reference"]
        out += (f"; model: against {r['model']} at {'/'.join(map(str, r['elements']))} elements per link "
                f"(dt {r['dt']:.3g} s)")
    return out


def budget_lines(b: dict) -> list[str]:
    """The printed table of an ``error_budget`` entry."""
    lines = [f"error budget (% of each output's peak; tolerance {pct(b['tolerance'])}{_probe_words(b)}; "
             f"cost {b['cpu_s']:.2f} s CPU)"]
    w = max([len(n) for n in b["columns"]] + [6])
    lines.append(f"{'output':<{w}}  {'time':>9} {'mesh':>9} {'model':>9} {'total':>9}  dominant")
    for n, c in b["columns"].items():
        if "negligible" in c:
            lines.append(f"{n:<{w}}  negligible: {c['negligible']}")
            continue
        cells = [(">" if k in c.get("lower_bound", ()) else "") + pct(c[k]) for k in ("time", "mesh", "model")]
        cells.append((">" if c.get("lower_bound") else "") + pct(c["total"]))
        lines.append(f"{n:<{w}}  " + " ".join(f"{x:>9}" for x in cells)
                     + f"  {c['dominant'] or '-'}" + (" *" if c["total"] > b["tolerance"] else ""))
    return lines + _note_lines(b)


def _note_lines(b: dict) -> list[str]:
    notes: dict = {}
    for n, c in b["columns"].items():
        for part, why in c.get("notes", {}).items():
            notes.setdefault((part, why), []).append(n)
    out = [f"  ({part} of {', '.join(ns)}: {why})" for (part, why), ns in notes.items()]
    if any(c["total"] > b["tolerance"] for c in b["columns"].values() if "negligible" not in c):
        out.append("  * above the tolerance")
    return out


def choice_lines(ch: dict) -> list[str]:
    """What ``model = "auto"`` chose and why (the ``model_choice`` entry)."""
    tried = "; ".join(f"{t['label']} {pct(t['estimate'])}" + (f" in {t['column']}" if t.get("column") else "")
                      + (f" ({t['partial']})" if t.get("partial") else "") for t in ch["tried"])
    return [f"model auto: {ch['label']}: {ch['reason']}"
            + (f" (estimated model errors against the nonlinear model: {tried})" if tried else "")
            + f"; probes {ch['cpu_s']:.2f} s CPU"]
