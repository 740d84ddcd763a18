"""Exception and warning classes of flexmech.

Every error a user can cause derives from :class:`FlexmechError`; the CLI turns
any of them into one line on stderr and its ``exit_code`` (2: nothing was started;
3: the command started and could not finish, its partial results kept and marked).
Compiled-kernel status codes are translated into these exceptions in exactly one place
(:func:`flexmech_py.base.kernels.check_status`).  A message is always one bounded line
(:func:`one_line`): a user's value that is very long is cut, saying how long it was.  Every
warning a run gives derives from :class:`FlexmechWarning` (issued by :mod:`flexmech_py.base.notices`).
"""

import re

__all__ = [
    "FlexmechError",
    "CaseError",
    "MechanismError",
    "SolverError",
    "OutputError",
    "Interrupted",
    "Terminated",
    "one_line",
    "signal_words",
    "FlexmechWarning",
    "ValidityWarning",
    "AccuracyWarning",
    "MechanismWarning",
    "StabilityWarning",
]

#: a word (no spaces) longer than this many characters is cut in a message
WORD_MAX = 200
#: a message longer than this many characters is cut in its middle
LINE_MAX = 1000
_LONG_WORD = re.compile(r"\S{%d,}" % (WORD_MAX + 1))


def _cut_word(m) -> str:
    word = m.group()
    return f"{word[:80]}... ({len(word)} characters)"


def one_line(text) -> str:
    """``text`` as one line of at most about LINE_MAX characters: line breaks written as ``\\n``, a word
    longer than WORD_MAX characters cut to its start and its length (``'xxxx... (100000 characters)'``),
    a line still too long cut in its middle (saying how long it was)."""
    text = str(text).replace("\r", "\\r").replace("\n", "\\n")
    text = _LONG_WORD.sub(_cut_word, text)
    if len(text) > LINE_MAX:
        text = f"{text[:LINE_MAX - 300]} ... ({len(text)} characters in all) ... {text[-200:]}"
    return text


class FlexmechError(Exception):
    """Base class of all errors flexmech reports to users; the message is cut to one bounded line
    (:func:`one_line`).  ``exit_code``: what the command line exits with (2: nothing was started)."""

    exit_code = 2

    def __init__(self, message="", *args):
        super().__init__(one_line(message), *args)


class CaseError(FlexmechError, ValueError):
    """A case file (or an override) is invalid: names the field and the fix."""

    def __init__(self, field: str, message: str):
        self.field = field
        super().__init__(f"{field}: {message}")


class MechanismError(FlexmechError):
    """The mechanism cannot assemble or cannot move through the requested motion.

    ``time`` [s]: when the motion reached the singular position or assembly limit (None: at set-up);
    ``code``: the kernel status (7 singular position, 8 cannot assemble); ``partial``: the rigid
    motion sampled before it (a RigidMotion), when there is one."""

    def __init__(self, message: str, time: float | None = None, code: int | None = None, partial=None):
        self.time = time
        self.code = code
        self.partial = partial
        super().__init__(message)


class SolverError(FlexmechError, RuntimeError):
    """A compiled solver stopped (singular matrix, non-finite values, divergence, Newton failure, ...).

    Attributes: ``time`` [s] of the failed step, ``code`` (the kernel status), ``step`` (1-based
    failed step), ``partial`` (a :class:`~flexmech_py.run.results.Result` holding the frames up to the
    failure, marked ``status = "failed"``; None when nothing could be kept), ``failure`` (the
    diagnosis written to summary.json: quantity, likely cause, evidence), ``data`` (the raw kernel
    arrays, used internally to build ``partial``)."""

    def __init__(self, message: str, time: float | None = None, code: int | None = None, *,
                 step: int | None = None, data: dict | None = None, partial=None, failure: dict | None = None):
        self.time = time
        self.code = code
        self.step = step
        self.data = data
        self.partial = partial
        self.failure = failure
        super().__init__(message)


class OutputError(FlexmechError):
    """Writing a command's results failed after the command started (a full disk, a file-size limit, a
    folder that became unwritable): ``path`` the file that failed, ``kept`` where the partial results
    are (marked), ``exit_code`` 3.  Before anything started the same trouble is a CaseError naming
    ``--out`` (exit code 2)."""

    exit_code = 3

    def __init__(self, message: str, path=None, kept=None, partial=None):
        self.path = path
        self.kept = kept
        self.partial = partial
        super().__init__(message)


class Interrupted(KeyboardInterrupt):
    """The user stopped a run (Ctrl-C), or a signal did (SIGTERM, SIGHUP: ``signum``); ``partial``: the
    Result of the frames computed before it (written and marked ``status = "interrupted"`` by a run
    that writes files).  A KeyboardInterrupt, not a FlexmechError: whatever stops on Ctrl-C (a batch
    of runs, the CLI's exit 130; 128 + the signal's number for the others) still does."""

    def __init__(self, message: str, partial=None, signum: int | None = None):
        self.partial = partial
        self.signum = signum
        super().__init__(message)


class Terminated(KeyboardInterrupt):
    """A signal asked the process to end (SIGTERM from a batch system, ``timeout`` or systemd; SIGHUP
    from a closed terminal): raised by the command line's handler in the main thread, and handled
    where Ctrl-C is (the frames so far kept, marked).  ``signum``, ``name``."""

    def __init__(self, signum: int):
        import signal

        self.signum = signum
        self.name = signal.Signals(signum).name
        super().__init__(f"terminated by {self.name}")


def signal_words(exc) -> str:
    """How a run was stopped, for its messages: 'interrupted by the user' (Ctrl-C) or 'terminated by SIGTERM'."""
    name = getattr(exc, "name", None)
    return f"terminated by {name}" if name else "interrupted by the user"


class FlexmechWarning(UserWarning):
    """Base class of the warnings of a run (``res.extra["warnings"]``), issued by the Python API
    (``fm.simulate``, ``Prepared.run``, ...) with :mod:`warnings`: filter them by class, e.g.
    ``warnings.filterwarnings("ignore", category=fm.ValidityWarning)``."""


class ValidityWarning(FlexmechWarning):
    """The model is used outside its range: a deflection, strain or compression past its limit
    (docs/stability.md, validity)."""


class AccuracyWarning(FlexmechWarning):
    """An estimated numerical error (time step, mesh) above its threshold (docs/stability.md, error
    estimate)."""


class MechanismWarning(FlexmechWarning):
    """Something about the mechanism as described that may not be what was meant (a free degree of
    freedom with no drive and no gravity)."""


class StabilityWarning(FlexmechWarning):
    """A periodic steady state that is unstable or ill-conditioned (flexmech steady, Floquet)."""
