"""The model gap: every linear configuration against the nonlinear model, over windows of
increasing length, with the time each leaves its validity range and its cost.

Used by ``flexmech reproduce`` (its report) and ``docs/validation.md``; regenerate with
``flexmech reproduce``.
"""

from __future__ import annotations

import time

import numpy as np

from ..base.families import family
from ..checks.guards import THRESHOLDS, deflection_over_length
from ..base.notices import silenced
from ..run.simulate import Prepared

__all__ = ["CONFIGS", "gap_study", "validity_time", "gap_table"]

# (model, geometric-stiffness source, driven-joint condition): "seed" keeps the case file's joints
CONFIGS = [("hac", "none", "seed"), ("classic", "none", "seed"), ("classic-translational", "none", "seed"),
           ("classic", "quasi_static", "seed"), ("classic", "current", "seed"), ("classic", "quasi_static", "torque"),
           ("coupled", "none", "seed")]
def validity_time(res) -> tuple[float, float]:
    """First times [s] at which (a) any link's bending deflection from its chord exceeds 2 % of its
    length and (b) any link's compressive axial force exceeds its Euler load (inf if never).  (b)
    also catches short axial transients (a torque step sends axial waves through the links)."""
    fe = res.fe
    bad = (deflection_over_length(res) > THRESHOLDS["displacement_over_length"]).any(axis=0)
    comp = np.zeros(res.t.size, bool)
    if res.axial is not None:
        for li, ln in enumerate(fe.case["links"]):
            if ln.get("rigid"):
                continue
            ne = np.pi ** 2 * ln["youngs_modulus"] * ln["second_moment"] / ln["length"] ** 2
            comp |= (-res.axial[fe.link_elements(li)]).max(axis=0) > THRESHOLDS["compression_over_euler"] * ne

    def first(mask):
        return float(res.t[np.argmax(mask)]) if mask.any() else float("inf")

    return first(bad), first(comp)


def _driven_torque_case(case):
    import copy

    c = copy.deepcopy(case)
    forced = {d["joint"] for d in c["drives"] if d["law"] == "force"}
    for j in c["joints"]:
        if j["name"] in forced:
            j["elastic"] = "torque"
    return c


@silenced()      # the study measures the errors itself
def gap_study(case: dict, column: str, windows, elements=8, ref_elements=16, configs=CONFIGS, progress=None) -> dict:
    """Run the configurations and the nonlinear reference on one case; returns a dict with rows.

    The 'closest' configuration is judged over the longest window in which the nonlinear run's
    deflections stay below 2 % of the link lengths."""
    say = progress or (lambda m: None)
    t0 = time.perf_counter()
    ref_prep = Prepared(case, elements_per_link=ref_elements)
    ref = ref_prep.run("nonlinear", estimate=False)   # the study measures the errors itself
    say(f"  nonlinear reference ({ref_elements} elements per link): {time.perf_counter() - t0:.1f} s")
    preps = {"seed": Prepared(case, elements_per_link=elements, out_every=case["solver"]["output_every"])}
    y_ref = ref.columns[column]
    rows = []
    for model, geo, joint in configs:
        if joint == "torque":
            if not any(d["law"] == "force" for d in case["drives"]):
                continue
            if "torque" not in preps:
                preps["torque"] = Prepared(_driven_torque_case(case), elements_per_link=elements)
        prep = preps[joint]
        row = {"model": model, "geometric": geo, "joint": joint, "elements": elements}
        try:
            r = prep.run(model, geometric=geo if family(model).superposition else None, estimate=False)
        except Exception as exc:   # a configuration that fails is reported, not hidden
            row.update(errors=[float("nan")] * len(windows), validity_s=(float("nan"),) * 2, kernel_s=float("nan"),
                       failed=str(exc).split(":")[0] + ": " + str(exc).split(":", 1)[-1][:80])
            rows.append(row)
            continue
        y = np.interp(ref.t, r.t, r.columns[column])
        errs = []
        for w in windows:
            sel = ref.t <= w + 1e-12
            pk = np.max(np.abs(y_ref[sel]))
            errs.append(float(np.max(np.abs(y[sel] - y_ref[sel])) / pk) if pk > 0 else float("nan"))
        row.update(errors=errs, validity_s=validity_time(r), kernel_s=r.timing["kernel_s"], failed="")
        rows.append(row)
    return {"column": column, "windows": list(windows), "rows": rows, "reference_validity_s": validity_time(ref),
            "reference_kernel_s": ref.timing["kernel_s"], "ref_elements": ref_elements}


def _when(t_s: float) -> str:
    return f"{t_s:.4g}" if np.isfinite(t_s) else "never"


def gap_table(name: str, study: dict) -> list[str]:
    w = study["windows"]
    t_defl, t_comp = study["reference_validity_s"]
    span = f"within [0, {w[-1]:g}] s"
    defl = (f"a deflection first exceeds 2 % of its link's length at t = {t_defl:.4g} s" if np.isfinite(t_defl)
            else f"no deflection exceeds 2 % of its link's length {span}")
    comp = (f"a compressive force first exceeds the Euler load at t = {t_comp:.4g} s" if np.isfinite(t_comp)
            else f"no compressive force exceeds the Euler load {span}")
    lines = [f"**{name}** — `{study['column']}` against the nonlinear model ({study['ref_elements']} elements per "
             f"link, kernel {study['reference_kernel_s']:.2f} s); in the nonlinear run {defl}, and {comp}.", "",
             "| model | K_σ | driven joints | elements | " + " | ".join(f"[0, {x:g}] s" for x in w)
             + " | deflection > 2 % L at [s] | compression > N_Euler at [s] | kernel [s] |",
             "|---|---|---|---|" + "---|" * len(w) + "---|---|---|"]
    for r in study["rows"]:
        if r["failed"]:
            when = r["failed"].split(" s:")[0].rsplit("t = ", 1)[-1] if "t = " in r["failed"] else "?"
            cells = [f"stopped at t = {when} s"] + ["–"] * (len(w) - 1)
            tail = " – | – | – |"
        else:
            cells = [f"{100 * e:.3g} %" for e in r["errors"]]
            tail = f" {_when(r['validity_s'][0])} | {_when(r['validity_s'][1])} | {r['kernel_s']:.3g} |"
        lines.append(f"| {r['model']} | {r['geometric']} | {r['joint']} | {r['elements']} | " + " | ".join(cells)
                     + " |" + tail)
    return lines + _closest(study) + [""]


def _closest(study: dict) -> list[str]:
    """The best configuration over the longest window inside the nonlinear run's small-deflection range,
    or, when even the shortest window reaches past it, over the shortest window, said so."""
    ok = [r for r in study["rows"] if not r["failed"]]
    if not ok:
        return []
    w, t_defl = study["windows"], study["reference_validity_s"][0]
    inside = [i for i, x in enumerate(w) if x <= t_defl]
    k = max(inside or [0])
    best = min(ok, key=lambda r: r["errors"][k])
    verdict = "within" if best["errors"][k] <= 0.10 else "NOT within"
    if inside:
        why = ("the nonlinear deflections stay below 2 % of the link lengths over the whole study" if not np.isfinite(t_defl)
               else f"the longest window before the nonlinear deflections pass 2 % of the link lengths at t = {t_defl:.4g} s")
    else:
        why = (f"no window lies inside the small-deflection range: the nonlinear deflections pass 2 % of the link "
               f"lengths at t = {t_defl:.4g} s, before the shortest window ends, so every configuration here is "
               "compared outside the range of the linear models")
    return ["", f"Closest over [0, {w[k]:g}] s ({why}): {best['model']}, K_σ {best['geometric']}, driven joints "
                f"{best['joint']}: {100 * best['errors'][k]:.3g} % — {verdict} 10 %."]
