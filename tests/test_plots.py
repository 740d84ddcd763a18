"""Figures a reader looks at: curves drawn at a screen's resolution with every extreme kept, curves
that coincide said to coincide, legends off the data, units on every axis, labels apart, titles that
say what ran.  (No timing here: docs/performance.md reports what the plots cost.)"""

import numpy as np
import pytest

import flexmech_py as fm
from flexmech_py.studies import bench, compare
from flexmech_py.figures import plots, study_plots


def test_decimate_keeps_every_bucket_extreme():
    rng = np.random.default_rng(3)
    n = 100_003
    x = np.linspace(0.0, 1.0, n)
    y = np.sin(40 * x) + 0.1 * rng.standard_normal(n)
    y[[17, 5000, 77_777]] = [9.0, -7.0, 8.5]                       # isolated spikes
    xd, yd = plots.decimate(x, y)
    assert xd.size == yd.size <= plots.MAX_POINTS
    assert np.all(np.diff(xd) > 0)                                  # order kept
    assert xd[0] == x[0] and xd[-1] == x[-1]
    assert {9.0, -7.0, 8.5} <= set(yd.tolist())
    size = -(-n // (plots.MAX_POINTS // 2 - 1))                     # each bucket's min and max survive
    kept = set(xd.tolist())
    for b in range(-(-n // size)):
        seg = slice(b * size, min(n, (b + 1) * size))
        assert x[seg][np.argmax(y[seg])] in kept and x[seg][np.argmin(y[seg])] in kept


def test_decimate_leaves_short_curves_alone():
    x, y = np.arange(50.0), np.arange(50.0) ** 2
    xd, yd = plots.decimate(x, y)
    assert xd is not None and np.array_equal(xd, x) and np.array_equal(yd, y)


def test_line_figure_draws_at_most_a_screen_of_points(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    sizes = []
    real = plots.decimate
    monkeypatch.setattr(plots, "decimate", lambda x, y: sizes.append(real(x, y)[0].size) or real(x, y))
    t = np.linspace(0, 1, 250_000)
    p = plots.line_figure(tmp_path / "f.png", [{"x": t, "ylabel": "y [m]", "series": [("a", np.sin(50 * t), None),
                                                                                      ("b", np.cos(50 * t), None)]}])
    assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sizes and max(sizes) <= plots.MAX_POINTS


def test_coincident_curves_are_said_to_coincide():
    t = np.linspace(0, 1, 500)
    a = np.sin(7 * t)
    series = [("case I (hac)", a, None), ("case II (classic)", a + 2e-3, None), ("other", 0.5 * a, None),
              ("same", a.copy(), None)]
    found = plots.coincidences(series)
    assert found[1][0] == 0 and found[1][1] == pytest.approx(2e-3 / np.max(np.abs(a + 2e-3)), rel=1e-6)
    assert 2 not in found and found[3] == (0, 0.0)
    marked = plots._mark_coincident(series)
    assert "on case I: max |diff| 0.2 % of case I's peak" in marked[1][0] and marked[1][2]["ls"] == "--"
    assert marked[3][0].endswith("on case I: identical") and marked[2] == series[2]


def test_coincidence_label_divides_by_the_reference_curves_peak():
    """A small reference curve drawn in a panel with a ten times larger one: the curve on it is said to
    differ by its difference over the reference's own peak (1.5 %), not over the panel's (0.15 %)."""
    t = np.linspace(0, 1, 500)
    ref = 0.1 * np.sin(7 * t)
    series = [("big", np.sin(7 * t) + 0.5, None), ("reference (model A)", ref, None),
              ("other (model B)", ref + 0.015 * np.max(np.abs(ref)) * np.cos(3 * t), None)]
    found = plots.coincidences(series)
    assert found[2][0] == 1 and found[2][1] < 0.0016              # coincide at the panel's scale
    marked = plots._mark_coincident(series)
    assert "on reference: max |diff| 1.5 % of reference's peak" in marked[2][0], marked[2][0]


def test_legend_goes_to_an_empty_corner_or_beside_the_axes():
    u = np.linspace(0, 1, 200)
    rising = [(u, u)]                                                # the diagonal: upper left is empty
    assert plots.legend_corner(rising, (0.3, 0.2)) == "upper left"
    full = [(u, 0.5 + 0.49 * np.sin(60 * u))]                        # fills the whole height
    assert plots.legend_corner(full, (0.3, 0.2)) is None
    assert plots.legend_corner(rising, (0.7, 0.2)) is None           # too wide for any corner


def test_label_spread_keeps_order_and_gap():
    y = study_plots.spread([510.0, 500.0, 305.0, 498.0], 28.0)
    assert y[2] == 305.0                                             # alone: unmoved
    close = sorted([y[0], y[1], y[3]])
    assert np.all(np.diff(close) >= 28.0 - 1e-9)
    assert y[3] < y[1] < y[0]                                        # order of the values kept
    assert np.mean(close) == pytest.approx(np.mean([510.0, 500.0, 498.0]))


def test_display_units():
    assert plots.display_unit("1") == "-" and plots.display_unit("N m") == "N m"


@pytest.fixture(scope="module")
def seed_short():
    return fm.simulate(fm.load_case("fourbar_hac", overrides=["solver.t_end=0.02"]))


def test_run_panels_small_and_labelled(seed_short):
    panels = plots._result_panels(seed_short, seed_short.t)
    assert all(1 <= len(p["series"]) <= 4 for p in panels)
    assert sum(len(p["series"]) for p in panels) == len(seed_short.columns)
    for p in panels:
        assert p["ylabel"].endswith("]") and "[1]" not in p["ylabel"]
    strain = next(p for p in panels if "strain" in p["ylabel"])
    assert strain["ylabel"] == "strain [-]"
    norms = next(p for p in panels if any(lab == "load_norm" for lab, _, _ in p["series"]))
    assert len(norms["series"]) == 4                                 # one kind at one place: the norm per model
    assert any("on load_norm" in lab for lab, _, _ in plots._mark_coincident(norms["series"]))


def test_run_panels_in_mm_for_small_lengths():
    res = fm.simulate(fm.load_case("manipulator_bricout", overrides=["solver.t_end=0.01"]))
    panels = plots._result_panels(res, res.t)
    tip = next(p for p in panels if any(lab == "tip_dy_elastic" for lab, _, _ in p["series"]))
    assert tip["ylabel"].endswith("[mm]")
    y = dict((lab, v) for lab, v, _ in tip["series"])["tip_dy_elastic"]
    assert np.allclose(y, 1e3 * res["tip_dy_elastic"])
    pos = next(p for p in panels if any(lab == "tip_x" for lab, _, _ in p["series"]))
    assert pos["ylabel"].endswith("[m]")                             # 1.9 m stays in m


def test_mechanism_sketch_of_the_seed_four_bar(seed_short, tmp_path):
    links, grounds, masses = plots._sketch_geometry(seed_short)
    assert [name for name, *_ in links] == ["crank", "coupler", "follower"]
    assert sorted({k for *_, nodes in links for _, k in nodes}) == list(range(1, 8))
    assert sorted(name for _, name in grounds) == ["crank_pivot", "follower_pivot"]
    assert sorted(txt for _, txt in masses) == ["0.0375 kg", "0.045 kg"]
    a, b = links[0][1], links[0][2]
    assert np.hypot(*(b - a)) == pytest.approx(0.10795)
    if plots.have_matplotlib():
        assert plots.mechanism_sketch(tmp_path / "s.png", seed_short, title="t").read_bytes()[:4] == b"\x89PNG"


def test_compare_plots_carry_units(tmp_path, monkeypatch):
    drawn = []
    monkeypatch.setattr(compare, "line_figure", lambda path, panels, **kw: drawn.append((panels, kw)) or None)
    t = np.linspace(0, 0.05, 200)
    metrics = compare.compare_columns({"t": t, "tip": 1e-4 * np.sin(90 * t), "a": t ** 2},
                                      {"t": t, "tip": 1.1e-4 * np.sin(90 * t), "a": t ** 2})
    compare._write(metrics, tmp_path, "t", "x against y", units={"tip": "m", "a": "rad"})
    (tip, kw), (ang, kw2) = drawn
    assert kw["xlabel"] == "t [s]" == kw2["xlabel"]
    assert tip[0]["ylabel"] == "tip [mm]" and tip[1]["ylabel"] == "result - reference [mm]"
    assert np.max(np.abs(tip[0]["series"][0][1])) == pytest.approx(0.11, rel=1e-2)
    assert ang[0]["ylabel"] == "a [rad]"
    drawn.clear()
    compare._write(metrics, tmp_path, "crank_angle", "x", units={"crank_angle": "rad"})
    assert drawn[0][1]["xlabel"] == "crank angle [rad]"


def test_quick_bench_title_and_exponents_say_what_ran():
    ladder = [{"model": "hac", "elements_per_link": e, "elements": 3 * e, "us_per_step": 2.0 * e ** 0.9}
              for e in (1, 2, 4, 8)]
    assert bench.plot_title(ladder) == "flexmech bench: seed four-bar, 1..8 elements per link"
    rows = bench._exponent_rows("exponent.hac", [(x["elements"], x["us_per_step"]) for x in ladder], 16, 1024,
                                "time per step ~ elements^p, elements in total:")
    (row,) = rows
    assert row["value"] == pytest.approx(0.9) and "3..24" in row["note"] and "below the asymptotic range" in row["note"]
    assert "nan" not in f"{row['value']} {row['note']}"
    assert bench._exponent_rows("e", [(24, 1.0)], 16, 1024, "w") == []   # one size: no exponent at all
    big = [(n, n ** 1.5) for n in (16, 32, 64, 128)]
    (row,) = bench._exponent_rows("e", big + [(3, 9.0)], 16, 1024, "w")
    assert row["value"] == pytest.approx(1.5) and "below" not in row["note"]
    assert bench.table([{"a": float("nan")}], ["a"]).splitlines()[-1].strip() == "-"
