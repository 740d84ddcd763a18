"""Monte-Carlo tolerance studies: ``flexmech sweep CASE --sample KEY.PATH=DIST --samples N --seed S``.

Each ``--sample`` gives one case value a distribution (manufacturing tolerances of link
lengths, sections, masses, joint stiffnesses):

* ``normal:MEAN:SD``
* ``uniform:LO:HI``
* ``lognormal:MEAN:SD`` -- MEAN and SD of the value itself (not of its logarithm):
  ln X is normal with sigma^2 = ln(1 + (SD/MEAN)^2) and mu = ln MEAN - sigma^2 / 2.

N points of the unit hypercube (one dimension per ``--sample``) are drawn from the seed
by Latin hypercube sampling (``lhs``, default: every one-dimensional projection has one
point in each of N equal-probability strata), a scrambled Sobol' sequence (``sobol``,
balanced for N a power of 2) or plain pseudo-random numbers (``random``) -- SciPy's
``stats.qmc`` and NumPy's generator -- and mapped through each distribution's inverse
CDF.  The samples run like sweep points (:func:`flexmech_py.studies.sweep.run_points`); the
statistics of the key outputs (each output's peak |value|) and their correlations with
the inputs (Pearson and Spearman rank: the rank correlation ranks which tolerance
matters) are computed from the successful samples.
"""

from __future__ import annotations

import copy
import inspect
import json
import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..base.errors import CaseError
from ..base.names import safe_name
from ..run.outdir import ResultFolder
from ..base.sizes import check_points
from ..base.fileio import atomic_write, csv_cell, json_default
from ..base.version import versions
from .accuracy import DEFAULT_KINDS
from ..run.parallel import using_executor
from .sweep import check_first_point, failure_reasons, load_base, run_points
from ..case import validate_case
from .sweep import write_table
from ..figures.study_plots import plot_samples

__all__ = ["Distribution", "parse_sample", "unit_points", "draw", "statistics", "correlations", "sample_study",
           "METHODS", "PERCENTILES"]

METHODS = ("lhs", "sobol", "random")
PERCENTILES = (5, 25, 50, 75, 95)
_FORMS = {"normal": "normal:MEAN:SD", "uniform": "uniform:LO:HI", "lognormal": "lognormal:MEAN:SD"}


@dataclass(frozen=True)
class Distribution:
    """One sampled case value: ``key`` (KEY.PATH), ``kind`` (normal, uniform, lognormal), its two
    parameters ``a``, ``b`` as written (MEAN, SD or LO, HI) and the text ``spec``."""

    key: str
    kind: str
    a: float
    b: float
    spec: str

    def ppf(self, u: np.ndarray) -> np.ndarray:
        """Values at the probabilities ``u`` in (0, 1) (the inverse CDF)."""
        from scipy import stats

        u = np.clip(np.asarray(u, float), 1e-12, 1.0 - 1e-12)
        if self.kind == "uniform":
            return self.a + (self.b - self.a) * u
        if self.kind == "normal":
            return stats.norm.ppf(u, loc=self.a, scale=self.b)
        s2 = math.log1p((self.b / self.a) ** 2)
        return np.exp(math.log(self.a) - 0.5 * s2 + math.sqrt(s2) * stats.norm.ppf(u))


def parse_sample(text: str) -> Distribution:
    """``KEY.PATH=normal:MEAN:SD``, ``KEY.PATH=uniform:LO:HI`` or ``KEY.PATH=lognormal:MEAN:SD``."""
    forms = ", ".join(_FORMS.values())
    if "=" not in text:
        raise CaseError("--sample", f"{text!r} must look like KEY.PATH=DIST with DIST one of {forms}")
    key, spec = (s.strip() for s in text.split("=", 1))
    kind, *args = [p.strip() for p in spec.split(":")]
    if not key or kind not in _FORMS:
        raise CaseError(f"--sample {key}", f"{spec!r}: the distribution must be one of {forms}")
    try:
        if len(args) != 2:
            raise ValueError
        a, b = float(args[0]), float(args[1])
        if not (math.isfinite(a) and math.isfinite(b)):
            raise ValueError
    except ValueError:
        raise CaseError(f"--sample {key}", f"{spec!r} must be {_FORMS[kind]} with two finite numbers") from None
    if kind == "uniform" and not a < b:
        raise CaseError(f"--sample {key}", f"{spec!r}: LO must be below HI")
    if kind in ("normal", "lognormal") and not b > 0:
        raise CaseError(f"--sample {key}", f"{spec!r}: SD must be > 0")
    if kind == "lognormal" and not a > 0:
        raise CaseError(f"--sample {key}", f"{spec!r}: a lognormal value is positive; MEAN must be > 0")
    return Distribution(key, kind, a, b, spec)


def _engine(cls, d: int, rng):
    # SciPy >= 1.15 names the generator argument rng, older versions seed
    name = "rng" if "rng" in inspect.signature(cls).parameters else "seed"
    return cls(d, **{name: rng})


def unit_points(d: int, n: int, seed: int, method: str = "lhs") -> tuple[np.ndarray, list[str]]:
    """(n, d) points in the unit hypercube from ``seed`` by ``method``, and any warnings."""
    from scipy.stats import qmc

    if method not in METHODS:
        raise CaseError("--method", f"must be one of {', '.join(METHODS)}, got {method!r}")
    if isinstance(n, bool) or int(n) < 1:
        raise CaseError("--samples", f"must be a whole number >= 1, got {n}")
    rng = np.random.default_rng(seed)
    notes = []
    if method == "random":
        return rng.random((int(n), d)), notes
    if method == "sobol" and n & (n - 1):
        notes.append(f"--method sobol: {n} samples is not a power of 2, so the Sobol' points lose their balance; "
                     f"use {1 << (n - 1).bit_length()} or {1 << (n.bit_length() - 1)}")
    engine = _engine(qmc.LatinHypercube if method == "lhs" else qmc.Sobol, d, rng)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)   # Sobol's own power-of-2 warning: said above
        return engine.random(int(n)), notes


def draw(dists: list[Distribution], n: int, seed: int, method: str = "lhs") -> tuple[list[dict], list[str]]:
    """The n sample points [{key: value}] and any warnings."""
    keys = [d.key for d in dists]
    if len(set(keys)) != len(keys):
        raise CaseError("--sample", f"a key is given twice: {', '.join(keys)}")
    u, notes = unit_points(len(dists), n, seed, method)
    cols = [d.ppf(u[:, j]) for j, d in enumerate(dists)]
    return [{d.key: float(c[i]) for d, c in zip(dists, cols)} for i in range(u.shape[0])], notes


def statistics(values: dict) -> list[dict]:
    """Per column {name: finite values}: count, mean, sd (n - 1), min, the PERCENTILES, max."""
    out = []
    for name, y in values.items():
        y = np.asarray(y, float)
        row = {"column": name, "n": int(y.size)}
        if y.size:
            row.update(mean=float(np.mean(y)), sd=float(np.std(y, ddof=1)) if y.size > 1 else float("nan"),
                       min=float(np.min(y)))
            row.update({f"p{p}": float(np.percentile(y, p)) for p in PERCENTILES})
            row["max"] = float(np.max(y))
        out.append(row)
    return out


def correlations(inputs: dict, outputs: dict) -> list[dict]:
    """Every (output, input) pair: Pearson and Spearman rank correlation over the samples, and the
    input's rank for that output (1 = the largest |Spearman|: the tolerance that matters most)."""
    from scipy.stats import rankdata

    def corr(x, y):
        return float(np.corrcoef(x, y)[0, 1]) if len(x) > 2 and np.std(x) > 0 and np.std(y) > 0 else float("nan")

    out = []
    for oname, y in outputs.items():
        rows = [{"output": oname, "input": iname, "pearson": corr(x, y),
                 "spearman": corr(rankdata(x), rankdata(y))} for iname, x in inputs.items()]
        ranked = sorted((r for r in rows if math.isfinite(r["spearman"])), key=lambda r: -abs(r["spearman"]))
        for rank, r in enumerate(ranked, start=1):
            r["rank"] = rank
        out += ranked + [r for r in rows if not math.isfinite(r["spearman"])]   # a constant output: no rank
    return out


def _write_rows(path: Path, rows: list[dict], names: list[str], header: str) -> Path:
    atomic_write(path, "\n".join([f"# {header}", ",".join(names)]
                                  + [",".join(csv_cell(r.get(n, "")) for n in names) for r in rows]) + "\n")
    return path


def key_outputs(case: dict, columns) -> list[str]:
    """The ``<output>_maxabs`` columns of the elastic outputs (strain, displacement), else of all."""
    peaks = [c for c in columns if c.endswith("_maxabs")]
    elastic = [f"{n}_maxabs" for n, sp in case["outputs"].items() if sp["kind"] in DEFAULT_KINDS]
    return [c for c in peaks if c in elastic] or peaks


def sample_study(case_path, samples: list[str], *, n: int, seed: int = 0, method: str = "lhs", model=None,
                 overrides=(), jobs: int | None = None, out_dir=None, progress: bool = True, scheduler=None,
                 plots: bool = True) -> dict:
    """Run the case at ``n`` samples of the ``samples`` distributions (``KEY.PATH=DIST`` strings) and
    write into ``out_dir`` (default ``results/<case>-samples``): ``samples.csv`` (a row per sample: its
    inputs and outputs, as sweep.csv), ``statistics.csv``, ``correlations.csv``, ``samples.json`` and
    ``samples.png``.  Returns {"rows", "batch", "paths", "statistics", "correlations", "failures",
    "warnings", "key_outputs"}."""

    path, base = load_base(case_path, overrides)
    dists = [parse_sample(s) for s in samples]
    check_points(n, "--samples", lambda k: f"draw at most {k:,} samples (e.g. --samples {min(k, 1024)})")
    points, notes = draw(dists, n, seed, method)
    check_first_point(base, path.name, points, "sample")
    out = out_dir if out_dir is not None else Path("results") / f"{safe_name(path.stem)}-samples"
    with using_executor(scheduler, jobs) as executor, ResultFolder(out, "samples") as rf:   # connect first
        rows, batch = run_points(path, base, points, model=model, out=rf.out, executor=executor, progress=progress)
        rows = [{"sample": k, **r} for k, r in enumerate(rows)]
        st = _write_study(rf.stage, path, base, dists, rows, batch, notes, plots,
                          dict(model=model, overrides=list(overrides), method=method, seed=seed, samples=n))
        rf.commit()
    st["paths"] = [rf.where(p) for p in st["paths"]]
    return {"rows": rows, "batch": batch, "failures": failure_reasons(rows), "warnings": notes, **st}


def _write_study(out: Path, path: Path, base: dict, dists, rows, batch, notes, plots: bool, settings: dict) -> dict:
    """samples.csv, statistics.csv, correlations.csv, samples.json and samples.png of a finished study;
    {"paths", "statistics", "correlations", "key_outputs"}."""

    n, method, seed = settings["samples"], settings["method"], settings["seed"]
    what = f"{n} {method} samples (seed {seed}) of {path.name}: " + "; ".join(f"{d.key} = {d.spec}" for d in dists)
    names = write_table(out / "samples.csv", rows, ["sample"] + [d.key for d in dists],
                        f"flexmech {versions()['flexmech']} {what}")
    ok = [r for r in rows if r["status"] == "ok"]
    inputs = {d.key: np.array([r[d.key] for r in ok], float) for d in dists}
    outputs = {c: np.array([r[c] for r in ok], float) for c in names if c.endswith("_maxabs")}
    stats = [{"kind": "input" if s["column"] in inputs else "output", **s} for s in statistics({**inputs, **outputs})]
    corr = correlations(inputs, outputs)
    paths = [out / "samples.csv",
             _write_rows(out / "statistics.csv", stats, ["kind", "column", "n", "mean", "sd", "min"]
                         + [f"p{p}" for p in PERCENTILES] + ["max"], f"statistics of the successful samples; {what}"),
             _write_rows(out / "correlations.csv", corr, ["output", "input", "pearson", "spearman", "rank"],
                         f"input-output correlations over the successful samples; {what}")]
    keys = key_outputs(validate_case(copy.deepcopy(base), source=str(path)), outputs)
    info = {"case": str(path), **settings, "distributions": [d.__dict__ for d in dists], "key_outputs": keys, "columns": names,
            "jobs": batch.jobs, "executor": batch.executor, "computed": batch.computed, "cached": batch.cached,
            "retries": batch.retries, "failed": batch.failed, "wall_s": batch.wall_s, "warnings": notes,
            "versions": versions()}
    paths.append(out / "samples.json")
    atomic_write(paths[-1], json.dumps(info, indent=2, default=json_default) + "\n")
    if plots and ok:
        png = plot_samples(out / "samples.png", inputs, {c: outputs[c] for c in keys[:4]}, corr,
                           title=f"{path.name}: {len(ok)} of {n} {method} samples, seed {seed}")
        paths += [png] if png else []
    return {"paths": paths, "statistics": stats, "correlations": corr, "key_outputs": keys}

