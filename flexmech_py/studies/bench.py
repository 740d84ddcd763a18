"""``flexmech bench``: what a run costs, measured against its arithmetic and the alternatives.

One process, one run (docs/performance.md):

- start-up: the Python interpreter, ``import flexmech_py``, and a whole ``flexmech run`` of the
  seed four-bar in a subprocess (with and without plots);
- every seed case: FE set-up, rigid-motion pre-computation, kernel and Python overhead;
- a mesh ladder (1, 2, 4, ... 256 elements per link) of the seed four-bar for every model: kernel
  time per step and per DOF-step, the floating-point operations of a step and the achieved fraction
  of one core's measured multiply-add rate, and the fitted exponent of time against elements;
- the NumPy/SciPy reference of the same equations (:mod:`flexmech_py.models.superposition.reference`) as a ratio, with
  the largest difference of the two solutions;
- banded (``dgbtrf``/``dgbtrs``) against dense (``dgetrf``/``dgetrs``) solves of the effective
  matrix across mesh sizes, with fitted growth exponents;
- peak memory of long runs with output decimation (tracemalloc and the resident-set high-water
  mark VmHWM, each in a fresh subprocess), at 10^5 and 10^6 steps;
- the scaling of every bundled mechanism in every model over a mesh ladder
  (:mod:`flexmech_py.studies.bench_scaling`);
- side by side with Exudyn, when installed (:mod:`flexmech_py.studies.bench_side_by_side`).

Results: tables on stdout, ``bench_ladder.csv``, ``bench_solves.csv``, ``bench_summary.csv``,
``bench_seed.csv``, ``bench_scaling.csv``, ``bench_scaling_fits.csv``, ``bench_exudyn*.csv`` and the
log-log plot ``bench.png`` in the output folder.  ``quick=True`` runs reduced ladders (the tests run
it).  Kernel, solve and peak timings are CPU time of the calling thread (``time.thread_time``; the
machine may be shared), subprocesses report wall and CPU time (``getrusage`` of the children);
minima over repeats where cheap.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from .bench_runs import DT, bench_case, fit_exponent, table, write_csv
from .bench_scaling import bench_scaling, scaling_summary, scaling_pivot, scaling_rows
from .bench_side_by_side import exudyn_sections, exudyn_rows, exudyn_report
from ..base.errors import FlexmechError, SolverError
from ..base.inputs import checked_file, checked_folder
from ..run.outdir import ResultFolder
from ..base.families import MODELS, family
from ..figures.plots import save_figure
from .bench_stepping import bench_stepping
from ..case import load_case
from ..run.simulate import Prepared
from ..models.superposition import reference
from ..base.kernels import api, check_status

__all__ = ["run_bench", "flops_superposition", "flops_newton", "fit_exponent", "DT"]

SEED = "fourbar_hac.toml"


# ---------------------------------------------------------------------------------------- flop models

def flops_superposition(nel: int, nlinks: int, n: int, kb: int, model: str = "hac") -> dict:
    """Floating-point operations of one superposition step as the kernel does it (add and multiply
    each count 1): the effective matrix of each uniform link formed and rotated once (504), per
    element the band scatter, residual and rigid load (284, classic models 308), the banded LU
    2 n kl (kl + ku) with kl = ku = kb, its forward/back substitution 2 n (2 kl + ku), and the
    Newmark predictor/corrector (12 n)."""
    per_el = 284 if family(model).load_mass == "translational" else 308
    f = {"assembly": 504 * nlinks + per_el * nel, "factorization": 2 * n * kb * (2 * kb),
         "solve": 2 * n * (3 * kb), "update": 12 * n}
    f["total"] = sum(f.values())
    return f


def flops_newton(structure: dict, iterations: float, factorizations: float) -> dict:
    """Floating-point operations of one Newton step of the coupled/nonlinear models as the kernel counts
    them for the structure it uses (CoupledModel.structure): the factorizations and one solve per
    iteration (assembly and element evaluation not counted: a lower bound)."""
    f = {"factorization": factorizations * structure["flops_per_factorization"],
         "solve": iterations * structure["flops_per_solve"]}
    f["total"] = sum(f.values())
    return f


# ---------------------------------------------------------------------------------------- helpers

def _children_cpu() -> float:
    import resource
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


# subprocesses start in a neutral folder: a source checkout in the caller's folder would shadow the
# installed package (its flexmech_py/ has no compiled extension)
_NEUTRAL_CWD = tempfile.gettempdir()


def _timed_subprocess(args, reps: int, env=None) -> tuple[float, float]:
    """(wall, CPU) seconds of a subprocess, each the minimum over reps runs."""
    wall = cpu = math.inf
    for _ in range(reps):
        t0, c0 = time.perf_counter(), _children_cpu()
        r = subprocess.run(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, cwd=_NEUTRAL_CWD)
        if r.returncode:
            last = (r.stderr or b"").decode("utf-8", "replace").strip().splitlines()[-1:] or ["no message"]
            raise FlexmechError(f"bench: `{' '.join(map(str, args[-4:]))}` failed (exit {r.returncode}): {last[0]}")
        wall, cpu = min(wall, time.perf_counter() - t0), min(cpu, _children_cpu() - c0)
    return wall, cpu


def _seed_dir(cases_dir) -> Path:
    if cases_dir is not None:
        return Path(cases_dir)
    from importlib import resources
    return Path(str(resources.files("flexmech_py") / "cases"))


# ---------------------------------------------------------------------------------------- sections

def bench_startup(seed: Path, reps: int) -> dict:
    py = sys.executable
    env = dict(os.environ, MPLBACKEND="Agg")
    out = {}
    out["python_startup_s"], out["python_startup_cpu_s"] = _timed_subprocess([py, "-c", "pass"], reps)
    w, c = _timed_subprocess([py, "-c", "import flexmech_py.cli"], reps)
    out["import_s"], out["import_cpu_s"] = w - out["python_startup_s"], c - out["python_startup_cpu_s"]
    chk = subprocess.run([py, "-c", "import sys, flexmech_py, flexmech_py.cli, flexmech_py.run.simulate; "
                                    "print(int('matplotlib' in sys.modules), int('scipy.integrate' in sys.modules))"],
                         check=True, capture_output=True, text=True, cwd=_NEUTRAL_CWD).stdout.split()
    out["matplotlib_imported_by_import"] = int(chk[0])
    out["scipy_integrate_imported_by_import"] = int(chk[1])
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [py, "-m", "flexmech_py", "run", str(Path(seed).resolve()), "--out", tmp]
        out["flexmech_run_no_plots_s"], out["flexmech_run_no_plots_cpu_s"] = _timed_subprocess(cmd + ["--no-plots"], reps, env)
        try:
            import matplotlib  # noqa: F401
            out["flexmech_run_with_plots_s"], out["flexmech_run_with_plots_cpu_s"] = _timed_subprocess(cmd, reps, env)
        except ImportError:
            out["flexmech_run_with_plots_s"] = out["flexmech_run_with_plots_cpu_s"] = float("nan")
    return out


def bench_seed_cases(cases: Path, reps: int) -> list[dict]:

    rows = []
    for path in sorted(cases.glob("*.toml")):
        case = load_case(path)
        best = None
        for _ in range(reps):
            t0, c0 = time.perf_counter(), time.thread_time()
            p = Prepared(case)
            res = p.run()
            wall, cpu = time.perf_counter() - t0, time.thread_time() - c0
            if best is None or cpu < best[1]:
                best = (wall, cpu, p, res)
        wall, cpu, p, res = best
        tm = dict(res.timing, **p.last_cpu)
        rig = tm["rigid_s"] + tm["rigid_samples_s"]
        rows.append({"case": path.stem, "model": res.model, "steps": p.nsteps, "dofs": p.fe.nfree,
                     "setup_s": p.t_prepare, "rigid_s": rig, "kernel_s": tm["kernel_s"],
                     "rigid_cpu_s": tm["rigid_cpu_s"], "kernel_cpu_s": tm["kernel_cpu_s"],
                     "python_overhead_s": wall - rig - tm["kernel_s"], "total_s": wall, "total_cpu_s": cpu,
                     "python_overhead_cpu_s": cpu - tm["rigid_cpu_s"] - tm["kernel_cpu_s"],
                     "us_per_step": 1e6 * tm["kernel_cpu_s"] / p.nsteps,
                     "ns_per_dof_step": 1e9 * tm["kernel_cpu_s"] / (p.nsteps * p.fe.nfree)})
    return rows


def _ladder_steps(model: str, epl: int, quick: bool) -> int:
    if quick:
        base = 400 if family(model).constrained else 2000
        return max(20, 10 * round(base / epl / 10))
    if family(model).constrained:   # cost per step ~ epl (element frames, the bordered band) or epl^1.5
        s = 20000 / epl if family(model).element_frames else 40000 / epl ** 1.5
    else:
        s = 100000 / epl
    return int(min(25000, max(20, 10 * round(s / 10))))


def bench_ladder(seed: Path, peak: float, quick: bool, progress) -> list[dict]:

    nan = float("nan")
    ladder = (1, 2, 4, 8) if quick else tuple(2 ** k for k in range(9))
    rows = []
    preps = {}
    for model in MODELS:
        for epl in ladder:
            steps = _ladder_steps(model, epl, quick)
            key = (epl, steps)
            if key not in preps:
                preps = {k: v for k, v in preps.items() if k[0] == epl}   # keep memory bounded
                preps[key] = Prepared(bench_case(seed, steps, 10), elements_per_link=epl)
                # the zero-stiffness check (a dense eigenvalue problem) would cost more than a timing run
                preps[key].elastic_checked = True
            p = preps[key]
            reps = 3 if steps * epl <= 20000 and family(model).superposition else 1
            kern = kcpu = math.inf
            try:
                for _ in range(reps):
                    res = p.run(model)
                    kern, kcpu = min(kern, res.timing["kernel_s"]), min(kcpu, p.last_cpu["kernel_cpu_s"])
            except SolverError as exc:   # reported, not fatal: the ladder goes on
                progress(f"  {model:22s} {epl:4d} el/link  failed: {exc}")
                rows.append({"model": model, "elements_per_link": epl, "elements": p.fe.nel, "dofs": p.fe.nfree,
                             "bandwidth": p.fe.bandwidth, "steps": steps, "kernel_wall_s": nan, "kernel_cpu_s": nan,
                             "us_per_step": nan, "ns_per_dof_step": nan, "newton_per_step": nan,
                             "flops_per_step": nan, "gflops": nan, "peak_fraction": nan})
                continue
            fe = p.fe
            if family(model).constrained:
                cm = p.coupled[model]
                nw = res.extra["coupled"]["newton"]
                n, kb, it = int(cm.free_of.max()), cm.solver["band_half_width"], nw["mean_per_step"]
                fl = flops_newton(cm.solver, it, nw["factorizations_per_step"])
            else:
                n, kb, it = fe.nfree, fe.bandwidth, float("nan")
                fl = flops_superposition(fe.nel, len(fe.n_el), n, kb, model)
            tps = kcpu / steps   # CPU time of the kernel thread: robust against other processes on the machine
            rows.append({"model": model, "elements_per_link": epl, "elements": fe.nel, "dofs": n, "bandwidth": kb,
                         "steps": steps, "kernel_wall_s": kern, "kernel_cpu_s": kcpu, "us_per_step": 1e6 * tps,
                         "ns_per_dof_step": 1e9 * tps / n, "newton_per_step": it,
                         "flops_per_step": fl["total"], "gflops": fl["total"] / tps / 1e9,
                         "peak_fraction": fl["total"] / tps / peak})
            progress(f"  {model:22s} {epl:4d} el/link  {n:5d} DOFs  kb {kb:4d}  {steps:6d} steps  "
                     f"{1e6 * tps:10.2f} us/step  {100 * fl['total'] / tps / peak:5.1f} % of peak")
    return rows


def bench_reference(seed: Path, nref: int, reps: int) -> dict:
    """Fortran against the NumPy reference of the same equations on the seed four-bar (hac)."""

    p = Prepared(bench_case(seed, nref, 1))
    rig = p.rig
    t0 = time.thread_time()
    u_ref = reference.newmark(p.fe, rig, "hac", p.dt)
    t_ref = time.thread_time() - t0
    t_f = math.inf
    for _ in range(reps):
        t0 = time.thread_time()
        uf, _, _ = p.fe.run(rig, "hac", p.dt)
        t_f = min(t_f, time.thread_time() - t0)
    # the Fortran per step from a full-length run (call overhead amortised)
    pl = Prepared(bench_case(seed, 25000, 10))
    t_long = math.inf
    for _ in range(reps):
        pl.run("hac")
        t_long = min(t_long, pl.last_cpu["kernel_cpu_s"] / pl.nsteps)
    diff = float(np.max(np.abs(uf - u_ref)) / np.max(np.abs(u_ref)))
    return {"reference_steps": nref, "reference_us_per_step": 1e6 * t_ref / nref,
            "fortran_us_per_step_same_steps": 1e6 * t_f / nref, "fortran_us_per_step_25000": 1e6 * t_long,
            "ratio_reference_to_fortran": (t_ref / nref) / t_long, "max_relative_difference": diff}


def bench_solves(seed: Path, quick: bool, progress) -> list[dict]:

    ladder = (1, 2, 4, 8) if quick else tuple(2 ** k for k in range(9))
    rows = []
    for epl in ladder:
        p = Prepared(bench_case(seed, 10, 10), elements_per_link=epl)
        mm, cm, km, _ = p.fe.matrices(p.rig[:, :, 0], "hac")
        s = np.asfortranarray(mm + 0.5 * DT * cm + 0.25 * DT * DT * km)
        b = np.ones(s.shape[0])
        n, kb = s.shape[0], p.fe.bandwidth
        row = {"elements_per_link": epl, "dofs": n, "bandwidth": kb}
        for mode, name in ((1, "banded"), (2, "dense")):
            if mode == 2 and n > (300 if quick else 1200):
                row[f"{name}_us"] = float("nan")
                continue
            t0 = time.thread_time()
            x, status = api.bench_solve(kb, 1, mode, s, b)
            t1 = time.thread_time() - t0
            check_status(status, "bench_solve")
            nrep = max(1, min(100000, int(0.05 / max(t1, 1e-7))))
            best = math.inf
            for _ in range(2):
                t0 = time.thread_time()
                x, status = api.bench_solve(kb, nrep, mode, s, b)
                best = min(best, (time.thread_time() - t0) / nrep)
            row[f"{name}_us"] = 1e6 * best
        rows.append(row)
        progress(f"  {n:5d} DOFs  kb {kb:3d}  banded {row['banded_us']:10.2f} us  dense {row['dense_us']:12.2f} us")
    return rows


def bench_peak(quick: bool) -> float:
    """Measured multiply-add rate of one core [flop/s] (bench_peak: 8 independent chains)."""
    n = 20_000_000 if quick else 200_000_000
    best = math.inf
    for _ in range(3):
        t0 = time.thread_time()
        api.bench_peak(n, 0.999999, 1e-6)
        best = min(best, time.thread_time() - t0)
    return 16 * n / best


def memory_probe(case_path, nsteps: int, out_every: int) -> dict:
    """Run a case for nsteps (dt = 1e-5 s) writing every out_every-th frame; peak memory of this process."""
    import resource
    import tracemalloc


    case = bench_case(case_path, nsteps, out_every)
    tracemalloc.start()
    t0 = time.perf_counter()
    res = Prepared(case).run()
    wall = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    # the resident-set high-water mark of this process image (VmHWM; ru_maxrss would carry over the
    # parent's peak across fork + exec on Linux)
    hwm = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    try:
        with open("/proc/self/status") as fh:
            hwm = next(int(line.split()[1]) for line in fh if line.startswith("VmHWM:")) / 1024
    except (OSError, StopIteration):
        pass
    return {"steps": nsteps, "frames": int(res.t.size), "tracemalloc_peak_MB": peak / 2 ** 20,
            "maxrss_MB": hwm, "wall_s": wall}


def bench_memory(cases: Path, quick: bool) -> list[dict]:
    path = (cases / "fourbar_constant_speed.toml").resolve()
    out = []
    for nsteps in ((10_000, 100_000) if quick else (100_000, 1_000_000)):
        r = subprocess.run([sys.executable, "-m", "flexmech_py.studies.bench", "--memory-probe", str(path), str(nsteps), "1000"],
                           check=True, capture_output=True, text=True, cwd=_NEUTRAL_CWD)
        out.append(json.loads(r.stdout.strip().splitlines()[-1]))
    return out


# ---------------------------------------------------------------------------------------- driver

def plot_title(ladder: list[dict]) -> str:
    """bench.png's title: the mesh sizes the ladder ran."""
    epl = sorted({x["elements_per_link"] for x in ladder})
    return f"flexmech bench: seed four-bar, {epl[0]}..{epl[-1]} elements per link" if epl else "flexmech bench"


def _plot(path: Path, ladder: list[dict], solves: list[dict]) -> Path | None:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    fig, ax = plt.subplots(figsize=(7.5, 5.5))
    for model in MODELS:
        r = [x for x in ladder if x["model"] == model]
        if r:
            r = [x for x in r if np.isfinite(x["us_per_step"])]
            ax.loglog([x["dofs"] for x in r], [x["us_per_step"] for x in r], "o-", label=f"{model}: kernel per step")
    for key, style in (("banded_us", "k--"), ("dense_us", "k:")):
        r = [x for x in solves if np.isfinite(x[key])]
        ax.loglog([x["dofs"] for x in r], [x[key] for x in r], style,
                  label=("banded" if key == "banded_us" else "dense") + " LU + solve (LAPACK)")
    d = np.array([x["dofs"] for x in solves], float)
    ax.loglog(d, 0.5 * d * solves[0]["banded_us"] / d[0], color="0.7", lw=0.8, label="slope 1")
    ax.set_xlabel("free DOFs")
    ax.set_ylabel("time per step or per solve [us]")
    ax.set_title(plot_title(ladder))
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def _exponent_rows(metric: str, pts: list, lo: float, hi: float, what: str) -> list[dict]:
    """The fitted exponent p of y ~ x^p over the points (x, y) with lo <= x <= hi (the asymptotic
    range); with fewer than 3 there (the quick ladder) over all the points, and the note says so; no
    row with fewer than 2 points."""
    big = [(x, y) for x, y in pts if lo <= x <= hi]
    use = big if len(big) >= 3 else pts
    if len(use) < 2:
        return []
    xs, ys = zip(*use)
    span = f"{lo:g}..{hi:g}" if math.isfinite(hi) else f">= {lo:g}"
    note = (f"{what} {min(xs):g}..{max(xs):g}"
            + ("" if use is big else f" (below the asymptotic range {span}: fixed costs weigh more)"))
    return [{"metric": metric, "value": fit_exponent(xs, ys), "unit": "1", "note": note}]


def _startup_rows(startup: dict, peak: float) -> list[dict]:
    """Summary rows of the start-up measurements and the scalar peak."""
    rows = []
    notes = {"python_startup": "python -c pass", "import": "import flexmech_py.cli (start-up subtracted)",
             "flexmech_run_no_plots": f"flexmech run {SEED} --no-plots (subprocess, start-up included)",
             "flexmech_run_with_plots": f"flexmech run {SEED} (subprocess, PNG plots included)"}
    for k, note in notes.items():
        rows.append({"metric": k, "value": startup[f"{k}_s"], "unit": "s", "note": note + ", wall"})
        rows.append({"metric": k + "_cpu", "value": startup[f"{k}_cpu_s"], "unit": "s", "note": note + ", CPU"})
    return rows + [{"metric": "matplotlib_imported_by_import", "value": startup["matplotlib_imported_by_import"],
                    "unit": "1", "note": "1 = plotting library loaded without plotting"},
                   {"metric": "scipy_integrate_imported_by_import", "value": startup["scipy_integrate_imported_by_import"],
                    "unit": "1", "note": "1 = loaded at import (it is needed only by torque-driven runs)"},
                   {"metric": "scalar_peak", "value": peak / 1e9, "unit": "GFLOP/s",
                    "note": "tight multiply-add loop, 8 independent chains, kernels' compiler flags"}]


def _seed_rows(seeds: list[dict], ref: dict) -> list[dict]:
    """Summary rows of the seed cases' runs and of the NumPy reference."""
    rows = []
    for r in seeds:
        for k in ("setup_s", "rigid_s", "rigid_cpu_s", "kernel_s", "kernel_cpu_s", "python_overhead_s",
                  "python_overhead_cpu_s", "total_s", "total_cpu_s", "us_per_step", "ns_per_dof_step"):
            rows.append({"metric": f"seed.{r['case']}.{k}", "value": r[k], "unit": k.rsplit("_", 1)[-1] if k.endswith("_s") else k.split("_per")[0],
                         "note": f"model {r['model']}, {r['steps']} steps, {r['dofs']} DOFs"})
    for k, v in ref.items():
        rows.append({"metric": f"reference.{k}", "value": v, "unit": "", "note": "seed four-bar, hac, NumPy reference"})
    return rows


def _scaling_rows(ladder: list[dict], solves: list[dict]) -> list[dict]:
    """Summary rows of the mesh ladder (exponents, fractions of the peak) and of the solves."""
    rows = []
    for model in MODELS:
        rows += _exponent_rows(f"exponent.{model}", [(x["elements"], x["us_per_step"]) for x in ladder
                                                     if x["model"] == model and np.isfinite(x["us_per_step"])],
                               16, 1024, "time per step ~ elements^p, elements in total:")
        big = [x["peak_fraction"] for x in ladder if x["model"] == model and x["elements"] >= 64
               and np.isfinite(x["peak_fraction"])]
        if big:
            rows.append({"metric": f"peak_fraction_min_ge64.{model}", "value": min(big), "unit": "1",
                         "note": "smallest fraction of the scalar peak at >= 64 elements"})
    for key in ("banded_us", "dense_us"):
        rows += _exponent_rows(f"exponent.solve_{key[:-3]}", [(x["dofs"], x[key]) for x in solves if np.isfinite(x[key])],
                               50, math.inf, "LU + solve time ~ DOFs^p, DOFs:")
    return rows


def _memory_rows(memory: list[dict]) -> list[dict]:
    """Summary rows of the long runs' memory."""
    return [{"metric": f"memory.{m['steps']}_steps.{k}", "value": m[k], "unit": k.rsplit("_", 1)[-1],
             "note": f"fourbar_constant_speed, {m['frames']} frames (every 1000th step)"}
            for m in memory for k in ("tracemalloc_peak_MB", "maxrss_MB", "wall_s")]


def run_bench(out_dir="bench", quick: bool = False, cases_dir=None, progress=print) -> dict:
    """Run every measurement; write the CSV files and the PNG into out_dir (a
    :class:`~flexmech_py.run.outdir.ResultFolder`: whole or not at all); return all results."""
    cases = _seed_dir(cases_dir)
    hint = f"give a folder holding {SEED}, fourbar_constant_speed.toml and manipulator_bricout.toml (or leave out --cases)"
    checked_folder(cases, "--cases", "case files", hint)
    for name in (SEED, "fourbar_constant_speed.toml", "manipulator_bricout.toml"):
        checked_file(cases / name, "--cases", "case file", hint)
    with ResultFolder(out_dir, "bench") as rf:
        res = _measure(rf.stage, cases, quick, progress)
        rf.commit()
    res["paths"] = [rf.where(p) for p in res["paths"]]
    return res


def _measure(out: Path, cases: Path, quick: bool, progress) -> dict:
    """Every measurement of :func:`run_bench`, its files written into ``out``."""
    seed = cases / SEED
    reps = 1 if quick else 3
    t_all = time.perf_counter()
    progress("start-up (subprocesses)")
    startup = bench_startup(seed, reps)
    progress("seed cases")
    seeds = bench_seed_cases(cases, 1 if quick else 2)
    progress("scalar multiply-add peak")
    peak = bench_peak(quick)
    progress("mesh ladder")
    ladder = bench_ladder(seed, peak, quick, progress)
    progress("NumPy reference")
    ref = bench_reference(seed, 20 if quick else 200, reps)
    progress("banded and dense solves")
    solves = bench_solves(seed, quick, progress)
    progress("memory of long runs (subprocesses)")
    memory = bench_memory(cases, quick)
    progress("scaling on every bundled mechanism and model")
    scaling = bench_scaling(cases, quick, progress)
    progress("side by side with Exudyn (seed four-bar, seed manipulator, plate six-bar)")
    side = exudyn_sections(seed, cases, quick, progress)

    progress("stepping from Python, one step per call (seed four-bar)")
    stepping = bench_stepping(seed, quick, progress)

    summary = (_startup_rows(startup, peak) + _seed_rows(seeds, ref) + _scaling_rows(ladder, solves)
               + scaling_rows(scaling) + _memory_rows(memory) + exudyn_rows(side)
               + [{"metric": f"stepping_ratio_{r['model']}", "value": r["ratio"], "unit": "1",
                   "note": f"{r['overhead_us_per_call']:.3g} us per call"} for r in stepping])
    summary.append({"metric": "bench_wall", "value": time.perf_counter() - t_all, "unit": "s", "note": "quick" if quick else "full"})

    paths = [out / "bench_ladder.csv", out / "bench_solves.csv", out / "bench_summary.csv", out / "bench_seed.csv",
             out / "bench_scaling.csv", out / "bench_scaling_fits.csv"]
    for path, rows in zip(paths, (ladder, solves, summary, seeds, scaling, scaling_summary(scaling))):
        write_csv(path, rows)
    if stepping:
        paths.append(out / "bench_stepping.csv")
        write_csv(paths[-1], stepping)
    for name in ("exudyn", "exudyn_manipulator", "exudyn_mechanism"):
        if side[name]:
            paths.append(out / f"bench_{name}.csv")
            write_csv(paths[-1], side[name])
    png = _plot(out / "bench.png", ladder, solves)
    if png is not None:
        paths.append(png)
    return {"startup": startup, "seeds": seeds, "peak": peak, "ladder": ladder, "reference": ref, "solves": solves,
            "memory": memory, "scaling": scaling, "stepping": stepping, **side, "summary": summary, "paths": paths}


def report(res: dict) -> str:
    """The stdout tables of a run_bench result."""
    out = ["seed cases (wall and CPU seconds; per step: kernel CPU)",
           table(res["seeds"], ["case", "model", "steps", "dofs", "setup_s", "rigid_s", "rigid_cpu_s", "kernel_s",
                                "kernel_cpu_s", "python_overhead_s", "total_s", "total_cpu_s", "us_per_step",
                                "ns_per_dof_step"]),
           "", "mesh ladder (seed four-bar, dt = 1e-5 s; kernel CPU time per step)",
           table(res["ladder"], ["model", "elements_per_link", "dofs", "bandwidth", "steps", "us_per_step",
                                 "ns_per_dof_step", "newton_per_step", "flops_per_step", "gflops", "peak_fraction"]),
           "", "banded against dense LU + solve of the effective matrix",
           table(res["solves"], ["elements_per_link", "dofs", "bandwidth", "banded_us", "dense_us"]),
           "", "long runs (output every 1000th step)",
           table(res["memory"], ["steps", "frames", "tracemalloc_peak_MB", "maxrss_MB", "wall_s"]),
           "", "stepping from Python, one step per call, against the batch run (seed four-bar; CPU)",
           table(res["stepping"], ["model", "steps", "batch_us_per_step", "ratio", "overhead_us_per_call",
                                   "max_rel_difference"]) if res.get("stepping") else "  (not run)",
           "", "scaling on every bundled mechanism (kernel CPU per step [us] against elements per link; "
               "generalized-alpha, dt = 1e-5 s)",
           table(scaling_pivot(res["scaling"]), list(scaling_pivot(res["scaling"])[0])),
           "", "scaling fits (exponent of time per step against elements; cost per element relative to the seed four-bar's)",
           table(scaling_summary(res["scaling"]), ["case", "model", "ladder", "exponent_time", "exponent_flops",
                                                   "us_per_element_step_finest", "relative_to_seed_fourbar",
                                                   "newton_per_step_finest"]),
           *exudyn_report(res),
           "", "summary", table(res["summary"], ["metric", "value", "unit", "note"])]
    return "\n".join(out)


if __name__ == "__main__":   # python -m flexmech_py.studies.bench --memory-probe CASE NSTEPS OUT_EVERY (used by bench_memory)
    if len(sys.argv) == 5 and sys.argv[1] == "--memory-probe":
        print(json.dumps(memory_probe(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]))))
    else:
        raise SystemExit("usage: python -m flexmech_py.studies.bench --memory-probe CASE NSTEPS OUT_EVERY (or: flexmech bench)")
