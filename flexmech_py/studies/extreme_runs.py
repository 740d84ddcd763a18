"""What every study of the stability suite (:mod:`flexmech_py.studies.extreme`) shares: the integrator
labels and their overrides, the suite's case files, one guarded run, the measures of a run's
warnings and validity, and the table row and command line of a result."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..base.bundled import cases_dir
from ..case import load_case
from ..base.errors import FlexmechError
from ..models.modal import superposition_frequencies
from ..run.simulate import Prepared

__all__ = ["INTEGRATORS", "LABEL", "SPINUP_CONFIGS", "SPINUP_REFERENCE", "integrator_overrides", "case_path", "load",
           "run_case", "attempt", "sawtooth", "lowest_frequencies", "run_warnings", "validity_peaks", "table_row",
           "run_command"]

INTEGRATORS = {
    "newmark": ["solver.integrator=newmark"],   # average acceleration (the superposition models' default)
    "hht-0.05": ["solver.integrator=hht", "solver.hht_alpha=0.05"],
    "hht-0.3": ["solver.integrator=hht", "solver.hht_alpha=0.3"],
    **{f"galpha-{r}": ["solver.integrator=generalized-alpha", f"solver.rho_inf={r}"]
       for r in ("0.0", "0.5", "0.7", "0.8", "0.9", "0.95")},
}
LABEL = {"newmark": "average acceleration", "hht-0.05": "HHT α = 0.05", "hht-0.3": "HHT α = 0.3",
         **{f"galpha-{r}": f"generalized-α ρ∞ = {r}" for r in ("0.0", "0.5", "0.7", "0.8", "0.9", "0.95")}}


def integrator_overrides(label: str) -> list[str]:
    """The ``--set`` overrides of an integrator label (``newmark``, ``hht-0.05``, ``galpha-0.8``, ...)."""
    return list(INTEGRATORS[label])


def case_path(name: str) -> Path:
    """Path of a stability-suite case file ``cases/extreme/NAME.toml`` (source tree or installed copy)."""
    path = cases_dir() / "extreme" / f"{name}.toml"
    if not path.is_file():
        raise FileNotFoundError(f"cases/extreme/{name}.toml is not installed")
    return path


def load(name: str, overrides=()) -> dict:
    """The resolved case ``cases/extreme/NAME.toml`` with ``--set`` overrides."""
    return load_case(case_path(name), overrides=list(overrides))


def run_case(name: str, overrides=(), model=None, geometric=None, **prep_kw):
    """Run one case; returns (Result or None, error message or "")."""
    res, err, _ = attempt(lambda: Prepared(load(name, overrides), **prep_kw).run(model, geometric=geometric))
    return (res, err) if not err else (None, err)


def attempt(fn):
    """(result, "", None) or, when the run stops, (its partial result or None, the error message, the
    time it stopped [s] or None)."""
    try:
        return fn(), "", None
    except FlexmechError as exc:
        return getattr(exc, "partial", None), str(exc), getattr(exc, "time", None)


def sawtooth(y: np.ndarray, start: float = 0.5) -> float:
    """Amplitude of the period-2-step content of y after the fraction ``start`` of the record,
    relative to max|y|: max |y[k+1] - 2 y[k] + y[k-1]| / 4 (a sawtooth of amplitude A gives A; a
    smooth signal sampled at Omega dt gives (Omega dt)^2 |y| / 4).  Needs a frame at every step."""
    y = np.asarray(y, float)
    d2 = np.abs(y[2:] - 2 * y[1:-1] + y[:-2]) / 4
    pk = np.max(np.abs(y))
    return float(np.max(d2[int(start * d2.size):]) / pk) if pk > 0 else 0.0


def lowest_frequencies(prep: Prepared, nmodes: int = 2, samples: int = 72, model: str = "hac") -> np.ndarray:
    """(samples, nmodes) lowest natural frequencies [rad/s] of (K + K_c, M) along the run (frozen
    coefficients; negative values: sign(lambda) sqrt|lambda|, an unstable frozen system;
    flexmech_py.models.modal.superposition_frequencies)."""
    idx = np.linspace(0, prep.nsteps, samples).round().astype(int)
    return superposition_frequencies(prep.fe, prep.rig[:, :, idx], model, nmodes)


def run_warnings(res) -> list[str]:
    return list(res.extra.get("warnings", [])) if res is not None else []


def validity_peaks(res) -> tuple[float, float]:
    """(largest displacement over link length, largest compression over the Euler load) of a run."""
    v = res.extra.get("validity", {})
    links = v.get("links", v) if isinstance(v, dict) else {}
    d = [x.get("max_displacement_over_length", 0.0) for x in links.values() if isinstance(x, dict)]
    c = [x.get("max_compression_over_euler", 0.0) for x in links.values() if isinstance(x, dict)]
    return (max(d) if d else float("nan")), (max(c) if c else float("nan"))


def table_row(case, model, integrator, dt, happened, why, command, **data):
    return {"case": case, "model": model, "integrator": integrator, "dt": dt, "happened": happened,
            "why": why, "command": command, **data}


def run_command(name, sets=(), model=None, extra=""):
    s = f"flexmech run cases/extreme/{name}.toml"
    if model:
        s += f" --model {model}"
    for o in sets:
        s += f" --set {o}"
    return s + extra


SPINUP_CONFIGS = [("classic", "none", "newmark"), ("classic", "current", "newmark"), ("classic", "quasi_static", "newmark"),
                  ("nonlinear", None, "newmark"), ("nonlinear", None, "galpha-0.8")]
SPINUP_REFERENCE = "nonlinear/galpha-0.8"
