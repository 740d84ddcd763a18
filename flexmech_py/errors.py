"""Exception and warning classes of flexmech.

Every error a user can cause derives from :class:`FlexmechError`; the CLI turns
any of them into one line on stderr and exit code 2.  Compiled-kernel status
codes are translated into these exceptions in exactly one place
(:func:`flexmech_py.kernels.check_status`).  Every warning a run gives derives from
:class:`FlexmechWarning` (issued by :mod:`flexmech_py.notices`).
"""

__all__ = [
    "FlexmechError",
    "CaseError",
    "MechanismError",
    "SolverError",
    "Interrupted",
    "FlexmechWarning",
    "ValidityWarning",
    "AccuracyWarning",
    "MechanismWarning",
    "StabilityWarning",
]


class FlexmechError(Exception):
    """Base class of all errors flexmech reports to users."""


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
    failed step), ``partial`` (a :class:`~flexmech_py.results.Result` holding the frames up to the
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


class Interrupted(KeyboardInterrupt):
    """The user stopped a run (Ctrl-C); ``partial``: the Result of the frames computed before it
    (written and marked ``status = "interrupted"`` by a run that writes files).  A KeyboardInterrupt,
    not a FlexmechError: whatever stops on Ctrl-C (a batch of runs, the CLI's exit 130) still does."""

    def __init__(self, message: str, partial=None):
        self.partial = partial
        super().__init__(message)


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
