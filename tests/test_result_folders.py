"""Every command's result folder (flexmech_py.run.outdir): whole or absent, one writer at a time, names
that cannot leave it.  Per command: a real SIGTERM arriving before the result is put in place, and a
disk too full to start; the bad folders of every command are in the catalogue (tests/fault_catalogue.py).
Then the folder's own rules: the commit journal finished after a crash, an earlier attempt's files
replaced or refused, the lock of a killed process taken over, file names made from user text."""

from __future__ import annotations

import fcntl
import json
import os
import resource
import shutil
import signal
from pathlib import Path

import pytest

from flexmech_py.run import outdir
from flexmech_py.cli import main
from flexmech_py.base.errors import CaseError
from flexmech_py.base.folderlock import LOCK_NAME, Busy, FolderLock
from flexmech_py.base.names import inside, safe_name
from flexmech_py.run.outdir import MANIFEST, MARKER, PARTIAL_DIR, ResultFolder

from test_faults import SmallDisk

FAST = ["--set", "solver.t_end=0.004"]
REF = "# source: a test\nt,slider_x\n0,0.45\n0.001,0.449\n0.002,0.447\n"


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory) -> Path:
    """A finished small run with shape.csv (for compare and draw)."""
    out = tmp_path_factory.mktemp("r") / "R"
    assert main(["run", "slider_crank", *FAST, "--elements-per-link", "2", "--no-plots", "--quiet", "--draw", "3",
                 "--out", str(out)]) == 0
    return out


def _command(name: str, tmp: Path, run_folder: Path) -> tuple[list, Path, str]:
    """(argv, the folder it writes, the manifest key) of a quick form of every command."""
    out = tmp / "D"
    if name in ("compare", "draw"):
        shutil.copytree(run_folder, tmp / "R")
        (tmp / "ref.csv").write_text(REF)
    return {
        "run": (["run", "slider_crank", *FAST, "--elements-per-link", "2", "--no-plots", "--quiet"], out, "run"),
        "steady": (["steady", "fourbar_constant_speed", "--set", "mesh.elements_per_link=2", "--no-plots"], out, "steady"),
        "modes": (["modes", "slider_crank", "--no-plots"], out, "modes"),
        "sweep": (["sweep", "slider_crank", "--param", "drives.0.speed=100,150", *FAST, "--jobs", "1"], out, "sweep"),
        "samples": (["sweep", "slider_crank", "--sample", "drives.0.speed=normal:150:1", "--samples", "2", *FAST,
                     "--jobs", "1", "--no-plots"], out, "samples"),
        "stability": (["stability", "fourbar_constant_speed", "--speed", "600", "--refine-rounds", "0", "--jobs", "1",
                       "--no-plots"], out, "stability"),
        "accuracy": (["accuracy", "slider_crank", "--set", "solver.t_end=0.002", "--dt-levels", "2", "--elements", "2",
                      "--ref-elements", "8", "--jobs", "1", "--quiet", "--no-plots"], out,
                     "accuracy"),
        "compare": (["compare", str(tmp / "R"), "--reference", str(tmp / "ref.csv")], out, "compare"),
        "compare-models": (["compare", "--models", "slider_crank", "--model-list", "hac", "--reference-model", "classic",
                            "--set", "solver.t_end=0.002", "--jobs", "1"], out, "compare-models"),
        "draw": (["draw", str(tmp / "R")], out / "drawing.png", "draw"),
        "reproduce": (["reproduce", "--t-end", "0.002", "--no-gap"], out, "reproduce"),
        "bench": (["bench", "--quick"], out, "bench"),
    }[name]


COMMANDS = ["run", "steady", "modes", "sweep", "samples", "stability", "accuracy", "compare", "compare-models", "draw",
            "reproduce", "bench"]


def _fake_slow_parts(monkeypatch):
    """reproduce and bench as their folders see them, without their minutes of runs."""
    import flexmech_py.studies.bench as bench
    import flexmech_py.studies.reproduce as reproduce

    def reproduce_into(out, *a):
        (out / "report.md").write_text("new report\n")
        return out / "report.md"

    def measure(out, *a):
        (out / "bench_summary.csv").write_text("metric,value\n")
        return {"paths": [out / "bench_summary.csv"]}
    monkeypatch.setattr(reproduce, "_reproduce_into", reproduce_into)
    monkeypatch.setattr(bench, "_measure", measure)


def _plant_old_result(target: Path, key: str) -> dict:
    """An earlier result of command ``key`` in ``target``'s folder; its files' bytes."""
    if key == "draw":
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(b"old drawing")
        return {target.name: b"old drawing"}
    target.mkdir(parents=True)
    (target / "old.txt").write_text("old result")
    (target / MANIFEST).write_text(json.dumps({key: {"files": ["old.txt"], "status": "complete"}}))
    return {"old.txt": b"old result"}


@pytest.mark.parametrize("name", COMMANDS)
def test_sigterm_before_the_result_is_in_place_keeps_the_old_one(name, tmp_path, run_folder, monkeypatch, capsys):
    """A real SIGTERM to this process while the command runs (just before its commit): exit 143, one
    line, the earlier result untouched, the new files apart in flexmech-partial/, marked."""
    argv, target, key = _command(name, tmp_path, run_folder)
    _fake_slow_parts(monkeypatch)
    old = _plant_old_result(target, key)
    real = ResultFolder.commit

    def commit(self):
        os.kill(os.getpid(), signal.SIGTERM)     # delivered to the command line's handler at once
        real(self)
    monkeypatch.setattr(ResultFolder, "commit", commit)
    code = main(argv + ["--out", str(target)])
    err = capsys.readouterr().err
    assert code == 128 + signal.SIGTERM, err
    assert err.strip().splitlines()[-1] == "flexmech: terminated by SIGTERM"
    folder = target.parent if key == "draw" else target
    assert {n: (folder / n).read_bytes() for n in old} == old
    assert not (folder / LOCK_NAME).exists()
    if key != "draw":
        assert "terminated by SIGTERM" in (target / PARTIAL_DIR / MARKER).read_text()
    else:
        assert sorted(p.name for p in folder.iterdir()) == ["drawing.png"]


@pytest.mark.parametrize("name", COMMANDS)
def test_a_disk_too_full_to_start_refuses_every_command(name, tmp_path, run_folder, monkeypatch, capsys):
    """Exit 2, one line naming --out, nothing left on the disk: a tmpfs left with 200 kB, or a 200 kB
    file-size limit on this process (the 1 MiB reserve cannot be made)."""
    (tmp_path / "disk").mkdir()
    disk = SmallDisk(tmp_path / "disk")
    try:
        argv, target, key = _command(name, tmp_path, run_folder)
        target = disk.root / target.relative_to(tmp_path)
        _fake_slow_parts(monkeypatch)
        disk.leave(200_000)
        before = sorted(p.name for p in disk.root.iterdir())
        old = resource.getrlimit(resource.RLIMIT_FSIZE)
        if disk.mode == "rlimit":
            resource.setrlimit(resource.RLIMIT_FSIZE, (disk.limit, old[1]))
        try:
            code = main(argv + ["--out", str(target)])
        finally:
            resource.setrlimit(resource.RLIMIT_FSIZE, old)
        err = capsys.readouterr().err
        lines = [ln for ln in err.splitlines() if ln.startswith("flexmech: error:")]
        assert code == 2 and len(lines) == 1 and "--out" in lines[0] and "no room to start" in lines[0], err
        assert sorted(p.name for p in disk.root.iterdir()) == before
    finally:
        disk.close()


# ----------------------------------------------------------------------------- the folder's own rules
def test_a_commit_cut_short_is_finished_by_the_next_command(tmp_path):
    out = tmp_path / "D"
    with ResultFolder(out, "modes") as rf:
        (rf.stage / "a.csv").write_text("one")
        rf.commit()
    with ResultFolder(out, "modes") as rf:         # the second result, its commit killed after one rename
        (rf.stage / "a.csv").write_text("two")
        (rf.stage / "b.csv").write_text("two")
        journal = rf._journal("complete")
        os.replace(rf.stage / "a.csv", out / "a.csv")
        rf.committed = True                        # as if the process had died here (no stop, no cleanup)
    assert (out / PARTIAL_DIR / "b.csv").exists() and journal["put"] == ["a.csv", "b.csv"]
    with ResultFolder(out, "sweep") as rf:         # any next command into the folder finishes it first
        assert any("finished putting" in n for n in rf.notes)
    assert (out / "a.csv").read_text() == "two" and (out / "b.csv").read_text() == "two"
    assert not (out / PARTIAL_DIR).exists()
    assert json.loads((out / MANIFEST).read_text())["modes"]["files"] == ["a.csv", "b.csv"]


def test_a_commit_replaces_only_what_the_same_command_wrote(tmp_path):
    out = tmp_path / "D"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    for files in (["x.csv", "x.png"], ["x.csv"]):
        with ResultFolder(out, "modes") as rf:
            for f in files:
                (rf.stage / f).write_text("m")
            rf.commit()
    with ResultFolder(out, "sweep") as rf:
        (rf.stage / "sweep.csv").write_text("s")
        rf.commit()
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST, "notes.txt", "sweep.csv", "x.csv"]


def test_an_earlier_attempt_is_replaced_by_the_same_command_and_refused_to_another(tmp_path):
    out = tmp_path / "D"
    with pytest.raises(KeyboardInterrupt):
        with ResultFolder(out, "modes") as rf:
            (rf.stage / "a.csv").write_text("half")
            raise KeyboardInterrupt
    assert (out / PARTIAL_DIR / "a.csv").exists()   # nothing to protect, but not marked: kept apart
    with pytest.raises(CaseError, match="unfinished files of .*result: modes|flexmech-partial"):
        with ResultFolder(out, "sweep"):
            pass
    with ResultFolder(out, "modes") as rf:
        assert any("replaced the unfinished files" in n for n in rf.notes)
        rf.commit()
    assert not (out / PARTIAL_DIR).exists()


def test_a_failed_command_that_wrote_nothing_leaves_nothing(tmp_path):
    out = tmp_path / "a" / "b" / "D"
    with pytest.raises(CaseError):
        with ResultFolder(out, "modes"):
            raise CaseError("x", "bad")
    assert not (tmp_path / "a").exists()


def test_the_lock_names_its_holder_and_a_dead_holder_is_taken_over(tmp_path):
    out = tmp_path / "D"
    out.mkdir()
    with FolderLock(out, command="flexmech run first") as lock:
        with pytest.raises(Busy, match=f"process {os.getpid()} .*flexmech run first"):
            FolderLock(out).acquire()
        assert lock.stale is None
    fd = os.open(out / LOCK_NAME, os.O_RDWR | os.O_CREAT)   # a record left by a killed process, no flock
    os.write(fd, json.dumps({"pid": 999999, "host": os.uname().nodename, "command": "flexmech run gone"}).encode())
    os.close(fd)
    with FolderLock(out) as lock:
        assert lock.stale["pid"] == 999999
    assert not (out / LOCK_NAME).exists()
    fd = os.open(out / LOCK_NAME, os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX)                # held by another open file: refused while held
    try:
        with pytest.raises(Busy):
            FolderLock(out).acquire()
    finally:
        os.close(fd)


# ----------------------------------------------------------------------------- names from user text
def test_safe_names_keep_ordinary_names_and_never_leave_the_folder(tmp_path):
    assert safe_name("strain_coupler_mid") == "strain_coupler_mid"
    for bad in ("x/../../../TRAVERSED", "..", ".", "/etc/passwd", "a\0b", "", "-rf", "a" * 500, "..\\..\\x", "é/ü"):
        name = safe_name(bad)
        assert "/" not in name and "\0" not in name and name not in (".", "..") and not name.startswith((".", "-"))
        assert len(name) <= 120 and inside(tmp_path, name).parent == tmp_path
    assert safe_name("a/b") != safe_name("a_b")      # two names stay two files
    with pytest.raises(Exception):
        inside(tmp_path, "../x")


def _files(root: Path) -> set:
    return {p for p in root.rglob("*") if p.is_file()}


def test_compare_writes_a_traversing_column_inside_its_folder(tmp_path, run_folder, capsys):
    """The issue's case: a result column named x/../../../TRAVERSED compared with a reference that has
    it, a folder RESULT/compare/compare_x/ present: every file stays in RESULT/compare."""
    res = tmp_path / "deep" / "er" / "RESULT"
    res.mkdir(parents=True)
    bad = "x/../../../TRAVERSED"
    (res / "timeseries.csv").write_text(f"# complete: 3 frames\n# flexmech\n# units: s,m\nt,{bad}\n0,1\n0.001,2\n0.002,3\n")
    (res / "compare" / "compare_x").mkdir(parents=True)
    (tmp_path / "ref.csv").write_text(f"# source: test\nt,{bad}\n0,1\n0.001,2.1\n0.002,3\n")
    before = _files(tmp_path)
    assert main(["compare", str(res), "--reference", str(tmp_path / "ref.csv")]) == 0
    new = _files(tmp_path) - before
    assert new and all((res / "compare") in p.parents for p in new), new
    assert not list(tmp_path.rglob("TRAVERSED*"))
    assert any(p.name.startswith("compare_x_.._") for p in new)


@pytest.mark.parametrize("where, text", [("links", '"../../LINK"'), ("outputs", '"../../OUT"'),
                                         ("joints", '"../../JOINT"')])
def test_names_in_a_case_file_cannot_become_paths(tmp_path, where, text, capsys):
    """Link, output and joint names are identifiers: a traversing one is refused before anything is written."""
    src = (Path(__file__).parents[1] / "cases" / "slider_crank.toml").read_text()
    edit = {"links": ('name = "rod"', f"name = {text}"), "outputs": ("strain_rod_mid =", f"{text} ="),
            "joints": ('name = "slide"', f"name = {text}")}[where]
    (tmp_path / "c.toml").write_text(src.replace(*edit, 1))
    before = _files(tmp_path)
    code = main(["run", str(tmp_path / "c.toml"), *FAST, "--out", str(tmp_path / "o")])
    assert code == 2 and "identifier" in capsys.readouterr().err
    assert _files(tmp_path) == before and not (tmp_path / "o").exists()


def test_a_case_file_name_becomes_a_safe_default_folder(tmp_path, monkeypatch, capsys):
    src = (Path(__file__).parents[1] / "cases" / "slider_crank.toml").read_text()
    (tmp_path / "..toml").write_text(src)                 # its stem is "."
    (tmp_path / "-x y.toml").write_text(src)
    monkeypatch.chdir(tmp_path)
    for name in ("..toml", "-x y.toml"):
        assert main(["run", name, *FAST, "--elements-per-link", "2", "--no-plots", "--quiet"]) == 0
    made = sorted(p.name for p in (tmp_path / "results").iterdir())
    assert len(made) == 2 and all(not n.startswith((".", "-")) and " " not in n for n in made), made


def test_draw_into_an_existing_folder_writes_inside_it_and_says_so(tmp_path, run_folder, capsys):
    shutil.copytree(run_folder, tmp_path / "R")
    (tmp_path / "pictures").mkdir()
    assert main(["draw", str(tmp_path / "R"), "--out", str(tmp_path / "pictures")]) == 0
    out = capsys.readouterr().out
    assert (tmp_path / "pictures" / "drawing.png").stat().st_size > 1000
    assert out.startswith(f"wrote {tmp_path / 'pictures' / 'drawing.png'} ")
    assert sorted(p.name for p in (tmp_path / "pictures").iterdir()) == ["drawing.png"]
