"""``flexmech view`` without a browser: the page's data against the result's files, the decimation
rule and its measured error against closed forms, the page being one self-contained file, and bad
input (one line, exit code 2, nothing written).  tests/test_view_browser.py opens the pages in a
real browser."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from flexmech_py.case import Case, read_case_file
from flexmech_py.cli import main
from flexmech_py.figures.plots import decimate
from flexmech_py.run.results import read_timeseries
from flexmech_py.models.shapes import Body, ShapeFrames, read_shape_csv
from flexmech_py.view import page_of, write_view
from flexmech_py.view import decimate as thin
from flexmech_py.view.page import PARTS, SCRIPTS

CASES = Path(__file__).resolve().parents[1] / "cases"
FLEXMECH = str(Path(sys.executable).parent / "flexmech")


def _run(*argv) -> int:
    return main([str(a) for a in argv])


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("view") / "run"
    assert _run("run", CASES / "slider_crank.toml", "--set", "solver.t_end=0.02", "--view", "--no-plots",
                "--quiet", "--out", out) == 0
    return out


@pytest.fixture(scope="module")
def modes_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("view") / "modes"
    assert _run("modes", CASES / "fourbar_constant_speed.toml", "--crank-angle", "90", "--count", "3", "--no-plots",
                "--out", out) == 0
    return out


def _data(html: str) -> dict:
    m = re.search(r'<script type="application/json" id="flexmech-data">(.*?)</script>', html, re.S)
    return json.loads(m.group(1))


def _f32(s: str) -> np.ndarray:
    import base64

    return np.frombuffer(base64.b64decode(s), dtype="<f4")


def test_run_view_page_holds_the_shapes_strain_and_curves_of_its_files(run_dir):
    html = (run_dir / "view.html").read_text(encoding="utf-8")
    data = _data(html)
    sf, _, _ = read_shape_csv(run_dir / "shape.csv")
    cols, units = read_timeseries(run_dir / "timeseries.csv")
    summary = json.loads((run_dir / "summary.json").read_text())
    assert data["kind"] == "run" and "view.html" in summary["files"]
    assert data["shapes"]["frames"] == sf.key.size == cols["t"].size    # a short run: every frame kept
    np.testing.assert_allclose(_f32(data["shapes"]["x"]).reshape(sf.x.shape), sf.x, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(_f32(data["shapes"]["d"]).reshape(sf.d.shape), sf.d, rtol=1e-6, atol=1e-12)
    half = {ln["name"]: ln.get("half_depth") for ln in Case(summary["input"])["links"]}
    strain = np.concatenate([half[b.name] * sf.kappa[:, b.sl] for b in sf.bodies if b.kind == "flexible"], axis=1)
    assert data["field"]["strain"]["min"] == pytest.approx(strain.min(), rel=1e-12)
    assert data["field"]["strain"]["max"] == pytest.approx(strain.max(), rel=1e-12)
    drawn = [s["name"] for p in data["curves"] for s in p["series"]]
    assert sorted(drawn) == sorted(c for c in cols if c != "t")           # every column, once
    assert data["decimation"]["curve_error"] == 0.0 and data["decimation"]["points_dropped"] == 0
    assert data["scale"] >= 1.0


def test_run_strain_in_the_page_is_the_runs_strain_output(run_dir):
    """shape.csv's curvature times the half depth is the strain the run writes at the same station
    (slider_crank: strain_rod_mid, the rod at 0.5)."""
    sf, _, _ = read_shape_csv(run_dir / "shape.csv")
    cols, _ = read_timeseries(run_dir / "timeseries.csv")
    summary = json.loads((run_dir / "summary.json").read_text())
    half = {ln["name"]: ln.get("half_depth") for ln in Case(summary["input"])["links"]}
    p = sf.point("rod", "0.5")
    assert p is not None and np.max(np.abs(cols["strain_rod_mid"])) > 1e-6
    np.testing.assert_allclose(half["rod"] * sf.kappa[:, p], cols["strain_rod_mid"], rtol=1e-5,
                               atol=1e-6 * np.max(np.abs(cols["strain_rod_mid"])))


def test_page_is_one_self_contained_file(run_dir):
    html = (run_dir / "view.html").read_text(encoding="utf-8")
    assert "default-src 'none'" in html                 # the page itself forbids any request
    assert not re.search(r"""(src|href)\s*=\s*["'](?!data:)""", html)   # no file or address to fetch
    assert not re.search(r"https?://", html)
    assert not re.search(r"\b(fetch|XMLHttpRequest|import\()", html)
    for part in SCRIPTS:                                  # every part of the script inside
        first = resources.files("flexmech_py.view").joinpath(part).read_text().splitlines()[0]
        assert first in html


def test_installed_package_has_every_part_of_the_page():
    for part in PARTS:
        assert resources.files("flexmech_py.view").joinpath(part).is_file(), part
        assert len(resources.files("flexmech_py.view").joinpath(part).read_text().splitlines()) <= 600


def test_text_of_a_result_cannot_end_the_data_or_fill_a_placeholder(tmp_path):
    title = "A </script><script>alert(1)</script> __JS__ __DATA__ & co"
    out = tmp_path / "r"
    assert _run("run", CASES / "slider_crank.toml", "--set", "solver.t_end=0.004", "--set", f'case.title="{title}"',
                "--view", "--no-plots", "--quiet", "--out", out) == 0
    html = (out / "view.html").read_text(encoding="utf-8")
    assert html.count("</script>") == 2                    # the data's and the script's
    assert _data(html)["title"] == title
    assert html.count("(function () {") == 1


def _beam_frames(n: int, field) -> ShapeFrames:
    """One flexible link along x of length 1 with n nodes, transverse displacement field(s) and its
    slope and curvature (two frames: +field, -field)."""
    s = np.linspace(0.0, 1.0, n)
    w, slope, kappa = field(s)
    x = np.stack([s, 0 * s], axis=-1)[None].repeat(2, axis=0)
    d = np.stack([0 * s, w], axis=-1)[None] * np.array([1.0, -1.0])[:, None, None]
    rot = slope[None] * np.array([1.0, -1.0])[:, None]
    kap = kappa[None] * np.array([1.0, -1.0])[:, None]
    body = Body("beam", "flexible", [f"{v:g}" for v in s], slice(0, n), s)
    return ShapeFrames([body], np.array([0.0, 1.0]), x, d, rot, kap)


def test_station_error_is_zero_for_a_cubic_and_within_the_hermite_bound_for_a_sine():
    cubic = _beam_frames(201, lambda s: (s**3 - s**2, 3 * s**2 - 2 * s, 6 * s - 2))
    err = thin.station_error(cubic)
    assert err["deflection"] < 1e-12 and err["curvature"] < 1e-12   # Hermite cubics and linear curvature: exact
    a = 1e-3
    sine = _beam_frames(201, lambda s: (a * np.sin(np.pi * s), a * np.pi * np.cos(np.pi * s),
                                        -a * np.pi**2 * np.sin(np.pi * s)))
    thinned, dropped = thin.thin_stations(sine)
    assert thinned.x.shape[1] <= thin.STATION_CAP and dropped == 201 - thinned.x.shape[1]
    h = float(np.max(np.diff(thinned.x[0, :, 0])))       # the longest span between kept nodes
    bound = h**4 / 384 * np.pi**4                         # |f - H3 f| <= h^4/384 max|f''''| (relative to a)
    err = thin.station_error(sine)
    assert 0.5 * bound < err["deflection"] <= bound * (1 + 1e-9)
    assert err["curvature"] <= h**2 / 8 * np.pi**2 * (1 + 1e-9)   # linear interpolation of -a pi^2 sin


def test_curve_error_is_the_largest_miss_of_the_drawn_line_over_every_sample():
    t = np.linspace(0.0, 1.0, 200_001)
    y = np.sin(2 * np.pi * 7 * t) + 0.2 * np.sin(2 * np.pi * 90 * t)
    x, yd = decimate(t, y, thin.CURVE_POINTS)
    err = thin.curve_error(t, y, x, yd)
    brute = max(abs(np.interp(tt, x, yd) - yy) for tt, yy in zip(t[::7], y[::7])) / np.max(np.abs(y))
    assert brute <= err < 0.02
    assert np.max(yd) == np.max(y) and np.min(yd) == np.min(y)     # every peak is drawn


def test_a_long_fine_run_is_thinned_to_the_rule_and_says_what_it_costs(tmp_path):
    out = tmp_path / "long"
    assert _run("run", CASES / "slider_crank.toml", "--set", "solver.t_end=0.08", "--set", "solver.output_every=1",
                "--elements-per-link", "48", "--view", "--no-plots", "--quiet", "--out", out) == 0
    html, data = page_of(out)
    dec = data["decimation"]
    assert dec["frames_run"] == 8001 and dec["frames_kept"] == dec["frames_stored"] < dec["frames_run"]
    assert dec["frames_kept"] * dec["points_kept"] <= thin.POINT_FRAMES
    assert all(b["n"] <= thin.STATION_CAP for b in data["bodies"] if b["kind"] == "flexible")
    assert dec["points_dropped"] > 0 and 0 < dec["deflection_error"] < 1e-3 and dec["curvature_error"] < 0.05
    assert all(s["points"] <= thin.CURVE_POINTS for p in data["curves"] for s in p["series"])
    cols, _ = read_timeseries(out / "timeseries.csv")      # what the page states is what the curves miss
    worst = 0.0
    for p in data["curves"]:
        for s in p["series"]:
            x, y = decimate(cols["t"], cols[s["name"]], thin.CURVE_POINTS)
            worst = max(worst, np.max(np.abs(np.interp(cols["t"], x, y) - cols[s["name"]])) / np.max(np.abs(cols[s["name"]])))
    assert dec["curve_error"] == pytest.approx(worst, rel=1e-9) and worst > 0 and dec["curve_bucket_s"] > 0
    assert len(html.encode()) < 4e6


def test_modes_page_holds_every_mode_with_its_frequency_and_kind(modes_dir):
    write_view(modes_dir)
    data = _data((modes_dir / "view.html").read_text(encoding="utf-8"))
    info = json.loads((modes_dir / "modes.json").read_text())
    assert data["kind"] == "modes" and data["shapes"]["frames"] == len(info["modes"]) == 3
    assert [m["f_hz"] for m in data["modes"]] == [m["f_hz"] for m in info["modes"]]
    kap = _f32(data["shapes"]["kappa"]).reshape(3, -1)
    assert np.allclose(np.nanmax(np.abs(kap), axis=1), 1.0, atol=1e-6)   # relative strain: largest 1


def test_view_command_prints_one_line_and_the_size(run_dir, tmp_path, capsys):
    assert _run("view", run_dir, "--out", tmp_path / "page.html") == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1 and "page.html" in out[0] and "frames of" in out[0]
    assert (tmp_path / "page.html").stat().st_size > 10_000


def _bad(argv, capsys) -> str:
    assert _run(*argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_bad_inputs_are_one_line_exit_2_and_leave_nothing(run_dir, tmp_path, capsys):
    assert "no such folder" in _bad(["view", tmp_path / "nope"], capsys)
    (tmp_path / "empty").mkdir()
    assert "not a flexmech result" in _bad(["view", tmp_path / "empty"], capsys)
    assert "is a file" in _bad(["view", run_dir / "summary.json"], capsys)
    bare = tmp_path / "bare"
    assert _run("run", CASES / "slider_crank.toml", "--set", "solver.t_end=0.004", "--no-plots", "--quiet",
                "--out", bare) == 0
    capsys.readouterr()
    line = _bad(["view", bare], capsys)
    assert "no shape.csv" in line and "--view" in line              # says which run option writes them
    assert ".html" in _bad(["view", run_dir, "--out", tmp_path / "page.txt"], capsys)
    assert "does not exist" in _bad(["view", run_dir, "--out", tmp_path / "no" / "page.html"], capsys)
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "summary.json").write_text("{not json")
    assert "summary" in _bad(["view", broken], capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bare", "broken", "empty"]
    assert not (bare / "view.html").exists() and not (broken / "view.html").exists()


def test_an_unwritable_target_is_one_line_exit_2_and_leaves_nothing(run_dir):
    """/proc: a folder nobody can create files in, root included."""
    p = subprocess.run([FLEXMECH, "view", str(run_dir), "--out", "/proc/flexmech-view.html"], capture_output=True,
                       text=True)
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1 and "--out" in p.stderr, p.stderr
    assert sorted(q.name for q in run_dir.iterdir()) == sorted([".flexmech-results.json", "shape.csv", "summary.json",
                                                                 "timeseries.csv", "view.html"])


@pytest.mark.parametrize("case, shape", [("geared_fivebar", "circle"), ("scotch_yoke", "slot")])
def test_a_gear_and_a_slot_bring_their_outline_to_the_page(tmp_path, case, shape):
    """The page carries each kind's own outline (Joint.glyph_shapes: a gear's two pitch circles of the
    case's radii and its line of centres; a slot's outline) with the two sides it is drawn between, and
    the PNG drawing's polylines from the same shapes pass through those sides."""
    from flexmech_py.figures.glyphs import shape_lines

    out = tmp_path / case
    assert _run("run", CASES / f"{case}.toml", "--set", "solver.t_end=0.002", "--view", "--no-plots", "--quiet",
                "--out", out) == 0
    data = _data((out / "view.html").read_text())
    joints = [j for j in data["joints"] if any(s["shape"] == shape for s in j["shapes"])]
    assert joints, [j["kind"] for j in data["joints"]]
    sf, _, _ = read_shape_csv(out / "shape.csv")
    table = read_case_file(CASES / f"{case}.toml")
    for j in joints:
        ends = [np.asarray(e, float) if isinstance(e, list) else sf.x[0, e] + sf.d[0, e] for e in j["ends"]]
        lines = shape_lines(j["shapes"], *ends)
        if shape == "circle":
            radii = [s["radius"] for s in j["shapes"] if s["shape"] == "circle"]
            gear = next(t for t in table["joints"] if isinstance(t, dict) and t.get("name") == j["name"])
            assert radii == gear["radii"]
            for line, r, c in zip(lines, radii, ends):
                assert np.allclose(np.hypot(*(line - c).T), r, rtol=1e-12)
            assert np.allclose(lines[2], np.array(ends))
        else:
            pin = lines[1]
            assert np.allclose(pin[:-1].mean(axis=0), ends[1], atol=1e-9)
