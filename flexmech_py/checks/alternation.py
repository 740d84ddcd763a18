"""The run's check for a period-2·dt oscillation: outputs that flip sign from step to step
(docs/stability.md, "Period-2·dt oscillation").  Such an oscillation is numerical, not physics: the
constraint multipliers of the coupled and nonlinear models under an integrator without numerical
dissipation (average acceleration leaves them undamped and lets them grow), or an elastic mode the
step does not resolve and the integrator does not damp.

:class:`AlternationCheck` is fed the run's blocks (:func:`flexmech_py.run.runner.execute`) and looks at
the steps, not only at the output frames: frames every few steps sample one phase of the oscillation
and show a smooth curve.  It reads

- the kernel's step-level watch of the multipliers (coupled and nonlinear models: a block's
  ``extra["step_alternation"]``, :func:`flexmech_py.models.constrained.outputs.multiplier_alternation`), which
  carries the reactions and drive forces (the watch starts again with every chunk of the run, so the
  first ALT_FLIPS steps of a chunk arm it and are not watched);
- every output column at the frames when the frames are the steps (``output_every = 1``); at a
  coarser output a frame-to-frame alternation may be the aliasing of a resolved vibration, so it is
  not read there.

A quantity alternates when its step-to-step change flips sign at ALT_FLIPS consecutive steps; its
alternating part is |y_n - 2 y_{n-1} + y_{n-2}| / 4.  Past ALT_WARN of the quantity's peak, and past
its round-off floor (:func:`roundoff_floors`), the run warns, naming the quantity, the cause and the
setting that removes it.
"""

from __future__ import annotations

import numpy as np

from ..base import notices
from ..case import integrator_coefficients, integrator_of

__all__ = ["AlternationCheck", "ALT_WARN", "ALT_FLIPS", "ROUNDOFF_ULPS", "dissipation", "roundoff_floors",
           "alternation_cause"]

#: alternating part, as a fraction of the quantity's peak, above which a run warns
ALT_WARN = 0.005
#: consecutive sign flips of a quantity's change that make an alternation (as fortran/flexmech_alternation.f90)
ALT_FLIPS = 20
SKIP_COLUMNS = ("newton_iterations",)
#: the round-off of a position in the time loops, in machine epsilons of the mechanism's size: the
#: Watt six-bar from rest (all forces ~1e-5 N) alternates at about 10 of them, the same at dt and dt/4
ROUNDOFF_ULPS = 100.0


def roundoff_floors(case, model: str, dt: float) -> dict:
    """{unit: the alternating part that round-off alone makes}, below which an alternation is not
    reported, whatever its share of the peak.  A step's positions carry a round-off
    delta = ROUNDOFF_ULPS eps L (L the mechanism's size); the time loop turns it into an acceleration
    delta c / dt^2 (c = (1 - alpha_m) / ((1 - alpha_f) beta), the integrator's coefficient of the new
    positions, theory.md section 15), and the multipliers balance it against the mechanism's mass m:
    a force m delta c / dt^2 [N], a moment that times L [N m], a length delta [m], an angle delta / L
    [rad].  It grows as 1/dt^2 like that round-off does, and stays far below a real oscillation (the
    trammel's drive force under average acceleration: 9e4 times it at dt = 1e-5 s, 2e4 at 5e-6 s)."""
    integ = integrator_of(case["solver"], model)
    am, af, beta, _ = integrator_coefficients(integ["integrator"], integ)
    mech = case.mechanism
    size = mech.characteristic_length()
    mass = sum(b.mass_properties()[0] for b in mech.bodies)
    delta = ROUNDOFF_ULPS * np.finfo(float).eps * size
    force = mass * delta * (1.0 - am) / ((1.0 - af) * beta * dt * dt)
    return {"N": force, "N m": force * size, "m": delta, "rad": delta / size}


def dissipation(sol: dict, model: str) -> float:
    """The integrator's spectral radius at infinite frequency, rho_inf (1: no numerical damping) for the
    solver table ``sol`` and ``model`` (docs/theory.md section 15.2)."""
    integ = integrator_of(sol, model)
    name = integ["integrator"]
    if name == "generalized-alpha":
        return float(integ["rho_inf"])
    if name == "hht":
        al = float(integ["hht_alpha"])
        return (1.0 - al) / (1.0 + al)
    gamma = float(integ.get("gamma", 0.5))
    return (1.5 - gamma) / (gamma + 0.5)


class _ColumnWatch:
    """Sign flips of every column's frame-to-frame change, carried across blocks: per column the last
    value and change, the current run of consecutive flips, and the largest alternating part seen
    while a run was at least ALT_FLIPS long (with its time)."""

    def __init__(self):
        self.last, self.change, self.flips = {}, {}, {}
        self.amp, self.t_at = {}, {}

    def add(self, t, columns: dict) -> None:
        t = np.asarray(t, float)
        for name, y in columns.items():
            if name not in SKIP_COLUMNS and np.size(y):
                self._scan(name, np.asarray(y, float), t)

    def _scan(self, name: str, y: np.ndarray, t: np.ndarray) -> None:
        y0, d0 = self.last.get(name), self.change.get(name)
        seq = y if y0 is None else np.r_[y0, y]
        tseq = t if y0 is None else np.r_[np.nan, t]
        d = np.diff(seq)
        self.last[name] = y[-1]
        if d.size == 0:
            return
        self.change[name] = d[-1]
        if d0 is None:                       # the first change has none before it
            cur, prv, first = d[1:], d[:-1], 2
        else:
            cur, prv, first = d, np.r_[d0, d[:-1]], 1
        if cur.size == 0:
            return
        flip = cur * prv < 0.0
        pos = np.arange(cur.size)
        last_break = np.maximum.accumulate(np.where(flip, -1, pos))
        run = np.where(last_break < 0, self.flips.get(name, 0) + pos + 1, pos - last_break)
        self.flips[name] = int(run[-1])
        part = np.where(run >= ALT_FLIPS, 0.25 * np.abs(cur - prv), 0.0)
        k = int(np.argmax(part))
        if part[k] > self.amp.get(name, 0.0):
            self.amp[name], self.t_at[name] = float(part[k]), float(tseq[k + first])


class AlternationCheck:
    """Fed every block of a run (``add``); ``finish(res)`` puts the ``alternation`` entry into the
    result's ``extra`` (summary.json) and a warning into its warnings when a quantity alternates past
    ALT_WARN of its peak."""

    def __init__(self, prep, model: str):
        self.model = model
        self.sol = prep.case["solver"]
        self.out_every = int(prep.out_every)
        self.dt = float(prep.dt)
        self.floors = roundoff_floors(prep.case, model, self.dt)
        self.rows: dict = {}
        self.columns: dict = {}
        self.frames = _ColumnWatch() if self.out_every == 1 else None

    def add(self, block) -> None:
        if block.t.size == 0:
            return
        step = block.extra.get("step_alternation")
        if step is not None:
            self.columns.update(step["columns"])
            for key, r in step["rows"].items():
                old = self.rows.get(key)
                if old is None:
                    self.rows[key] = dict(r)
                    continue
                if r["amplitude"] > old["amplitude"]:
                    old.update(amplitude=r["amplitude"], t=r["t"])
                old["peak"] = max(old["peak"], r["peak"])
        if self.frames is not None:
            self.frames.add(block.t, block.columns)

    def finish(self, res) -> dict:
        """The ``alternation`` entry of the finished run (also into ``res.extra``): what was checked,
        the threshold, rho_inf, every quantity past it (``found``, the worst first) and the largest
        alternating part seen (``largest``, past the threshold or not)."""
        rows = self._rows_seen()
        on_rows = {c for f in rows for c in f["columns"]}        # a column seen through its multipliers
        seen = rows + [f for f in self._columns_seen(res) if f["columns"][0] not in on_rows]
        seen.sort(key=lambda f: -f["relative"])
        found = [f for f in seen if f["relative"] > ALT_WARN and f["amplitude"] > self.floors.get(f["unit"], 0.0)]
        rho = dissipation(self.sol, self.model)
        checked = [what for what, on in (("the multipliers at every step", bool(self.rows)),
                                         ("every output at every step", self.frames is not None)) if on]
        out = {"checked": " and ".join(checked) or "nothing (no multipliers, and frames every > 1 step)",
               "threshold": ALT_WARN, "roundoff_floor": self.floors, "rho_inf": rho, "found": found,
               "largest": ({k: seen[0][k] for k in ("quantity", "relative", "t_s")} if seen else None)}
        if found:
            out["warning"] = _warning(found, rho, self.model, self.dt)
            notices.add(res.extra, out["warning"], "accuracy")
        res.extra["alternation"] = out
        return out

    def _rows_seen(self) -> list:
        out = []
        for key, r in self.rows.items():
            if r["peak"] > 0.0 and r["amplitude"] > 0.0:
                role = key.rsplit(".", 1)[1]
                out.append({"quantity": f"the {_ROLE_WORDS.get((role, r['unit']), role)} of joint {r['joint']}",
                            "joint": r["joint"], "amplitude": r["amplitude"], "unit": r["unit"],
                            "relative": r["amplitude"] / r["peak"], "t_s": r["t"],
                            "columns": sorted(c for c, j in self.columns.items() if j == r["joint"])})
        return out

    def _columns_seen(self, res) -> list:
        if self.frames is None:
            return []
        stats, out = res.all_stats().columns, []
        for name, amp in self.frames.amp.items():
            peak = stats.get(name, {}).get("peak_abs", 0.0)
            if peak > 0.0 and amp > 0.0:
                out.append({"quantity": f"output {name}", "joint": None, "amplitude": amp,
                            "unit": res.units.get(name, ""), "relative": amp / peak, "t_s": self.frames.t_at[name],
                            "columns": [name]})
        return out


#: words for a multiplier row by (role, unit) (flexmech_py.models.constrained.layout: the rows of a joint)
_ROLE_WORDS = {("drive", "N"): "drive force", ("drive", "N m"): "drive torque", ("x", "N"): "reaction x",
               ("y", "N"): "reaction y", ("normal", "N"): "guide normal force", ("angle", "N m"): "reaction moment",
               ("hold", "N"): "holding force", ("hold", "N m"): "holding torque"}


def alternation_cause(res, name: str) -> dict | None:
    """For the step-doubling warning (flexmech_py.checks.step_doubling): when output ``name`` is among the ones
    this run found alternating, its step-doubling difference measures that oscillation, not a time-step
    error; the cause to name instead (None otherwise)."""
    for f in res.extra.get("alternation", {}).get("found", []):
        if name in f["columns"]:
            return {"cause": "alternation",
                    "message": f"{name} flips sign from step to step (see the period-2·dt warning), so its step-doubling "
                               "difference measures that numerical oscillation, not a time-step error; remove the "
                               "oscillation first"}
    return None


def _fmt(x: float, unit: str) -> str:
    return f"{x:.3g} {unit}".strip()


def _more_dissipation(rho: float) -> str:
    """The fix of a period-2 dt oscillation the integrator's dissipation rho_inf damps too slowly."""
    if rho <= 0.05:
        return "a smaller solver.dt (the integrator's dissipation is already the largest)"
    return (f"more dissipation, --integrator generalized-alpha --rho-inf {max(0.0, min(0.5, round(rho - 0.3, 1))):g}, "
            "or a smaller solver.dt")


def _warning(found: list, rho: float, model: str, dt: float) -> str:
    """One line: the worst alternating quantity, its size, the cause and the fix."""
    f = found[0]
    what = f["quantity"] + (f" (output {', '.join(f['columns'])})" if f["columns"] and f["joint"] else "")
    more = f" and {len(found) - 1} more quantities" if len(found) > 1 else ""
    head = (f"period-2·dt oscillation: {what}{more} flip{'' if more else 's'} sign at every step, alternating part "
            f"{_fmt(f['amplitude'], f['unit'])} = {100 * f['relative']:.3g} % of its peak (largest at t = "
            f"{f['t_s']:.6g} s); this is numerical, not physics: ")
    if f["joint"] is not None and rho >= 0.999:
        cause = (f"the integrator has no numerical dissipation (rho_inf = {rho:.3g}), and under it the {model} "
                 "model's constraint multipliers (reactions, drive forces) are undamped: their error grows with "
                 "time whatever the step")
        fix = "--integrator generalized-alpha --rho-inf 0.8 (the default of the coupled and nonlinear models)"
    elif f["joint"] is not None:
        cause = (f"the integrator's numerical dissipation (rho_inf = {rho:.3g}) is too weak for the constraint "
                 f"multipliers' period-2·dt oscillation, which an elastic mode the step dt = {dt:.3g} s does not "
                 "resolve, or a sudden load, keeps exciting")
        fix = _more_dissipation(rho)
    elif rho >= 0.999:
        cause = (f"an elastic mode the step dt = {dt:.3g} s does not resolve rings undamped "
                 f"(rho_inf = {rho:.3g}: no numerical dissipation)")
        fix = "numerical dissipation, --integrator generalized-alpha --rho-inf 0.5, or a smaller solver.dt"
    else:
        cause = (f"an elastic mode the step dt = {dt:.3g} s does not resolve is damped too slowly "
                 f"(rho_inf = {rho:.3g})")
        fix = _more_dissipation(rho)
    return head + cause + "; rerun with " + fix
