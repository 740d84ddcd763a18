"""``flexmech view`` pages in a real browser: headless Chromium driven by Selenium (tests/browser.py).
Skipped, with the reason, where no browser is installed (``bash .ci/setup.sh test`` installs Debian's
chromium and chromium-driver and selenium)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from browser import Browser, missing  # noqa: E402

from flexmech_py.case import Case  # noqa: E402
from flexmech_py.cli import main  # noqa: E402
from flexmech_py.models.shapes import read_shape_csv  # noqa: E402

pytestmark = pytest.mark.skipif(missing() is not None, reason=f"no browser to test the view in: {missing()}")
CASES = Path(__file__).resolve().parents[1] / "cases"


@pytest.fixture(scope="module")
def browser():
    b = Browser(1400, 900)
    yield b
    b.close()


@pytest.fixture(scope="module")
def pages(tmp_path_factory) -> dict:
    root = tmp_path_factory.mktemp("view-browser")
    assert main(["run", str(CASES / "slider_crank.toml"), "--set", "solver.t_end=0.02", "--view", "--no-plots",
                 "--quiet", "--out", str(root / "run")]) == 0
    assert main(["modes", str(CASES / "fourbar_constant_speed.toml"), "--crank-angle", "90", "--count", "3",
                 "--no-plots", "--out", str(root / "modes")]) == 0
    assert main(["stability", str(CASES / "fourbar_constant_speed.toml"), "--speed", "100:200:5", "--refine-rounds", "0",
                 "--set", "links.crank.elements=2", "--no-plots", "--out", str(root / "stab")]) == 0
    for k in ("modes", "stab"):
        assert main(["view", str(root / k)]) == 0
    return {k: root / k for k in ("run", "modes", "stab")}


def _clean_load(b: Browser, folder: Path) -> None:
    b.open(folder / "view.html")
    errors = [m for m in b.console() if m["level"] in ("SEVERE", "WARNING")]
    assert errors == [], errors
    asked = [u for u in b.requests() if u != (folder / "view.html").resolve().as_uri()]
    assert asked == [], asked


def _changed(a, b) -> int:
    return int(np.count_nonzero(np.any(np.asarray(a, int) != np.asarray(b, int), axis=-1)))


def test_run_page_loads_clean_and_the_slider_moves_the_mechanism_and_the_cursors(browser, pages):
    b = browser
    _clean_load(b, pages["run"])
    n = b.js("return window.flexmechView.frames")
    b.js("window.flexmechView.setFrame(0)")
    first = b.shot("mech")
    assert _changed(first, b.shot("mech")) == 0                # the same frame draws the same pixels
    b.js(f"window.flexmechView.setFrame({n - 1})")
    last = b.shot("mech")
    assert _changed(first, last) > 500                         # the mechanism moved
    t = b.js("return window.flexmechView.time")
    cursors = b.js("return window.flexmechView.cursors")
    assert cursors and all(c == pytest.approx(t) for c in cursors)
    slider = b.driver.find_element("id", "time")               # the slider itself, as a user drags it
    b.js("arguments[0].value = 3; arguments[0].dispatchEvent(new Event('input'))", slider)
    assert b.js("return window.flexmechView.frame") == 3
    sf, _, _ = read_shape_csv(pages["run"] / "shape.csv")
    assert b.js("return window.flexmechView.time") == pytest.approx(sf.key[3])
    assert all(c == pytest.approx(sf.key[3]) for c in b.js("return window.flexmechView.cursors"))


def test_colour_bar_spans_the_strain_of_the_data(browser, pages):
    b = browser
    b.open(pages["run"] / "view.html")
    sf, _, _ = read_shape_csv(pages["run"] / "shape.csv")
    case = Case(json.loads((pages["run"] / "summary.json").read_text())["input"])
    half = {ln["name"]: ln.get("half_depth") for ln in case["links"]}
    strain = np.concatenate([half[bd.name] * sf.kappa[:, bd.sl] for bd in sf.bodies if bd.kind == "flexible"], axis=1)
    lo, hi = b.js("return window.flexmechView.colourRange")
    assert (lo, hi) == (pytest.approx(strain.min(), rel=1e-9), pytest.approx(strain.max(), rel=1e-9))
    shown = float(b.driver.find_element("id", "cb-max").get_attribute("data-value"))
    assert shown == pytest.approx(strain.max(), rel=1e-9)
    b.js("window.flexmechView.setField('stress')")
    lo_s, hi_s = b.js("return window.flexmechView.colourRange")
    assert hi_s == pytest.approx(case["links"][1]["youngs_modulus"] * strain.max() / 1e6, rel=1e-9)


def test_hovering_a_curve_reads_its_value_with_its_unit(browser, pages):
    from selenium.webdriver import ActionChains

    b = browser
    b.open(pages["run"] / "view.html")
    canvas = b.driver.find_element("css selector", "canvas.curve")
    ActionChains(b.driver).move_to_element_with_offset(canvas, 20, 0).perform()
    tip = b.driver.find_element("id", "tip")
    assert tip.is_displayed() and "t = " in tip.text and " rad" in tip.text


def test_a_mode_result_animates(browser, pages):
    b = browser
    _clean_load(b, pages["modes"])
    assert b.js("return window.flexmechView.modes") == 3
    b.js("window.flexmechView.pause(); window.flexmechView.setPhase(Math.PI / 2)")
    up = b.shot("mech")
    b.js("window.flexmechView.setPhase(3 * Math.PI / 2)")
    assert _changed(up, b.shot("mech")) > 300                 # the shape swings to its other side
    b.js("window.flexmechView.play()")
    p0 = b.js("return window.flexmechView.phase")
    b.driver.implicitly_wait(0)
    import time

    time.sleep(0.5)
    assert b.js("return window.flexmechView.phase") != p0       # it animates by itself
    b.js("window.flexmechView.setMode(2)")
    assert b.js("return window.flexmechView.mode") == 2


def test_stability_chart_loads_clean_and_hovers(browser, pages):
    from selenium.webdriver import ActionChains

    b = browser
    _clean_load(b, pages["stab"])
    canvas = b.driver.find_element("id", "growth")
    ActionChains(b.driver).move_to_element(canvas).perform()
    tip = b.driver.find_element("id", "tip")
    assert tip.is_displayed() and "rad/s" in tip.text and "growth rate" in tip.text


def test_the_page_draws_a_gears_pitch_circles_and_a_slot_as_the_pngs_do(browser, tmp_path):
    """The page's shapeLines (view_mechanism.js) gives the polylines of flexmech_py.figures.glyphs.shape_lines
    for every joint kind's outline (the page loads clean with them drawn)."""
    from flexmech_py.figures.glyphs import shape_lines

    b = browser
    for case in ("geared_fivebar", "scotch_yoke"):
        out = tmp_path / case
        assert main(["run", str(CASES / f"{case}.toml"), "--set", "solver.t_end=0.002", "--view", "--no-plots",
                     "--quiet", "--out", str(out)]) == 0
        _clean_load(b, out)
        data = json.loads(b.js("return document.getElementById('flexmech-data').textContent"))
        drawn = [j for j in data["joints"] if j["shapes"]]
        assert drawn
        for j in drawn:
            pa, pb = [0.01, -0.02], [0.13, 0.05]
            page = b.js("return window.flexmechView.shapeLines(arguments[0], arguments[1], arguments[2])", j["shapes"], pa, pb)
            ours = shape_lines(j["shapes"], np.array(pa), np.array(pb))
            assert len(page) == len(ours)
            for a, c in zip(page, ours):
                assert np.allclose(np.asarray(a, float), c, rtol=0, atol=1e-12)
