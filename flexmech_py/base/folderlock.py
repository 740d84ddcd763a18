"""One writer per result folder: an advisory lock held for the whole of a command.

:class:`FolderLock` takes an exclusive ``flock`` on ``FOLDER/.flexmech.lock`` and writes into it who
holds it (PID, host, command, start time).  A second process asking for the same folder is refused
at once (:class:`Busy`, a CaseError naming ``--out`` and the holder's PID); it does not wait: two
commands aimed at one folder are almost always a mistake, and a script that means to queue them
waits for the first one's PID.  The kernel drops the lock when its holder ends, however it ends, so
a lock file left by a killed process (kill -9, a crash, a power cut) is *stale*: the next command
takes it over (and says whose it was).  The holder removes the file when it releases the lock; a
process that opened it just before checks, once it holds the lock, that the file it locked is still
the one at that path.

On a file system without ``flock`` (some network and FUSE file systems) the file's PID decides: held
while a process of that PID runs on this host.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import socket
import sys
import time
from pathlib import Path

from .errors import CaseError

__all__ = ["FolderLock", "Busy", "LOCK_NAME"]

#: the lock file in the folder it guards
LOCK_NAME = ".flexmech.lock"


class Busy(CaseError):
    """The folder is being written by another flexmech process: ``holder`` its lock record."""

    def __init__(self, field: str, folder, holder: dict):
        self.holder = holder
        pid, host = holder.get("pid", "?"), holder.get("host", "")
        where = "" if host in ("", socket.gethostname()) else f" on {host}"
        since = time.strftime("%H:%M:%S", time.localtime(holder["started"])) if "started" in holder else "?"
        super().__init__(field, f"{folder} is being written by flexmech process {pid}{where} (`{holder.get('command', '?')}`"
                                f", since {since}); wait until it ends (e.g. `tail --pid={pid} -f /dev/null`), "
                                "or choose another folder")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _record(fd: int) -> dict:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        data = json.loads(os.read(fd, 65536).decode("utf-8", "replace") or "{}")
        return data if isinstance(data, dict) else {}
    except (OSError, ValueError):
        return {}


class FolderLock:
    """``with FolderLock(folder, field="--out"):`` the folder is ours; Busy (exit 2) when another
    process holds it.  ``stale``: the record of a killed holder whose lock was taken over, else None."""

    def __init__(self, folder, field: str = "--out", command: str | None = None):
        self.folder = Path(folder)
        self.path = self.folder / LOCK_NAME
        self.field = field
        self.command = command if command is not None else " ".join(["flexmech"] + sys.argv[1:])[:300]
        self.fd: int | None = None
        self.stale: dict | None = None

    def acquire(self) -> "FolderLock":
        for _ in range(20):      # a holder may remove the file between our open and our lock: open again
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
            try:
                held = self._lock(fd)
                if not held:
                    raise Busy(self.field, self.folder, _record(fd))
                if os.fstat(fd).st_ino == os.stat(self.path).st_ino:
                    break
            except FileNotFoundError:
                pass
            except BaseException:
                os.close(fd)
                raise
            os.close(fd)
        else:   # pragma: no cover - twenty holders in a row removed the file under us
            raise Busy(self.field, self.folder, {"command": "several flexmech processes"})
        previous = _record(fd)
        self.stale = previous if previous.get("pid") not in (None, os.getpid()) else None
        os.ftruncate(fd, 0)
        os.lseek(fd, 0, os.SEEK_SET)
        os.write(fd, json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "command": self.command,
                                 "started": time.time()}).encode())
        self.fd = fd
        return self

    @staticmethod
    def _lock(fd: int) -> bool:
        """True when the lock on fd is ours (flock, or the PID rule where flock is not supported)."""
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            return False
        except OSError as exc:
            if exc.errno not in (errno.ENOLCK, errno.EOPNOTSUPP, errno.EINVAL):
                raise
        rec = _record(fd)
        mine = rec.get("host") in (None, socket.gethostname())
        return not (rec.get("pid") and rec["pid"] != os.getpid() and mine and _alive(int(rec["pid"])))

    def release(self) -> None:
        if self.fd is None:
            return
        try:
            os.unlink(self.path)
        except OSError:
            pass
        os.close(self.fd)       # closing drops the flock
        self.fd = None

    def __enter__(self) -> "FolderLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
