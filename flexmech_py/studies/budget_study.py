"""Validation and cost of the error budget (docs/validation.md "Error budget"):

    python -m flexmech_py.studies.budget_study [--out DIR] [--only NAME ...] [--repeat N] [--no-cost]

For every study case (the bundled cases and the fast six-bars of :data:`STUDY`), the run with its
error budget (its own model, mesh and step) and reference runs that give each part's true error, as
fractions of the run's peak of each column:

- time: the run against the same model and mesh at dt / TIME_REF;
- mesh: the run against the same model at dt with the reference mesh (:func:`ref_elements`);
- model: the run's model against the exact model, both at the reference mesh and dt;
- total: the run against the exact model at the reference mesh and dt.

Writes ``budget_validation.csv`` (one row per case, model and column) and ``budget_validation.md``
(per case the column with the largest true error, and the range of estimate / true error over the
columns whose true error is above FLOOR), and with the cost study ``budget_cost.csv``: the CPU time
of the run with its budget against the bare run (``solver.error_estimate = "none"``), in alternating
pairs, and of ``model = "auto"`` against its chosen model's run.
"""

from __future__ import annotations

import argparse
import csv
import math
import time
from pathlib import Path

import numpy as np

from ..base.bundled import case_path
from ..checks.budget_text import pct
from ..case import load_case
from ..base.errors import FlexmechError
from ..run.simulate import Prepared

__all__ = ["STUDY", "validate", "cost", "ref_elements", "main"]

TIME_REF = 8          # the time reference's step: dt / TIME_REF
FLOOR = 1e-4          # true errors below this fraction of the peak are not used for the ratios
SIXBAR = "watt_sixbar"
#: (label, case, overrides, models): models None = the case's own; "auto" = the default choice
STUDY = [
    ("fourbar_hac", "fourbar_hac", [], None),
    ("fourbar_constant_speed", "fourbar_constant_speed", [], None),
    ("manipulator_bricout", "manipulator_bricout", [], None),
    ("manipulator_bricout_no_payload", "manipulator_bricout_no_payload", [], None),
    ("fivebar", "fivebar", [], None),
    ("quick_return", "quick_return", [], None),
    ("sixbar_plate", "sixbar_plate", [], None),
    ("sixbar_welded", "sixbar_welded", [], None),
    ("slider_crank", "slider_crank", [], None),
    ("slider_crank_torque", "slider_crank_torque", [], None),
    ("watt 60 rad/s, 0.1 s", SIXBAR, [], ["hac", "classic", "classic+lagged", "coupled", "auto"]),
    ("watt 120 rad/s, 0.1 s", SIXBAR, ["drives.0.final_speed=120"], ["hac", "classic", "classic+lagged", "auto"]),
    ("watt 60 rad/s, 0.3 s", SIXBAR, ["solver.t_end=0.3"], ["classic", "classic+lagged", "auto"]),
    ("watt 120 rad/s, 0.3 s", SIXBAR, ["drives.0.final_speed=120", "solver.t_end=0.3"], ["classic", "auto"]),
]


def ref_elements(case) -> int:
    """The reference mesh: four times the run's finest link mesh, at least 16 and at most 32 per link."""
    n = max(ln["elements"] for ln in case["links"] if not ln.get("rigid"))
    return int(min(32, max(16, 4 * n)))


def _split(model: str):
    m, _, g = model.partition("+")
    return m, (g or None)


def _run(case, model, *, elements=None, dt_div=1, estimate=False):
    sol = case["solver"]
    prep = Prepared(case, elements_per_link=elements, dt=sol["dt"] / dt_div, out_every=sol["output_every"] * dt_div)
    m, g = _split(model)
    c0 = time.process_time()
    try:
        res = prep.run(m, geometric=g, estimate=estimate)
    except FlexmechError as exc:          # a reference that stops: compare the frames it has
        res = getattr(exc, "partial", None)
        if res is None:
            raise
    return res, time.process_time() - c0


def _diff(a, b) -> dict:
    """{column: max |a - b|} over the frames both have (b's frames, a interpolated)."""
    n = min(a.t.size, b.t.size)
    out = {}
    for c, y in a.columns.items():
        if c in b.columns:
            out[c] = float(np.max(np.abs(y[:n] - b.columns[c][:n]))) if n else float("nan")
    return out


def validate(label: str, case, model: str) -> list[dict]:
    """Rows of estimate and true error per column of one case and model (see the module's docstring)."""
    run, _ = _run(case, model, estimate=None)
    m, g = _split(model)
    nref = ref_elements(case)
    t_ref, _ = _run(case, m if m != "auto" else run.model, dt_div=TIME_REF)
    eff = run.model + ("+" + run.extra["geometric_stiffness"]["source"] if "geometric_stiffness" in run.extra else "")
    m_ref, _ = _run(case, eff, elements=nref)
    exact, _ = _run(case, "nonlinear", elements=nref)
    true = {"time": _diff(run, t_ref), "mesh": _diff(run, m_ref), "model": _diff(m_ref, exact),
            "total": _diff(run, exact)}
    b = run.extra.get("error_budget", {})
    rows = []
    for col, c in b.get("columns", {}).items():
        pk = run.all_stats().columns[col]["peak_abs"]
        row = {"case": label, "model": model, "ran": eff, "column": col, "negligible": c.get("negligible", "")}
        for part in ("time", "mesh", "model", "total"):
            tr = true[part].get(col, float("nan")) / pk if pk > 0 else float("nan")
            row[f"est_{part}"] = c.get(part) if c.get(part) is not None else float("nan")
            row[f"true_{part}"] = tr
        if c.get("model") is None and c.get("notes", {}).get("model"):   # defined otherwise in the exact model
            row["true_model"] = row["true_total"] = float("nan")
            row["why_no_model"] = c["notes"]["model"]
        row.setdefault("why_no_model", "")
        row["ref_elements"], row["ref_stopped_s"] = nref, exact.failure["time_s"] if exact.failure else ""
        rows.append(row)
    return rows


def _ratio(est, true) -> float:
    return est / true if math.isfinite(est) and math.isfinite(true) and true >= FLOOR else float("nan")


def summary_table(rows: list[dict]) -> list[str]:
    """Markdown: per case, model and part (time, mesh, model, total), the column with the largest true
    error of that part, its estimate, true error and their ratio, and the range of the ratios over every
    column whose true error of that part is above FLOOR (how many)."""
    out = ["| case | model (ran) | part | column | estimate | true error | ratio | ratios, all columns (n) |",
           "|---|---|---|---|---|---|---|---|"]
    for key in dict.fromkeys((r["case"], r["model"]) for r in rows):
        rs = [r for r in rows if (r["case"], r["model"]) == key and not r["negligible"]]
        for part in ("time", "mesh", "model", "total"):
            ok = [r for r in rs if math.isfinite(r[f"true_{part}"]) and math.isfinite(r[f"est_{part}"])]
            if not ok:
                continue
            w = max(ok, key=lambda r: r[f"true_{part}"])
            ratios = [x for x in (_ratio(r[f"est_{part}"], r[f"true_{part}"]) for r in ok) if math.isfinite(x)]
            span = f"{min(ratios):.2g}–{max(ratios):.2g} ({len(ratios)})" if ratios else "– (0)"
            r = _ratio(w[f"est_{part}"], w[f"true_{part}"])
            out.append(f"| {key[0]} | {key[1]} ({w['ran']}) | {part} | {w['column']} | {pct(w['est_' + part])} | "
                       f"{pct(w['true_' + part])} | {f'{r:.2g}' if math.isfinite(r) else '–'} | {span} |")
    return out


def cost(case, model: str, repeat: int = 5) -> dict:
    """CPU time of the run with its budget over the bare run (alternating pairs, the medians), and, for
    ``model = "auto"``, of the chosen model's run with its budget."""
    bare, full = [], []
    for _ in range(repeat):
        bare.append(_run(case, model, estimate=False)[1])
        res, t = _run(case, model, estimate=None)
        full.append(t)
    out = {"bare_s": float(np.median(bare)), "budget_s": float(np.median(full))}
    out["budget_ratio"] = out["budget_s"] / out["bare_s"] - 1.0
    if model == "auto":
        eff = res.model + ("+" + res.extra["geometric_stiffness"]["source"] if "geometric_stiffness" in res.extra else "")
        chosen = [_run(case, eff, estimate=None)[1] for _ in range(repeat)]
        out.update(chosen=eff, chosen_s=float(np.median(chosen)))
        out["auto_over_chosen"] = out["budget_s"] / out["chosen_s"] - 1.0
    return out


def _write_csv(path: Path, rows: list[dict]) -> None:
    if not rows:
        return
    with path.open("w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.4g}" if isinstance(v, float) else v) for k, v in r.items()})


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m flexmech_py.studies.budget_study", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="budget_study", help="output folder (default ./budget_study)")
    ap.add_argument("--only", nargs="*", help="study cases whose label contains one of these words")
    ap.add_argument("--repeat", type=int, default=5, help="alternating pairs per cost measurement")
    ap.add_argument("--no-cost", action="store_true", help="skip the cost study")
    ap.add_argument("--no-validation", action="store_true", help="skip the validation study")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows, costs = [], []
    for label, name, sets, models in STUDY:
        if args.only and not any(w in label for w in args.only):
            continue
        case = load_case(case_path(name), overrides=sets)
        for model in models or [case["solver"]["model"]]:
            if not args.no_validation:
                rows += validate(label, case, model)
                print(f"{label}, {model}: validated", flush=True)
            if not args.no_cost:
                c = cost(case, model, args.repeat)
                costs.append({"case": label, "model": model, **c})
                print(f"{label}, {model}: budget +{100 * c['budget_ratio']:.0f} %", flush=True)
            _write_csv(out / "budget_validation.csv", rows)      # after every run: a stopped study keeps its rows
            _write_csv(out / "budget_cost.csv", costs)
    if rows:
        (out / "budget_validation.md").write_text("\n".join(summary_table(rows)) + "\n", encoding="utf-8")
        print("\n".join(summary_table(rows)))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
