"""The bad-input catalogue: inputs a demanding user gives every command, and what a clean answer is.

Each entry runs ``flexmech`` (``cli.main``) in a forked child, in a fresh folder, with a memory limit
and a time limit, and is judged:

- **clean**: the documented exit code (2: nothing started; 3: a run that started and failed), one
  error line (``flexmech: error: ...``, or argparse's usage line and its message), no traceback, no
  line longer than MAX_LINE characters, nothing new left in the folder after an exit 2;
- **unclear**: clean, but the line lacks what the entry says a clear message must name (the field,
  the value's trouble, the fix);
- **not clean**: anything else (a traceback, exit 0 or 1, several error lines, a line of megabytes,
  files left behind, out of memory, a hang).

``python tests/fault_catalogue.py`` prints every entry's verdict and the counts; tests/test_catalogue.py
requires every entry to be clean.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import resource
import select
import shutil
import signal
import stat
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

#: longest acceptable line on stderr [characters]
MAX_LINE = 2000
#: the child's address-space limit [bytes]: an input that makes flexmech allocate without bound fails here
MEMORY_LIMIT = 6 * 2 ** 30
#: seconds an entry may take
TIME_LIMIT = 60

R = ["run", "slider_crank", "--set", "solver.t_end=0.01", "--elements-per-link", "2", "--no-plots", "--quiet"]
TORQUE = ["run", "slider_crank_torque", "--set", "solver.t_end=0.01", "--no-plots", "--quiet"]


@dataclass
class Entry:
    """One bad input: ``argv`` (``{tmp}`` is the entry's folder), a ``setup(tmp)`` making its input
    files, the words a clear message holds (``needles``, any case), the exit codes accepted."""

    name: str
    argv: list
    needles: tuple = ()
    codes: tuple = (2,)
    setup: object = None
    root_only: bool | None = None      # True: only as root; False: only as another user

    def args(self, tmp: Path) -> list[str]:
        return [a.replace("{tmp}", str(tmp)) for a in self.argv]


@dataclass
class Outcome:
    code: int | None
    out: str
    err: str
    left: list = field(default_factory=list)
    verdict: str = ""
    why: str = ""


# ----------------------------------------------------------------------------- input files
def _bundled(name: str) -> str:
    from flexmech_py.base.bundled import case_path

    return case_path(name).read_text(encoding="utf-8")


def _write(tmp: Path, name: str, text, binary: bool = False) -> None:
    p = tmp / name
    p.parent.mkdir(parents=True, exist_ok=True)
    if binary:
        p.write_bytes(text)
    else:
        p.write_text(text, encoding="utf-8")


def _case(tmp: Path, edit=lambda s: s, name="c.toml") -> None:
    _write(tmp, name, edit(_bundled("slider_crank")))


def _replace(old: str, new: str):
    def edit(text: str) -> str:
        assert old in text, old
        return text.replace(old, new, 1)
    return edit


def _reference(tmp: Path, body: str, name="ref.csv", bom=False) -> None:
    text = "# source: a test\n" + body
    _write(tmp, name, (b"\xef\xbb\xbf" if bom else b"") + text.encode(), binary=True)


#: a finished run folder made once (:func:`preload`), copied into the entries that need one
RUN_TEMPLATE: Path | None = None


def _run_folder(tmp: Path) -> None:
    """A small finished run in tmp/R (with shape.csv): a copy of RUN_TEMPLATE, else run here."""
    if RUN_TEMPLATE is not None:
        shutil.copytree(RUN_TEMPLATE, tmp / "R")
        return
    from flexmech_py.cli import main

    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        code = main(R[:2] + ["--set", "solver.t_end=0.004", "--elements-per-link", "2", "--no-plots", "--quiet",
                             "--draw", "3", "--out", str(tmp / "R")])
    assert code == 0


_HELD = []


def _held(tmp: Path) -> None:
    """Hold tmp/o's lock as another process would (flock on a second open file description)."""
    import fcntl
    import json as _json

    (tmp / "o").mkdir()
    fd = os.open(tmp / "o" / ".flexmech.lock", os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX)
    os.write(fd, _json.dumps({"pid": 4242, "host": os.uname().nodename, "command": "flexmech run other",
                              "started": 0}).encode())
    _HELD.append(fd)


def _setups(*fns):
    def setup(tmp):
        for f in fns:
            f(tmp)
    return setup


LONG = "x" * 100_000


def _entries() -> list[Entry]:
    E = Entry
    c = "{tmp}/c.toml"
    out = ["--out", "{tmp}/o"]
    run_c = ["run", c, "--set", "solver.t_end=0.01", "--elements-per-link", "2", "--no-plots", "--quiet"] + out
    ref = "{tmp}/ref.csv"
    cmp_r = ["compare", "{tmp}/R", "--reference", ref, "--out", "{tmp}/cmp"]
    rows = "t,slider_x\n0,0.45\n0.001,0.449\n0.002,0.447\n"
    return [
        # --- the case file itself
        E("case: no such file", ["run", "{tmp}/none.toml"] + out, ("does not exist",)),
        E("case: a folder", ["run", "{tmp}/d"] + out, ("folder",), setup=lambda t: (t / "d").mkdir()),
        E("case: a symlink loop", ["run", "{tmp}/loop.toml"] + out, ("link",),
          setup=lambda t: os.symlink(t / "loop.toml", t / "loop.toml")),
        E("case: a symlink to nothing", ["run", "{tmp}/dangling.toml"] + out, ("symbolic link", "does not exist"),
          setup=lambda t: os.symlink(t / "gone.toml", t / "dangling.toml")),
        E("case: /dev/null", ["run", "/dev/null"] + out, ("not a regular file",)),
        E("case: a FIFO", ["run", "{tmp}/fifo.toml"] + out, ("not a regular file",),
          setup=lambda t: os.mkfifo(t / "fifo.toml")),
        E("case: unreadable (EIO)", ["run", "/proc/self/mem"] + out, ("cannot be read",)),
        E("case: unreadable (mode 000)", ["run", c] + out, ("cannot be read",), root_only=False,
          setup=lambda t: (_case(t), os.chmod(t / "c.toml", 0))),
        E("case: path too long", ["run", "{tmp}/" + "a" * 5000 + ".toml"] + out, ("too long",)),
        E("case: empty file", ["run", c] + out, ("case",), setup=lambda t: _write(t, "c.toml", "")),
        E("case: binary", ["run", c] + out, ("not a text case file",), setup=lambda t: _write(t, "c.toml", b"\x00\xff\xfe" * 50, True)),
        E("case: not UTF-8", ["run", c] + out, ("utf-8",),
          setup=lambda t: _write(t, "c.toml", "[case]\ntitle = '\xe9'\n".encode("latin-1"), True)),
        E("case: TOML syntax", ["run", c] + out, ("toml", "line"), setup=lambda t: _write(t, "c.toml", "[case\n")),
        E("case: 50 000-deep array", ["run", c] + out, ("nest",),
          setup=lambda t: _write(t, "c.toml", "x = " + "[" * 50_000 + "]" * 50_000 + "\n")),
        E("case: 50 000-deep inline table", ["run", c] + out, ("nest",),
          setup=lambda t: _write(t, "c.toml", "x = " + "{a=" * 50_000 + "1" + "}" * 50_000 + "\n")),
        E("case: 100 KB link name in a joint", ["run", c] + out, ("characters",),
          setup=lambda t: _case(t, _replace('"crank.end", "rod.start"', f'"crank.end", "{LONG}.start"'))),
        E("case: 100 KB unknown key", ["run", c] + out, ("characters",),
          setup=lambda t: _case(t, _replace("[mesh]\n", f"[mesh]\n{LONG} = 1\n"))),
        E("case: 100 KB title is fine but 100 KB model is not", ["run", c] + out, ("characters", "solver.model"),
          setup=lambda t: _case(t, _replace('model = "classic"', f'model = "{LONG}"'))),
        E("case: unknown top-level table", ["run", c] + out, ("nonsense",),
          setup=lambda t: _case(t, lambda s: s + "\n[nonsense]\na = 1\n")),
        E("case: link length zero", ["run", c] + out, ("rod",),
          setup=lambda t: _case(t, _replace("end = [0.45, 0.0]", "end = [0.15, 0.0]"))),
        E("case: zero second moment", ["run", c] + out, ("second_moment",),
          setup=lambda t: _case(t, _replace("second_moment = 3.4133333333333335e-10", "second_moment = 0.0"))),
        E("case: joint to a missing point", ["run", c] + out, ("nowhere",),
          setup=lambda t: _case(t, _replace('"rod.end", "slider.pin"', '"rod.nowhere", "slider.pin"'))),
        # --- overrides
        E("--set solver..dt=1", R + ["--set", "solver..dt=1"] + out, ("empty",)),
        E("--set .solver.dt=1", R + ["--set", ".solver.dt=1"] + out, ("empty",)),
        E("--set solver.dt.=1", R + ["--set", "solver.dt.=1"] + out, ("empty",)),
        E("--set =1", R + ["--set", "=1"] + out, ("empty",)),
        E("--set without =", R + ["--set", "solver.dt"] + out, ("key.path=value",)),
        E("--set a 50 000-deep value", R + ["--set", "solver.dt=" + "[" * 50_000 + "]" * 50_000] + out, ("nested",)),
        E("--set unknown key", R + ["--set", "nosuchkey=1"] + out, ("nosuchkey",)),
        E("--set index out of range", R + ["--set", "links.99.length=1"] + out, ("out of range",)),
        E("--set no such link", R + ["--set", "links.nosuch.area=1"] + out, ("nosuch",)),
        E("--set dt a word", R + ["--set", "solver.dt=abc"] + out, ("solver.dt",)),
        E("--set dt negative", R + ["--set", "solver.dt=-1"] + out, ("solver.dt",)),
        E("--set dt nan", R + ["--set", "solver.dt=nan"] + out, ("solver.dt",)),
        E("--set dt inf", R + ["--set", "solver.dt=inf"] + out, ("solver.dt",)),
        E("--set dt an array", R + ["--set", "solver.dt=[1,2]"] + out, ("solver.dt",)),
        E("--set t_end 0", R + ["--set", "solver.t_end=0"] + out, ("solver.t_end",)),
        E("--set model unknown", R + ["--set", "solver.model=bogus"] + out, ("solver.model",)),
        E("--set model 100 KB", R + ["--set", f"solver.model={LONG}"] + out, ("solver.model", "characters")),
        E("--set integrator unknown", R + ["--set", "solver.integrator=bogus"] + out, ("integrator",)),
        E("--set area 0", R + ["--set", "links.rod.area=0"] + out, ("area",)),
        E("--set density negative", R + ["--set", "links.rod.density=-1"] + out, ("density",)),
        E("--set E zero", R + ["--set", "links.rod.youngs_modulus=0"] + out, ("youngs_modulus",)),
        E("--set body inertia negative", R + ["--set", "bodies.slider.inertia=-1"] + out, ("inertia",)),
        E("--set output_every 0", R + ["--set", "solver.output_every=0"] + out, ("output_every",)),
        E("--set output_every 1.5", R + ["--set", "solver.output_every=1.5"] + out, ("output_every",)),
        E("--set a value in a value", R + ["--set", "solver.dt.x=1"] + out, ("solver.dt",)),
        E("--set a whole array element", R + ["--set", "links.0=1"] + out, ("links",)),
        E("--rho-inf 2", R + ["--rho-inf", "2"] + out, ("rho_inf",)),
        E("--hht-alpha 1", R + ["--hht-alpha", "1"] + out, ("hht_alpha",)),
        E("--model unknown", R + ["--model", "bogus"] + out, ("--model",)),
        E("--dt 0", R + ["--dt", "0"] + out, ("--dt",)),
        E("--dt larger than t_end", R + ["--dt", "1"] + out, ("dt",)),
        E("--draw 1", R + ["--draw", "1"] + out, ("--draw",)),
        # --- sizes
        E("--elements-per-link 999999999999", R + ["--elements-per-link", "999999999999"] + out,
          ("elements", "about")),
        E("mesh.elements_per_link 1e9", R[:2] + ["--set", "mesh.elements_per_link=1000000000", "--set",
                                                  "solver.t_end=0.01", "--quiet"] + out, ("elements_per_link", "about")),
        E("--dt 1e-300", R + ["--dt", "1e-300"] + out, ("steps", "solver.dt")),
        E("t_end 1e300", R[:2] + ["--set", "solver.t_end=1e300", "--elements-per-link", "2", "--quiet"] + out,
          ("steps", "solver.dt")),
        E("--draw 10^12 of 10^7 frames", R[:2] + ["--set", "solver.t_end=1000", "--set", "solver.output_every=1",
                                                   "--elements-per-link", "2", "--no-plots", "--quiet", "--force",
                                                   "--draw", "1000000000000"] + out, ("--draw", "about")),
        E("sweep 10^12 points", ["sweep", "slider_crank", "--param", "drives.0.speed=100:200:1000000000000",
                                 "--set", "solver.t_end=0.01", "--jobs", "1"] + out, ("--param", "about")),
        E("sweep 10^6 x 10^6 grid", ["sweep", "slider_crank", "--param", "drives.0.speed=100:200:1000000",
                                     "--param", "links.rod.area=1e-5:1e-4:1000000", "--jobs", "1"] + out,
          ("--param", "about")),
        E("sweep 10^12 samples", ["sweep", "slider_crank", "--sample", "drives.0.speed=normal:150:1",
                                  "--samples", "1000000000000", "--jobs", "1"] + out, ("--samples", "about")),
        E("stability 10^12 speeds", ["stability", "fourbar_constant_speed", "--speed", "100:200:1000000000000",
                                     "--jobs", "1"] + out, ("--speed", "about")),
        E("modes --along-cycle 10^9", ["modes", "fourbar_constant_speed", "--along-cycle", "1000000000",
                                       "--no-plots"] + out, ("--along-cycle", "about")),
        E("accuracy --dt-levels 60", ["accuracy", "slider_crank", "--dt-levels", "60", "--jobs", "1", "--quiet"] + out,
          ("--dt-levels", "about")),
        E("accuracy --elements 10^9", ["accuracy", "slider_crank", "--elements", "1,1000000000", "--jobs", "1",
                                       "--quiet"] + out, ("--elements", "about")),
        E("accuracy --ref-elements 10^9", ["accuracy", "slider_crank", "--ref-elements", "1000000000", "--jobs", "1",
                                           "--quiet"] + out, ("--ref-elements", "about")),
        E("accuracy --ref-dt-factor 2^40", ["accuracy", "slider_crank", "--ref-dt-factor", str(2 ** 40), "--jobs", "1",
                                            "--quiet"] + out, ("--ref-dt-factor", "about")),
        # --- the output folder
        E("--out empty", R + ["--out", ""], ("--out",)),
        E("--out /proc/x", R + ["--out", "/proc/x"], ("--out", "/proc/x")),
        E("--out /dev/null", R + ["--out", "/dev/null"], ("--out",)),
        E("--out a file", R + ["--out", "{tmp}/f"], ("--out", "file"), setup=lambda t: _write(t, "f", "mine")),
        E("--out below a file", R + ["--out", "{tmp}/f/sub"], ("--out",), setup=lambda t: _write(t, "f", "mine")),
        E("--out name too long", R + ["--out", "{tmp}/" + "o" * 300], ("--out", "too long")),
        E("sweep --out /proc/x", ["sweep", "slider_crank", "--param", "drives.0.speed=100,200", "--set",
                                  "solver.t_end=0.01", "--jobs", "1", "--out", "/proc/x"], ("--out",)),
        E("sweep --sample --out /proc/x", ["sweep", "slider_crank", "--sample", "drives.0.speed=normal:150:1", "--samples",
                                           "2", "--set", "solver.t_end=0.01", "--jobs", "1", "--out", "/proc/x"], ("--out",)),
        E("compare --models --out /proc/x", ["compare", "--models", "slider_crank", "--model-list", "hac",
                                             "--reference-model", "classic", "--set", "solver.t_end=0.002", "--jobs", "1",
                                             "--out", "/proc/x"], ("--out",)),
        E("modes --out /proc/x", ["modes", "slider_crank", "--no-plots", "--out", "/proc/x"], ("--out",)),
        E("stability --out /proc/x", ["stability", "fourbar_constant_speed", "--speed", "500", "--jobs", "1",
                                      "--out", "/proc/x"], ("--out",)),
        E("accuracy --out /proc/x", ["accuracy", "slider_crank", "--jobs", "1", "--quiet", "--out", "/proc/x"],
          ("--out",)),
        E("steady --out /proc/x", ["steady", "fourbar_constant_speed", "--no-plots", "--out", "/proc/x"], ("--out",)),
        E("reproduce --out /proc/x", ["reproduce", "--t-end", "0.002", "--no-gap", "--out", "/proc/x"], ("--out",)),
        E("bench --out /proc/x", ["bench", "--quick", "--out", "/proc/x"], ("--out",)),
        E("compare --out /proc/x", cmp_r[:-1] + ["/proc/x"], ("--out",),
          setup=_setups(_run_folder, lambda t: _reference(t, rows))),
        E("draw --out /proc/x.png", ["draw", "{tmp}/R", "--out", "/proc/x.png"], ("--out",), setup=_run_folder),
        E("reproduce --out empty", ["reproduce", "--out", ""], ("--out",)),
        E("--out held by another process", R + out, ("--out", "process"), setup=_held),
        E("--out holds another command's unfinished files", R + out, ("--out", "flexmech-partial"),
          setup=lambda t: _write(t, "o/flexmech-partial/PARTIAL.txt", "These files are NOT a complete result\n"
                                 "command: flexmech modes x\nresult: modes\nprocess: 1 on h\nstatus: running\n")),
        # --- sweep, samples
        E("sweep --param without =", ["sweep", "slider_crank", "--param", "drives.0.speed"] + out, ("--param",)),
        E("sweep --param N 0", ["sweep", "slider_crank", "--param", "drives.0.speed=1:2:0"] + out, ("--param",)),
        E("sweep --param words", ["sweep", "slider_crank", "--param", "drives.0.speed=a:b:3"] + out, ("--param",)),
        E("sweep --param unknown key", ["sweep", "slider_crank", "--param", "nosuch=1,2", "--jobs", "1"] + out,
          ("nosuch",)),
        E("sweep --param twice", ["sweep", "slider_crank", "--param", "drives.0.speed=1,2", "--param",
                                  "drives.0.speed=3"] + out, ("twice",)),
        E("sweep --param array", ["sweep", "slider_crank", "--param", "drives.0.speed=[1,2]"] + out, ("array",)),
        E("sweep --param and --sample", ["sweep", "slider_crank", "--param", "drives.0.speed=1,2", "--sample",
                                         "drives.0.speed=normal:1:1", "--samples", "2"] + out, ("--param", "--sample")),
        E("sweep --sample bad distribution", ["sweep", "slider_crank", "--sample", "drives.0.speed=foo:1:2",
                                              "--samples", "4"] + out, ("foo",)),
        E("sweep --sample negative sd", ["sweep", "slider_crank", "--sample", "drives.0.speed=normal:100:-1",
                                         "--samples", "4"] + out, ("sd",)),
        E("sweep --samples without --sample", ["sweep", "slider_crank", "--param", "drives.0.speed=1,2", "--samples",
                                               "4"] + out, ("--samples",)),
        E("sweep --scheduler bogus", ["sweep", "slider_crank", "--param", "drives.0.speed=1,2", "--scheduler",
                                      "bogus"] + out, ("--scheduler",)),
        E("sweep --jobs with --scheduler", ["sweep", "slider_crank", "--param", "drives.0.speed=1,2", "--jobs", "2",
                                            "--scheduler", "local:1"] + out, ("--jobs",)),
        E("sweep case missing", ["sweep", "{tmp}/none.toml", "--param", "drives.0.speed=1,2"] + out,
          ("does not exist",)),
        # --- stability, steady, modes
        E("stability --speed words", ["stability", "fourbar_constant_speed", "--speed", "abc"] + out, ("--speed",)),
        E("stability not constant speed", ["stability", "slider_crank_torque", "--speed", "1:2:2"] + out,
          ("constant",)),
        E("stability nonlinear", ["stability", "fourbar_constant_speed", "--speed", "500", "--model", "nonlinear"]
          + out, ("model",)),
        E("stability --resolution -1", ["stability", "fourbar_constant_speed", "--speed", "500:600:2",
                                        "--resolution", "-1"] + out, ("resolution",)),
        E("steady not constant speed", ["steady", "slider_crank_torque", "--no-plots"] + out, ("constant",)),
        E("modes --along-cycle 1", ["modes", "fourbar_constant_speed", "--along-cycle", "1", "--no-plots"] + out,
          ("--along-cycle",)),
        E("modes --at -1", ["modes", "slider_crank", "--at", "-1", "--no-plots"] + out, ("--at",)),
        E("modes --at past t_end", ["modes", "slider_crank", "--at", "1e9", "--no-plots"] + out, ("--at",)),
        E("modes --at and --crank-angle", ["modes", "slider_crank", "--at", "0", "--crank-angle", "5",
                                           "--no-plots"] + out, ("--crank-angle",)),
        # --- accuracy
        E("accuracy --elements 0", ["accuracy", "slider_crank", "--elements", "0,2", "--quiet"] + out, ("--elements",)),
        E("accuracy --ref-dt-factor 1 --dt-levels 2", ["accuracy", "slider_crank", "--dt-levels", "2", "--ref-dt-factor",
                                                       "1", "--quiet"] + out, ("--ref-dt-factor", "--dt-levels")),
        E("accuracy --ref-dt-factor 3", ["accuracy", "slider_crank", "--ref-dt-factor", "3", "--quiet"] + out,
          ("--ref-dt-factor",)),
        E("accuracy --integrators bogus", ["accuracy", "slider_crank", "--integrators", "bogus", "--quiet"] + out,
          ("bogus",)),
        E("accuracy --models bogus", ["accuracy", "slider_crank", "--models", "bogus", "--quiet"] + out, ("bogus",)),
        E("accuracy --tolerances -1", ["accuracy", "slider_crank", "--tolerances", "-1", "--quiet"] + out,
          ("--tolerances",)),
        E("accuracy --columns unknown", ["accuracy", "slider_crank", "--columns", "nosuch", "--quiet"] + out,
          ("nosuch",)),
        # --- compare
        E("compare: no RESULT", ["compare", "--reference", ref] + out, ("RESULT",)),
        E("compare: RESULT without a run", ["compare", "{tmp}", "--reference", ref], ("timeseries.csv",),
          setup=lambda t: _reference(t, rows)),
        E("compare: no such reference", cmp_r, ("--reference", "does not exist"), setup=_run_folder),
        E("compare: reference a folder", ["compare", "{tmp}/R", "--reference", "{tmp}/R", "--out", "{tmp}/cmp"],
          ("--reference", "folder"), setup=_run_folder),
        E("compare: reference with a BOM and duplicate times", cmp_r, ("t = 0.002", "twice"),
          setup=_setups(_run_folder, lambda t: _reference(t, rows + "0.002,0.446\n", bom=True))),
        E("compare: duplicate columns", cmp_r, ("slider_x", "twice"),
          setup=_setups(_run_folder, lambda t: _reference(t, "t,slider_x,slider_x\n0,1,1\n0.001,1,1\n"))),
        E("compare: duplicate times", cmp_r, ("t = 0.002", "twice"),
          setup=_setups(_run_folder, lambda t: _reference(t, rows + "0.002,0.446\n"))),
        E("compare: 10 MB cell", cmp_r, ("characters",),
          setup=_setups(_run_folder, lambda t: _reference(t, rows + "0.003," + "9" * 10_000_000 + "x\n"))),
        E("compare: 100 KB header name", cmp_r, ("characters",),
          setup=_setups(_run_folder, lambda t: _reference(t, f"t,{LONG}\n0,1\n0.001,1\n"))),
        E("compare: no source line", cmp_r, ("source",),
          setup=_setups(_run_folder, lambda t: _write(t, "ref.csv", rows))),
        E("compare: empty reference", cmp_r, ("header",),
          setup=_setups(_run_folder, lambda t: _write(t, "ref.csv", ""))),
        E("compare: binary reference", cmp_r, ("text",),
          setup=_setups(_run_folder, lambda t: _write(t, "ref.csv", b"\x00\x01" * 20, True))),
        E("compare: --columns unknown", cmp_r + ["--columns", "nosuch"], ("nosuch",),
          setup=_setups(_run_folder, lambda t: _reference(t, rows))),
        E("compare: --x crank_angle missing", cmp_r + ["--x", "crank_angle"], ("crank_angle",),
          setup=_setups(_run_folder, lambda t: _reference(t, rows))),
        E("compare: RESULT and --models", ["compare", "{tmp}/R", "--models", "slider_crank", "--reference", ref],
          ("--models",)),
        E("compare --models --model-list bogus", ["compare", "--models", "slider_crank", "--model-list", "bogus"]
          + out, ("bogus",)),
        # --- draw
        E("draw: no such folder", ["draw", "{tmp}/none"], ("shape.csv",)),
        E("draw: no shape.csv", ["draw", "{tmp}"], ("shape.csv",)),
        E("draw: --out d.xyz", ["draw", "{tmp}/R", "--out", "{tmp}/d.xyz"], ("--out", "xyz"), setup=_run_folder),
        E("draw: --gif --out d.png", ["draw", "{tmp}/R", "--gif", "--out", "{tmp}/d.png"], ("--out", "gif"),
          setup=_run_folder),
        E("draw: corrupt shape.csv", ["draw", "{tmp}/R"], ("shape.csv",),
          setup=_setups(_run_folder, lambda t: _write(t, "R/shape.csv", "garbage\n1,2\n"))),
        E("draw: corrupt summary.json", ["draw", "{tmp}/R"], ("summary.json",),
          setup=_setups(_run_folder, lambda t: _write(t, "R/summary.json", "{"))),
        # --- view
        E("view: no such folder", ["view", "{tmp}/none"], ("no such folder",)),
        E("view: not a result", ["view", "{tmp}"], ("not a flexmech result",)),
        E("view: a file", ["view", "{tmp}/f.txt"], ("is a file",), setup=lambda t: _write(t, "f.txt", "x")),
        E("view: no shape.csv", ["view", "{tmp}/R"], ("shape.csv", "--view"),
          setup=_setups(_run_folder, lambda t: (t / "R" / "shape.csv").unlink())),
        E("view: corrupt summary.json", ["view", "{tmp}/R"], ("summary.json",),
          setup=_setups(_run_folder, lambda t: _write(t, "R/summary.json", "{"))),
        E("view: corrupt shape.csv", ["view", "{tmp}/R"], ("shape.csv",),
          setup=_setups(_run_folder, lambda t: _write(t, "R/shape.csv", "garbage\n1,2\n"))),
        E("view: --out v.txt", ["view", "{tmp}/R", "--out", "{tmp}/v.txt"], ("--out", ".html"), setup=_run_folder),
        E("view: --out in a missing folder", ["view", "{tmp}/R", "--out", "{tmp}/no/v.html"], ("--out",),
          setup=_run_folder),
        E("view: --out /proc/v.html", ["view", "{tmp}/R", "--out", "/proc/v.html"], ("--out",), setup=_run_folder),
        # --- reproduce, bench
        E("reproduce --cases missing", ["reproduce", "--cases", "{tmp}/none", "--out", "{tmp}/o"], ("--cases",)),
        E("reproduce --cases empty", ["reproduce", "--cases", "{tmp}/d", "--out", "{tmp}/o"], ("--cases",),
          setup=lambda t: (t / "d").mkdir()),
        E("reproduce --cases a broken case", ["reproduce", "--cases", "{tmp}/d", "--t-end", "0.002", "--no-gap",
                                              "--out", "{tmp}/o"], ("fourbar_hac",),
          setup=lambda t: [_write(t, f"d/{n}.toml", _bundled(n) if n != "fourbar_hac" else "[case\n")
                           for n in ("fourbar_hac", "fourbar_constant_speed", "manipulator_bricout",
                                     "manipulator_bricout_no_payload")]),
        E("bench --cases missing", ["bench", "--quick", "--cases", "{tmp}/none", "--out", "{tmp}/B"], ("--cases",)),
        E("bench --cases a file", ["bench", "--quick", "--cases", "{tmp}/f", "--out", "{tmp}/B"], ("--cases",),
          setup=lambda t: _write(t, "f", "x")),
    ]


ENTRIES = _entries()


# ----------------------------------------------------------------------------- running an entry
def _tree(folder: Path) -> set:
    out = set()
    for root, dirs, files in os.walk(folder):
        for n in dirs + files:
            p = Path(root) / n
            try:
                st = p.lstat()
            except OSError:
                continue
            out.add((str(p.relative_to(folder)), stat.S_IFMT(st.st_mode), 0 if stat.S_ISDIR(st.st_mode) else st.st_size,
                     st.st_mtime_ns if not stat.S_ISDIR(st.st_mode) else 0))
    return out


def _child(entry: Entry, tmp: Path, wfd: int) -> None:
    """In the forked child: set up, run the entry, send (code, stdout, stderr, new files) through wfd."""
    code, out, err, left = None, io.StringIO(), io.StringIO(), []
    try:
        os.chdir(tmp)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
        if entry.setup is not None:
            entry.setup(tmp)
        before = _tree(tmp)
        from flexmech_py.cli import main

        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(entry.args(tmp))
            except SystemExit as exc:              # argparse
                code = exc.code if isinstance(exc.code, int) else 2
            except BaseException:                  # noqa: BLE001 - a traceback is the finding
                import traceback

                traceback.print_exc()
                code = 1
        left = sorted(n for n, *_ in _tree(tmp) - before)
    except BaseException as exc:                   # noqa: BLE001 - setup failed
        err.write(f"CATALOGUE SETUP FAILED: {type(exc).__name__}: {exc}\n")
        code = -1
    msg = json.dumps({"code": code, "out": out.getvalue()[-20000:], "err": err.getvalue()[:200_000],
                      "left": left}).encode()
    view = memoryview(msg)
    while view:
        n = os.write(wfd, view[:65536])
        view = view[n:]
    os.close(wfd)


def run_entry(entry: Entry, tmp: Path) -> Outcome:
    """Run one entry in a forked child (memory limit, TIME_LIMIT) and judge it."""
    rfd, wfd = os.pipe()
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:                                   # pragma: no cover - the child
        os.close(rfd)
        try:
            _child(entry, tmp, wfd)
        finally:
            os._exit(0)
    os.close(wfd)
    chunks, deadline = [], TIME_LIMIT
    import time

    t0 = time.monotonic()
    while True:
        left = deadline - (time.monotonic() - t0)
        ready, _, _ = select.select([rfd], [], [], max(0.0, left))
        if not ready:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            os.close(rfd)
            return judge(entry, Outcome(None, "", f"hung for more than {TIME_LIMIT} s"))
        data = os.read(rfd, 1 << 20)
        if not data:
            break
        chunks.append(data)
    os.close(rfd)
    _, status = os.waitpid(pid, 0)
    if not chunks:
        sig = os.WTERMSIG(status) if os.WIFSIGNALED(status) else None
        return judge(entry, Outcome(None, "", f"the process died (signal {sig}, status {status})"))
    d = json.loads(b"".join(chunks))
    return judge(entry, Outcome(d["code"], d["out"], d["err"], d["left"]))


def judge(entry: Entry, o: Outcome) -> Outcome:
    lines = [ln for ln in o.err.splitlines() if ln.strip() and not ln.startswith(("flexmech: warning:", "flexmech: note:"))]
    errors = [ln for ln in lines if not ln.startswith("usage:") and not ln.startswith("  ")]
    if o.code is None or o.code == -1:
        o.verdict, o.why = "not clean", o.err.strip()[:300]
    elif "Traceback" in o.err:
        o.verdict, o.why = "not clean", "traceback: " + o.err.strip().splitlines()[-1][:300]
    elif o.code not in entry.codes:
        o.verdict, o.why = "not clean", f"exit {o.code}; {o.err.strip()[:300]}"
    elif len(errors) != 1:
        o.verdict, o.why = "not clean", f"{len(errors)} error lines: {o.err.strip()[:300]}"
    elif max(len(ln) for ln in lines) > MAX_LINE:
        o.verdict, o.why = "not clean", f"a line of {max(len(ln) for ln in lines)} characters"
    elif o.code == 2 and o.left:
        o.verdict, o.why = "not clean", f"left behind after exit 2: {', '.join(o.left[:5])}"
    else:
        missing = [n for n in entry.needles if n.lower() not in errors[0].lower()]
        o.verdict = "unclear" if missing else "clean"
        o.why = (f"does not say {', '.join(map(repr, missing))}: " if missing else "") + errors[0][:300]
    return o


def preload(folder: Path) -> None:
    """Import what the entries use and make RUN_TEMPLATE in ``folder``, once, before the children are
    forked (each then starts at once)."""
    global RUN_TEMPLATE
    import flexmech_py.cli  # noqa: F401
    import flexmech_py.run.simulate  # noqa: F401

    (folder / "template").mkdir()
    _run_folder(folder / "template")
    RUN_TEMPLATE = folder / "template" / "R"


def applicable(entry: Entry) -> bool:
    root = os.geteuid() == 0
    return entry.root_only is None or entry.root_only == root


def main() -> int:
    import time

    counts = {"clean": 0, "unclear": 0, "not clean": 0}
    base = Path(tempfile.mkdtemp(prefix="flexmech-catalogue-"))
    try:
        preload(base)
        for k, entry in enumerate(e for e in ENTRIES if applicable(e)):
            tmp = base / f"e{k:03d}"
            tmp.mkdir()
            t0 = time.monotonic()
            o = run_entry(entry, tmp)
            counts[o.verdict] += 1
            print(f"{o.verdict:>9} | {time.monotonic() - t0:5.1f} s | {entry.name} | exit {o.code} | {o.why}", flush=True)
    finally:
        shutil.rmtree(base, ignore_errors=True)
    print(f"{sum(counts.values())} entries: " + ", ".join(f"{v} {k}" for k, v in counts.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
