"""The life of a result folder: a command's results are whole or absent (docs/cli.md, "What is left
on disk").

Every command that writes results (run, steady, modes, sweep, stability, accuracy, compare, draw,
reproduce, bench) writes them through one :class:`ResultFolder`:

1. **check** the target before anything starts: an empty name, a file, a folder that cannot be
   created or written are one CaseError naming ``--out`` (exit code 2, nothing left behind);
2. **lock** it (:class:`~flexmech_py.base.folderlock.FolderLock`): a second command into the same
   folder is refused with the holder's PID; the lock of a killed process is taken over;
3. **stage**: the command writes its files into ``OUT/flexmech-partial/``, whose ``PARTIAL.txt``
   says what they are (the command, its PID, "running", later why it stopped), beside a reserve
   of RESERVE_BYTES that is given back when the disk fills, so the partial files can still be
   marked; a disk too full for the reserve refuses the command before it starts (exit code 2);
4. **commit** when the result is whole: the staged files replace, one rename each, the files this
   command wrote there before (the folder's manifest ``.flexmech-results.json`` lists them), under
   a journal: a commit cut short (kill -9 between two renames) is finished by the next command
   that takes the folder; signals wait until it is done;
5. **stop** otherwise (an error, a signal, a full disk): the earlier results stay untouched and
   the new files stay in ``OUT/flexmech-partial/``, marked -- or, when the folder held no earlier
   result of this command and the files mark themselves (a run's ``# partial`` CSV and summary),
   they take the results' place.  Nothing staged: nothing is left (a folder created for the
   command is removed again).

A folder's ``cache/`` (resumable batches) is written in place, each entry whole.  An earlier
command's ``flexmech-partial/`` is replaced by the next attempt of the same command (with a note);
another command is refused while it is there (run: unless ``--overwrite``).  A single file (``draw
--out FILE``) is written beside its name and renamed, under the lock of its folder.

:func:`claim` is the run's own rule on top: a folder holding another case's run is refused unless
``overwrite``.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import socket
import sys
import time
from pathlib import Path

from ..base.errors import CaseError, OutputError
from ..base.folderlock import LOCK_NAME, FolderLock
from ..base.signals import held_signals
from ..base.sizes import format_bytes

__all__ = ["ResultFolder", "claim", "RUN_FILES", "PARTIAL_DIR", "MARKER", "MANIFEST", "RESERVE_BYTES",
           "release_reserve", "command_line"]

#: the staging folder inside a result folder (kept, marked, when a command does not finish)
PARTIAL_DIR = "flexmech-partial"
#: the note in it saying what its files are
MARKER = "PARTIAL.txt"
#: the result folder's list of the files each command put there
MANIFEST = ".flexmech-results.json"
#: bytes held back in the staging folder while a command runs (given back to mark partial files)
RESERVE_BYTES = 1 << 20
_RESERVE = ".reserve"
_JOURNAL = ".commit"
_REPLACED = ".replaced"
#: subfolders a command writes in place (never staged, never replaced)
PERSISTENT = ("cache",)
_OURS = {LOCK_NAME, MANIFEST, PARTIAL_DIR, *PERSISTENT}

#: the names a run writes (the plots are listed by the run itself)
RUN_FILES = ("timeseries.csv", "timeseries.csv.part", "summary.json", "timeseries.png",
             "strain_vs_crank_angle.png", "shape.csv", "drawing.png", "view.html")


def command_line() -> str:
    """The command being run, as the lock and PARTIAL.txt record it."""
    return " ".join(["flexmech"] + sys.argv[1:])[:500]


def release_reserve(folder) -> None:
    """Give back the reserve of a staging folder (a full disk: room to mark the partial files)."""
    try:
        os.unlink(Path(folder) / _RESERVE)
    except OSError:
        pass


def _entries(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name not in (MARKER, _RESERVE, _JOURNAL, _REPLACED))


def _remove(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p, ignore_errors=True)
    else:
        try:
            p.unlink()
        except FileNotFoundError:
            pass


def _write_json(path: Path, data) -> None:
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    try:
        tmp.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
        os.replace(tmp, path)
    except BaseException:
        _remove(tmp)
        raise


class ResultFolder:
    """``with ResultFolder(out, "run") as rf:`` write into ``rf.stage``, then ``rf.commit()``; leaving the
    block without a commit stops the command (the module's docstring).  ``field``: the option the
    messages name; ``claim``: a callable (run under the lock) returning the files of an earlier result
    this one replaces besides the manifest's, or raising CaseError; ``overwrite``: replace another
    command's leftover staging folder; ``single``: ``out`` is one file (``draw --out FILE``), not a
    folder (no manifest then: the file is all there is).  After the block:
    ``kept`` (where the files are: ``out``, the staging folder, or None), ``notes`` (what was taken
    over or replaced, for the user)."""

    def __init__(self, out, command: str, *, field: str = "--out", claim=None, overwrite: bool = False,
                 single: bool = False):
        if not str(out).strip():     # a Path("") would be the current folder
            raise CaseError(field, "is empty; give a folder (e.g. --out results/run1)")
        self.out = Path(out)
        self.command = command
        self.field = field
        self.claim = claim
        self.overwrite = overwrite
        self.single = single
        self.folder = self.out.parent if single else self.out
        self.stage = self.folder / (f".{self.out.name}.flexmech-{os.getpid()}" if single else PARTIAL_DIR)
        self.notes: list[str] = []
        self.kept: Path | None = None
        self.replaces: list[Path] = []
        self.committed = False
        self._lock = None
        self._created: list[Path] = []
        self._stop_reason: str | None = None
        self._marked = False
        self._stage_made = False
        self._started = time.time()

    # ------------------------------------------------------------------ opening
    def __enter__(self) -> "ResultFolder":
        try:
            self._make_folder()
            self._lock = FolderLock(self.folder, self.field, command_line()).acquire()
            if self._lock.stale:
                s = self._lock.stale
                self.notes.append(f"took over {self.folder}: flexmech process {s.get('pid')} (`{s.get('command', '?')}`) "
                                  "that held it has ended without finishing")
            self._recover()
            if self.claim is not None:
                self.replaces = list(self.claim())
            self._open_stage()
            for note in self.notes:
                print(f"flexmech: note: {note}", file=sys.stderr)
        except BaseException as exc:
            if self._stage_made:
                _remove(self.stage)
            self._abandon()
            if isinstance(exc, OSError):
                raise self._unusable(exc) from None
            raise
        return self

    def _unusable(self, exc: OSError) -> CaseError:
        """The CaseError (exit code 2) of a target that cannot be used before anything started."""
        where = None if exc.filename is None else str(exc.filename)
        if exc.errno in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT):
            free = _free_bytes(self.folder)
            return CaseError(self.field, f"{self.out}: no room to start ({exc.strerror}; {format_bytes(free)} free on its "
                                         f"disk, and a command keeps {format_bytes(RESERVE_BYTES)} in hand to mark results "
                                         "that cannot finish): free some space, or choose another folder")
        at = "" if where in (None, str(self.out)) else f" at {where}"
        return CaseError(self.field, f"cannot write {self.out} ({exc.strerror or exc}{at}): choose another folder")

    def _make_folder(self) -> None:
        target = self.folder
        if self.single and self.out.is_dir():
            raise CaseError(self.field, f"{self.out} is a folder; give a file name")
        if target.exists() and not target.is_dir():
            raise CaseError(self.field, f"{target} is a file, not a folder: choose another folder")
        missing = []
        p = target
        while not p.exists() and p != p.parent:
            missing.append(p)
            p = p.parent
        target.mkdir(parents=True, exist_ok=True)
        self._created = missing            # innermost first: removed again if nothing is written

    def _open_stage(self) -> None:
        self.stage.mkdir()
        self._stage_made = True
        if not self.single:
            self._mark("running (if no flexmech process with this PID runs, it was killed before it finished)")
        fd = os.open(self.stage / _RESERVE, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            try:
                os.posix_fallocate(fd, 0, RESERVE_BYTES)
            except OSError as exc:
                if exc.errno not in (errno.EOPNOTSUPP, errno.EINVAL):
                    raise
                os.write(fd, b"\0" * RESERVE_BYTES)
        finally:
            os.close(fd)

    def _mark(self, status: str) -> None:
        """PARTIAL.txt: what the staging folder's files are and where they stand."""
        started = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(self._started))
        text = ("These files are NOT a complete result: a flexmech command wrote them and did not finish.\n"
                f"command: {command_line()}\n"
                f"result: {self.command}\n"
                f"process: {os.getpid()} on {socket.gethostname()}, started {started}\n"
                f"status: {status}\n"
                f"The complete results of earlier commands, if any, are in {self.folder} and were not touched.\n")
        (self.stage / MARKER).write_text(text, encoding="utf-8")

    def _recover(self) -> None:
        """Finish a commit that was cut short; replace (or refuse) an earlier attempt's staging folder."""
        if self.single:
            return
        stage = self.stage
        if (stage / _JOURNAL).exists():
            journal = json.loads((stage / _JOURNAL).read_text(encoding="utf-8"))
            self._apply(journal)
            self.notes.append(f"finished putting the results of an earlier `{journal.get('line', '?')}` in place "
                              "(it was stopped while renaming its files)")
            return
        if not stage.exists():
            return
        info = _marker_info(stage)
        what = f"`{info.get('command', '?')}` ({info.get('process', 'process unknown')}; {info.get('status', '?')})"
        if info.get("result") != self.command and not self.overwrite:
            raise CaseError(self.field, f"{stage} holds the unfinished files of {what}: move them away or delete "
                                        "them, or choose another folder")
        _remove(stage)
        self.notes.append(f"replaced the unfinished files of {what} in {stage}")

    # ------------------------------------------------------------------ the end
    def stopped(self, reason: str, marked: bool = False) -> None:
        """The command stops without a whole result: ``reason`` goes into PARTIAL.txt; ``marked``: the
        staged files mark themselves as partial (they may take the place of an absent result)."""
        self._stop_reason, self._marked = reason, marked

    def commit(self) -> None:
        """The result is whole: put the staged files in place of this command's earlier ones."""
        release_reserve(self.stage)
        with held_signals():
            if self.single:
                os.replace(self.stage / self.out.name, self.out)
                _remove(self.stage)
            else:
                self._apply(self._journal("complete"))
            self.committed, self.kept = True, self.out

    def _journal(self, status: str) -> dict:
        put = _entries(self.stage)
        manifest = _read_manifest(self.folder)
        before = manifest.get(self.command, {}).get("files", []) + [p.name for p in self.replaces]
        remove = sorted({n for n in before if n not in put and n not in _OURS and "/" not in n and n not in ("", ".", "..")})
        journal = {"command": self.command, "line": command_line(), "put": put, "remove": remove, "status": status}
        _write_json(self.stage / _JOURNAL, journal)
        return journal

    def _apply(self, journal: dict) -> None:
        """Carry out a commit journal (again, after a crash: every step can be repeated)."""
        stage, out = self.stage, self.folder
        trash = stage / _REPLACED
        trash.mkdir(exist_ok=True)
        for name in journal["put"]:
            src, dst = stage / name, out / name
            if not os.path.lexists(src):
                continue                      # moved before the crash
            if os.path.lexists(dst) and (dst.is_dir() or src.is_dir()):
                _remove(trash / name)
                os.replace(dst, trash / name)
            os.replace(src, dst)
        for name in journal["remove"]:
            if os.path.lexists(out / name):
                _remove(trash / name)
                os.replace(out / name, trash / name)
        manifest = _read_manifest(out)
        manifest[journal["command"]] = {"files": journal["put"], "status": journal["status"]}
        _write_json(out / MANIFEST, manifest)
        shutil.rmtree(stage, ignore_errors=True)

    def __exit__(self, etype, exc, tb):
        failed = None
        if isinstance(exc, OSError):
            failed = exc.filename or (str(self.out) if self.single else None)
        try:
            if not self.committed:
                with held_signals():
                    self._stop(exc, failed)
        finally:
            self._abandon()
        if isinstance(exc, OSError):
            raise self._output_error(exc, failed) from None
        return False

    def _stop(self, exc, failed: str | None) -> None:
        if self._lock is None or not self.stage.exists():
            return
        release_reserve(self.stage)
        if failed and Path(failed).parent == self.stage and Path(failed).is_file():
            Path(failed).unlink()           # a file cut short by a failed write: nothing in it to keep
        staged = _entries(self.stage)
        if not staged or self.single:
            _remove(self.stage)
            return
        reason = self._stop_reason or _describe(exc, failed)
        try:
            self._mark(f"stopped: {reason}")
        except OSError:
            pass
        nothing_to_protect = not _read_manifest(self.folder).get(self.command) and not self.replaces
        self.kept = self.stage
        if self._marked and nothing_to_protect:
            try:
                self._apply(self._journal("partial"))
                self.kept = self.out
            except OSError:        # the disk is full even now: the files stay staged (a journal finishes later)
                pass

    def _abandon(self) -> None:
        """Release the lock; remove the folders made for a command that left nothing in them."""
        if self._lock is not None:
            self._lock.release()
            self._lock = None
        for p in self._created:
            try:
                p.rmdir()
            except OSError:
                break

    def _output_error(self, exc: OSError, failed: str | None) -> OutputError:
        """The OutputError (exit code 3) of a write that failed after the command started."""
        name = failed or "a file"
        if self.kept == self.out:
            where = f"the partial results are in {self.out}, marked"
        elif self.kept is not None:
            where = f"the files written so far are in {self.kept} (PARTIAL.txt says what they are); {self.folder} " \
                    "keeps its earlier results"
        else:
            where = f"nothing was kept; {self.folder} keeps its earlier results"
        fix = "free some space there" if exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG) else "fix the folder"
        return OutputError(f"writing {name} failed ({exc.strerror or exc}); {where}; {fix}, or choose another "
                           "--out, and run the command again", path=exc.filename, kept=self.kept)

    def where(self, path) -> Path:
        """Where a file written into the staging folder is now (after the block)."""
        p = Path(path)
        try:
            rel = p.relative_to(self.stage)
        except ValueError:
            return p
        if self.kept in (None, self.stage):
            return p
        return self.out if self.single else self.out / rel


def _describe(exc, failed: str | None = None) -> str:
    if exc is None:
        return "the command ended without a whole result"
    if isinstance(exc, KeyboardInterrupt):
        return str(exc) or "interrupted (Ctrl-C)"
    if isinstance(exc, OSError):
        return f"writing {failed or 'a file'} failed ({exc.strerror or exc})"
    return f"{type(exc).__name__}: {exc}"


def _marker_info(stage: Path) -> dict:
    try:
        lines = (stage / MARKER).read_text(encoding="utf-8").splitlines()
    except OSError:
        return {}
    return {k.strip(): v.strip() for k, _, v in (ln.partition(":") for ln in lines[1:5])}


def _read_manifest(folder: Path) -> dict:
    try:
        data = json.loads((folder / MANIFEST).read_text(encoding="utf-8"))
        return data if isinstance(data, dict) else {}
    except (OSError, ValueError):
        return {}


def _free_bytes(folder: Path) -> int:
    try:
        return shutil.disk_usage(folder).free
    except OSError:
        return 0


# ----------------------------------------------------------------------------- the run's rule
def _identity(case) -> str:
    c = case["case"]
    return str(c.get("path") or c.get("title", ""))


def claim(out_dir, case, overwrite: bool = False) -> list[Path]:
    """The files of an earlier run in ``out_dir`` that a run of ``case`` replaces (when it commits);
    CaseError naming ``--out`` for a folder holding another case's run, or run files of unknown
    origin, unless ``overwrite``."""
    out = Path(out_dir)
    if not out.is_dir():
        if out.exists():
            raise CaseError("--out", f"{out} is a file, not a folder: choose another --out")
        return []
    present = [out / n for n in RUN_FILES if (out / n).exists()]
    summary = out / "summary.json"
    previous = _previous_run(summary) if summary.exists() else None
    if previous is not None:
        listed = [out / n for n in previous.get("files", []) if "/" not in n and (out / n).exists()]
        present = sorted(set(present) | set(listed))
    if not present or overwrite:
        return present
    if previous is None:
        raise CaseError("--out", f"{out} holds results of an unknown run ({', '.join(p.name for p in present)}): "
                                 "choose another --out, or add --overwrite to replace them")
    if previous["case"] != _identity(case):
        raise CaseError("--out", f"{out} holds the results of another case ({previous['case']}): choose another "
                                 "--out, or add --overwrite to replace them")
    return present


def _previous_run(summary: Path) -> dict | None:
    """{'case': identity, 'files': [...]} of the run that wrote ``summary``, None when unreadable."""
    try:
        data = json.loads(summary.read_text(encoding="utf-8"))
        return {"case": _identity(data["input"]), "files": list(data.get("files", []))}
    except (OSError, ValueError, KeyError, TypeError):
        return None
