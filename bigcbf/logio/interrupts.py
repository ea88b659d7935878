"""Ctrl-C and SIGTERM as one KeyboardInterrupt that never lands inside a log write.

An interrupted ``bigcbf run --log X.mcap`` keeps what it recorded as ``X.partial.mcap``, a complete MCAP (see
:meth:`bigcbf.logio.writer.LogWriter.finish_partial`). For that file to be valid, the interrupt must not tear the
MCAP writer's state halfway through a message (Python raises KeyboardInterrupt between any two bytecodes, and the
writer updates several structures per message). So:

- :data:`critical` is a section that log writes enter (the writer per message, the episode logger per control
  step, the partial finish itself);
- :func:`interrupts_as_keyboard_interrupt` installs handlers for SIGINT and SIGTERM that raise KeyboardInterrupt
  at once outside such a section and at its end inside one. Without it SIGTERM ends the process on the spot (no
  cleanup, the temporary file stays) and Ctrl-C may land inside a write.

Only the main thread's sections count (signal handlers run in the main thread); writes from other threads (a live
stream) are not delayed.

Compiled kernels: Python runs a signal's handler at the next bytecode of the main thread. While a numba kernel runs,
that bytecode is usually inside numba's own helpers that the compiled code calls back (``_numba_unpickle``, called
on every return that boxes an array), and an exception raised there leaves the kernel as ``SystemError: ...
returned a result with an exception set``: no KeyboardInterrupt, so no partial log, a traceback instead of
"interrupted". A signal that lands in numba's code is delivered again a few milliseconds later (never lost: once
the handlers are restored, the default one takes it).
"""
from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from typing import Iterator

#: the signals turned into KeyboardInterrupt
SIGNALS = (signal.SIGINT, signal.SIGTERM)


class _Critical:
    """``with critical: ...``: a signal handled by :func:`interrupts_as_keyboard_interrupt` inside the block
    raises KeyboardInterrupt when the outermost block ends (not when the block ends with an exception: that one
    propagates)."""

    def __init__(self):
        self.depth = 0
        self.pending: int | None = None

    def __enter__(self) -> None:
        if threading.current_thread() is threading.main_thread():
            self.depth += 1

    def __exit__(self, exc_type, *exc) -> None:
        if threading.current_thread() is not threading.main_thread():
            return
        self.depth -= 1
        if self.depth == 0 and self.pending is not None:
            signum, self.pending = self.pending, None
            # not over an exception leaving the block, nor inside the handling of an interrupt (a second Ctrl-C
            # while the partial log is being finished: that one is already ending the command)
            if exc_type is None and not isinstance(sys.exc_info()[1], KeyboardInterrupt):
                raise KeyboardInterrupt(signal.Signals(signum).name)


critical = _Critical()


#: a signal that lands in numba's code is sent again after this long (module docstring)
RETRY_S = 0.005


def _in_numba(frame) -> bool:
    """Whether ``frame`` (the one a signal interrupted) is numba's code: a helper that a compiled kernel calls back,
    where an exception turns into SystemError."""
    if frame is None:
        return False
    name = frame.f_globals.get("__name__", "")
    return name == "numba" or name.startswith("numba.")


def _handler(signum, frame) -> None:
    if critical.depth > 0:
        critical.pending = signum          # raised when the write ends
        return
    if _in_numba(frame):                   # raised a few ms later, outside the kernel
        t = threading.Timer(RETRY_S, os.kill, (os.getpid(), signum))
        t.daemon = True
        t.start()
        return
    raise KeyboardInterrupt(signal.Signals(signum).name)


@contextlib.contextmanager
def interrupts_as_keyboard_interrupt() -> Iterator[None]:
    """``with interrupts_as_keyboard_interrupt(): run ...``: SIGINT and SIGTERM raise KeyboardInterrupt (its
    message names the signal), never inside a log write; the previous handlers come back at the end. From the main
    thread only (``signal.signal``'s rule); elsewhere it changes nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.signal(s, _handler) for s in SIGNALS}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
