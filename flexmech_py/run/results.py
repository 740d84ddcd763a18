"""Results of a run: arrays, summary, and the files a run writes (CSV, JSON).

Files (``docs/cli.md``):

- ``timeseries.csv``: three ``#`` comment lines (the run's status: ``# complete: N frames``,
  ``# partial: the run stopped at ...`` or, while a run writes it as ``timeseries.csv.part``,
  ``# running: ...``, padded to STATUS_BYTES; provenance; units per column), then a header
  ``t,<output names>`` and one row per output frame.
- ``summary.json``: status, peaks, final values, steps, DOFs, timings, validity,
  warnings, error estimate, versions and the fully resolved input.

Files are written to a temporary name and renamed, so a failed run never
leaves a half-written file under the final name.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..checks.budget_text import budget_lines, choice_lines
from ..base.fileio import atomic_write, json_default
from ..base.version import versions
from .frames import ColumnStats

__all__ = ["Result", "TimeseriesWriter", "read_timeseries", "versions"]


@dataclass
class Result:
    """One run, or one block of a run's frames.  ``t`` (nf,) frame times [s]; ``columns[name]`` (nf,)
    outputs; ``u, v, a`` (ndof, nf) elastic displacements, velocities, accelerations over all DOFs
    (zeros at constrained DOFs); ``q, qd, qdd`` (nf, ndof_rigid) rigid generalized coordinates (the
    superposition models: the rigid-body solution's; the coupled and nonlinear models: their own, as
    their ``joint_*`` outputs measure them).

    A run streamed to files (:class:`flexmech_py.run.runner.FileSink`) keeps only its last block's frames
    here; ``stats`` (:class:`~flexmech_py.run.frames.ColumnStats`) then describes every frame and
    ``envelope`` holds the frames to draw (:meth:`plot_view`)."""

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
    failure: dict | None = None                 # set when the run stopped: a partial result (guards.failed)
    motion: object = field(default=None, repr=False)   # LinkMotion of the rigid-body solution at the frames
    rigid: object = field(default=None, repr=False)    # RigidMotion (the rigid-body solution) at the frames
    steps: np.ndarray | None = None             # (nf,) step number of each frame on the run's time grid
    state: np.ndarray | None = field(default=None, repr=False)   # (n, nf) the model's own coordinates (coupled: q)
    curvature_of: object = field(default=None, repr=False)       # f(result, link, fraction) -> (nf,) curvature [1/m]
    node_curvatures_of: object = field(default=None, repr=False)  # f(result, link) -> (n+1, nf) at its nodes (optional)
    reactions: object = field(default=None, repr=False)          # superposition: joint -> (nf, 3) model reactions
    stats: object = field(default=None, repr=False)              # ColumnStats over every frame of the run
    envelope: object = field(default=None, repr=False)           # Envelope: the frames to draw of a streamed run

    @property
    def status(self) -> str:
        """``"completed"``; ``"failed"`` for the partial result of a run that stopped, ``"interrupted"``
        for one stopped by the user."""
        if not self.failure:
            return "completed"
        return "interrupted" if self.failure.get("cause") == "interrupted" else "failed"

    def __getitem__(self, name: str) -> np.ndarray:
        if name == "t":
            return self.t
        return self.columns[name]

    def curvature(self, li: int, frac: float) -> np.ndarray:
        """(nf,) curvature [1/m] of link ``li`` at ``frac`` of its length over the frames."""
        return self.curvature_of(self, li, frac)

    def node_curvatures(self, li: int) -> np.ndarray:
        """(n+1, nf) curvature [1/m] at the n+1 mesh nodes of link ``li`` over the frames (the mean of
        the two elements at an interior node)."""
        if self.node_curvatures_of is not None:
            return self.node_curvatures_of(self, li)
        f = self.fe.node_frac[li]
        return np.array([self.curvature(li, float(x)) for x in f])

    def all_stats(self):
        """ColumnStats over every frame of the run (those of the frames held when not streamed)."""
        if self.stats is None:
            self.stats = ColumnStats.of(self.t, self.columns)
        return self.stats

    def plot_view(self) -> "Result":
        """This result with the frames to draw: the envelope of a streamed run, else itself."""
        if self.envelope is None or self.envelope.names is None:
            return self
        return replace(self, t=self.envelope.t, columns=self.envelope.columns)

    # ------------------------------------------------------------------ summary
    def summary(self) -> dict:
        stats = self.all_stats()
        outs = {name: {"unit": self.units[name], **st} for name, st in stats.columns.items()}
        fe = self.fe
        fail = {"failed_at_s": self.failure["time_s"], "failure": self.failure} if self.failure else {}
        return {
            "title": self.case["case"]["title"],
            "status": self.status,
            **fail,
            "model": self.model,
            "steps": self.nsteps,
            "dt": self.dt,
            "frames": int(stats.frames),
            "t_end": stats.t_last,
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
        lines = [f"{s['title']}  [model {self._model_words()}]",
                 f"{s['steps']} steps of {self.dt:.4g} s, {s['dofs']['free']} free DOFs "
                 f"(half bandwidth {s['dofs']['half_bandwidth']}); kernel {self.timing.get('kernel_s', 0):.3f} s, "
                 f"total {self.timing.get('total_s', 0):.3f} s",
                 f"{'output':<{w}}  {'unit':<7} {'min':>12} {'max':>12} {'final':>12}"]
        for name, o in s["outputs"].items():
            lines.append(f"{name:<{w}}  {o['unit']:<7} {o['min']:>12.5g} {o['max']:>12.5g} {o['final']:>12.5g}")
        if self.failure:
            lines.insert(1, f"PARTIAL: the run stopped at t = {self.failure['time_s']:.6g} s; frames up to "
                            f"t = {self.all_stats().t_last:.6g} s")
        return "\n".join(lines + self._assembly_lines() + self._validity_lines() + self._estimate_lines()
                         + self._budget_lines())

    def _model_words(self) -> str:
        """What ran: the model, its geometric stiffness, and model = "auto"'s choice ("auto → classic +
        geometric stiffness (lagged)")."""
        geo = self.extra.get("geometric_stiffness", {}).get("source", "none")
        ran = self.model + (f" + geometric stiffness ({geo})" if geo not in (None, "none") else "")
        return f"auto → {ran}" if self.extra.get("model_choice") else ran

    def _budget_lines(self) -> list[str]:
        out = choice_lines(self.extra["model_choice"]) if self.extra.get("model_choice") else []
        b = self.extra.get("error_budget")
        if b and ("mesh" in b["parts"] or "model" in b["parts"]):
            out += budget_lines(b)
        return out

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
    def csv_head(self, running: bool = False) -> list[str]:
        """The comment lines and the header of timeseries.csv.  The first line says the run's status
        (running, complete, or partial with where it stopped), padded to STATUS_BYTES so that a file
        written while the run goes gets its final status in place (:class:`TimeseriesWriter`)."""
        names = list(self.columns)
        return [self.status_line(running),
                f"# flexmech {versions()['flexmech']}; case {self.case['case']['title']!r}; model {self.model}; "
                f"dt {self.dt:.6g} s; {self.nsteps} steps",
                "# units: " + ",".join(["s"] + [self.units[n] for n in names]),
                ",".join(["t"] + names)]

    def status_line(self, running: bool = False) -> str:
        """timeseries.csv's first line, exactly STATUS_BYTES long in UTF-8 (message cut if longer;
        summary.json holds it whole)."""
        if running:
            text = "# running: flexmech is writing this file; if no run is going on, it was killed"
        elif self.failure and self.failure.get("cause") == "interrupted":
            text = f"# partial: {self.failure.get('message', 'interrupted by the user')}"
        elif self.failure:
            text = (f"# partial: the run stopped at t = {self.failure['time_s']:.6g} s; frames up to t = "
                    f"{self.all_stats().t_last:.6g} s only ({self.failure.get('message', '')})")
        else:
            text = f"# complete: {int(self.all_stats().frames)} frames"
        raw = text.encode("utf-8")
        if len(raw) > STATUS_BYTES:
            raw = raw[:STATUS_BYTES - 24].decode("utf-8", "ignore").encode("utf-8") + b" ... (summary.json)"
        return raw.ljust(STATUS_BYTES).decode("utf-8")

    def write(self, out_dir) -> list[Path]:
        """Write timeseries.csv and summary.json into out_dir (created); returns the paths."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        csv = out / "timeseries.csv"
        atomic_write(csv, "\n".join(self.csv_head()) + "\n" + csv_rows(self.t, self.columns))
        return [csv, self.write_summary(out)]

    def write_summary(self, out_dir) -> Path:
        js = Path(out_dir) / "summary.json"
        atomic_write(js, json.dumps(self.summary(), indent=2, default=json_default) + "\n")
        return js


#: bytes of timeseries.csv's first (status) line, padding included
STATUS_BYTES = 240


def csv_rows(t: np.ndarray, columns: dict) -> str:
    """Rows of timeseries.csv (10 significant digits), each ending in a newline."""
    data = np.column_stack([t] + list(columns.values()))
    if data.shape[0] == 0:
        return ""
    fmt = ",".join(["%.10g"] * data.shape[1])
    return "\n".join(fmt % tuple(row) for row in data.tolist()) + "\n"


class TimeseriesWriter:
    """timeseries.csv written block by block, so a run of any length keeps none of its frames: the
    head and the rows go to ``timeseries.csv.part``, whose first line says the run is still going;
    :meth:`finish` writes the run's final status over that line (same length) and renames the file
    to ``timeseries.csv`` (no copy: the disk holds the rows once).  A run killed outright leaves
    only the part file.  A write that fails (a full disk) raises OSError naming the part file; the
    rows of the block it was writing are cut off again by :meth:`finish`, so the file ends with the
    last whole block."""

    def __init__(self, out_dir):
        self.path = Path(out_dir) / "timeseries.csv"
        self.part = self.path.with_name("timeseries.csv.part")
        self._file = None
        self.bytes = 0
        self.rows = 0
        self._whole = 0           # bytes up to the end of the last block written whole

    def add(self, block) -> None:
        if block.t.size == 0:
            return
        if self._file is None:
            self._file = _opened(self.part, "wb", buffering=0)
            self._write("\n".join(block.csv_head(running=True)) + "\n")
        self._write(csv_rows(block.t, block.columns))
        self.rows += block.t.size
        self._whole = self.bytes

    def _write(self, text: str) -> None:
        view = memoryview(text.encode("utf-8"))
        try:
            while view:
                n = self._file.write(view)
                self.bytes += n
                view = view[n:]
        except OSError as exc:
            raise OSError(exc.errno, exc.strerror, str(self.part)) from None

    def finish(self, res) -> Path | None:
        """timeseries.csv of the run ``res`` (its status line, then what was written); None when no
        frame came."""
        if self._file is None:
            return None
        try:
            if self.bytes != self._whole:          # a block cut short by a failed write
                self._file.truncate(self._whole)
                self.bytes = self._whole
            self._file.seek(0)
            self._file.write(res.status_line().encode("utf-8"))
        except OSError as exc:
            raise OSError(exc.errno, exc.strerror, str(self.part)) from None
        finally:
            self._file.close()
            self._file = None
        os.replace(self.part, self.path)
        return self.path

    def abandon(self) -> None:
        """Close and remove the part file (a run that produced nothing worth keeping)."""
        if self._file is not None:
            self._file.close()
            self.part.unlink(missing_ok=True)
            self._file = None


def _opened(path: Path, mode: str, **kw):
    try:
        return open(path, mode, **kw)
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, str(path)) from None


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
