"""How flexmech's processes end.

- :func:`stop_on_signals`: while a command runs, SIGTERM (a batch system, ``timeout``, systemd) and
  SIGHUP (a closed terminal) raise :class:`~flexmech_py.base.errors.Terminated` in the main thread, a
  KeyboardInterrupt: whatever Ctrl-C does, they do (a run keeps its frames, marked; a batch keeps
  its cache).  A second one while the command stops is ignored, so the partial results get written;
  SIGKILL still ends it at once.  :func:`exit_code`: 130 for Ctrl-C, 128 + the signal's number for
  the others (143 SIGTERM, 129 SIGHUP), as shells report them.
- :func:`held_signals`: a few lines that must not be cut in two (renaming a result's files) hold
  the signals back until they are done.
- :func:`die_with_parent`: a worker process (the local pool's) ends when the process that started it
  ends, even by kill -9: Linux's parent-death signal (SIGKILL), and a watchdog thread where there is
  none.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import signal
import threading
import time

from .errors import Terminated

__all__ = ["stop_on_signals", "held_signals", "exit_code", "die_with_parent", "STOP_SIGNALS"]

#: the signals handled like Ctrl-C
STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGTERM", "SIGHUP") if hasattr(signal, n))
_PR_SET_PDEATHSIG = 1
#: seconds between the watchdog's looks at the parent (where there is no parent-death signal)
WATCH_S = 1.0


@contextlib.contextmanager
def stop_on_signals():
    """Within: SIGTERM and SIGHUP raise Terminated (main thread only; elsewhere nothing changes)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    raised = []

    def handler(signum, frame):
        if raised:               # already stopping: let the partial results be written
            return
        raised.append(signum)
        raise Terminated(signum)

    old = {s: signal.signal(s, handler) for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


@contextlib.contextmanager
def held_signals():
    """Within: SIGINT, SIGTERM and SIGHUP wait (delivered when the block ends), so that what it does --
    renaming a result's files, writing a block of frames and counting it -- is done whole.  Main
    thread only; elsewhere nothing is held."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, (signal.SIGINT,) + STOP_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def exit_code(exc) -> int:
    """The exit code of a command stopped by ``exc`` (a KeyboardInterrupt): 128 + its signal."""
    return 128 + int(getattr(exc, "signum", None) or signal.SIGINT)


def die_with_parent(parent_pid: int) -> None:
    """Make this (worker) process end when ``parent_pid`` ends: the initializer of a process pool."""
    libc = ctypes.util.find_library("c")
    armed = False
    if libc and hasattr(os, "getppid"):
        try:
            armed = ctypes.CDLL(libc, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
        except (OSError, AttributeError):
            armed = False
    if os.getppid() != parent_pid:      # the parent died before the signal was armed
        os._exit(1)
    if not armed:
        threading.Thread(target=_watch, args=(parent_pid,), daemon=True, name="flexmech-parent-watch").start()


def _watch(parent_pid: int) -> None:
    while os.getppid() == parent_pid:
        time.sleep(WATCH_S)
    os._exit(1)
