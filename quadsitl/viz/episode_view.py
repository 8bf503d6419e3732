"""``render_mode="rerun"`` of the task envs (and ``quadsitl eval --rerun``): episodes in Rerun.

Logged on the ``step`` timeline (one tick per env step), in the task's world frame
(ENU, metres): the vehicle posed from the physics state (with the episode's path), what the task
flies to — the goal (a sphere of the task's goal radius), the landing pad (a disc of
its radius) or the moving target — and the reward, the goal errors the reward is made
of (position, attitude, velocity, rates), the distance to the goal, altitude and speed,
and in wind the air's velocity at the vehicle (a panel and an arrow).
Each episode's outcome (landed, crashed, timed out ...) is an event. Each episode
starts a new ``episode`` on its own timeline; the layout (blueprint) frames the task's
start and goal on the first reset.

Recording must not slow the env down (within 10 % of its steps per second), so a step
only copies one row of numbers into a buffer (:class:`EpisodeRows`); the buffer goes to
Rerun in whole columns (``send_columns``) when it is full, when an episode has waited
longer than ``FLUSH_AFTER`` wall seconds (a viewer watching a slow loop still sees it
move), and at ``close``.
"""

from __future__ import annotations

import math
import time
import warnings

import numpy as np
import pyarrow as pa
import rerun as rr

from quadsitl.physics import layout as L
from quadsitl.tasks import TaskEngine
from quadsitl.tasks import features as F
from quadsitl.tasks import recording as R
from quadsitl.tasks import spec as S
from quadsitl.tasks.land import PAD_RADIUS
from quadsitl.tasks.recording import (
    C_AIR,
    C_DIST,
    C_DISTANCE,
    C_EPISODE,
    C_GOAL,
    C_RETURN,
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
CAPACITY = 32768  # steps buffered before they are sent
FLUSH_AFTER = 0.5  # wall s: a buffer older than this is sent at the next step

CLOCK_EVERY = 16  # rows between two looks at the clock (FLUSH_AFTER)
# Rows a step's end may write before the view looks: the step's and, when the caller
# resets the env at once (a vector env, eval), the reset's.
HEADROOM = 2


class _Arrow:
    """A ready-made Arrow array, as Rerun's columns take their data."""

    def __init__(self, array: pa.Array) -> None:
        self.array = array

    def as_arrow_array(self) -> pa.Array:
        return self.array


class EpisodeView:
    """Logs env ``index`` of an engine. ``save``: an .rrd path, else a viewer is spawned."""

    def __init__(
        self, name: str, save: str | None = None, index: int = 0, windy: bool = False
    ) -> None:
        """``windy``: the env flies in wind (the layout sent at once has its panel)."""
        self.layout = lambda frame=None, windy=False: blueprint(
            (*EPISODE_PANELS, "wind") if windy else EPISODE_PANELS,
            state=False,
            frame=frame,
            timeline=STEP_TIMELINE,
        )
        self.rec = open_recording(
            "quadsitl_episodes", save, spawn=True, default_blueprint=self.layout(None, windy)
        )
        self.rec.send_recording_name(name)
        self.index = index
        self.episode = -1
        self.ended = False
        self.framed = False
        self.task = ""
        self.windy = False  # the env flies in wind: its panel and arrow are sent
        self.goal_radius = 0.05
        self.rows, self.counters = R.new_buffer(CAPACITY, index)  # the engine writes them
        self.oldest = time.monotonic()  # wall time of (about) the oldest buffered row
        self.track: list[np.ndarray] = []  # positions of this episode already sent
        self.last_goal = np.full((1, 4), np.nan)  # episode and goal last sent
        self.events: list[tuple[int, int, str, str]] = []  # episode, step, text, level

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
            engine.record(self.rows, self.counters)
        engine.record_now()
        self._rows_written(int(self.counters[R.COUNT]))

    def step(self, engine: TaskEngine) -> None:
        """After a step of ``engine`` (which wrote its row): all a step costs, unless
        the buffer is due to be sent."""
        rows = engine.recorded
        if rows < 0:
            rows = -rows
            if not self.ended:
                self._outcome(S.OUTCOME_NAMES[int(engine.outcome[self.index])])
        if rows % CLOCK_EVERY == 0 or rows >= CAPACITY - HEADROOM:
            self._rows_written(rows)

    def _rows_written(self, rows: int) -> None:
        """Send the buffer when it is (nearly) full, or its oldest row has waited long."""
        if rows >= CAPACITY - HEADROOM or (
            rows % CLOCK_EVERY == 0 and time.monotonic() - self.oldest > FLUSH_AFTER
        ):
            self.flush()

    def _frame(self, engine: TaskEngine) -> None:
        """Camera on the start, the goal and the ground under them (first reset); the
        goal's look, which every episode shares."""
        position = engine.fleet.state[self.index, L.POS]
        goal = engine.goal[self.index, F.GOAL_POS]
        points = [position, goal, [position[0], position[1], 0.0], [goal[0], goal[1], 0.0]]
        self.windy = engine.fleet.windy
        self.rec.send_blueprint(self.layout(framing(points), self.windy), make_active=True)
        self.task = engine.task.name
        names = rr.SeriesLines(names=list(TERMS))
        self.rec.log("plots/reward_terms/terms", names, static=True)
        if self.task == "land":
            pad = rr.LineStrips3D.from_fields(colors=[[0, 170, 0]], labels=["pad"])
            self.rec.log("world/goal", pad, static=True)
        else:
            target = engine.task.advance_goal is not None  # a moving target
            self.rec.log(
                "world/goal",
                rr.Ellipsoids3D.from_fields(
                    half_sizes=[[max(float(engine.task.goal_radius), 0.05)] * 3],
                    colors=[[220, 40, 40] if target else [0, 190, 0]],
                    labels=["target" if target else "goal"],
                    show_labels=False,  # at the centre, the label would hide the vehicle
                    fill_mode="MajorWireframe",
                ),
                static=True,
            )

    def _outcome(self, outcome: str) -> None:
        self.ended = True
        last = self.rows[max(int(self.counters[R.COUNT]) - 1, 0)]  # the episode's last row
        steps, episode_return = int(last[C_STEP]), float(last[C_RETURN])
        level = "INFO" if outcome in ("landed", "timed_out") else "WARN"
        text = (
            f"episode {self.episode}: {outcome.replace('_', ' ')} after {steps} steps, "
            f"return {episode_return:.1f}"
        )
        self.events.append((self.episode, steps, text, level))

    def flush(self) -> None:
        """Send the buffered rows to Rerun, a column per series."""
        rows = self.rows[: self.counters[R.COUNT]]
        self.counters[R.COUNT] = 0
        self.oldest = time.monotonic()  # (nearly) when the next row comes
        if len(rows):
            self._send(rows.copy())
        if self.events:
            episode, step, text, level = zip(*self.events, strict=True)
            self.rec.send_columns(
                "events",
                indexes=[
                    rr.TimeColumn(STEP_TIMELINE, sequence=step),
                    rr.TimeColumn("episode", sequence=episode),
                ],
                columns=rr.TextLog.columns(text=text, level=level),
            )
            self.events.clear()

    def _send(self, rows: np.ndarray) -> None:
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
        self._send_goal(rows, send)
        self._send_path(rows)
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

    def _send_goal(self, rows: np.ndarray, send) -> None:  # type: ignore[no-untyped-def]
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

    def _send_path(self, rows: np.ndarray) -> None:
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
        """Send what is buffered, flush and let go of the recording; a viewer that went
        away is not an error."""
        try:
            self.flush()
            self.rec.flush()
            self.rec.disconnect()
        except Exception as error:  # rerun raises RuntimeError from its sinks
            warnings.warn(
                f"Rerun recording could not be closed cleanly: {error}",
                RuntimeWarning,
                stacklevel=2,
            )
