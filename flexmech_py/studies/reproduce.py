"""``flexmech reproduce``: the seed paper's Figs. 2-12 for every model, the seed cases' runs and the
model-gap study, as PNGs, run folders and a Markdown report (its text: :mod:`flexmech_py.studies.seed_report`).

Seed claims checked (Hac, Sec. 4):
- four-bar midspan strains of case I (``hac``) and case II (``classic``) differ
  by at most 3 % (relative to the peak strain);
- the inertia-force vectors ``F_c0 = M0 x0''`` and ``F_c = M x0''`` differ by about 1 %;
- manipulator: the two cases differ considerably; without payload the vibration increases.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..base.bundled import cases_dir as cases_dir_bundled
from ..case import load_case
from ..base.families import FAMILIES, MODELS, SUPERPOSITION_MODELS
from ..base.errors import CaseError
from ..base.notices import silenced
from ..base.inputs import checked_file, checked_folder
from ..mechanism.materials import MATERIALS
from ..run.outdir import ResultFolder
from ..figures.plots import line_figure, mechanism_sketch
from .reproduce_modes import modes_section
from .seed_cases import SEED_CASES, load_vector_difference, model_differences
from .seed_report import report_text
from ..run.simulate import simulate_models
from .gap import gap_study, gap_table

__all__ = ["reproduce", "seed_case_path", "model_differences"]

STYLE = {"hac": {"color": "C0", "lw": 2.2}, "classic": {"color": "C3", "lw": 1.1, "ls": "--"},
         "classic-translational": {"color": "C2", "lw": 1.1, "ls": ":"}, "coupled": {"color": "k", "lw": 1.1, "ls": "--"},
         "rigid": {"color": "0.55", "lw": 1.0, "ls": "--"}, "nonlinear": {"color": "C1", "lw": 2.4, "alpha": 0.8}}
LABEL = {**{name: f.label for name, f in FAMILIES.items()}, "rigid": "rigid-body solution"}
#: drawing order: a thin dashed curve over a wide solid one it may coincide with (coupled over nonlinear)
ORDER = ("hac", "classic", "classic-translational", "nonlinear", "coupled")
NEEDED = {"fourbar_hac": ("crank_angle", "crank_speed", "strain_coupler_mid", "strain_follower_mid",
                          "load_coupler_mid_x", "load_coupler_mid_y", "load_joint_b_x", "load_joint_b_y", "load_norm"),
          "fourbar_constant_speed": ("strain_coupler_mid", "strain_follower_mid"),
          "manipulator_bricout": ("tip_dx_elastic", "tip_dy_elastic", "tip_dx_deflection", "tip_dy_deflection",
                                  "tip_transverse_deflection", "alpha", "beta"),
          "manipulator_bricout_no_payload": ("tip_dx_deflection", "tip_dy_deflection", "tip_transverse_deflection")}
#: (yield strength, Young's modulus) [Pa] of the two structural aluminium alloys the seed's links could be,
#: from the materials table (flexmech_py.mechanism.materials; sources in docs/cases.md): the seed gives E = 71 GPa
#: and no alloy
ALLOYS = {name: (MATERIALS[name]["yield_strength"], MATERIALS[name]["youngs_modulus"])
          for name in ("6061-T6", "7075-T6")}


def seed_case_path(name: str, cases_dir=None) -> Path:
    """Path of a seed case file: ``NAME.toml`` in ``cases_dir``, else the bundled one (bundled.cases_dir)."""
    return Path(cases_dir) / f"{name}.toml" if cases_dir is not None else cases_dir_bundled() / f"{name}.toml"


def _fig(out, name, panels, title, xlabel):
    p = line_figure(out / name, panels, title=title, xlabel=xlabel)
    return p.name if p is not None else None


def _series(rr: dict, col: str, models=ORDER, scale: float = 1.0) -> list:
    """(label, scale * column, style) of every model of ``rr`` in ``models``, in drawing order."""
    return [(LABEL[m], scale * rr[m].columns[col], STYLE[m]) for m in ORDER if m in rr and m in models]


GAP_CASES = {"fourbar_hac": ("strain_coupler_mid", 0.15), "fourbar_constant_speed": ("strain_coupler_mid", 0.1),
             "manipulator_bricout": ("tip_dy_deflection", 0.15)}


@silenced()      # the report states each run's validity; its runs' warnings are not issued one by one
def reproduce(out_dir="reproduce", cases_dir=None, progress=None, models=MODELS, t_end=None, gap=True) -> Path:
    """Run the seed cases with every model, write figures, run folders and ``report.md`` into ``out_dir``
    (a :class:`~flexmech_py.run.outdir.ResultFolder`: the earlier report stays until the new one is whole).

    ``t_end`` (s) shortens every run (for quick checks); default: the case files' values.
    """
    if cases_dir is not None:     # every seed case there, before anything starts
        hint = f"give a folder holding {', '.join(n + '.toml' for n in SEED_CASES)} (or leave out --cases)"
        checked_folder(cases_dir, "--cases", "case files", hint)
        for name in SEED_CASES:
            checked_file(seed_case_path(name, cases_dir), "--cases", "case file", hint)
    with ResultFolder(out_dir, "reproduce") as rf:
        report = _reproduce_into(rf.stage, cases_dir, progress, models, t_end, gap)
        rf.commit()
    return rf.where(report)


def _reproduce_into(out: Path, cases_dir, progress, models, t_end, gap) -> Path:
    """What :func:`reproduce` writes, into ``out``."""

    say = progress or (lambda msg: None)
    runs, timings = {}, {}
    for name in SEED_CASES:
        path = seed_case_path(name, cases_dir)
        case = load_case(path, overrides=[f"solver.t_end={t_end}"] if t_end else None)
        missing = [c for c in NEEDED[name] if c not in case["outputs"]]
        if missing:
            raise CaseError("outputs", f"{path} lacks the outputs {', '.join(missing)} that the reproduced figures "
                                       "need; use the bundled case file or add them")
        t0 = time.perf_counter()
        runs[name] = simulate_models(case, list(models))
        timings[name] = time.perf_counter() - t0
        for m, r in runs[name].items():
            r.write(out / "runs" / f"{name}-{m}")
        say(f"{name}: {len(models)} models in {timings[name]:.2f} s")
    sup = [m for m in models if m in SUPERPOSITION_MODELS]
    dvec = {m: load_vector_difference(runs["fourbar_hac"], m, "classic") for m in sup if m != "classic"}
    figs = {**_fourbar_figures(out, runs["fourbar_hac"], sup, dvec), **_manipulator_figures(out, runs),
            **_coupled_figures(out, runs)}
    gap_lines = _gap_section(cases_dir, t_end, say) if gap else []
    gap_lines += modes_section(out, lambda n: seed_case_path(n, cases_dir), runs, say)
    report = out / "report.md"
    report.write_text(report_text(runs, figs, dvec, timings, models) + "\n".join(gap_lines) + "\n", encoding="utf-8")
    return report


def _fourbar_figures(out: Path, fb: dict, sup: list, dvec: dict) -> dict:
    """The seed's Figs. 2-8: the torque-driven four-bar, superposition models against the crank angle."""
    ang = np.degrees(fb["hac"].columns["crank_angle"])
    figs = {2: _sketch(out, "fig2_fourbar.png", fb["hac"], "Fig. 2: the four-bar at t = 0, flexmech's nodes "
                                                            "(2 elements per link) and lumped masses")}
    for fig, col, what in ((3, "strain_coupler_mid", "coupler"), (4, "strain_follower_mid", "follower")):
        figs[fig] = _fig(out, f"fig{fig}_{what}_strain.png",
                         [{"x": ang, "ylabel": f"{what} midspan strain [-]", "series": _series(fb, col, sup)}],
                         f"Fig. {fig}: {what} midspan bending strain, torque-driven four-bar\n"
                         f"(the models' curves coincide at this scale; their differences: Fig. {fig + 2})",
                         "crank angle [deg]")
    for fig, col, what in ((5, "strain_coupler_mid", "coupler"), (6, "strain_follower_mid", "follower")):
        ref = fb["classic"].columns[col]
        peak = float(np.max(np.abs(ref)))
        panels = [{"x": ang, "ylabel": "strain difference [-]",
                   "title": f"{LABEL[m]} minus case II: max {_rel_text(fb[m].columns[col] - ref, peak)}",
                   "series": [("", fb[m].columns[col] - ref, STYLE[m])]} for m in sup if m != "classic"]
        figs[fig] = _fig(out, f"fig{fig}_{what}_strain_difference.png", panels,
                         f"Fig. {fig}: difference in {what} midspan strain from case II (classic), one panel per "
                         "model\n(own scales; the peak strain is " + f"{peak:.3g})", "crank angle [deg]")
    comps = (("load_coupler_mid_x", "coupler midspan, X [N]"), ("load_coupler_mid_y", "coupler midspan, Y [N]"),
             ("load_norm", "norm over the free DOFs [N]"))
    figs[7] = _fig(out, "fig7_inertia_force.png",
                   [{"x": ang, "ylabel": lab, "series": _series(fb, c, sup)} for c, lab in comps if c in fb["hac"].columns],
                   "Fig. 7: rigid-inertia force F_c0 = M0 x0'' (case I) and F_c = M x0'' (case II); the curves coincide\n"
                   "(legends: the curves' differences, of the norms in the last panel; the norm of F_c - F_c0: Fig. 8)",
                   "crank angle [deg]")
    # Fig. 8: the difference vectors.  At interior nodes of equal elements the element
    # differences cancel (theory.md, section 4), so the joint components are shown.
    panels = [{"x": ang, "ylabel": "norm of F_c - F [N]",
               "series": [(f"{LABEL[m]}", dvec[m]["diff_norm"], STYLE[m]) for m in dvec]}]
    for col, c in (("load_joint_b_x", "X"), ("load_joint_b_y", "Y")):
        panels.append({"x": ang, "ylabel": f"joint B, {c} [N]",
                       "series": [(LABEL[m], fb["classic"].columns[col] - fb[m].columns[col], STYLE[m]) for m in dvec]})
    figs[8] = _fig(out, "fig8_inertia_force_difference.png", panels,
                   "Fig. 8: rigid-inertia force of case II (F_c) minus each other model's (F):\n"
                   "the norm over the free DOFs, and at joint B (at interior nodes the difference cancels)",
                   "crank angle [deg]")
    return figs


def _manipulator_figures(out: Path, runs: dict) -> dict:
    """The seed's Figs. 9-12 (the tip's elastic deflection in mm: from the rigid arm at each model's own joint
    angles, the same quantity in every model) and the constant-speed four-bar."""
    man = runs["manipulator_bricout"]
    figs = {9: _sketch(out, "fig9_manipulator.png", man["hac"], "Fig. 9: the two-link manipulator at t = 0, "
                                                                "flexmech's nodes, elbow mass and hub, payload")}
    for fig, name, col, what in ((10, "manipulator_bricout", "tip_dx_deflection", "X (horizontal), with payload"),
                                 (11, "manipulator_bricout", "tip_dy_deflection", "Y (vertical), with payload"),
                                 (12, "manipulator_bricout_no_payload", "tip_dy_deflection", "Y (vertical), no payload")):
        rr = runs[name]
        figs[fig] = _fig(out, f"fig{fig}_{name}_{col}.png",
                         [{"x": rr["hac"].t, "ylabel": f"elastic tip deflection {col[5].upper()} [mm]",
                           "series": _series(rr, col, scale=1e3)}],
                         f"Fig. {fig}: elastic deflection of the manipulator tip in {what}\n"
                         "(from the rigid arm at each model's own joint angles)", "t [s]")
    cs = runs["fourbar_constant_speed"]
    figs["cs"] = _fig(out, "fourbar_constant_speed_strains.png",
                      [{"x": cs["hac"].t, "ylabel": f"{what} midspan strain [-]", "series": _series(cs, col)}
                       for col, what in (("strain_coupler_mid", "coupler"), ("strain_follower_mid", "follower"))],
                      "Four-bar at constant crank speed: midspan strains", "t [s]")
    return figs


def _coupled_figures(out: Path, runs: dict) -> dict:
    """The one-pass coupled (and nonlinear) model's own rigid motion against the rigid-body solution."""
    fb = runs["fourbar_hac"]
    if "coupled" not in fb:
        return {}
    figs = {}
    own = [m for m in ("nonlinear", "coupled") if m in fb]
    rigid = [(LABEL["rigid"], fb["hac"].columns[c], STYLE["rigid"]) for c in ("crank_angle", "crank_speed")]
    figs["c1"] = _fig(out, "coupled_fourbar.png",
                      [{"x": fb["hac"].t, "ylabel": lab, "series": [rigid[k]] + _series(fb, c, own)}
                       for k, (c, lab) in enumerate((("crank_angle", "crank angle [rad]"),
                                                     ("crank_speed", "crank speed [rad/s]")))]
                      + [{"x": fb["hac"].t, "ylabel": f"{w} midspan strain [-]",
                          "series": _series(fb, c, ("hac", "classic", "nonlinear", "coupled"))}
                         for c, w in (("strain_coupler_mid", "coupler"), ("strain_follower_mid", "follower"))],
                      "Four-bar: the coupled model's own crank motion against the rigid-body solution", "t [s]")
    for key, name in (("c2", "manipulator_bricout"), ("c3", "manipulator_bricout_no_payload")):
        rr = runs[name]
        figs[key] = _fig(out, f"coupled_{name}.png",
                         [{"x": rr["hac"].t, "ylabel": f"{c} [rad]",
                           "series": [(LABEL["rigid"], rr["hac"].columns[c], STYLE["rigid"])] + _series(rr, c, own)}
                          for c in ("alpha", "beta")]
                         + [{"x": rr["hac"].t, "ylabel": f"tip deflection {c[5].upper()} [mm]",
                             "series": _series(rr, c, scale=1e3)} for c in ("tip_dx_deflection", "tip_dy_deflection")],
                         f"{name}: coupled and nonlinear models against the superposition models", "t [s]")
    return figs


def _sketch(out: Path, name: str, res, title: str):
    p = mechanism_sketch(out / name, res, title=title)
    return p.name if p is not None else None


def _rel_text(diff, peak: float) -> str:
    """max |diff| as a percentage of ``peak``, short."""
    return f"{100 * float(np.max(np.abs(diff))) / peak:.2g} % of the peak" if peak > 0 else "-"


def _gap_section(cases_dir, t_end, say) -> list[str]:
    lines = ["", "## The model gap: linear configurations against the nonlinear model", "",
             "Coupler midspan strain (four-bars) or the tip's Y deflection from the rigid arm at each model's own "
             "joint angles (manipulator), max |error| over "
             "[0, T] relative to the nonlinear model's peak there; 8 elements per link, the nonlinear "
             "reference 16.  K_σ: geometric stiffness source (theory.md §13); driven joints `torque`: left "
             "free in the elastic problem (§14).  Regenerate: `flexmech reproduce`.", ""]
    for name, (col, t_gap) in GAP_CASES.items():
        tg = min(t_gap, t_end) if t_end else t_gap
        case = load_case(seed_case_path(name, cases_dir), overrides=[f"solver.t_end={tg}"])
        windows = [w for w in (0.025, 0.05, 0.1, 0.15) if w <= tg + 1e-12] or [tg]
        t0 = time.perf_counter()
        study = gap_study(case, col, windows)
        say(f"model gap, {name}: {time.perf_counter() - t0:.1f} s")
        lines += gap_table(name, study)
    return lines
