"""``flexmech optimize`` (issue 28, item 4): the optimizer on a problem with a known optimum -- the
lightest height of a spinning-up bar that keeps its peak stress below a limit, in closed form --,
its cache, an infeasible problem (the least infeasible design, exit 4) and bad names."""

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

from flexmech_py.case import apply_overrides, read_case_file
from flexmech_py.mechanism.materials import MATERIALS
from flexmech_py.studies.optimize import EXIT_INFEASIBLE, optimize
from flexmech_py.studies.optimize_problem import Problem, design_point, parse_constraint, parse_vary, task_of

BEAM = Path(__file__).parent / "data" / "rotating_beam.toml"
FLEXMECH = [sys.executable, "-m", "flexmech_py"]
LIMIT = 16e6      # Pa
FAST = ["solver.output_every=10"]


def _closed_form_height(limit: float) -> float:
    """The height h at which the root's peak stress of the bar (rho A omega^2 L^2 / 2 axial, 2 rho |alpha| L^3 / h
    bending at the outer fibre, Simo and Vu-Quoc's spin-up to 20 rad/s in 1 s) reaches ``limit``."""
    rho, L, ws, T = MATERIALS["structural-steel"]["density"], 0.5, 20.0, 1.0
    t = np.linspace(0.0, 1.0, 100001)
    w = ws / T * (t - T / (2 * math.pi) * np.sin(2 * math.pi * t / T))
    al = ws / T * (1 - np.cos(2 * math.pi * t / T))
    peak = lambda h: np.max(rho * w ** 2 * L ** 2 / 2 + 2 * rho * al * L ** 3 / h)   # noqa: E731
    return brentq(lambda h: peak(h) - limit, 1e-4, 0.1, xtol=1e-12)


def _raw(extra=()):
    return apply_overrides(read_case_file(BEAM), FAST + list(extra))


def test_slsqp_finds_the_closed_form_height_of_a_stress_limit(tmp_path):
    h_star = _closed_form_height(LIMIT)
    problem = Problem([parse_vary("links.bar.section.height=2e-3:2e-2")], "mass",
                      [parse_constraint(f"peak_stress <= {LIMIT}")], "run", None, "goodman")
    r = optimize(problem, _raw(), "beam", executor=None, cache=tmp_path / "cache", maxiter=20)
    assert r["feasible"]
    h = r["optimum"]["links.bar.section.height"]
    assert h == pytest.approx(h_star, rel=0.01)            # the stress's mesh error is about 0.5 %
    c = r["constraints"][0]
    assert c["active"] and abs(c["value"] - LIMIT) < 2e-3 * LIMIT
    assert r["quantities"]["mass"] == pytest.approx(7850 * 0.01 * h * 0.5, rel=1e-9)
    # a repeated optimization takes every design from the cache
    again = optimize(problem, _raw(), "beam", executor=None, cache=tmp_path / "cache", maxiter=20)
    assert again["computed"] == 0 and again["optimum"] == r["optimum"]


def test_cli_optimize_writes_the_optimum_case_and_an_infeasible_problem_exits_4(tmp_path):
    out = tmp_path / "o"
    args = ["optimize", str(BEAM), "--vary", "links.bar.section.height=2e-3:2e-2", "--objective", "mass",
            "--constraint", "peak_stress <= 1e3", "--maxiter", "3", "--jobs", "1", "--out", str(out), "--no-plots"]
    args += [x for ov in FAST for x in ("--set", ov)]
    p = subprocess.run(FLEXMECH + args, capture_output=True, text=True)
    assert p.returncode == EXIT_INFEASIBLE, p.stderr
    assert "no feasible design" in p.stdout and "widen the bounds or relax a constraint" in p.stderr
    text = (out / "optimum.toml").read_text()
    assert text.startswith("# flexmech optimize: NO FEASIBLE DESIGN")
    info = json.loads((out / "optimize.json").read_text())
    assert not info["feasible"] and info["optimum"]["links.bar.section.height"] == pytest.approx(0.02)  # least stress
    assert (out / "iterations.csv").is_file() and (out / "evaluations.csv").is_file()


@pytest.mark.parametrize("args, words", [
    (["--objective", "weight"], "--objective: unknown quantity 'weight'; quantities are mass, peak_stress"),
    (["--objective", "mass", "--constraint", "stress < 3"], "--constraint: 'stress < 3' must be"),
    (["--objective", "mass", "--constraint", "bar.lifetime >= 3"], "unknown quantity 'bar.lifetime'"),
])
def test_bad_objective_or_constraint_lists_what_exists(tmp_path, args, words):
    p = subprocess.run(FLEXMECH + ["optimize", str(BEAM), "--vary", "links.bar.section.height=2e-3:2e-2",
                                   "--out", str(tmp_path / "o")] + args, capture_output=True, text=True)
    assert p.returncode == 2 and words in p.stderr and p.stderr.count("\n") == 1
    assert not (tmp_path / "o").exists()


def test_joint_loads_computed_only_when_a_quantity_needs_them():
    """A design's joint loads (a reaction solve per frame) are computed only when the objective or a constraint
    is a joint's max_load; the stresses do not depend on whether they are."""
    var = [parse_vary("links.bar.section.height=2e-3:2e-2")]
    plain = Problem(var, "mass", [parse_constraint(f"peak_stress <= {LIMIT}")], "run", None, "goodman")
    joint = Problem(var, "mass", [parse_constraint("base.max_load <= 1e4")], "run", None, "goodman")
    assert not plain.needs_joint_loads and joint.needs_joint_loads
    values = {"links.bar.section.height": 5e-3}
    q = {p is joint: design_point(task_of(_raw(["solver.t_end=0.1"]), "beam", values, p, None))["quantities"]
         for p in (plain, joint)}
    assert "base.max_load" not in q[False] and q[True]["base.max_load"] > 0
    assert q[False]["peak_stress"] == q[True]["peak_stress"]
