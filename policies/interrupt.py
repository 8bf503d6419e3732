"""Ctrl-C during a training command, as one line and exit status 130, never a traceback.

The first Ctrl-C raises KeyboardInterrupt as usual: the command stops and says so
(``quadsitl train`` first saves its last checkpoint). A second one while it is stopping
(an env closing, torch's import unwinding) would raise another KeyboardInterrupt wherever
it lands, often in code that prints it ("Exception ignored in ...") or in the
interpreter's own shutdown (the process then dies by the signal): instead it ends the
process at once with the one line and status 130. Once a Ctrl-C came, Ctrl-C is ignored
from the end of the command on: the process is only exiting.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Iterator
from types import FrameType

INTERRUPTED = 130  # the exit status of a command stopped by Ctrl-C: 128 + SIGINT


def stop_at_once(command: str) -> None:
    """The second Ctrl-C: one line on stderr, then exit with status 130 (no clean-up is
    waited for; what was printed so far is flushed)."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os.write(2, f"{command}: interrupted again; stopped at once\n".encode())
    os._exit(INTERRUPTED)


@contextlib.contextmanager
def second_interrupt_stops(command: str) -> Iterator[None]:
    """Within: the first Ctrl-C raises KeyboardInterrupt, a second :func:`stop_at_once`.
    After it: SIGINT is ignored if one came (the process is exiting), else as before.
    Outside the main thread (where signals cannot be handled) it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGINT)
    if previous is None:  # a handler not set from Python: the default is the nearest
        previous = signal.SIG_DFL
    interrupted = False

    def second(signum: int, frame: FrameType | None) -> None:
        stop_at_once(command)

    def first(signum: int, frame: FrameType | None) -> None:
        nonlocal interrupted
        interrupted = True
        signal.signal(signal.SIGINT, second)
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, first)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN if interrupted else previous)
