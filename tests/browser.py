"""A real browser for the tests of ``flexmech view``: headless Chromium (Debian's ``chromium`` and
``chromium-driver``, installed by ``bash .ci/setup.sh test``) driven by Selenium, with the
browser's console and network logs, so a test can check that a page loads with no console error
and makes no request.

Run as a script it regenerates the screenshots of docs/cli.md (``flexmech view``)::

    .venv/bin/python tests/browser.py docs/img
"""

from __future__ import annotations

import io
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CHROMIUM = ("chromium", "chromium-browser", "google-chrome")
DRIVER = ("chromedriver",)


def missing() -> str | None:
    """Why there is no browser to test with (None when there is one)."""
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium is not installed (bash .ci/setup.sh test installs it)"
    if not any(shutil.which(b) for b in CHROMIUM):
        return "no chromium on PATH (bash .ci/setup.sh test installs Debian's chromium and chromium-driver)"
    if not any(shutil.which(d) for d in DRIVER):
        return "no chromedriver on PATH (bash .ci/setup.sh test installs Debian's chromium-driver)"
    return None


class Browser:
    """Headless Chromium at a fixed window size, its console and network logged."""

    def __init__(self, width: int = 1400, height: int = 900):
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service

        opts = webdriver.ChromeOptions()
        opts.binary_location = next(shutil.which(b) for b in CHROMIUM if shutil.which(b))
        for a in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                  f"--window-size={width},{height}", "--force-device-scale-factor=1", "--hide-scrollbars",
                  "--no-first-run", "--disable-extensions", "--disable-background-networking",
                  "--disable-component-update", "--disable-default-apps", "--disable-sync"):
            opts.add_argument(a)
        self._profile = tempfile.mkdtemp(prefix="flexmech-chromium-")
        opts.add_argument(f"--user-data-dir={self._profile}")
        opts.set_capability("goog:loggingPrefs", {"browser": "ALL", "performance": "ALL"})
        service = Service(executable_path=next(shutil.which(d) for d in DRIVER if shutil.which(d)))
        self.driver = webdriver.Chrome(options=opts, service=service)
        self.driver.set_window_size(width, height)

    def open(self, path: Path, timeout: float = 20.0) -> float:
        """Load a file and wait until its script says it is ready; the seconds from the navigation's
        start to that moment (the browser's own clock).  The logs of what came before (the browser's
        own start page) are dropped first, so console() and requests() tell of this page only."""
        self.driver.get("about:blank")
        self.console()
        self.requests()
        self.driver.get(Path(path).resolve().as_uri())
        end = time.time() + timeout
        while time.time() < end:
            if self.js("return !!(window.flexmechView && window.flexmechView.ready)"):
                return self.js("return performance.now()") / 1000.0
            time.sleep(0.05)
        raise TimeoutError(f"{path}: the page did not say it is ready within {timeout} s; console: {self.console()}")

    def js(self, script: str, *args):
        return self.driver.execute_script(script, *args)

    def console(self) -> list[dict]:
        """The console messages since the last call (level, message)."""
        return [{"level": e["level"], "message": e["message"]} for e in self.driver.get_log("browser")]

    def requests(self) -> list[str]:
        """The URLs the page asked for since the last call (every Network.requestWillBeSent)."""
        out = []
        for e in self.driver.get_log("performance"):
            msg = json.loads(e["message"])["message"]
            if msg.get("method") == "Network.requestWillBeSent":
                out.append(msg["params"]["request"]["url"])
        return out

    def shot(self, element_id: str | None = None):
        """A screenshot (PIL image, RGB) of the page or of one element."""
        from PIL import Image

        png = (self.driver.find_element("id", element_id).screenshot_as_png if element_id
               else self.driver.get_screenshot_as_png())
        return Image.open(io.BytesIO(png)).convert("RGB")

    def close(self) -> None:
        self.driver.quit()
        shutil.rmtree(self._profile, ignore_errors=True)


def _flexmech(*args: str) -> None:
    subprocess.run([str(Path(sys.executable).parent / "flexmech"), *args], check=True, stdout=subprocess.DEVNULL)


def docs_screenshots(out: Path) -> list[Path]:
    """The screenshots of docs/cli.md: the seed four-bar (hac) run, its modes and the stability chart
    of the constant-speed four-bar, each page made by flexmech and shown in headless Chromium."""
    root = Path(__file__).resolve().parents[1]
    cases = root / "cases"
    out.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="flexmech-view-docs-"))
    _flexmech("run", str(cases / "fourbar_hac.toml"), "--view", "--no-plots", "--quiet", "--out", str(work / "run"))
    _flexmech("run", str(cases / "manipulator_bricout.toml"), "--model", "coupled", "--view", "--no-plots", "--quiet",
              "--out", str(work / "arm"))
    _flexmech("modes", str(cases / "fourbar_constant_speed.toml"), "--crank-angle", "90", "--along-cycle", "36",
              "--no-plots", "--out", str(work / "modes"))
    _flexmech("stability", str(cases / "fourbar_constant_speed.toml"), "--speed", "100:200:21", "--refine-rounds", "2",
              "--no-plots", "--out", str(work / "stab"))
    paths = []
    b = Browser(1400, 900)
    try:
        for name, setup in (("run", "window.flexmechView.setFrame(Math.round(0.86 * window.flexmechView.frames))"),
                            ("arm", "window.flexmechView.setFrame(Math.round(0.5 * window.flexmechView.frames))"),
                            ("modes", "window.flexmechView.pause(); window.flexmechView.setPhase(Math.PI / 2)"),
                            ("stab", "")):
            _flexmech("view", str(work / name))
            b.open(work / name / "view.html")
            if setup:
                b.js(setup)
            time.sleep(0.3)
            p = out / f"view_{name}.png"
            b.shot().save(p, optimize=True)
            paths.append(p)
    finally:
        b.close()
        shutil.rmtree(work, ignore_errors=True)
    return paths


if __name__ == "__main__":
    why = missing()
    if why:
        sys.exit(f"tests/browser.py: {why}")
    for p in docs_screenshots(Path(sys.argv[1] if len(sys.argv) > 1 else "docs/img")):
        print(f"wrote {p}")
