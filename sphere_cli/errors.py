"""Errors a user can cause or meet, each mapped to the exit code of the design guide (§6).

The CLI catches `SphereError` and prints its message; any other exception is a bug.
"""


class SphereError(Exception):
    """Base class: a message for the user and the process exit code."""

    exit_code = 1


class UsageError(SphereError):
    exit_code = 2


class CaseError(SphereError):
    """The case file is malformed or describes an impossible scene (EX_DATAERR)."""

    exit_code = 65


class MissingInputError(SphereError):
    """A file the case or command names does not exist or holds nothing usable (EX_NOINPUT)."""

    exit_code = 66


class NumericalError(SphereError):
    """The integration failed: NaN, blow-up, or a limit violated during the run (EX_SOFTWARE)."""

    exit_code = 70


class OutputError(SphereError):
    """Writing or reading an output file failed (EX_IOERR)."""

    exit_code = 74


class StoppedEarly(SphereError):
    """Stopped on request (signal or wall-time budget) after writing a checkpoint (EX_TEMPFAIL).
    `reason`: what asked for the stop ("SIGTERM received", the wall-time budget)."""

    exit_code = 75

    def __init__(self, message: str, reason: str | None = None):
        super().__init__(message)
        self.reason = reason


class ResumeRefused(SphereError):
    """The case no longer matches the checkpoint it would resume from (EX_CONFIG)."""

    exit_code = 78


class MissingDependency(SphereError):
    """An optional package a command needs is not installed (EX_UNAVAILABLE)."""

    exit_code = 69


class RunBusy(SphereError):
    """Another process holds the run directory's writer lock (EX_CANTCREAT)."""

    exit_code = 73
