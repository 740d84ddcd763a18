"""The error budget of a run (``solver.error_estimate``; docs/theory.md section 21): for every output
column, its time-step, mesh and model error as fractions of its peak, made beside the run.

- time: step doubling (:mod:`flexmech_py.checks.step_doubling`: the run's model at 2 dt, S);
- mesh: the run's model on the probe mesh (half, or twice, the elements) at 2 dt against S, Richardson
  with the strain's order (:mod:`flexmech_py.checks.mesh_error`);
- model: the run's model against the exact ``nonlinear`` model, both at 16 dt on the probe mesh when it
  is coarser and keeps 2 elements per link, else on the run's (:mod:`flexmech_py.checks.model_error`; zero for
  the nonlinear model itself).

The probes (:class:`~flexmech_py.checks.probes.Probe`) advance block by block beside the run and take the
run's rigid motion from it (:mod:`flexmech_py.models.motion_tap`), so a run of any length still holds one
chunk.  Past ``solver.tolerance`` a warning names the worst column (never a negligible one,
:mod:`flexmech_py.checks.scales`), the part that dominates and the setting that cuts it.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from . import mesh_error, model_error, scales, step_doubling
from ..base import notices
from .budget_text import budget_warning, unchecked_model_warning
from ..case import SUPERPOSITION_MODELS, Case
from ..base.errors import CaseError
from .probes import SKIP_COLUMNS, Matcher, Probe

__all__ = ["ErrorBudget", "ProbeGrids", "PARTS", "TOLERANCE", "MESH_STEP", "MODEL_STEP", "parts_of", "probe_plan"]

PARTS = ("time", "mesh", "model")
#: default solver.tolerance: the error, as a fraction of each output's peak, a run should stay within
#: (5 %: the step-doubling warning's threshold since before the budget; docs/cases.md "[solver]")
TOLERANCE = 0.05
#: the mesh probe's step over the run's: that of the step-doubling run, so that their difference is
#: the mesh's alone (at 4 dt the probe's larger time error had to be removed with the step-doubling
#: difference, which fails where the time error is not asymptotic: undamped axial ringing)
MESH_STEP = 2
#: the model probes' step over the run's (most): the exact model's steps cost about ten times a
#: superposition model's, and model differences change by less than 15 % from dt to 16 dt on the cases
#: measured (docs/validation.md "Error budget")
MODEL_STEP = 16
#: the mesh probe is compared at every PROBE_THIN-th frame of the step-doubling run (outputs cost per frame)
PROBE_THIN = 2
#: fewest elements per flexible link of the model probes' mesh (the probe mesh, or the run's when halving
#: leaves fewer): with one element per link the model difference is half the true one on the six-bar
MODEL_MIN_ELEMENTS = 2


def parts_of(setting: str) -> tuple:
    """The parts a ``solver.error_estimate`` value switches on: "all", "none", or parts joined by "+"."""
    if setting == "all":
        return PARTS
    if setting == "none":
        return ()
    return tuple(p for p in PARTS if p in setting.split("+"))


#: the exact model's probe integrates with generalized-alpha and this spectral radius (at 16 dt its
#: constraint forces carry an undamped 2-step oscillation under average acceleration)
REFERENCE_RHO_INF = 0.8


@dataclass
class ProbeGrids:
    """Where the probes run: ``mesh`` the probe mesh (element lengths ``ratio`` times the run's) at
    MESH_STEP dt; ``model`` the coarser of that mesh and the run's at ``model_step`` dt, and
    ``reference`` the same grid with the exact model's integrator."""

    mesh: object
    model: object
    reference: object
    ratio: float
    model_step: int

    def grid_of(self, model: str):
        """The model grid a model's probe runs on."""
        return self.reference if model_error.is_reference(model) else self.model


def _coarser(prep, times: int):
    """``prep`` on every 2^times-th step (fewer when the run has too few steps), and that ratio."""
    out, k = prep, 1
    for _ in range(times):
        nxt = out.coarsened()
        if nxt is None:
            break
        out, k = nxt, 2 * k
    return out, k


def _probe_mesh(p2):
    """(the case at 2 dt on the probe mesh, r) or (None, why not)."""
    for coarser in (True, False):
        elements, ratio = mesh_error.probe_elements(p2.case, coarser)
        if not elements:
            return None, "the mechanism has no flexible link"
        mesh = p2.remeshed(mesh_error.remesh(p2.case, elements))
        if not mesh.case["outputs"]:
            return None, "no output has a mesh limit (rigid-inertia loads only)"
        try:
            mesh.fe                      # the outputs' mesh points must be nodes of the probe mesh
        except CaseError:
            continue
        return mesh, ratio
    return None, "no probe mesh keeps the outputs' points on nodes"


def probe_plan(prep):
    """(:class:`ProbeGrids`, '') of a run, or (None, why not).  The probe mesh halves every flexible
    link's elements where all have an even number and the outputs' mesh points stay nodes, else doubles
    them; the probes' frames fall on the run's frames."""
    p2 = prep.coarsened()
    if p2 is None:
        return None, "too few steps for a run at 2 dt"
    mesh, ratio = _probe_mesh(p2)
    if mesh is None:
        return None, ratio
    own = {ln["name"]: ln["elements"] for ln in p2.case["links"] if not ln.get("rigid")}
    halved = ratio > 1 and min(ln["elements"] for ln in mesh.case["links"] if not ln.get("rigid")) >= MODEL_MIN_ELEMENTS
    model_case = mesh.case if halved else mesh_error.remesh(p2.case, own)
    model, k = _coarser(p2.remeshed(model_case), int(math.log2(MODEL_STEP)) - 1)
    return ProbeGrids(mesh.thinned(PROBE_THIN), model, model.remeshed(_dissipative(model.case)), ratio, 2 * k), ""


def _dissipative(case):
    """``case`` with generalized-alpha (REFERENCE_RHO_INF) when it names average acceleration (a case that
    names no integrator runs the exact model with its family's default, generalized-alpha)."""
    sol = case["solver"]
    if sol.get("integrator", "default") != "newmark" or sol.get("gamma", 0.5) > 0.5:
        return case
    solver = {k: v for k, v in sol.items() if k not in ("beta", "gamma")}
    return Case(case, solver=dict(solver, integrator="generalized-alpha", rho_inf=REFERENCE_RHO_INF))


class ErrorBudget:
    """The budget of one run of ``model`` (see the module's docstring): :meth:`add` every block of the
    run, then :meth:`finish`.  ``made``: {"grids": ProbeGrids, "probes": {(model, geometric, ratio):
    Probe}} made before the run (by ``model = "auto"``), replayed instead of made again when they kept
    their frames."""

    def __init__(self, prep, model: str, geometric, parts, tolerance: float = TOLERANCE, made=None):
        self.prep, self.model, self.parts, self.tolerance = prep, model, tuple(parts), float(tolerance)
        self.geometric = geometric if geometric is not None else prep.case["solver"]["geometric_stiffness"]
        if model not in SUPERPOSITION_MODELS:
            self.geometric = None
        self.cpu_s = 0.0
        c0 = time.process_time()
        self.sd = step_doubling.StepDoubling(prep, model, geometric) if "time" in self.parts else None
        if self.sd is not None and self.sd.pc is not None:
            prep.share_motion(self.sd.pc, 2)
        self.matcher = Matcher(["run", "S"])
        self.probes: dict = {}           # role (P: mesh, M: model's own, R: reference) -> Probe
        self.grids, self.why_no_probe, self.reference = None, "", None
        self.diff = {"mesh": {}, "model": {}}
        self.t_at = {"mesh": {}, "model": {}}
        if "mesh" in self.parts or "model" in self.parts:
            self._setup_probes(made or {})
        self.cpu_s += time.process_time() - c0

    # ------------------------------------------------------------------ set-up
    def _setup_probes(self, made: dict) -> None:
        grids, why = (made["grids"], "") if made.get("grids") else probe_plan(self.prep)
        if grids is None:
            self.why_no_probe = why
            return
        self.grids, given = grids, made.get("probes", {})
        self.every = MESH_STEP * grids.mesh.out_every             # the mesh probe's frames, in run steps
        if "mesh" in self.parts:
            self.probes["P"] = self._probe(given, grids.mesh, self.model, self.geometric, MESH_STEP)
        if "model" in self.parts and not model_error.is_reference(self.model):
            k = grids.model_step
            self.reference = model_error.label(*model_error.EXACT)
            self.probes["M"] = self._probe(given, grids.model, self.model, self.geometric, k)
            self.probes["R"] = self._probe(given, grids.reference, *model_error.EXACT, k)
        for role, p in self.probes.items():
            self.matcher.attach(role, p)
        for p in self.probes.values():
            if not p.done and p.prep.tap is None:
                self.prep.share_motion(p.prep, p.ratio)
        if self.sd is not None and self.sd.cmp is not None and "P" in self.probes:
            self.sd.cmp.observers.append(self._take_coarse)

    def _probe(self, given: dict, grid, model, geometric, k: int) -> Probe:
        made = given.get((model, geometric, k))
        again = made.replay() if made is not None else None
        return again or Probe(grid, model, geometric, k, model_error.label(model, geometric))

    def _take_coarse(self, steps, t, columns) -> None:
        self.matcher.buffers["S"].add(steps, t, columns, self.every)

    @property
    def _with_s(self) -> bool:
        return self.sd is not None and self.sd.cmp is not None

    # ------------------------------------------------------------------ while the run goes
    def add(self, block) -> None:
        c0 = time.process_time()
        if self.sd is not None:
            self.sd.add(block)
        if self.probes and block.t.size:
            self.matcher.buffers["run"].add(block.steps, block.t, block.columns, self.every)
            last = int(block.steps[-1])
            for p in set(self.probes.values()):
                p.advance_to(last)
            self._match(finished=False)
        self.cpu_s += time.process_time() - c0

    def _match(self, finished: bool) -> None:
        m = self.matcher
        if "P" in self.probes:
            ref = "S" if self._with_s else "run"          # the run at 2 dt, or (no step doubling) the run
            _, t, f = m.common([ref, "P"])
            for col, p in f["P"].items():
                if t.size and col in f[ref]:
                    self._keep_max("mesh", col, np.abs(f[ref][col] - p), t)
        if "R" in self.probes:
            _, t, f = m.common(["M", "R"])
            for col, p in f["M"].items():
                if t.size and col in f["R"]:
                    self._keep_max("model", col, np.abs(p - f["R"][col]), t)
        pushed = m.buffers["run"].last
        if self._with_s and not self.sd.cmp.done:
            pushed = min(pushed, m.buffers["S"].last)
        m.release(pushed, finished)

    def _keep_max(self, part: str, col: str, d: np.ndarray, t: np.ndarray) -> None:
        k = int(np.argmax(d))
        if not (self.diff[part].get(col, -1.0) >= d[k]):
            self.diff[part][col], self.t_at[part][col] = float(d[k]), float(t[k])

    # ------------------------------------------------------------------ the end
    def finish(self, res) -> tuple[dict, dict]:
        """(the step-doubling ``error_estimate`` entry, the ``error_budget`` entry) of the finished run."""
        c0 = time.process_time()
        est = self.sd.finish(res) if self.sd is not None else {"method": "none"}
        if self.probes:
            for p in set(self.probes.values()):
                p.run_to_end()
            self._match(finished=True)
        self.cpu_s += time.process_time() - c0
        return est, self._summary(res, est)

    def _summary(self, res, est: dict) -> dict:
        stats = res.all_stats().columns
        names = [n for n in res.columns if n not in SKIP_COLUMNS]
        peaks = {n: stats[n]["peak_abs"] for n in names}
        tiny = scales.negligible(res.case, res.units, peaks)
        cols = {n: self._column(n, peaks[n], est, tiny.get(n, "")) for n in names}
        ranked = [n for n in names if n not in tiny and math.isfinite(cols[n]["total"])]
        worst = max(ranked, key=lambda n: cols[n]["total"], default=None)
        out = {"parts": list(self.parts), "tolerance": self.tolerance, "order_mesh": mesh_error.MESH_ORDER,
               "probes": self._probe_summary(), "columns": cols, "worst_column": worst,
               "worst_total": cols[worst]["total"] if worst else None, "cpu_s": self.cpu_s}
        warn = budget_warning(out, est, self.prep, self.model, self.geometric)
        if warn is not None:
            out["warning"] = warn
            notices.add(res.extra, warn["message"], "accuracy")
        unchecked = unchecked_model_warning(out, float(res.t[-1]), self.model)
        if unchecked is not None:
            out["model_unchecked"] = unchecked
            notices.add(res.extra, unchecked, "accuracy")
        return out

    def _column(self, name: str, peak: float, est: dict, tiny: str) -> dict:
        spec = self.prep.case["outputs"].get(name)
        c, notes = {}, {}
        tc = est.get("columns", {}).get(name)
        c["time"] = tc["relative"] if tc is not None else None
        if "time" in self.parts and tc is None:
            notes["time"] = est.get("reason") or est.get("failed") or "not estimated"
        c["mesh"], notes["mesh"] = self._mesh(name, spec, peak)
        c["model"], notes["model"] = self._model(name, spec, peak)
        parts = {k: v for k, v in c.items() if v is not None}
        c["total"] = float(sum(parts.values())) if parts else float("nan")
        c["dominant"] = max(parts, key=parts.get) if parts and c["total"] > 0 else None
        c["lower_bound"] = [k for k in ("mesh", "model") if c[k] is not None and notes[k]]
        if tiny:
            c["negligible"] = tiny
        c["notes"] = {k: v for k, v in notes.items() if v}
        return c

    def _mesh(self, name, spec, peak):
        if "mesh" not in self.parts:
            return None, ""
        if "P" not in self.probes:
            return None, self.why_no_probe
        if spec is not None and spec["kind"] in mesh_error.NOT_CONVERGING:
            return None, "a nodal load of the mesh has no mesh limit (it scales with the element length)"
        d = self.diff["mesh"].get(name)
        partial = self._partial(["P"])
        if d is None:
            return None, partial or "not compared"
        return (mesh_error.spatial_error(d, self.grids.ratio) / peak if peak > 0 else 0.0), partial

    def _model(self, name, spec, peak):
        if "model" not in self.parts:
            return None, ""
        if model_error.is_reference(self.model):
            return 0.0, ""
        if "R" not in self.probes:
            return None, self.why_no_probe
        why = model_error.comparable(name, self.prep.case, self.model, self.prep.setup.mode == "dynamic")
        if why:
            return None, why
        d = self.diff["model"].get(name)
        partial = self._partial(["M", "R"])
        if d is None:
            return None, partial or f"{self.reference} has no such column"
        return (d / peak if peak > 0 else 0.0), partial

    def _partial(self, roles) -> str:
        """Why a part covers only the start of the run (a probe stopped), else ''."""
        for role in roles:
            p = self.probes[role]
            if p.stopped_at is not None:
                return (f"a lower bound, over [0, {p.stopped_at:.4g}] s only: the probe run of {p.label} stopped "
                        f"there ({p.reason})")
            if p.reason:
                return f"the probe run of {p.label} could not run ({p.reason})"
        if "P" in roles and self._with_s and self.sd.cmp.failed is not None:
            return "over the frames before the run at 2 dt stopped only"
        return ""

    def _probe_summary(self) -> dict:
        if self.grids is None:
            return {"made": False, "reason": self.why_no_probe}
        els = {ln["name"]: ln["elements"] for ln in self.grids.mesh.case["links"] if not ln.get("rigid")}
        out = {"made": True, "elements": els, "element_length_ratio": self.grids.ratio, "runs": []}
        for role, what in (("P", "mesh"), ("M", "model"), ("R", "reference")):
            p = self.probes.get(role)
            if p is not None:
                out["runs"].append({"role": what, "model": p.label, "dt": p.prep.dt, "cpu_s": p.cpu_s,
                                    "elements": sorted({ln["elements"] for ln in p.prep.case["links"]
                                                        if not ln.get("rigid")}), "stopped_at_s": p.stopped_at})
        if self.reference:
            out["reference"] = self.reference
        return out
