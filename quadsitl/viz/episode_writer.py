"""The writer of an episode recording: a process of its own, so that sending to Rerun
never takes the env's time.

The env's side (:class:`~quadsitl.viz.episode_view.EpisodeView`) only buffers one row of
numbers per step. When it sends a buffer, :class:`EpisodeWriter` hands it (not a copy:
the view goes on in a buffer of its own meanwhile) to a thread that pushes it down a
pipe (the copy into the pipe releases the GIL) and then gives it back, and the
writer process (:func:`serve`) turns the rows into Rerun columns and sends them
(:class:`~quadsitl.viz.episode_sender.EpisodeSender`): the env goes on stepping
meanwhile, and ``close()`` returns at once. The recording is complete when the writer
process ends: at the latest before the program exits (Python waits for it), or when
:func:`wait_for_recordings` returns.
"""

from __future__ import annotations

import atexit
import contextlib
import json
import os
import queue
import signal
import struct
import subprocess
import sys
import threading
import warnings
from collections.abc import Callable
from typing import Any, BinaryIO

import numpy as np

from quadsitl.viz.episode_sender import EpisodeSender, Event

# To the feeder thread: kind, detail, rows or None, what to call once the rows are sent.
_Message = tuple[str, dict[str, Any], np.ndarray | None, "Callable[[], None] | None"]


# --- the writer process's side ---------------------------------------------------------


def _away_from_the_env(pid: int = 0) -> None:
    """Run process ``pid`` (0: the calling thread) on the cores the calling thread (the
    env's, or one it started) is not pinned to, if there are any (a benchmark or a
    trainer's worker pins the env to one: the writer must not take its time), else on
    any core."""
    if not hasattr(os, "sched_setaffinity"):
        return
    every = set(range(os.cpu_count() or 1))
    others = every - os.sched_getaffinity(0)  # the caller's: the env's, or inherited from it
    with contextlib.suppress(OSError):
        os.sched_setaffinity(pid, others or every)


# The pipe from the env to its writer carries messages: a 4-byte length and a JSON
# header ``[kind, detail]``; a "rows" message then 8 bytes of length and the rows' raw
# float64 bytes. Data, never code: nothing is unpickled.
_HEADER, _PAYLOAD = struct.Struct("<I"), struct.Struct("<Q")


def _read_exactly(stream: BinaryIO, size: int) -> bytes:
    data = stream.read(size)
    if len(data) != size:
        raise EOFError("the env's end of the pipe closed")
    return data


def serve(stream: BinaryIO, name: str, save: str | None, windy: bool) -> None:
    """The writer process: what the env hands over, in order, until ``close`` (or until
    the env's process is gone: then what came is kept)."""
    sender = EpisodeSender(name, save, windy)
    while True:
        try:
            (size,) = _HEADER.unpack(_read_exactly(stream, _HEADER.size))
            kind, detail = json.loads(_read_exactly(stream, size))
            if kind == "rows":
                (size,) = _PAYLOAD.unpack(_read_exactly(stream, _PAYLOAD.size))
                data = _read_exactly(stream, size)
        except EOFError:
            sender.close()
            return
        if kind == "frame":
            sender.frame(**detail)
        elif kind == "rows":
            events = [tuple(event) for event in detail["events"]]
            sender.rows(np.frombuffer(data).reshape(detail["shape"]), events)  # type: ignore[arg-type]
            sender.events(events)  # type: ignore[arg-type]
        elif kind == "close":
            sender.close()
            return
        else:
            raise ValueError(f"the episode writer got an unknown message {kind!r}")


# --- the env's side ------------------------------------------------------------------

_WRITERS: list[EpisodeWriter] = []


class EpisodeWriter:
    """The env's handle on its writer process (``python -m quadsitl.viz.episode_writer``,
    a program of its own: nothing of the caller's script is run again in it). Nothing
    here waits for the writer: the rows go to a queue, a thread of this process feeds
    them to the pipe."""

    def __init__(self, name: str, save: str | None, windy: bool) -> None:
        self.process = subprocess.Popen(
            [sys.executable, "-m", "quadsitl.viz.episode_writer", json.dumps([name, save, windy])],
            stdin=subprocess.PIPE,
            # Its own process group: a terminal's Ctrl-C is for the env's program, which
            # decides what it means; its end closes the pipe, and the writer finishes.
            start_new_session=True,
        )
        # At once: its start-up (imports) is its busiest time.
        _away_from_the_env(self.process.pid)
        # (kind, detail, rows or None, what to call once the rows are sent or None)
        self.outbox: queue.SimpleQueue[_Message] = queue.SimpleQueue()
        self.error: BaseException | None = None
        self.closed = False
        # A daemon: an env never closed must not keep the program from exiting; what it
        # buffered is sent by the views' and the writers' handlers at exit.
        self.feeder = threading.Thread(target=self._feed, name="quadsitl-rerun-feeder", daemon=True)
        self.feeder.start()
        _WRITERS.append(self)

    def frame(self, **detail: Any) -> None:
        self.outbox.put(("frame", detail, None, None))

    def rows(
        self, rows: np.ndarray, events: list[Event], sent: Callable[[], None] | None = None
    ) -> None:
        """Hand over ``rows`` and ``events``. With ``sent``, the rows themselves: the
        caller leaves them alone until ``sent()`` is called (from the feeder thread,
        once they are down the pipe, or the writer is gone); without it, a copy."""
        if self.error is not None:  # the writer died (warned): nothing to send to
            if sent is not None:
                sent()
            return
        detail = {"shape": list(rows.shape), "events": [list(event) for event in events]}
        data = np.ascontiguousarray(rows, np.float64)
        self.outbox.put(("rows", detail, data if sent else data.copy(), sent))

    def close(self, wait: bool = False) -> None:
        """The last message; ``wait``: until the recording is complete."""
        if not self.closed:
            self.closed = True
            self.outbox.put(("close", {}, None, None))
        if wait:
            self.join()

    def join(self, timeout: float | None = None) -> None:
        self.feeder.join(timeout)
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.process.wait(timeout)

    def _feed(self) -> None:
        """In the feeder thread: each message down the pipe (its writes release the GIL)."""
        _away_from_the_env()  # this thread only (its writes are short)
        pipe = self.process.stdin
        assert pipe is not None
        while True:
            kind, detail, rows, sent = self.outbox.get()
            header = json.dumps([kind, detail]).encode()
            try:
                pipe.write(_HEADER.pack(len(header)) + header)
                if rows is not None:
                    pipe.write(_PAYLOAD.pack(rows.nbytes))
                    pipe.write(rows.data.cast("B"))
                pipe.flush()
                if sent is not None:
                    sent()
                if kind == "close":
                    pipe.close()
                    return
            except (OSError, ValueError) as error:  # the writer died: nothing to send to
                self.error = error
                warnings.warn(
                    f"Rerun recording lost: its writer process ended ({error})",
                    RuntimeWarning,
                    stacklevel=1,
                )
                self._drop_unsent(sent)
                return

    def _drop_unsent(self, sent: Callable[[], None] | None) -> None:
        """After the writer died: give back the rows of the message that failed and of
        those queued behind it (later ones are not queued: ``rows`` sees the error)."""
        while True:
            if sent is not None:
                sent()
            try:
                sent = self.outbox.get_nowait()[3]
            except queue.Empty:
                return


def wait_for_recordings(timeout: float | None = None) -> None:
    """Until every episode recording closed so far is complete (its writer ended)."""
    for writer in list(_WRITERS):
        if writer.closed:
            writer.join(timeout)
            if writer.process.poll() is not None:
                _WRITERS.remove(writer)


@atexit.register
def _close_all() -> None:
    """At exit: close the recordings of envs never closed, and wait for every writer."""
    for writer in _WRITERS:
        writer.close()
    wait_for_recordings()


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # (a session of its own: see EpisodeWriter)
    _name, _save, _windy = json.loads(sys.argv[1])
    serve(sys.stdin.buffer, _name, _save, _windy)
