"""Results of a run: arrays, summary, and the files a run writes (CSV, JSON).

Files (``docs/cli.md``):

- ``timeseries.csv``: two ``#`` comment lines (provenance; units per column),
  then a header ``t,<output names>`` and one row per output frame.  A run that
  stopped (partial result) has a third comment line ``# partial: ...`` first.
- ``summary.json``: status, peaks, final values, steps, DOFs, timings, validity,
  warnings, error estimate, versions and the fully resolved input.

Files are written to a temporary name and renamed, so a failed run never
leaves a half-written file behind.
"""

from __future__ import annotations

import json
import os
import platform
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["Result", "read_timeseries", "versions"]


def versions() -> dict:
    import scipy

    from . import __version__

    return {"flexmech": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "platform": platform.platform()}


@dataclass
class Result:
    """One run.  ``t`` (nf,) frame times [s]; ``columns[name]`` (nf,) outputs; ``u, v, a`` (ndof, nf)
    elastic displacements, velocities, accelerations over all DOFs (zeros at constrained DOFs);
    ``q, qd, qdd`` (nf, ndof_rigid) rigid generalized coordinates."""

    case: dict
    model: str
    t: np.ndarray
    columns: dict
    units: dict
    fe: object
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    u: np.ndarray
    v: np.ndarray
    a: np.ndarray
    rig: np.ndarray   # (5, nlinks, nf) rigid samples at the frames (kernel layout), e.g. for fe.loads(rig, model)
    nsteps: int
    dt: float
    timing: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)   # model-specific summary entries (e.g. the coupled model's)
    axial: np.ndarray | None = None             # (nel, nf) element axial forces [N], tension > 0
    curvature: object = field(default=None, repr=False)   # callable(link, fraction) -> (nf,) curvature [1/m]
    failure: dict | None = None                 # set when the run stopped: a partial result (guards.failed)
    motion: object = field(default=None, repr=False)   # LinkMotion of the rigid-body solution at the frames

    @property
    def status(self) -> str:
        """``"completed"``, or ``"failed"`` for the partial result of a run that stopped."""
        return "failed" if self.failure else "completed"

    def __getitem__(self, name: str) -> np.ndarray:
        if name == "t":
            return self.t
        return self.columns[name]

    # ------------------------------------------------------------------ summary
    def summary(self) -> dict:
        outs = {}
        for name, y in self.columns.items():
            i = int(np.argmax(np.abs(y)))
            outs[name] = {"unit": self.units[name], "min": float(y.min()), "max": float(y.max()),
                          "peak_abs": float(abs(y[i])), "t_peak_abs": float(self.t[i]), "final": float(y[-1])}
        fe = self.fe
        fail = {"failed_at_s": self.failure["time_s"], "failure": self.failure} if self.failure else {}
        return {
            "title": self.case["case"]["title"],
            "status": self.status,
            **fail,
            "model": self.model,
            "steps": self.nsteps,
            "dt": self.dt,
            "frames": int(self.t.size),
            "t_end": float(self.t[-1]),
            "dofs": {"all": fe.ndof, "free": fe.nfree, "half_bandwidth": fe.bandwidth, "elements": fe.nel},
            "wall_time_s": {k: round(v, 6) for k, v in self.timing.items()},
            "outputs": outs,
            **self.extra,
            "versions": versions(),
            "input": self.case,
        }

    def table(self) -> str:
        """A short human-readable table of the outputs."""
        s = self.summary()
        w = max(len(n) for n in self.columns) if self.columns else 4
        lines = [f"{s['title']}  [model {self.model}]",
                 f"{s['steps']} steps of {self.dt:.4g} s, {s['dofs']['free']} free DOFs "
                 f"(half bandwidth {s['dofs']['half_bandwidth']}); kernel {self.timing.get('kernel_s', 0):.3f} s, "
                 f"total {self.timing.get('total_s', 0):.3f} s",
                 f"{'output':<{w}}  {'unit':<7} {'min':>12} {'max':>12} {'final':>12}"]
        for name, o in s["outputs"].items():
            lines.append(f"{name:<{w}}  {o['unit']:<7} {o['min']:>12.5g} {o['max']:>12.5g} {o['final']:>12.5g}")
        if self.failure:
            lines.insert(1, f"PARTIAL: the run stopped at t = {self.failure['time_s']:.6g} s; frames up to "
                            f"t = {self.t[-1]:.6g} s")
        return "\n".join(lines + self._assembly_lines() + self._validity_lines() + self._estimate_lines())

    def _assembly_lines(self) -> list[str]:
        mech = self.extra.get("mechanism")
        if not mech or mech["assembly"]["max_moved_m"] <= 0.0:
            return []
        a = mech["assembly"]
        return [f"assembly: the loops were closed from the drawn configuration; points moved by up to "
                f"{a['max_moved_m']:.3g} m ({a['point']}; all in summary.json, mechanism.assembly)"]

    def _validity_lines(self) -> list[str]:
        val, ov = self.extra.get("validity"), self.extra.get("validity_overall")
        if not val or not ov:
            return []
        th = ov["thresholds"]
        lines = [f"validity (limits: deflection {100 * th['deflection_over_length']:g} % of L, compression "
                 f"{th['compression_over_euler']:g} x Euler load, yield strain if given)",
                 f"{'link':<12} {'deflection/L':>12} {'max strain':>11} {'compr./Euler':>12}  first past a limit [s]"]
        for name, v in list(val.items()) + [("overall", None)]:
            if v is None:
                d, e, c = ov["max_deflection_over_length"], ov["max_strain"], ov["max_compression_over_euler"]
                first = ov["valid_until_s"]
            else:
                d, e, c = v["max_deflection_over_length"], v["max_strain"], v["max_compression_over_euler"]
                times = [x for x in (v.get("deflection_exceeds_at_s"), v.get("compression_exceeds_at_s"),
                                     v.get("strain_exceeds_yield_at_s")) if x is not None]
                first = min(times) if times else None
            lines.append(f"{name:<12} {100 * d:>11.3g}% {e:>11.3g} {c:>12.3g}  {'-' if first is None else f'{first:.4g}'}")
        return lines

    def _estimate_lines(self) -> list[str]:
        est = self.extra.get("error_estimate")
        if not est or est.get("method") == "none":
            return []
        if est.get("failed"):
            return [f"error estimate (step doubling): {est['failed']}"]
        if not est.get("worst_column"):
            return []
        w = est["worst_column"]
        return [f"time-step error estimate (step doubling, dt vs 2 dt): largest in {w}, "
                f"{est['columns'][w]['max_abs']:.3g}{'' if self.units.get(w, '1') == '1' else ' ' + self.units[w]} = "
                f"{100 * est['worst_relative']:.3g} % "
                f"of its peak (extra run {est.get('kernel_s', 0):.3f} s)"]

    # ------------------------------------------------------------------ files
    def write(self, out_dir) -> list[Path]:
        """Write timeseries.csv and summary.json into out_dir (created); returns the paths."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        names = list(self.columns)
        data = np.column_stack([self.t] + [self.columns[n] for n in names])
        head = ([f"# partial: the run stopped at t = {self.failure['time_s']:.6g} s; frames up to t = {self.t[-1]:.6g} s "
                 f"only ({self.failure.get('message', '')})"] if self.failure else [])
        head += [f"# flexmech {versions()['flexmech']}; case {self.case['case']['title']!r}; model {self.model}; "
                f"dt {self.dt:.6g} s; {self.nsteps} steps",
                "# units: " + ",".join(["s"] + [self.units[n] for n in names]),
                ",".join(["t"] + names)]
        paths = []
        csv = out / "timeseries.csv"
        _atomic_write(csv, "\n".join(head) + "\n" + "\n".join(",".join(f"{x:.10g}" for x in row) for row in data) + "\n")
        paths.append(csv)
        js = out / "summary.json"
        _atomic_write(js, json.dumps(self.summary(), indent=2, default=_json_default) + "\n")
        paths.append(js)
        return paths


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o))


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def read_timeseries(path) -> tuple[dict, dict]:
    """Read a timeseries.csv written by flexmech: returns ({name: array}, {name: unit})."""
    lines = Path(path).read_text(encoding="utf-8").splitlines()
    units, body = [], []
    for line in lines:
        if line.startswith("# units:"):
            units = line.split(":", 1)[1].strip().split(",")
        elif line and not line.startswith("#"):
            body.append(line)
    if not body:
        raise ValueError(f"{path}: no header line")
    header = body[0].split(",")
    data = np.array([[float(x) for x in row.split(",")] for row in body[1:]]).reshape(-1, len(header))
    return {n: data[:, i] for i, n in enumerate(header)}, dict(zip(header, units))
