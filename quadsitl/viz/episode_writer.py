"""The writer of an episode recording: a process of its own, so that sending to Rerun
never takes the env's time.

The env's side (:class:`~quadsitl.viz.episode_view.EpisodeView`) only buffers one row of
numbers per step. When it sends a buffer, :class:`EpisodeWriter` hands it (not a copy:
the view goes on in a buffer of its own meanwhile) to a thread that pushes it down a
pipe (the copy into the pipe releases the GIL) and then gives it back, and the
writer process (:func:`serve`) turns the rows into Rerun columns and sends them
(:class:`EpisodeSender`): the env goes on stepping meanwhile, and ``close()`` returns at
once. The recording is complete when the writer process ends: at the latest before the
program exits (Python waits for it), or when :func:`wait_for_recordings` returns.
"""

from __future__ import annotations

import atexit
import contextlib
import json
import math
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
import pyarrow as pa
import rerun as rr

from quadsitl.physics import layout as L
from quadsitl.tasks.land import PAD_RADIUS
from quadsitl.tasks.recording import (
    C_AIR,
    C_DIST,
    C_DISTANCE,
    C_EPISODE,
    C_GOAL,
    C_REWARD,
    C_SPEED,
    C_STEP,
)
from quadsitl.viz.scene import (
    EPISODE_PANELS,
    WIND_ARROW_SCALE,
    WIND_COLOR,
    blueprint,
    framing,
)
from quadsitl.viz.viewer import open_recording

STEP_TIMELINE = "step"
TERMS = ("position", "attitude", "velocity", "rates")  # the columns of engine.dist
PATH_EVERY = 10  # steps between two loggings of an episode's path
MAX_PATH = 200  # points a path is thinned to (a long episode's path stays light)

Event = tuple[int, int, str, str]  # episode, step, text, level
# To the feeder thread: kind, detail, rows or None, what to call once the rows are sent.
_Message = tuple[str, dict[str, Any], np.ndarray | None, "Callable[[], None] | None"]


class _Arrow:
    """A ready-made Arrow array, as Rerun's columns take their data."""

    def __init__(self, array: pa.Array) -> None:
        self.array = array

    def as_arrow_array(self) -> pa.Array:
        return self.array


def layout(frame: Any = None, windy: bool = False) -> Any:
    """The episode recording's blueprint (with the wind panel in wind)."""
    panels = (*EPISODE_PANELS, "wind") if windy else EPISODE_PANELS
    return blueprint(panels, state=False, frame=frame, timeline=STEP_TIMELINE)


# --- the writer process's side ---------------------------------------------------------


class EpisodeSender:
    """Sends an env's buffered rows to a Rerun recording (in the writer process)."""

    def __init__(self, name: str, save: str | None, windy: bool) -> None:
        self.rec = open_recording(
            "quadsitl_episodes", save, spawn=True, default_blueprint=layout(None, windy)
        )
        self.rec.send_recording_name(name)
        self.task = ""
        self.windy = False  # the env flies in wind: its panel and arrow are sent
        self.track: list[np.ndarray] = []  # positions of this episode already sent
        self.last_goal = np.full((1, 4), np.nan)  # episode and goal last sent

    def frame(
        self, points: list[Any], windy: bool, task: str, goal_radius: float, target: bool
    ) -> None:
        """Camera on the start, the goal and the ground under them (first reset); the
        goal's look, which every episode shares."""
        self.windy, self.task = windy, task
        self.rec.send_blueprint(layout(framing(points), windy), make_active=True)
        names = rr.SeriesLines(names=list(TERMS))
        self.rec.log("plots/reward_terms/terms", names, static=True)
        if task == "land":
            pad = rr.LineStrips3D.from_fields(colors=[[0, 170, 0]], labels=["pad"])
            self.rec.log("world/goal", pad, static=True)
            return
        self.rec.log(
            "world/goal",
            rr.Ellipsoids3D.from_fields(
                half_sizes=[[max(goal_radius, 0.05)] * 3],
                colors=[[220, 40, 40] if target else [0, 190, 0]],
                labels=["target" if target else "goal"],
                show_labels=False,  # at the centre, the label would hide the vehicle
                fill_mode="MajorWireframe",
            ),
            static=True,
        )

    def events(self, events: list[Event]) -> None:
        """Episode outcomes, in the event table."""
        if not events:
            return
        episode, step, text, level = zip(*events, strict=True)
        self.rec.send_columns(
            "events",
            indexes=[
                rr.TimeColumn(STEP_TIMELINE, sequence=step),
                rr.TimeColumn("episode", sequence=episode),
            ],
            columns=rr.TextLog.columns(text=text, level=level),
        )

    def rows(self, rows: np.ndarray) -> None:
        """A column per series of the buffered rows."""
        steps = rows[:, C_STEP].astype(np.int64)
        episodes = rows[:, C_EPISODE].astype(np.int64)

        def send(entity: str, columns: object, where: np.ndarray | slice = slice(None)):
            indexes = [
                rr.TimeColumn(STEP_TIMELINE, sequence=steps[where]),
                rr.TimeColumn("episode", sequence=episodes[where]),
            ]
            self.rec.send_columns(entity, indexes=indexes, columns=columns)  # type: ignore[arg-type]

        position = rows[:, L.POS]
        quaternion = rows[:, [L.I_QX, L.I_QY, L.I_QZ, L.I_QW]]  # Rerun's order: x, y, z, w
        send("world/vehicle", rr.Transform3D.columns(translation=position, quaternion=quaternion))
        self._goal(rows, send)
        self._path(rows)
        send("plots/altitude/altitude", rr.Scalars.columns(scalars=position[:, 2]))
        send("plots/speed/speed", rr.Scalars.columns(scalars=rows[:, C_SPEED]))
        distance = rr.Scalars.columns(scalars=rows[:, C_DISTANCE])
        send("plots/distance_to_goal/distance", distance)
        terms = rr.Scalars.columns(scalars=rows[:, C_DIST]).partition(np.full(len(rows), 4))
        send("plots/reward_terms/terms", terms)
        stepped = ~np.isnan(rows[:, C_REWARD])  # a reset has no reward
        if stepped.any():
            reward = rr.Scalars.columns(scalars=rows[stepped, C_REWARD])
            send("plots/reward/reward", reward, stepped)
        if self.windy:
            air = rows[:, C_AIR]
            send("plots/wind/speed", rr.Scalars.columns(scalars=np.linalg.norm(air, axis=1)))
            for k, name in enumerate(("east", "north", "up")):
                send(f"plots/wind/{name}", rr.Scalars.columns(scalars=air[:, k]))
            colors = np.tile(np.array(WIND_COLOR, np.uint8), (len(rows), 1))
            arrows = rr.Arrows3D.columns(
                origins=position, vectors=air * WIND_ARROW_SCALE, colors=colors
            )
            send("world/wind", arrows)

    def _goal(self, rows: np.ndarray, send) -> None:  # type: ignore[no-untyped-def]
        """The goal where it is new (each row a moving target has moved) and, as the
        path, every PATH_EVERY steps: episodes share the step timeline, so whichever
        episode's vehicle the cursor shows, its goal is drawn with it."""
        key = rows[:, [C_EPISODE, *range(C_GOAL.start, C_GOAL.stop)]]  # episode, goal
        before = np.vstack((self.last_goal, key[:-1]))  # each row's predecessor
        new = np.any(key != before, axis=1) | (rows[:, C_STEP] % PATH_EVERY == 0)
        self.last_goal = key[-1:]
        goal = rows[:, C_GOAL]
        if self.task != "land":
            send("world/goal", rr.Ellipsoids3D.columns(centers=goal[new]), new)
            return
        circle = np.linspace(0.0, 2 * math.pi, 49)
        rings = [
            np.column_stack(
                (
                    x + PAD_RADIUS * np.cos(circle),
                    y + PAD_RADIUS * np.sin(circle),
                    np.full_like(circle, 0.01),
                )
            )
            for x, y, _ in goal[new]
        ]
        send("world/goal", rr.LineStrips3D.columns(strips=rings), new)

    def _path(self, rows: np.ndarray) -> None:
        """Each episode's whole path (as far as it has been flown when its rows are
        sent), thinned to MAX_PATH points, logged every PATH_EVERY steps: whichever
        episode's vehicle the cursor shows, its path is drawn with it."""
        episodes, steps = rows[:, C_EPISODE], rows[:, C_STEP]
        starts = np.flatnonzero(np.r_[True, episodes[1:] != episodes[:-1]])
        marked = steps % PATH_EVERY == 0
        paths, copies = [], []
        for start, end in zip(starts, np.r_[starts[1:], len(rows)], strict=True):
            if start > 0 or steps[0] == 0:
                self.track = []  # an episode that starts in these rows
            self.track.append(rows[start:end, L.POS].astype(np.float32))
            path = np.concatenate(self.track)
            stride = max(1, math.ceil(len(path) / MAX_PATH))
            paths.append(np.concatenate((path[:-1:stride], path[-1:])))
            copies.append(int(marked[start:end].sum()))
        if not any(copies):
            return
        points = np.concatenate([np.tile(p, (c, 1)) for p, c in zip(paths, copies, strict=True)])
        lengths = np.repeat([len(p) for p in paths], copies)
        offsets = np.zeros(len(lengths) + 1, np.int32)
        np.cumsum(lengths, out=offsets[1:])
        strip_type = rr.components.LineStrip3DBatch._ARROW_DATATYPE  # what the viewer reads
        points_type = strip_type.value_type
        strips = pa.ListArray.from_arrays(
            offsets,
            pa.FixedSizeListArray.from_arrays(points.ravel(), type=points_type),
            type=strip_type,
        )
        column = rr.ComponentColumn(rr.LineStrips3D.descriptor_strips(), _Arrow(strips))
        self.rec.send_columns(
            "world/trajectory",
            indexes=[
                rr.TimeColumn(STEP_TIMELINE, sequence=steps[marked].astype(np.int64)),
                rr.TimeColumn("episode", sequence=episodes[marked].astype(np.int64)),
            ],
            columns=[column],
        )

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()


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
            sender.rows(np.frombuffer(data).reshape(detail["shape"]))
            sender.events([tuple(event) for event in detail["events"]])
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
