"""Runs of any size (docs/theory.md section 19, docs/cli.md): a run goes chunk by chunk, its frames
streamed to timeseries.csv as they come; the numbers do not depend on the chunking or on whether the
frames are kept in memory; memory does not grow with the run's length; a run stopped by Ctrl-C keeps
what it wrote, marked; a re-run into the same folder replaces the old run's files; a run that would
not fit on the disk is refused before anything is written."""

import json
import os
import signal
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

import flexmech_py as fm
from flexmech_py.run import runner
from flexmech_py.cli import main
from flexmech_py.run.frames import ColumnStats, Envelope
from flexmech_py.base.progress import RunProgress
from flexmech_py.run.results import STATUS_BYTES, read_timeseries
from flexmech_py.run.simulate import Prepared


def _case(cases_dir, name, *sets):
    return fm.load_case(cases_dir / f"{name}.toml", overrides=list(sets))


@pytest.mark.parametrize("name, model, t_end", [("fourbar_hac", "hac", 0.03), ("slider_crank", "coupled", 0.01),
                                                ("fourbar_constant_speed", "nonlinear", 0.012)])
def test_streamed_files_equal_the_run_kept_in_memory(cases_dir, tmp_path, name, model, t_end):
    """Same CSV bytes and the same summary statistics whether the frames are kept or streamed, and
    whatever the chunk size (the first chunk 256 steps then doubling, or fixed 300-step chunks)."""
    case = _case(cases_dir, name, f"solver.t_end={t_end}", "solver.output_every=3")
    kept = Prepared(case).run(model)
    kept.write(tmp_path / "kept")
    streamed = Prepared(case).stream(tmp_path / "streamed", model)
    fixed = Prepared(case, chunk_steps=300).stream(tmp_path / "fixed", model)
    ref = (tmp_path / "kept" / "timeseries.csv").read_bytes()
    assert Prepared(case).nsteps > 256 + 512               # three chunks or more of either kind
    assert (tmp_path / "streamed" / "timeseries.csv").read_bytes() == ref
    assert (tmp_path / "fixed" / "timeseries.csv").read_bytes() == ref
    for res in (streamed, fixed):
        assert res.t.size < kept.t.size                     # only the last block is held
        assert res.summary()["outputs"] == kept.summary()["outputs"]
        clocks = ("kernel_s", "wall_s")
        same = {k: v for k, v in res.extra["error_estimate"].items() if k not in clocks}
        assert same == {k: v for k, v in kept.extra["error_estimate"].items() if k not in clocks}
    cols, _ = read_timeseries(tmp_path / "streamed" / "timeseries.csv")
    np.testing.assert_allclose(cols["t"], kept.t, rtol=1e-9)


def test_status_line_is_rewritten_in_place(cases_dir, tmp_path):
    case = _case(cases_dir, "fourbar_hac", "solver.t_end=0.01")
    Prepared(case).stream(tmp_path, "hac")
    raw = (tmp_path / "timeseries.csv").read_bytes()
    first = raw.split(b"\n", 1)[0]
    assert len(first) == STATUS_BYTES and first.startswith(b"# complete: 101 frames")
    assert not (tmp_path / "timeseries.csv.part").exists()


def test_memory_does_not_grow_with_the_run(cases_dir, tmp_path):
    """Peak Python-side memory of a streamed run 8x longer stays within 1.5x (a kept run's grows 8x)."""
    def peak(t_end, keep):
        case = _case(cases_dir, "fourbar_constant_speed", f"solver.t_end={t_end}", "solver.output_every=1",
                     "solver.error_estimate='none'")
        p = Prepared(case, chunk_steps=2000)
        tracemalloc.start()
        if keep:
            p.run("hac")
        else:
            p.stream(tmp_path / f"s{t_end}", "hac")
        _, top = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        return top

    short, long = peak(0.05, False), peak(0.4, False)
    kept_short, kept_long = peak(0.05, True), peak(0.4, True)
    print(f"\npeak traced memory: streamed {short / 1e6:.2f} -> {long / 1e6:.2f} MB, "
          f"kept {kept_short / 1e6:.2f} -> {kept_long / 1e6:.2f} MB for 8x the steps")
    assert long < 1.5 * short
    assert kept_long > 4 * kept_short


def test_envelope_keeps_every_extreme_and_both_ends():
    rng = np.random.default_rng(3)
    n = 200_000
    t = np.arange(n) * 1e-3
    y = {"a": rng.normal(size=n), "b": np.cumsum(rng.normal(size=n))}
    env, stats = Envelope(buckets=50), ColumnStats()
    for i0 in range(0, n, 7919):
        sl = slice(i0, i0 + 7919)
        env.add(t[sl], {k: v[sl] for k, v in y.items()})
        stats.add(t[sl], {k: v[sl] for k, v in y.items()})
    assert env.t.size <= 2 * 2 * 50 * 2 + 2
    assert env.t[0] == t[0] and env.t[-1] == t[-1] and np.all(np.diff(env.t) > 0)
    for k, v in y.items():
        assert env.columns[k].min() == v.min() == stats.columns[k]["min"]
        assert env.columns[k].max() == v.max() == stats.columns[k]["max"]
        # every bucket of the final width shows its own extremes
        w = env.width
        for b in (0, 17, n // w - 1):
            seg = v[b * w:(b + 1) * w]
            inb = (env.t >= t[b * w]) & (env.t <= t[min(n, (b + 1) * w) - 1])
            assert env.columns[k][inb].max() == seg.max() and env.columns[k][inb].min() == seg.min()


def test_ctrl_c_keeps_the_frames_written_marked_interrupted(cases_dir, tmp_path):
    case = _case(cases_dir, "fourbar_hac", "solver.t_end=0.05")
    calls = []

    def progress(done, total):
        calls.append(done)
        if len(calls) == 3:
            raise KeyboardInterrupt

    with pytest.raises(fm.Interrupted) as err:
        Prepared(case).stream(tmp_path, "hac", progress=progress)
    res = err.value.partial
    assert isinstance(err.value, KeyboardInterrupt)       # a batch that stops on Ctrl-C still stops
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["frames"] == res.all_stats().frames
    cols, _ = read_timeseries(tmp_path / "timeseries.csv")
    assert cols["t"].size == summary["frames"] and 1 < summary["frames"] < Prepared(case).frames
    head = (tmp_path / "timeseries.csv").read_text().splitlines()[0]
    assert head.startswith("# partial: interrupted by the user")


def test_a_run_that_would_not_fit_on_the_disk_is_refused(cases_dir, tmp_path, monkeypatch):
    case = _case(cases_dir, "fourbar_hac", "solver.t_end=0.05")
    free = 2_000.0
    monkeypatch.setattr(runner.shutil, "disk_usage", lambda p: type("U", (), {"free": free})())
    with pytest.raises(fm.CaseError) as err:
        Prepared(case).stream(tmp_path / "out", "hac")
    assert err.value.field == "solver.output_every" and "--force" in str(err.value)
    assert "solver.output_every=" in str(err.value)
    assert not (tmp_path / "out").exists()                 # nothing written
    Prepared(case).stream(tmp_path / "out", "hac", force=True)
    assert (tmp_path / "out" / "timeseries.csv").exists()


def test_progress_estimate_and_bar_on_a_fake_clock():
    class Clock:
        now = 0.0

        def __call__(self):
            return self.now

    class Tty:
        def __init__(self, tty):
            self.text, self.tty = "", tty

        def write(self, s):
            self.text += s

        def flush(self):
            pass

        def isatty(self):
            return self.tty

    def drive(stream, total_s, **kw):
        clock = Clock()
        pr = RunProgress(lambda: "N steps", stream=stream, clock=clock, **kw)
        for k in range(1, 11):
            clock.now = total_s * k / 10
            pr(k * 100, 1000)
        pr.close(finished=True)
        return stream.text

    long = drive(Tty(True), 60.0)
    assert long.count("this run takes about 1 min 00 s (N steps)") == 1
    assert "100.0 %" in long and "\r[" in long
    assert drive(Tty(False), 60.0).count("\r") == 0                       # not a terminal: no bar
    assert "\r[" in drive(Tty(False), 60.0, bar=True)                     # unless asked
    assert drive(Tty(True), 1.5) == ""                                   # short: nothing at all
    assert drive(Tty(True), 60.0, quiet=True) == ""
    # a start-up of 5 s before the first block (1 % of the steps), then 10 s for the rest: the forecast
    # projects the rate since the first block (about 15 s), not 5 s / 1 % (8 min)
    clock, stream = Clock(), Tty(False)
    pr = RunProgress(lambda: "N steps", stream=stream, clock=clock)
    for now, done in ((5.0, 10), (6.0, 109), (7.0, 208), (15.0, 1000)):
        clock.now = now
        pr(done, 1000)
    assert "this run takes about 15" in stream.text, stream.text


def _run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_rerun_into_the_same_folder_replaces_the_old_files(cases_dir, tmp_path, capsys):
    case = str(cases_dir / "fourbar_hac.toml")
    out = tmp_path / "r"
    code, _, _ = _run(["run", case, "--set", "solver.t_end=0.01", "--out", str(out)], capsys)
    assert code == 0 and (out / "timeseries.png").exists()
    (out / "notes.txt").write_text("mine")
    code, _, _ = _run(["run", case, "--set", "solver.t_end=0.01", "--out", str(out), "--no-plots"], capsys)
    assert code == 0
    assert sorted(p.name for p in out.iterdir()) == [".flexmech-results.json", "notes.txt", "summary.json",
                                                     "timeseries.csv"]
    other = str(cases_dir / "manipulator_bricout.toml")
    before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    code, _, err = _run(["run", other, "--set", "solver.t_end=0.01", "--out", str(out)], capsys)
    assert code == 2 and err.count("\n") == 1 and "another case" in err and "--overwrite" in err
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == before
    code, _, _ = _run(["run", other, "--set", "solver.t_end=0.01", "--out", str(out), "--overwrite", "--quiet"],
                      capsys)
    assert code == 0 and (out / "notes.txt").read_text() == "mine"
    assert json.loads((out / "summary.json").read_text())["files"] == [
        "timeseries.csv", "summary.json", "timeseries.png"]


def test_cli_ctrl_c_exits_130_with_the_partial_result(cases_dir, tmp_path):
    """SIGINT to `flexmech run` as a terminal would send it: exit 130, the frames so far written."""
    exe = Path(sys.executable).with_name("flexmech")
    out = tmp_path / "r"
    p = subprocess.Popen([str(exe), "run", str(cases_dir / "fourbar_constant_speed.toml"), "--set",
                          "solver.t_end=200", "--out", str(out), "--no-plots"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    part = out / "flexmech-partial" / "timeseries.csv.part"      # the run's files while it goes
    t0 = time.monotonic()
    while not part.exists() and time.monotonic() - t0 < 60:
        time.sleep(0.05)
    time.sleep(0.5)
    p.send_signal(signal.SIGINT)
    stdout, stderr = p.communicate(timeout=60)
    assert p.returncode == 130, stderr
    assert "interrupted by the user" in stderr and "wrote partial results" in stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and 0 < summary["t_end"] < 200
    cols, _ = read_timeseries(out / "timeseries.csv")
    assert cols["t"].size == summary["frames"] and cols["t"][-1] == pytest.approx(summary["t_end"])
    assert not part.exists() and os.path.getsize(out / "timeseries.csv") > 0
