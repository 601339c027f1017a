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

A console can also be there but slow: a descriptor the parent left non-blocking (O_NONBLOCK, as
some launchers and tools do) whose pipe is full refuses a write instead of waiting (Python raises
BlockingIOError, or, unbuffered under PYTHONUNBUFFERED / -u, drops the text without a word). Its
reader is alive, so nothing is dropped at once: the write waits for the pipe to drain, up to
STALL_WAIT seconds; a reader that does not read for that long is said once in the log to be
stalled, and what does not fit is then dropped without waiting until it reads again (a blocking
pipe would hold the run for as long instead).
"""

from __future__ import annotations

import io
import logging
import os
import select
import sys
import time

STALL_WAIT = 10.0  # [s] the longest a run waits for a non-blocking console's reader to drain


class GuardedStream:
    """A text stream whose writes never fail: after the first failure it writes nowhere."""

    def __init__(self, stream, name: str):
        self._stream = stream
        self._name = name
        self.gone = False
        self.stalled = False  # a non-blocking console's reader has not read for STALL_WAIT s
        # unbuffered (PYTHONUNBUFFERED, -u): the text layer writes straight to the descriptor and
        # ignores a write it refused, so the bytes are written here
        raw = getattr(stream, "buffer", None)
        self._raw = raw if isinstance(raw, io.RawIOBase) and getattr(stream, "write_through", False) else None

    def write(self, text: str) -> int:
        if not self.gone:
            try:
                if self._raw is not None:
                    self._write_raw(text)
                    return len(text)
                return self._stream.write(text)
            except UnicodeEncodeError:  # a console whose encoding lacks a character: still there
                encoding = getattr(self._stream, "encoding", None) or "ascii"
                return self.write(text.encode(encoding, "replace").decode(encoding))
            except BlockingIOError:  # the buffer kept what it could: written once the pipe drains
                self._drain()
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
                self.stalled = self.stalled and self._raw is not None  # written if buffered
            except BlockingIOError:
                self._drain()
            except (OSError, ValueError) as exc:
                self._lose(exc)

    def isatty(self) -> bool:
        return not self.gone and self._stream.isatty()

    def __getattr__(self, name: str):
        return getattr(self._stream, name)

    def _write_raw(self, text: str) -> None:
        """Write to the descriptor of an unbuffered stream, waiting while its pipe is full (a
        character its encoding lacks raises UnicodeEncodeError, which `write` replaces)."""
        data = memoryview(text.encode(self._stream.encoding or "ascii", self._stream.errors or "strict"))
        deadline = self._deadline()
        while data:
            written = self._raw.write(data)
            if written is None:  # a non-blocking descriptor whose pipe is full
                if not self._wait(deadline):
                    return
            else:
                data = data[written:]
                self.stalled = False

    def _drain(self) -> None:
        """Flush a buffered stream whose pipe is full as its reader empties it."""
        deadline = self._deadline()
        while True:
            try:
                self._stream.flush()
                self.stalled = False
                return
            except BlockingIOError:
                if not self._wait(deadline):
                    return

    def _deadline(self) -> float:
        """When to stop waiting for a full pipe: STALL_WAIT from now, or now if its reader is
        known to be stalled."""
        return time.monotonic() + (0.0 if self.stalled else STALL_WAIT)

    def _wait(self, deadline: float) -> bool:
        """Wait until the descriptor takes more or the deadline passes (then False, the reader
        said once to be stalled)."""
        left = deadline - time.monotonic()
        if left > 0.0:
            try:
                select.select([], [self._stream.fileno()], [], left)
            except (OSError, ValueError):
                time.sleep(min(left, 0.01))  # no descriptor to wait on
            return True
        if not self.stalled:
            self.stalled = True
            logging.getLogger("sphere").warning(
                "%s is not being read (its pipe has been full for %g s): what does not fit there is "
                "dropped until it is read again; run.log keeps the record",
                self._name,
                STALL_WAIT,
            )
        return False

    def _lose(self, exc: Exception) -> None:
        self.gone = True
        try:
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, self._stream.fileno())  # what is still buffered goes there too
            os.close(null)
        except (OSError, ValueError):
            pass  # no descriptor of its own (a test's capture): the flag alone keeps it quiet
        reason = type(exc).__name__ if not str(exc) else f"{type(exc).__name__}: {exc}"
        log = logging.getLogger("sphere")
        # said where a log keeps it (a run's run.log); a command without one (`sphere validate |
        # head`, `sphere schema | less` quit early) ends as other tools do, without a word
        if log.hasHandlers():
            log.warning(
                "%s is gone (%s): nothing more is printed there; run.log keeps the record", self._name, reason
            )


def guard_console() -> None:
    """Wrap sys.stdout and sys.stderr (once) so that a console that goes away never ends the
    process (module docstring)."""
    for name in ("stdout", "stderr"):
        stream = getattr(sys, name)
        if stream is not None and not isinstance(stream, GuardedStream):
            setattr(sys, name, GuardedStream(stream, name))
