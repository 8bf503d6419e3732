"""``render_mode="rerun"`` of the task envs (and ``quadsitl eval --rerun``): episodes in Rerun.

Logged on the ``step`` timeline (one tick per env step) and the ``time`` timeline
(simulated seconds since the episode's start: the plots' axis), in the task's world
frame (ENU, metres): the vehicle posed from the physics state (with the episode's
path), what the task flies to — the goal (a sphere of the task's goal radius and a
labelled pin standing on it), the landing pad (a disc of its radius) or the moving
target (with its track) — and the reward per step (but an episode's last, whose
landing bonus or crash penalty would flatten the rest: its outcome event gives it), the
goal errors the reward is made of (position m, attitude, velocity m/s, rates rad/s),
the distance to the goal, the height above it and the speed, and in wind the air's
velocity at the vehicle (a panel and an arrow). Each episode's outcome (landed,
crashed, timed out ...) is an event. Each episode starts a new ``episode`` on its own
timeline; the layout (blueprint) frames the task's start and goal on the first reset,
and is sent again at the end with its plots fitted to the data.

Recording must not slow the env down (within 10 % of its steps per second), so a step
only copies one row of numbers into a buffer; the buffer is handed to the recording's
writer process (:mod:`quadsitl.viz.episode_writer`, which sends it to Rerun in whole
columns), not copied (the engine goes on in a spare buffer, and the sent one becomes
the next spare once it is down the pipe): when it is full, when an episode has waited
longer than ``FLUSH_AFTER`` wall seconds (a viewer watching a slow loop still sees it
move), and at ``close``. ``close`` returns at once; the .rrd is complete when the writer
ends (before the program exits, or when
:func:`~quadsitl.viz.episode_writer.wait_for_recordings` returns).
"""

from __future__ import annotations

import atexit
import queue
import time
import weakref

import numpy as np

from quadsitl.physics import layout as L
from quadsitl.tasks import TaskEngine
from quadsitl.tasks import features as F
from quadsitl.tasks import recording as R
from quadsitl.tasks import spec as S
from quadsitl.tasks.recording import C_RETURN, C_REWARD, C_STEP
from quadsitl.viz.episode_writer import EpisodeWriter, Event
from quadsitl.viz.viewer import check_output_path

CAPACITY = 32768  # steps buffered before they are sent
FLUSH_AFTER = 0.5  # wall s: a buffer older than this is sent at the next step


class EpisodeView:
    """Logs env ``index`` of an engine. ``save``: an .rrd path, else a viewer is spawned."""

    def __init__(
        self, name: str, save: str | None = None, index: int = 0, windy: bool = False
    ) -> None:
        """``windy``: the env flies in wind (the layout sent at once has its panel)."""
        if save is not None:
            check_output_path(save)  # here, not in the writer: the caller is told
        self.writer = EpisodeWriter(name, save, windy)
        _OPEN.add(self)
        self.index = index
        self.episode = -1
        self.ended = False
        self.framed = False
        # The engine writes the buffer; the rows and the counters are its views.
        self.buffer, self.rows, self.counters = R.new_buffer(CAPACITY, index)
        self.spares: queue.SimpleQueue[np.ndarray] = queue.SimpleQueue()  # sent, free again
        self.engine: TaskEngine | None = None  # the engine writing the buffer
        self.last_sent: np.ndarray | None = None  # the last row of the last buffer sent
        self.oldest = time.monotonic()  # wall time of (about) the oldest buffered row
        self.events: list[Event] = []

    def reset(self, engine: TaskEngine, previous_outcome: str | None = None) -> None:
        """A new episode; ``previous_outcome``: how the one before ended, where the caller
        knows it (a vector env resets at once, so the engine no longer does)."""
        if previous_outcome is not None and not self.ended and self.episode >= 0:
            self._outcome(previous_outcome)
        self.episode += 1
        self.counters[R.EPISODE] = self.episode
        self.ended = False
        if not self.framed:
            self.framed = True
            self._frame(engine)
            engine.record(self.buffer)
            self.engine = engine
        engine.record_now()
        self._rows_written(int(self.counters[R.COUNT]))

    def step(self, engine: TaskEngine) -> None:
        """After a step of ``engine`` (which wrote its row): an episode's end, or a look
        at the buffer when one is due. The env calls this only then (``engine.recorded``
        not 0): other steps cost the view nothing."""
        rows = engine.recorded
        if rows < 0:
            rows = -rows
            if not self.ended:
                self._outcome(S.OUTCOME_NAMES[int(engine.outcome[self.index])])
        if rows:
            self._rows_written(rows)

    def _rows_written(self, rows: int) -> None:
        """Send the buffer when it is (nearly) full, or its oldest row has waited long."""
        if rows >= CAPACITY - R.HEADROOM or (
            rows % R.CHECK_EVERY == 0 and time.monotonic() - self.oldest > FLUSH_AFTER
        ):
            self.flush()

    def _frame(self, engine: TaskEngine) -> None:
        """Camera on the start, the goal and the ground under them (first reset); the
        goal's look, which every episode shares."""
        position = engine.fleet.state[self.index, L.POS].tolist()
        goal = engine.goal[self.index, F.GOAL_POS].tolist()
        points = [position, goal, [position[0], position[1], 0.0], [goal[0], goal[1], 0.0]]
        self.writer.frame(
            points=points,
            windy=bool(engine.fleet.windy),
            task=engine.task.name,
            goal_radius=float(engine.task.goal_radius),
            target=engine.task.advance_goal is not None,  # a moving target
            period=float(engine.control_period),
        )

    def _outcome(self, outcome: str) -> None:
        self.ended = True
        count = int(self.counters[R.COUNT])
        last = self.rows[count - 1] if count or self.last_sent is None else self.last_sent
        steps, episode_return = int(last[C_STEP]), float(last[C_RETURN])
        level = "INFO" if outcome in ("landed", "timed_out") else "WARN"
        text = (
            f"episode {self.episode}: {outcome.replace('_', ' ')} after {steps} steps, "
            f"return {episode_return:.1f} (last step {float(last[C_REWARD]):.1f})"
        )
        self.events.append((self.episode, steps, text, level))

    def flush(self) -> None:
        """Hand the buffered rows and events to the writer: the rows in their buffer,
        while the engine goes on in a spare one."""
        count = int(self.counters[R.COUNT])
        self.oldest = time.monotonic()  # (nearly) when the next row comes
        if not count:
            if self.events:
                self.writer.rows(self.rows[:0], self.events)
                self.events.clear()
            return
        sent, rows = self.buffer, self.rows[:count]
        self.last_sent = rows[-1].copy()
        self._next_buffer()
        self.writer.rows(rows, self.events, sent=lambda: self.spares.put(sent))
        self.events.clear()

    def _next_buffer(self) -> None:
        """Go on in a spare buffer (a new one while every buffer is still being sent)."""
        try:
            self.buffer = self.spares.get_nowait()
            self.rows, self.counters = self.buffer[:CAPACITY], self.buffer[CAPACITY]
            self.counters[R.COUNT] = 0
        except queue.Empty:
            self.buffer, self.rows, self.counters = R.new_buffer(CAPACITY, self.index)
        self.counters[R.EPISODE] = self.episode
        if self.engine is not None:
            self.engine.record(self.buffer)

    def close(self, wait: bool = False) -> None:
        """Hand over what is buffered and let the writer finish the recording; ``wait``:
        until it has (else it finishes on its own, before the program exits)."""
        _OPEN.discard(self)
        self.flush()
        self.writer.close(wait)


_OPEN: weakref.WeakSet[EpisodeView] = weakref.WeakSet()  # views not closed yet


@atexit.register  # before the writers' own (registered earlier, run later): they wait
def _close_open_views() -> None:
    """At exit: what the views of envs never closed buffered goes to their writers."""
    for view in list(_OPEN):
        view.close()
