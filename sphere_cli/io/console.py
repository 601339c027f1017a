"""The console may go away while a run goes on.

A run's record is run.log, status.json and its output files; what it prints (the progress, its
warnings, the closing lines) is a copy. The reader of that copy can leave: a pipe whose reader
has exited (`sphere run case.toml | head`, a `tee` that died, a log collector restarted), or a
terminal closed under nohup (EIO). Python then raises BrokenPipeError or OSError at the next
print, which ended the run as an internal error at the first step that printed anything. So
`guard_console` wraps stdout and stderr: the first write to a stream that fails points the
stream's file descriptor at the null device (nothing can reach that reader again, and the
interpreter's own flush at exit then succeeds, where it would set exit code 120), and says once
in the run's log that the console is gone; the run goes on.
"""

from __future__ import annotations

import logging
import os
import sys


class GuardedStream:
    """A text stream whose writes never fail: after the first failure it writes nowhere."""

    def __init__(self, stream, name: str):
        self._stream = stream
        self._name = name
        self.gone = False

    def write(self, text: str) -> int:
        if not self.gone:
            try:
                return self._stream.write(text)
            except UnicodeEncodeError:  # a console whose encoding lacks a character: still there
                encoding = getattr(self._stream, "encoding", None) or "ascii"
                return self.write(text.encode(encoding, "replace").decode(encoding))
            except (OSError, ValueError) as exc:  # ValueError: the stream was closed
                self._lose(exc)
        return len(text)

    def writelines(self, lines) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        if not self.gone:
            try:
                self._stream.flush()
            except (OSError, ValueError) as exc:
                self._lose(exc)

    def isatty(self) -> bool:
        return not self.gone and self._stream.isatty()

    def __getattr__(self, name: str):
        return getattr(self._stream, name)

    def _lose(self, exc: Exception) -> None:
        self.gone = True
        try:
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, self._stream.fileno())  # what is still buffered goes there too
            os.close(null)
        except (OSError, ValueError):
            pass  # no descriptor of its own (a test's capture): the flag alone keeps it quiet
        reason = type(exc).__name__ if not str(exc) else f"{type(exc).__name__}: {exc}"
        logging.getLogger("sphere").warning(
            "%s is gone (%s): nothing more is printed there; run.log keeps the record", self._name, reason
        )


def guard_console() -> None:
    """Wrap sys.stdout and sys.stderr (once) so that a console that goes away never ends the
    process (module docstring)."""
    for name in ("stdout", "stderr"):
        stream = getattr(sys, name)
        if stream is not None and not isinstance(stream, GuardedStream):
            setattr(sys, name, GuardedStream(stream, name))
