"""Faults made for real (docs/cli.md, "What is left on disk"): two commands into one folder, kill -9
and SIGTERM/SIGHUP of real `flexmech` processes, a full file system, a `--jobs 2` sweep killed
outright, a Dask scheduler killed mid-batch.  Each checks what a user finds afterwards: the earlier
result untouched, the new frames apart and marked, one line on stderr, the documented exit code.

The full file system is a small tmpfs where this runs as root and may mount one; elsewhere (a CI
container without CAP_SYS_ADMIN, a normal user) the same tests give the flexmech process a file-size
limit (RLIMIT_FSIZE: writes past it fail with EFBIG, which flexmech treats as a full disk); set
FLEXMECH_TEST_DISK=rlimit to take that way here too.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from flexmech_py.base.folderlock import LOCK_NAME
from flexmech_py.run.outdir import MARKER, PARTIAL_DIR
from flexmech_py.run.results import read_timeseries

PY = sys.executable
FLEXMECH = str(Path(sys.executable).with_name("flexmech"))
#: a run of slider_crank that streams for a long time (killed before it ends)
ENDLESS = ["run", "fourbar_constant_speed", "--set", "solver.t_end=200", "--no-plots", "--quiet"]
#: a short run
SHORT = ["run", "slider_crank", "--set", "solver.t_end=0.01", "--elements-per-link", "2", "--no-plots", "--quiet"]


def _start(args, **kw):
    return subprocess.Popen([FLEXMECH, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def _wait_for(pred, timeout=60.0, what="the condition"):
    t0 = time.monotonic()
    while not pred():
        if time.monotonic() - t0 > timeout:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


def _streaming(folder: Path, rows: int = 50):
    """True once a run writing into ``folder`` has streamed some rows into its staged part file."""
    part = folder / PARTIAL_DIR / "timeseries.csv.part"
    return lambda: part.exists() and part.stat().st_size > 400 + 40 * rows


def _one_error_line(stderr: str) -> str:
    """The one line saying why a command ended (besides warnings, notes and progress lines); no traceback."""
    lines = [ln for ln in stderr.splitlines() if ln.startswith("flexmech:")
             and not ln.startswith(("flexmech: warning:", "flexmech: note:"))]
    assert len(lines) == 1 and "Traceback" not in stderr and "ERROR" not in stderr, stderr
    return lines[0]


def _snapshot(folder: Path) -> dict:
    """The result files of a folder (not the lock a killed process leaves) and their bytes."""
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file() and p.name != LOCK_NAME}


def _check_whole_csv(path: Path, frames: int | None = None):
    cols, _ = read_timeseries(path)
    t = cols["t"]
    assert (t[1:] > t[:-1]).all(), "time is not increasing"
    if frames is not None:
        assert t.size == frames
    return t


# ----------------------------------------------------------------------------- two commands, one folder
def test_a_second_run_into_a_busy_folder_is_refused_naming_the_first(tmp_path):
    out = tmp_path / "D"
    first = _start(["run", "slider_crank", "--set", "solver.t_end=1", "--elements-per-link", "8", "--no-plots",
                    "--quiet", "--out", str(out)])
    _wait_for(lambda: (out / ".flexmech.lock").exists(), what="the first run's lock")
    second = subprocess.run([FLEXMECH, *SHORT, "--set", "drives.0.speed=100", "--out", str(out)],
                            capture_output=True, text=True, timeout=120)
    line = _one_error_line(second.stderr)
    assert second.returncode == 2 and "--out" in line and f"process {first.pid}" in line, line
    _, err = first.communicate(timeout=300)
    assert first.returncode == 0, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed"
    assert (out / "timeseries.csv").read_text().startswith(f"# complete: {summary['frames']} frames")
    _check_whole_csv(out / "timeseries.csv", summary["frames"])
    assert not (out / PARTIAL_DIR).exists() and not (out / ".flexmech.lock").exists()


# ----------------------------------------------------------------------------- kill -9, SIGTERM, SIGHUP
def test_a_rerun_killed_outright_leaves_the_old_result_and_its_frames_apart(tmp_path):
    out = tmp_path / "D"
    done = subprocess.run([FLEXMECH, *ENDLESS[:2], "--set", "solver.t_end=0.01", "--no-plots", "--quiet",
                           "--out", str(out)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    old = _snapshot(out)
    p = _start([*ENDLESS, "--out", str(out)])
    _wait_for(_streaming(out), what="the rerun's frames")
    p.kill()
    p.wait(timeout=30)
    assert _snapshot(out) == old                               # the earlier result, byte for byte
    assert json.loads((out / LOCK_NAME).read_text())["pid"] == p.pid   # a stale lock: its holder is dead
    stage = out / PARTIAL_DIR
    assert "status: running" in (stage / MARKER).read_text()   # marked: "if no such process runs, it was killed"
    assert (stage / "timeseries.csv.part").read_text().startswith("# running:")
    again = subprocess.run([FLEXMECH, *ENDLESS[:2], "--set", "solver.t_end=0.01", "--no-plots", "--quiet",
                            "--out", str(out)], capture_output=True, text=True, timeout=120)
    assert again.returncode == 0, again.stderr                 # the stale lock is taken over
    assert f"flexmech process {p.pid}" in again.stderr and "replaced the unfinished files" in again.stderr
    assert not stage.exists() and _snapshot(out)["timeseries.csv"] == old["timeseries.csv"]   # rerun: same bytes


@pytest.mark.parametrize("sig, earlier", [(signal.SIGTERM, False), (signal.SIGHUP, True)])
def test_sigterm_and_sighup_keep_the_frames_marked_and_exit_128_plus_n(tmp_path, sig, earlier):
    out = tmp_path / "D"
    if earlier:
        assert subprocess.run([FLEXMECH, *ENDLESS[:2], "--set", "solver.t_end=0.01", "--no-plots", "--quiet",
                               "--out", str(out)], capture_output=True).returncode == 0
    old = _snapshot(out) if earlier else {}
    p = _start([*ENDLESS, "--out", str(out)])
    _wait_for(_streaming(out), what="the run's frames")
    p.send_signal(sig)
    _, err = p.communicate(timeout=60)
    name = signal.Signals(sig).name
    assert p.returncode == 128 + sig, err
    assert _one_error_line(err).startswith(f"flexmech: stopped: terminated by {name} during the run; frames up to")
    kept = out / PARTIAL_DIR if earlier else out              # beside the earlier result, or in its place
    summary = json.loads((kept / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["failure"]["signal"] == name
    assert (kept / "timeseries.csv").read_text().startswith(f"# partial: terminated by {name}")
    _check_whole_csv(kept / "timeseries.csv", summary["frames"])
    if earlier:
        assert _snapshot(out) == old and f"stopped: terminated by {name}" in (kept / MARKER).read_text()
    else:
        assert not (out / PARTIAL_DIR).exists()


# ----------------------------------------------------------------------------- workers end with their parent
def _descendants(pid: int) -> set:
    out, todo = set(), [pid]
    while todo:
        p = todo.pop()
        for task in Path(f"/proc/{p}/task").glob("*"):
            try:
                kids = [int(x) for x in (task / "children").read_text().split()]
            except OSError:
                continue
            todo += [k for k in kids if k not in out]
            out.update(kids)
    return out


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc (Linux)")
def test_the_workers_of_a_sweep_killed_outright_end_with_it_and_it_resumes(tmp_path):
    out = tmp_path / "S"
    args = ["sweep", "slider_crank", "--param", "drives.0.speed=100:200:6", "--set", "solver.t_end=0.15",
            "--set", "mesh.elements_per_link=4", "--jobs", "2", "--out", str(out)]
    p = _start(args)
    _wait_for(lambda: len(list((out / "cache").glob("*.json"))) >= 1, timeout=120, what="a finished point")
    kids = _descendants(p.pid)
    assert len(kids) >= 3                         # two pool workers and the resource tracker
    p.kill()
    p.wait(timeout=30)
    t0 = time.monotonic()
    _wait_for(lambda: not any(_alive(k) for k in kids), timeout=10, what="the workers to end")
    print(f"\n{len(kids)} worker processes ended {time.monotonic() - t0:.2f} s after their parent was killed")
    cached = len(list((out / "cache").glob("*.json")))
    assert not (out / "sweep.csv").exists()
    again = subprocess.run([FLEXMECH, *args], capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    assert f"{cached} cached" in again.stdout


# ----------------------------------------------------------------------------- a full file system
class SmallDisk:
    """A folder whose file system fills: a tmpfs (``mode = "tmpfs"``) or, where none can be mounted, a
    file-size limit given to the flexmech process (``mode = "rlimit"``)."""

    def __init__(self, root: Path):
        self.root = root
        self.mode = "rlimit"
        self.limit = None
        if os.geteuid() == 0 and shutil.which("mount") and os.environ.get("FLEXMECH_TEST_DISK") != "rlimit":
            r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=8m", "tmpfs", str(root)], capture_output=True)
            self.mode = "tmpfs" if r.returncode == 0 else "rlimit"

    def leave(self, free_bytes: int) -> None:
        """Fill the disk (tmpfs) or limit every file (rlimit) so that about ``free_bytes`` can be written."""
        if self.mode == "rlimit":
            self.limit = free_bytes
            return
        filler = self.root / "filler"
        filler.unlink(missing_ok=True)
        st = os.statvfs(self.root)
        with open(filler, "wb") as f:
            os.posix_fallocate(f.fileno(), 0, st.f_bavail * st.f_frsize - free_bytes)

    def run(self, args, reserve: int | None = None) -> subprocess.CompletedProcess:
        """``flexmech args`` in a process on this disk; ``reserve``: the result folder's reserve [bytes]."""
        code = ("import sys; import flexmech_py.run.outdir as o; o.RESERVE_BYTES = int(sys.argv[1]) or o.RESERVE_BYTES; "
                "from flexmech_py.cli import main; raise SystemExit(main(sys.argv[2:]))")
        limit = self.limit

        def pre():
            if limit is not None:
                resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
        return subprocess.run([PY, "-c", code, str(reserve or 0), *args], capture_output=True, text=True, timeout=300,
                              preexec_fn=pre, cwd=self.root)

    def close(self) -> None:
        if self.mode == "tmpfs":
            subprocess.run(["umount", "-l", str(self.root)], capture_output=True)


@pytest.fixture
def disk(tmp_path):
    root = tmp_path / "disk"
    root.mkdir()
    d = SmallDisk(root)
    print(f"\nfull file system made with: {d.mode}")
    yield d
    d.close()


def test_a_disk_too_full_to_start_refuses_with_exit_2_and_leaves_all_as_it_was(disk):
    out = disk.root / "D"
    assert disk.run([*SHORT, "--out", str(out)]).returncode == 0
    old = _snapshot(out)
    disk.leave(200_000)                                         # less than the 1 MiB a command keeps in hand
    r = disk.run([*SHORT, "--set", "drives.0.speed=100", "--out", str(out)])
    line = _one_error_line(r.stderr)
    assert r.returncode == 2 and line.startswith("flexmech: error: --out:") and "no room to start" in line, line
    assert _snapshot(out) == old and sorted(p.name for p in out.iterdir()) == sorted(old)


def test_a_disk_that_fills_during_the_run_exit_3_the_old_result_kept_the_frames_marked(disk):
    out = disk.root / "D"
    assert disk.run([*SHORT, "--out", str(out)], reserve=65536).returncode == 0
    old = _snapshot(out)
    disk.leave(65536 + 400_000)
    r = disk.run(["run", "slider_crank", "--set", "solver.t_end=0.3", "--set", "solver.output_every=1",
                  "--elements-per-link", "2", "--no-plots", "--quiet", "--force", "--out", str(out)], reserve=65536)
    line = _one_error_line(r.stderr)
    assert r.returncode == 3 and "timeseries.csv.part failed" in line, line
    assert _snapshot(out) == old
    stage = out / PARTIAL_DIR
    summary = json.loads((stage / "summary.json").read_text())
    assert summary["status"] == "failed" and summary["failure"]["cause"] == "write_failed"
    assert (stage / "timeseries.csv").read_text().startswith("# partial: the run stopped")
    _check_whole_csv(stage / "timeseries.csv", summary["frames"])     # whole rows only: the torn block cut off
    assert "stopped:" in (stage / MARKER).read_text()


def test_a_disk_that_fills_while_the_plots_are_written_names_the_file(disk, tmp_path):
    out = disk.root / "D"
    args = ["run", "slider_crank", "--set", "solver.t_end=0.01", "--elements-per-link", "2", "--quiet"]
    numbers = tmp_path / "numbers"                             # the same run's CSV and summary, on a roomy disk
    assert subprocess.run([PY, "-m", "flexmech_py", *args, "--no-plots", "--out", str(numbers)],
                          capture_output=True).returncode == 0
    sizes = [p.stat().st_size for p in numbers.iterdir() if p.is_file() and p.suffix in (".csv", ".json")]
    pages = sum(4096 * -(-n // 4096) for n in sizes)           # tmpfs allocates whole pages
    room = max(sizes) if disk.mode == "rlimit" else pages      # rlimit bounds each file, tmpfs the sum
    disk.leave(65536 + room + 16384)                           # the CSV and summary fit, timeseries.png does not
    r = disk.run([*args, "--out", str(out)], reserve=65536)
    line = _one_error_line(r.stderr)
    assert r.returncode == 3 and ".png failed" in line and PARTIAL_DIR in line, line
    stage = out / PARTIAL_DIR
    assert json.loads((stage / "summary.json").read_text())["status"] == "completed"   # the numbers are whole
    assert "png failed" in (stage / MARKER).read_text()
    assert not any(p.suffix == ".png" for p in stage.iterdir())  # the file cut short is not left
    assert not (out / "summary.json").exists()                 # nothing in the result's place


# ----------------------------------------------------------------------------- a Dask scheduler killed
def test_a_killed_dask_scheduler_is_one_line_exit_3_and_the_finished_runs_stay_cached(tmp_path):
    """A real `dask scheduler` and `dask worker` (own sessions); the scheduler killed with kill -9 once
    a run has finished: the sweep ends with one line and exit 3, the finished runs in its cache, no
    table.  (A worker killed mid-batch loses nothing: tests/test_cluster.py.)"""
    pytest.importorskip("distributed")
    dask = str(Path(sys.executable).with_name("dask"))
    sfile = tmp_path / "scheduler.json"
    procs = [subprocess.Popen([dask, "scheduler", "--scheduler-file", str(sfile), "--port", "0", "--no-dashboard"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)]
    try:
        _wait_for(lambda: sfile.exists() and sfile.stat().st_size > 0, timeout=60, what="the scheduler")
        procs.append(subprocess.Popen([dask, "worker", "--scheduler-file", str(sfile), "--nthreads", "1",
                                       "--nworkers", "1", "--no-dashboard"], stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL, start_new_session=True))
        out = tmp_path / "S"
        address = json.loads(sfile.read_text())["address"]
        p = _start(["sweep", "slider_crank", "--param", "drives.0.speed=100:200:8", "--set", "solver.t_end=0.15",
                    "--set", "mesh.elements_per_link=4", "--scheduler", address, "--out", str(out)])
        _wait_for(lambda: len(list((out / "cache").glob("*.json"))) >= 1, timeout=120, what="a finished run")
        procs[0].kill()
        _, err = p.communicate(timeout=120)
        line = _one_error_line(err)
        assert p.returncode == 3 and "--scheduler" in line and "stopped answering" in line and "cached" in line, err
        assert len(list((out / "cache").glob("*.json"))) >= 1 and not (out / "sweep.csv").exists()
        assert not (out / PARTIAL_DIR).exists()
    finally:
        for q in procs:
            try:
                os.killpg(q.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            q.wait(timeout=30)
