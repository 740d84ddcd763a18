"""Every example in docs/ runs.

- docs/cases.md: ```toml blocks preceded by ``<!-- example: NAME -->`` are complete cases; they
  validate and run (t_end cut to 0.02 s).  Every other ```toml block is at least valid TOML.
- docs/api.md: ```python blocks preceded by ``<!-- example -->`` are executed, each in a fresh
  namespace, from a temporary folder in which ``cases/`` is the bundled case folder.
- docs/*.md: ```console blocks preceded by ``<!-- example -->``: every line ``$ flexmech ...``
  runs through flexmech_py.cli.main in a temporary folder (``cases/...`` made absolute) and
  exits with 0.
"""

import json
import os
import re
import shlex
from pathlib import Path

import numpy as np
import pytest

import flexmech_py as fm
from flexmech_py.case import MODELS, OUTPUT_KINDS
from flexmech_py.cli import main
from flexmech_py.run.results import read_timeseries

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
CASES = ROOT / "cases"
T_END_MAX = 0.02  # s

_BLOCK = re.compile(r"(?:<!--\s*example(?::\s*(?P<name>[\w.-]+))?\s*-->\s*\n)?```(?P<lang>\w*)\n(?P<body>.*?)^```",
                    re.S | re.M)


def blocks(doc: str, lang: str, marked: bool | None = True) -> list[tuple[str, str]]:
    """(name, body) of the fenced blocks of a language; marked=True: only those after an example
    marker, False: only unmarked ones, None: all.  Unnamed examples are named by position."""
    text = (DOCS / doc).read_text(encoding="utf-8")
    out = []
    for i, m in enumerate(_BLOCK.finditer(text)):
        if m["lang"] != lang:
            continue
        is_marked = m.group(0).startswith("<!--")
        if marked is None or is_marked == marked:
            out.append((m["name"] or f"{doc}#{i}", m["body"]))
    return out


def _ids(items):
    return [name for name, _ in items]


# ----------------------------------------------------------------------------- cases.md
CASE_EXAMPLES = blocks("cases.md", "toml")


def test_cases_md_has_the_minimal_example():
    assert "spinning_cantilever" in _ids(CASE_EXAMPLES)


@pytest.mark.parametrize("name, text", CASE_EXAMPLES, ids=_ids(CASE_EXAMPLES))
def test_case_example_validates_and_runs(name, text):
    raw = tomllib.loads(text)
    case = fm.validate_case(raw)               # the example as written is valid
    if case["solver"]["t_end"] > T_END_MAX:
        ov = [f"solver.t_end={T_END_MAX}"]
        if case["solver"]["dt"] > T_END_MAX:
            ov.append(f"solver.dt={T_END_MAX / 10}")
        case = fm.validate_case(fm.apply_overrides(raw, ov))
    res = fm.simulate(case)
    assert res.t[-1] == pytest.approx(case["solver"]["t_end"])
    extra = set(res.columns) - set(case["outputs"])       # a case that names no model may run a coupled one
    assert set(case["outputs"]) <= set(res.columns) and (not extra or res.model in ("coupled", "nonlinear"))
    for name_, y in res.columns.items():
        assert np.all(np.isfinite(y)), name_


def test_spinning_cantilever_example_is_one_spun_up_link():
    text = dict(CASE_EXAMPLES)["spinning_cantilever"]
    case = fm.validate_case(tomllib.loads(text))
    assert case["mechanism"]["template"]["type"] == "serial" and len(case["links"]) == 1
    assert len(case["drives"]) == 1 and case["drives"][0]["law"] == "spinup"
    assert [(j["name"], j["elastic"]) for j in case["joints"]] == [("base", "clamp")]
    assert case["links"][0]["half_depth"] == pytest.approx(0.01, rel=1e-4)  # as the text says


@pytest.mark.parametrize("name, text", blocks("cases.md", "toml", marked=False),
                         ids=_ids(blocks("cases.md", "toml", marked=False)))
def test_case_fragments_are_valid_toml(name, text):
    tomllib.loads(text)


def test_cases_md_documents_every_kind_model_and_key():
    text = (DOCS / "cases.md").read_text(encoding="utf-8")
    for word in list(OUTPUT_KINDS) + list(MODELS) + [
            "ground_length", "assembly", "base", "half_depth", "second_moment", "youngs_modulus",
            "elements_per_link", "crank_pivot", "crank_coupler", "coupler_follower", "follower_pivot",
            "joint_k", "constant_speed", "spinup", "final_speed", "spinup_time", "turns_with", "gravity",
            "output_every", "rayleigh", "rigid_rtol", "rigid_atol", "beta", "gamma", "newton_tol", "newton_maxit",
                "geometric_stiffness", "geometric_tol", "geometric_maxit", "integrator", "hht_alpha", "rho_inf",
                "divergence_limit", "generalized-alpha"]:
        assert f"`{word}`" in text, word


# ----------------------------------------------------------------------------- api.md
API_EXAMPLES = blocks("api.md", "python")


@pytest.fixture
def in_tmp_with_cases(tmp_path, monkeypatch):
    """A temporary working folder where ``cases/`` is the bundled case folder."""
    (tmp_path / "cases").symlink_to(CASES, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_api_md_has_examples():
    assert len(API_EXAMPLES) >= 6


@pytest.mark.parametrize("name, code", API_EXAMPLES, ids=_ids(API_EXAMPLES))
def test_api_example_runs(name, code, in_tmp_with_cases):
    if "fmpy" in code and os.environ.get("CI") != "true":      # CI installs them: never skipped there
        pytest.importorskip("fmpy", reason="the FMU example needs fmpy and PythonFMU (pip install 'flexmech[fmi]' fmpy)")
    exec(compile(code, f"docs/api.md:{name}", "exec"), {"__name__": "__docs__"})


def test_api_md_names_every_raw_routine():
    text = (DOCS / "api.md").read_text(encoding="utf-8")
    from flexmech_py.base import kernels

    for routine in ("element_matrices", "element_curvatures", "ked_run", "ked_matrices", "ked_loads",
                    "ked_bandwidth"):
        assert hasattr(kernels.api, routine)
        assert f"`{routine}(" in text, routine


# ----------------------------------------------------------------------------- console examples
def _commands(doc):
    out = []
    for name, body in blocks(doc, "console"):
        for line in body.splitlines():
            if line.startswith("$ flexmech "):
                out.append((f"{name}: {line[2:]}", line[2:]))
    return out


CLI_COMMANDS = [c for doc in ("cli.md", "cases.md", "api.md", "compare.md", "accuracy.md", "cluster.md")
                for c in _commands(doc)]


def test_cli_md_has_examples():
    assert len(_commands("cli.md")) >= 3


@pytest.mark.parametrize("name, line", CLI_COMMANDS, ids=_ids(CLI_COMMANDS))
def test_console_example_runs(name, line, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    argv = shlex.split(line)[1:]
    argv = [str(CASES / a[len("cases/"):]) if a.startswith("cases/") else a for a in argv]
    if "--scheduler" in argv and os.environ.get("CI") != "true":   # CI installs distributed: never skipped there
        pytest.importorskip("distributed", reason="--scheduler examples need the optional package distributed")
    if argv[0] == "fmu" and os.environ.get("CI") != "true":
        pytest.importorskip("pythonfmu", reason="flexmech fmu needs PythonFMU (pip install 'flexmech[fmi]')")
    if argv[0] == "run":  # keep it short even if a doc example is not
        case = fm.load_case(argv[1], overrides=[argv[i + 1] for i, a in enumerate(argv) if a == "--set"])
        assert case["solver"]["t_end"] <= T_END_MAX, "doc examples must stay short (--set solver.t_end=...)"
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 0, err
    if argv[0] == "compare":
        assert list(tmp_path.rglob("compare.json"))
        return
    if argv[0] == "modes" and "--closed-loop" in argv:
        assert list(tmp_path.rglob("closed_loop.csv")) and list(tmp_path.rglob("closed_loop.json"))
        return
    if argv[0] == "modes":
        assert list(tmp_path.rglob("modes.csv")) and list(tmp_path.rglob("mode_shapes.csv"))
        return
    if argv[0] == "optimize":
        assert list(tmp_path.rglob("optimize.json")) and list(tmp_path.rglob("optimum.toml"))
        return
    if argv[0] == "fmu":
        assert list(tmp_path.rglob("*.fmu"))
        return
    if argv[0] in ("stability", "sweep", "accuracy"):   # their tables: stability.csv, sweep.csv, accuracy.csv
        assert list(tmp_path.rglob("samples.csv" if "--sample" in argv else f"{argv[0]}.csv"))
        return
    csvs = list(tmp_path.rglob("timeseries.csv"))
    assert csvs
    cols, units = read_timeseries(csvs[0])
    assert units["t"] == "s" and np.all(np.isfinite(cols["t"]))


# ----------------------------------------------------------------------------- documented file formats
def test_documented_csv_and_summary_format(tmp_path):
    """The timeseries.csv layout and the summary.json keys are as docs/cli.md says."""
    rc = main(["run", str(CASES / "manipulator_bricout.toml"), "--set", "solver.t_end=0.005", "--no-plots",
               "--out", str(tmp_path)])
    assert rc == 0
    lines = (tmp_path / "timeseries.csv").read_text().splitlines()
    assert lines[0].startswith("# complete: ") and len(lines[0].encode()) == 240
    assert lines[1].startswith("# flexmech ") and lines[2].startswith("# units: s,")
    assert lines[3].startswith("t,") and not lines[4].startswith("#")
    np.loadtxt(tmp_path / "timeseries.csv", delimiter=",", skiprows=4)            # as documented
    np.genfromtxt(tmp_path / "timeseries.csv", delimiter=",", names=True, skip_header=3)
    summary = json.loads((tmp_path / "summary.json").read_text())
    doc = (DOCS / "cli.md").read_text(encoding="utf-8")
    section = doc.split("**summary.json**", 1)[1].split("**stdout**", 1)[0]
    documented = set(re.findall(r"^\| `(\w+)` \|", section, re.M))
    optional = {"coupled", "geometric_stiffness", "failed_at_s", "failure", "reactions",   # some models, options, failed runs
                "model_choice"}                                                           # model = "auto"
    assert set(summary) <= documented and documented - set(summary) <= optional
    assert set(summary["dofs"]) == {"all", "free", "half_bandwidth", "elements"}
    assert set(summary["wall_time_s"]) == {"rigid_s", "kernel_s", "total_s"}
    assert set(next(iter(summary["outputs"].values()))) == {"unit", "min", "max", "peak_abs", "t_peak_abs", "final"}
    assert set(summary["versions"]) == {"flexmech", "python", "numpy", "scipy", "platform"}
