"""What an accuracy study (:mod:`flexmech_py.studies.accuracy`) computes from its runs: observed orders and
Richardson extrapolation, the reference of each model and column, each run's errors against it, the
observed orders of the ladders, and the cheapest run that meets each tolerance."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["max_difference", "successive_orders", "richardson", "Outcome", "level_label", "constant_ratio",
           "references", "run_rows", "observed_orders", "cheapest_runs"]


def max_difference(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))))


def successive_orders(levels, ratio: float = 2.0) -> list:
    """Observed orders from successive differences of ``levels`` (finest first, refinement ``ratio``):
    p_i = log(|Y_{i+1} - Y_{i+2}| / |Y_i - Y_{i+1}|) / log(ratio) (max norm); NaN where undefined."""
    d = [max_difference(levels[i], levels[i + 1]) for i in range(len(levels) - 1)]
    out = []
    for i in range(len(d) - 1):
        out.append(math.log(d[i + 1] / d[i]) / math.log(ratio) if d[i] > 0 and d[i + 1] > 0 else float("nan"))
    return out


def richardson(levels, ratio: float = 2.0, consistency: float = 0.3, min_order: float = 0.5) -> dict:
    """Richardson extrapolation of the finest of ``levels`` (arrays, finest first, each refined by
    ``ratio`` from the next), applied only where the observed order is consistent.

    Needs 4 levels: the orders of the two finest pairs of successive differences must agree
    within ``consistency`` and exceed ``min_order``.  Returns ``applied``, ``orders``, ``order``
    (the finest), ``reason`` (why not, or ''), ``correction`` (array, zero if not applied)
    and ``uncertainty`` (max-norm estimate of the extrapolated or finest level's remaining error).
    """
    levels = [np.asarray(y, float) for y in levels]
    fine = levels[0]
    d0 = max_difference(levels[0], levels[1]) if len(levels) > 1 else float("nan")
    orders = successive_orders(levels, ratio)
    out = {"applied": False, "orders": orders, "order": orders[0] if orders else float("nan"), "reason": "",
           "correction": np.zeros_like(fine), "uncertainty": d0, "finest_difference": d0}
    scale = float(np.max(np.abs(fine))) if fine.size else 0.0
    if len(levels) < 4:
        out["reason"] = f"needs 4 levels to check the order, got {len(levels)}"
    elif not d0 > 1e-13 * scale:
        out["reason"] = "the two finest levels agree to round-off: nothing to extrapolate"
        out["uncertainty"] = 0.0
    elif not all(math.isfinite(p) for p in orders[:2]):
        out["reason"] = "a difference of successive levels is zero: the order is undefined"
    elif orders[0] < min_order:
        out["reason"] = f"observed order {orders[0]:.2f} < {min_order}: not in the asymptotic range"
    elif abs(orders[0] - orders[1]) > consistency:
        out["reason"] = (f"orders of successive differences {orders[1]:.2f} (coarser) and {orders[0]:.2f} (finer) "
                         f"differ by more than {consistency}: not in the asymptotic range")
    else:
        p_f, p_c = orders[0], orders[1]
        diff = levels[0] - levels[1]
        corr = diff / (ratio ** p_f - 1.0)
        out.update(applied=True, correction=corr, uncertainty=float(np.max(np.abs(corr - diff / (ratio ** p_c - 1.0)))))
    return out


# ----------------------------------------------------------------------------- the study


# ----------------------------------------------------------------------------- the study's results
class Outcome:
    """The runs' results by point key: ``res`` (a run_point dict, or a failure dict with ``error``),
    ``secs`` (the task's wall time), ``workers`` (where it ran)."""

    def __init__(self, keys, batch):
        self.res = dict(zip(keys, batch.results))
        self.secs = dict(zip(keys, batch.task_s))
        self.workers = dict(zip(keys, batch.task_worker))

    def ok(self, k) -> bool:
        return k in self.res and isinstance(self.res[k], dict) and "error" not in self.res[k]

    def col(self, k, c) -> np.ndarray:
        return np.asarray(self.res[k]["columns"][c], float)

    def error(self, k) -> str:
        return self.res[k].get("error", "")


def level_label(p: dict, t_end: float, case_mesh) -> str:
    n = p["elements"] if p["elements"] is not None else (case_mesh or "case")
    return f"dt={t_end / p['nsteps']:.3g}/n={n}"


def constant_ratio(ns) -> bool:
    if len(ns) < 3 or any(n is None for n in ns):
        return False
    ratios = [ns[i] / ns[i + 1] for i in range(len(ns) - 1)]
    return all(abs(x - ratios[0]) < 1e-12 for x in ratios)


NO_RICHARDSON = {"applied": False, "orders": [], "order": float("nan"), "correction": 0.0,
                 "uncertainty": float("nan"), "finest_difference": float("nan")}


def references(s, plan, out: Outcome, consistency: float) -> tuple[dict, dict]:
    """(reference info per model (JSON-ready), {(model, column): the reference series}): per model and
    column the finest reference run plus the Richardson corrections of its time and mesh families."""
    reference, yref = {}, {}
    for m in s.models:
        info = {}
        for c in s.columns:
            info[c], y = _reference_column(s, plan, out, m, c, consistency)
            if y is not None:
                yref[(m, c)] = y
        reference[m] = {"integrator": s.ref_integrator.label, "elements": s.n_ref,
                        "dt": s.t_end / (s.N0 * 2 ** s.r), "columns": info}
    return reference, yref


def _reference_column(s, plan, out: Outcome, m: str, c: str, consistency: float):
    """(info, reference series or None) of one model's column."""
    tk, sk = plan.ref_keys[(m, "time")], plan.ref_keys[(m, "space")]
    if not out.ok(tk[0]):
        return {"available": False, "reason": f"the finest reference run failed: {out.res[tk[0]].get('error')}"}, None
    y = out.col(tk[0], c)
    entry, corr, unc = {}, np.zeros_like(y), 0.0
    for direction, fam in (("time", tk), ("space", sk)):
        first_bad = next((i for i, k in enumerate(fam) if not out.ok(k)), len(fam))
        levels = [out.col(k, c) for k in fam[:first_bad]]
        rich = richardson(levels, consistency=consistency) if len(levels) >= 2 else dict(NO_RICHARDSON)
        if len(levels) < len(fam):
            rich["reason"] = (f"reference run {len(levels)} of the {direction} family failed: "
                              f"{out.res[fam[len(levels)]].get('error')}")
        corr = corr + rich["correction"]
        unc += rich["uncertainty"]
        peak = max(np.max(np.abs(y)), 1e-300)
        entry[direction] = {"applied": rich["applied"], "orders": rich["orders"], "reason": rich["reason"],
                            "levels": [level_label(plan.points[k], s.t_end, s.case_mesh) for k in fam],
                            "finest_difference_rel": rich["finest_difference"] / peak,
                            "correction_rel": float(np.max(np.abs(rich["correction"]))) / peak}
    yr = y + corr
    scale = float(np.max(np.abs(yr)))
    entry.update(available=scale > 0, peak_abs=scale, uncertainty_rel=unc / scale if scale > 0 else float("nan"),
                 reason="" if scale > 0 else "the reference is zero: relative error undefined")
    return entry, (yr if scale > 0 else None)


def run_rows(s, plan, out: Outcome, yref: dict, clock: str) -> list:
    """One row per run (accuracy.csv): its point, status, timings and errors against the reference."""
    rows = []
    for k in plan.keys:
        p, rr = plan.points[k], out.res[k]
        row = {"model": p["model"], "integrator": p["integrator"], "ladders": ";".join(p["roles"]),
               "dt": s.t_end / p["nsteps"], "dt_over_case_dt": s.t_end / p["nsteps"] / s.dt_case, "nsteps": p["nsteps"],
               "elements_per_link": p["elements"] if p["elements"] is not None else (s.case_mesh or "case"),
               "status": "ok" if out.ok(k) else "failed", "error_message": "" if out.ok(k) else rr.get("error", ""),
               "task_s": out.secs[k], "worker": out.workers[k]}
        if out.ok(k):
            row.update(_run_errors(s, out, k, p["model"], yref, clock))
        rows.append(row)
    return rows


def _run_errors(s, out: Outcome, k, model: str, yref: dict, clock: str) -> dict:
    rr = out.res[k]
    row = dict(nfree=rr["nfree"], kernel_s=rr["kernel_s"], kernel_cpu_s=rr["kernel_cpu_s"], total_s=rr["total_s"],
               run_cpu_s=rr["run_cpu_s"], rigid_s=rr["rigid_s"], repeats=len(rr["kernel_s_all"]),
               kernel_s_all=" ".join(f"{x:.4g}" for x in rr["kernel_s_all"]))
    row["time_s"] = rr["kernel_cpu_s"] if clock == "cpu" and math.isfinite(rr["kernel_cpu_s"]) else rr["kernel_s"]
    errs = {}
    for c in s.columns:
        ref = yref.get((model, c))
        errs[c] = max_difference(out.col(k, c), ref) / float(np.max(np.abs(ref))) if ref is not None else float("nan")
    for c in s.columns:
        row[f"err_{c}"] = errs[c]
    est = rr.get("estimate_rel") or {}
    ests = [est[c] for c in s.columns if c in est and math.isfinite(est[c])]
    row["est_time_worst"] = max(ests) if ests else float("nan")
    finite = {c: e for c, e in errs.items() if math.isfinite(e)}
    row["err_worst"] = max(finite.values()) if finite else float("nan")
    row["worst_column"] = max(finite, key=finite.get) if finite else ""
    return row


def observed_orders(s, plan, out: Outcome, reference: dict, row_of: dict) -> list:
    """The observed orders (orders.csv): of each ladder's successive differences, of the mesh
    ladder's errors against the reference, and of the reference families."""
    orders = []
    for m in s.models:
        for it in s.integrators:
            for direction in ("time", "space"):
                orders += _ladder_orders(s, plan, out, row_of, m, it.label, direction)
        for direction in ("time", "space"):
            fam = plan.ref_keys[(m, direction)]
            for c in s.columns:
                info = reference[m]["columns"][c].get(direction)
                for i, p_ in enumerate(info["orders"] if info else []):
                    orders.append({"model": m, "integrator": s.ref_integrator.label, "direction": direction,
                                   "source": "reference family", "column": c,
                                   "levels": " ".join(level_label(plan.points[k], s.t_end, s.case_mesh)
                                                      for k in fam[i:i + 3]), "order": p_})
    return orders


def _ladder_orders(s, plan, out: Outcome, row_of: dict, m: str, label: str, direction: str) -> list:
    lad = plan.ladders[(m, label, direction)]
    lv = [level_label(plan.points[k], s.t_end, s.case_mesh) for k in lad]
    good = lad[:next((i for i, k in enumerate(lad) if not out.ok(k)), len(lad))]
    mesh = [plan.points[k]["elements"] or s.case_mesh for k in lad]
    base = {"model": m, "integrator": label, "direction": direction}
    orders = []
    for c in s.columns:
        ys = [out.col(k, c) for k in good]
        if direction == "time" or constant_ratio(mesh):
            ratio = 2.0 if direction == "time" else mesh[0] / mesh[1]
            for i, p_ in enumerate(successive_orders(ys, ratio)):
                orders.append({**base, "source": "successive differences", "column": c,
                               "levels": " ".join(lv[i:i + 3]), "order": p_})
        if direction == "space":   # errors against the reference: space error dominates at dt_0
            for i in range(len(good) - 1):
                e1, e2 = row_of[good[i]].get(f"err_{c}"), row_of[good[i + 1]].get(f"err_{c}")
                n1, n2 = mesh[i], mesh[i + 1]
                p_ = (math.log(e2 / e1) / math.log(n1 / n2)
                      if n1 and n2 and e1 and e2 and e1 > 0 and e2 > 0 and math.isfinite(e1 + e2) else float("nan"))
                orders.append({**base, "source": "errors against the reference", "column": c,
                               "levels": " ".join(lv[i:i + 2]), "order": p_})
    return orders


def cheapest_runs(s, plan, out: Outcome, reference: dict, row_of: dict) -> list:
    """The cheapest run per (model, tolerance, column) among the ladder and grid runs."""
    cheapest = []
    for m in s.models:
        cand = [row_of[k] for k in plan.keys if plan.points[k]["model"] == m and out.ok(k)
                and set(plan.points[k]["roles"]) != {"reference"}]
        cols = reference[m]["columns"]
        for tol in s.tolerances:
            for c in s.columns + ["worst"]:
                unc = (max((cols[cc].get("uncertainty_rel", float("nan")) for cc in s.columns), default=float("nan"))
                       if c == "worst" else cols[c].get("uncertainty_rel", float("nan")))
                cheapest.append(_cheapest(cand, m, tol, c, unc))
    return cheapest


def _cheapest(cand: list, m: str, tol: float, c: str, unc: float) -> dict:
    entry = {"model": m, "tolerance": tol, "column": c}
    if not math.isfinite(unc):
        entry["note"] = "no reference"
    elif unc > tol / 3:
        entry["note"] = f"not resolved: reference uncertainty {unc:.2g} > tolerance/3"
    else:
        meet = [rw for rw in cand if rw.get(f"err_{c}", float("nan")) <= tol]
        if not meet:
            entry["note"] = "no run reached it"
        else:
            best = min(meet, key=lambda rw: rw["time_s"])
            entry.update(integrator=best["integrator"], dt=best["dt"], elements_per_link=best["elements_per_link"],
                         time_s=best["time_s"], kernel_s=best["kernel_s"], kernel_cpu_s=best["kernel_cpu_s"],
                         total_s=best["total_s"], error=best[f"err_{c}"], note="")
    return entry
