"""The README as a new user reads it: its Python snippet runs as written from the repository root and
from any other folder (a subprocess with this environment's python, as a user would start it), the
bundled cases are reachable by name, and what it says about the first run of the seed four-bar is
what flexmech prints and computes."""

import json
import re
import subprocess
import sys
from importlib import machinery
from pathlib import Path

import pytest

import flexmech_py as fm
from flexmech_py.cli import main

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def _snippet() -> str:
    section = README.split("### From Python", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def _repository_root_like(folder: Path) -> Path:
    """A folder that is the repository root as Python sees it: the source package and cases/ in it
    (links to the real ones).  Python started there finds the source flexmech_py first."""
    (folder / "flexmech_py").symlink_to(ROOT / "flexmech_py", target_is_directory=True)
    (folder / "cases").symlink_to(ROOT / "cases", target_is_directory=True)
    spec = machinery.PathFinder.find_spec("flexmech_py", [str(folder)])
    assert Path(spec.origin).resolve().parent == (ROOT / "flexmech_py").resolve()   # it does shadow
    return folder


def _run_snippet(cwd: Path, as_script: bool = False) -> subprocess.CompletedProcess:
    code = _snippet() + "\nimport sys; print(fm.__file__, file=sys.stderr)\n"
    if as_script:
        (cwd / "snippet.py").write_text(code)
        cmd = [sys.executable, "snippet.py"]
    else:
        cmd = [sys.executable, "-c", code]
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=300)


def test_readme_snippet_is_the_documented_one():
    code = _snippet()
    assert 'fm.load_case("cases/fourbar_hac.toml")' in code and 'res.write("out/fourbar")' in code


@pytest.mark.parametrize("as_script", [False, True], ids=["python -c", "python snippet.py"])
def test_readme_snippet_runs_from_the_repository_root(tmp_path, as_script):
    root = _repository_root_like(tmp_path)
    p = _run_snippet(root, as_script)
    assert p.returncode == 0, p.stderr
    assert (root / "out" / "fourbar" / "timeseries.csv").is_file()
    assert (root / "out" / "fourbar" / "summary.json").is_file()
    used = Path(p.stderr.strip().splitlines()[-1]).resolve().parent
    assert used != (ROOT / "flexmech_py").resolve()   # the installed package, with its kernels


def test_readme_snippet_runs_from_another_folder(tmp_path):
    assert not (tmp_path / "cases").exists()
    p = _run_snippet(tmp_path)
    assert p.returncode == 0, p.stderr
    summary = json.loads((tmp_path / "out" / "fourbar" / "summary.json").read_text())
    assert summary["t_end"] == pytest.approx(0.25) and summary["model"] == "hac"


def test_bundled_cases_reachable_by_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    names = fm.case_names()
    assert {"fourbar_hac", "fourbar_constant_speed", "manipulator_bricout", "extreme/spinup_beam"} <= set(names)
    for name in names:   # every bundled case is the source tree's file
        assert fm.case_path(name).read_text() == (ROOT / "cases" / f"{name}.toml").read_text(), name
    p = fm.case_path("fourbar_hac")
    assert fm.case_path("fourbar_hac.toml") == fm.case_path("cases/fourbar_hac.toml") == p
    for ref in ("fourbar_hac", "cases/fourbar_hac.toml"):
        assert fm.load_case(ref)["case"]["path"] == str(p)
    with pytest.raises(fm.CaseError, match="not a bundled case; bundled: .*fourbar_hac"):
        fm.case_path("no_such_case")
    with pytest.raises(fm.CaseError, match="does not exist"):
        fm.load_case("cases/no_such_case.toml")


def test_a_local_file_comes_before_the_bundled_one(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "cases").mkdir()
    text = (ROOT / "cases" / "fourbar_hac.toml").read_text().replace(
        'title = "Four-bar linkage, torque-driven from rest (Hac, Sec. 4.1)"', 'title = "my own four-bar"')
    (tmp_path / "cases" / "fourbar_hac.toml").write_text(text)
    case = fm.load_case("cases/fourbar_hac.toml")
    assert case["case"]["title"] == "my own four-bar" and case["case"]["path"] == "cases/fourbar_hac.toml"


def _warnings(capsys) -> list[str]:
    return [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("flexmech: warning:")]


def test_first_run_as_the_readme_describes_it(tmp_path, capsys):
    """'prints six warnings'; 'from t = 0.055 s the coupler bends by more than 2 % of its length (by the
    end 51 %), the strains reach 1.7 % ... compressed up to 8 and 9 times their Euler loads (78 and 83 N)'."""
    section = README.split("### Your first run", 1)[1].split("### From Python", 1)[0]
    assert "seven `flexmech: warning:` lines" in section
    assert main(["run", "cases/fourbar_hac.toml", "--no-plots", "--out", str(tmp_path / "a")]) == 0
    w = _warnings(capsys)
    assert len(w) == 7 and w[-1].startswith("flexmech: warning: error budget: strain_follower_mid")
    b = json.loads((tmp_path / "a" / "summary.json").read_text())["error_budget"]["columns"]["strain_follower_mid"]
    assert round(b["model"], 1) == 1.6 and "about 160 %" in section
    assert round(b["mesh"], 1) == 0.3 and "add about 30 %" in section
    v = json.loads((tmp_path / "a" / "summary.json").read_text())["validity"]
    assert round(v["coupler"]["deflection_exceeds_at_s"], 3) == 0.055 and "t = 0.055 s" in section
    assert round(100 * v["coupler"]["max_deflection_over_length"]) == 51 and "(by the end 51 %)" in section
    assert round(100 * max(x["max_strain"] for x in v.values()), 1) == 1.7 and "reach 1.7 %" in section
    assert [round(v[k]["max_compression_over_euler"]) for k in ("coupler", "follower")] == [8, 9]
    assert [round(v[k]["euler_load_N"]) for k in ("coupler", "follower")] == [78, 83] and "(78 and 83 N)" in section


@pytest.mark.parametrize("argv, warned", [
    (["run", "cases/fourbar_hac.toml", "--set", "solver.t_end=0.05"], "budget"),       # "only the error budget warns"
    (["run", "cases/manipulator_bricout.toml", "--set", "solver.t_end=0.25"], "coupling"),   # "yet its error budget warns"
    (["run", "cases/fourbar_hac.toml", "--set", "links.coupler.yield_strain=0.004"], "yield")])
def test_readme_first_run_commands(tmp_path, capsys, argv, warned):
    assert " ".join(argv[:2]) in README.replace("flexmech run", "run")
    assert main(argv + ["--no-plots", "--out", str(tmp_path / "r")]) == 0
    w = _warnings(capsys)
    assert bool(w) == bool(warned)
    if warned == "yield":
        assert any("coupler: strain exceeds its yield strain 0.004" in x for x in w)
    if warned == "coupling":      # inside the validity range, but hac misses the elastic-rigid coupling
        assert len(w) == 1 and "error budget: tip_dy_deflection may be off by about 120 %" in w[0]
        assert "the model error dominates" in w[0] and "--model nonlinear" in w[0]
        v = json.loads((tmp_path / "r" / "summary.json").read_text())["validity_overall"]
        assert v["valid_until_s"] is None
    if warned == "budget":
        assert len(w) == 1 and "error budget: strain_follower_mid" in w[0] and "the model error dominates" in w[0]
        b = json.loads((tmp_path / "r" / "summary.json").read_text())["error_budget"]["columns"]
        assert [round(100 * b[c]["model"]) for c in ("strain_coupler_mid", "strain_follower_mid")] == [24, 95]
