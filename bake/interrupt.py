"""Ctrl-C while worker threads run native code.

Some library calls split their work over Python threads that run compiled code without the
GIL (scipy's ``cKDTree.query(..., workers=-1)`` starts ``threading.Thread`` workers and joins
them). Ctrl-C raises KeyboardInterrupt in the main thread *inside that join*: the main thread
unwinds and frees the arrays the workers are still writing into, and the process may crash
(SIGSEGV) after printing "interrupted". :func:`deferred_interrupt` holds SIGINT back for the
length of such a call: the call finishes (its threads joined), then KeyboardInterrupt is raised
as usual, so the CLI exits 130 with nothing half-done in memory.
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Iterator

__all__ = ["deferred_interrupt"]


@contextmanager
def deferred_interrupt() -> Iterator[None]:
    """Within the block, SIGINT is recorded, not raised; on leaving it, a recorded SIGINT goes
    to the handler that was there before (KeyboardInterrupt by default). Outside the main
    thread (where Python delivers no signals) it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got: list[int] = []

    def hold(signum, frame) -> None:  # noqa: ARG001 (signal handler signature)
        got.append(signum)

    try:
        previous = signal.signal(signal.SIGINT, hold)
    except (ValueError, OSError):  # signals unavailable here
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if got:
            if callable(previous):
                previous(signal.SIGINT, None)
            elif previous == signal.SIG_DFL:
                raise KeyboardInterrupt
