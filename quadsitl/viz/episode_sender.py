"""The Rerun side of an episode recording, in the writer process
(:mod:`quadsitl.viz.episode_writer`): the rows an env buffered, turned into Rerun
columns, and the layout (its plots fitted to the data at the end). What is logged:
:mod:`quadsitl.viz.episode_view`.
"""

from __future__ import annotations

import math
from typing import Any

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
from quadsitl.viz import palette
from quadsitl.viz.plot_fit import PanelFit, fit
from quadsitl.viz.plot_layout import plot_sizes
from quadsitl.viz.scene import (
    EPISODE_PANELS,
    WIND_ARROW_SCALE,
    WIND_COLOR,
    blueprint,
    framing,
    series_style,
)
from quadsitl.viz.series_colors import REWARD_TERMS
from quadsitl.viz.viewer import open_recording

STEP_TIMELINE = "step"
TIME_TIMELINE = "time"  # simulated seconds since the episode's start: the plots' axis
PATH_EVERY = 10  # steps between two loggings of an episode's path
MAX_PATH = 200  # points a path is thinned to (a long episode's path stays light)
LEAST_EXTENT = 1.0  # m: the 3-D view frames at least this (a hover's 0.3 m is seen)
CAMERA_DISTANCE = 1.5  # extents from the framed centre: see layout()
PIN = 0.5  # m: the height of the pin that marks the goal (its label half way up)
FIT_ROWS = 200_000  # rows kept to fit the plots to at the end (a longer run: its start)
PLOTTED = (  # the series plotted, but the goal errors (one entity, four instances)
    "plots/reward/reward",
    "plots/distance_to_goal/distance",
    "plots/height_above_goal/height",
    "plots/speed/speed",
)
WIND_PLOTTED = tuple(f"plots/wind/{name}" for name in ("east", "north", "up", "speed"))
TARGET_COLOR = palette.RED  # the moving target and its track
GOAL_COLOR = palette.GREEN  # a fixed goal, the landing pad

Event = tuple[int, int, str, str]  # episode, step, text, level


class _Arrow:
    """A ready-made Arrow array, as Rerun's columns take their data."""

    def __init__(self, array: pa.Array) -> None:
        self.array = array

    def as_arrow_array(self) -> pa.Array:
        return self.array


def panels(windy: bool) -> tuple[str, ...]:
    """The episode recording's panels (with the wind panel in wind)."""
    return (*EPISODE_PANELS, "wind") if windy else EPISODE_PANELS


def layout(frame: Any = None, windy: bool = False, fits: Any = None) -> Any:
    """The episode recording's blueprint; ``fits``: each panel's y range and legend
    corner, once the data is known. The camera CAMERA_DISTANCE extents (the framed
    points' diagonal) from their centre: a task's few metres fill the view, where the
    usual framing is for a flight's tens."""
    extent = frame[1] if frame is not None else LEAST_EXTENT
    zoom = max(1.0, (1.3 * extent + 3.0) / (CAMERA_DISTANCE * extent))
    return blueprint(
        panels(windy), state=False, frame=frame, timeline=TIME_TIMELINE, fits=fits, zoom=zoom
    )


class EpisodeSender:
    """Sends an env's buffered rows to a Rerun recording (in the writer process)."""

    def __init__(self, name: str, save: str | None, windy: bool) -> None:
        self.rec = open_recording(
            "quadsitl_episodes", save, spawn=True, default_blueprint=layout(None, windy), home=False
        )
        self.rec.send_recording_name(name)
        self.task = ""
        self.windy = False  # the env flies in wind: its panel and arrow are sent
        self.target = False  # the goal moves: its track is drawn
        self.period = 1.0  # s of simulated time per step
        self.framed: Any = None  # the 3-D view's (centre, extent)
        self.track: list[np.ndarray] = []  # positions of this episode already sent
        self.target_track: list[np.ndarray] = []  # the target's, where it moves
        self.last_goal = np.full((1, 4), np.nan)  # episode and goal last sent
        self.plotted: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}  # to fit
        self.kept = 0  # rows of self.plotted
        # Episode -> (its last step, the least and most of its points, m): the view
        # frames the one drawn at the end of the time line.
        self.reach: dict[int, tuple[int, np.ndarray]] = {}

    def frame(
        self,
        points: list[Any],
        windy: bool,
        task: str,
        goal_radius: float,
        target: bool,
        period: float = 1.0,
    ) -> None:
        """Camera on the start, the goal and the ground under them (first reset); the
        series' and the goal's looks, which every episode shares; ``period``: s per step."""
        self.windy, self.task, self.target, self.period = windy, task, target, period
        self.framed = framing(points, least=LEAST_EXTENT)
        self.rec.send_blueprint(layout(self.framed, windy), make_active=True)
        colors = [palette.series(k) for k in range(len(REWARD_TERMS))]
        terms = rr.SeriesLines(names=list(REWARD_TERMS), colors=colors)
        self.rec.log("plots/reward_terms/terms", terms, static=True)
        for entity in PLOTTED + (WIND_PLOTTED if windy else ()):
            style = series_style(entity)
            if style is not None:
                self.rec.log(entity, style, static=True)
        self.rec.log(
            "world/trajectory",
            rr.LineStrips3D.from_fields(colors=[palette.BLUE], radii=rr.Radius.ui_points(2.0)),
            static=True,
        )
        if task == "land":
            pad = rr.LineStrips3D.from_fields(colors=[GOAL_COLOR], labels=["pad"])
            self.rec.log("world/goal", pad, static=True)
            return
        color = TARGET_COLOR if target else GOAL_COLOR
        self.rec.log(
            "world/goal",
            rr.Ellipsoids3D.from_fields(
                half_sizes=[[max(goal_radius, 0.05)] * 3],
                colors=[color],
                labels=[self._goal_name()],
                show_labels=False,  # at the centre, the label would hide the vehicle: the pin's
                fill_mode="MajorWireframe",
            ),
            static=True,
        )
        # A pin standing on it, labelled: seen above the vehicle that hides the goal
        # once it is there (the vehicle's model is wider than a hover's goal).
        pin = rr.LineStrips3D.from_fields(
            colors=[color], radii=rr.Radius.ui_points(2.0), labels=[self._goal_name()]
        )
        self.rec.log("world/goal_pin", pin, static=True)
        if target:
            track = rr.LineStrips3D.from_fields(
                colors=[palette.lighter(TARGET_COLOR, 0.3)], radii=rr.Radius.ui_points(1.5)
            )
            self.rec.log("world/target_track", track, static=True)

    def _goal_name(self) -> str:
        return "target" if self.target else "goal"

    def events(self, events: list[Event]) -> None:
        """Episode outcomes, in the event table."""
        if not events:
            return
        episode, step, text, level = zip(*events, strict=True)
        self.rec.send_columns(
            "events",
            indexes=[
                rr.TimeColumn(STEP_TIMELINE, sequence=step),
                rr.TimeColumn(TIME_TIMELINE, duration=np.asarray(step) * self.period),
                rr.TimeColumn("episode", sequence=episode),
            ],
            columns=rr.TextLog.columns(text=text, level=level),
        )

    def rows(self, rows: np.ndarray, events: list[Event] | tuple = ()) -> None:
        """A column per series of the buffered rows; ``events``: the outcomes among
        them, whose steps (an episode's last) keep their reward out of the reward plot."""
        steps = rows[:, C_STEP].astype(np.int64)
        episodes = rows[:, C_EPISODE].astype(np.int64)
        seconds = steps * self.period

        def send(entity: str, columns: object, where: np.ndarray | slice = slice(None)):
            indexes = [
                rr.TimeColumn(STEP_TIMELINE, sequence=steps[where]),
                rr.TimeColumn(TIME_TIMELINE, duration=seconds[where]),
                rr.TimeColumn("episode", sequence=episodes[where]),
            ]
            self.rec.send_columns(entity, indexes=indexes, columns=columns)  # type: ignore[arg-type]

        position = rows[:, L.POS]
        self._reach(rows)
        quaternion = rows[:, [L.I_QX, L.I_QY, L.I_QZ, L.I_QW]]  # Rerun's order: x, y, z, w
        send("world/vehicle", rr.Transform3D.columns(translation=position, quaternion=quaternion))
        self._goal(rows, send)
        self._path(rows, position, self.track, "world/trajectory", send)
        if self.target:
            self._path(rows, rows[:, C_GOAL], self.target_track, "world/target_track", send)
        terms = rr.Scalars.columns(scalars=rows[:, C_DIST]).partition(np.full(len(rows), 4))
        send("plots/reward_terms/terms", terms)
        self._keep("reward_terms", [(seconds, rows[:, C_DIST.start + k]) for k in range(4)])
        for entity, (where, values) in self._series(rows, events).items():
            send(entity, rr.Scalars.columns(scalars=values), where)
            self._keep(entity.split("/")[1], [(seconds[where], values)])
        self.kept += len(rows)
        if self.windy:
            air = rows[:, C_AIR]
            colors = np.tile(np.array(WIND_COLOR, np.uint8), (len(rows), 1))
            arrows = rr.Arrows3D.columns(
                origins=position, vectors=air * WIND_ARROW_SCALE, colors=colors
            )
            send("world/wind", arrows)

    def _reach(self, rows: np.ndarray) -> None:
        """Each episode's last step and the bounds of its vehicle's and goal's points."""
        for episode in np.unique(rows[:, C_EPISODE]).astype(int):
            mine = rows[rows[:, C_EPISODE] == episode]
            step, bounds = self.reach.get(episode, (0, np.full((2, 3), np.nan)))
            flown = np.vstack((mine[:, L.POS], mine[:, C_GOAL], bounds))
            bounds = np.vstack((np.nanmin(flown, axis=0), np.nanmax(flown, axis=0)))
            self.reach[episode] = (max(step, int(mine[:, C_STEP].max())), bounds)

    def _last_drawn(self) -> np.ndarray:
        """The bounds of the episode drawn at the end of the time line (episodes share
        it: the longest, the latest of those)."""
        return max(self.reach.items(), key=lambda item: (item[1][0], item[0]))[1][1]

    def _series(
        self, rows: np.ndarray, events: list[Event] | tuple
    ) -> dict[str, tuple[np.ndarray | slice, np.ndarray]]:
        """Entity -> (the rows it has a value at, its values) of each plotted series
        but the goal errors: the height is above the goal (the task's frame may put
        the goal anywhere), the reward is at the steps (a reset has none) but an
        episode's last (its landing bonus or crash penalty would flatten the rest: its
        outcome event says it)."""
        last = {(episode, step) for episode, step, _, _ in events}
        ends = np.array([(e, s) in last for e, s in rows[:, [C_EPISODE, C_STEP]]], bool)
        stepped = ~np.isnan(rows[:, C_REWARD]) & ~ends
        everywhere = slice(None)
        series = {
            "plots/reward/reward": (stepped, rows[stepped, C_REWARD]),
            "plots/distance_to_goal/distance": (everywhere, rows[:, C_DISTANCE]),
            "plots/height_above_goal/height": (
                everywhere,
                rows[:, L.I_PZ] - rows[:, C_GOAL.stop - 1],
            ),
            "plots/speed/speed": (everywhere, rows[:, C_SPEED]),
        }
        if self.windy:
            air = rows[:, C_AIR]
            for k, name in enumerate(("east", "north", "up")):
                series[f"plots/wind/{name}"] = (everywhere, air[:, k])
            series["plots/wind/speed"] = (everywhere, np.linalg.norm(air, axis=1))
        return series

    def _keep(self, panel: str, series: list[tuple[np.ndarray, np.ndarray]]) -> None:
        """A panel's samples, for the plots' fit at the end (the first FIT_ROWS rows)."""
        if self.kept < FIT_ROWS:
            kept = self.plotted.setdefault(panel, [(np.zeros(0), np.zeros(0))] * len(series))
            self.plotted[panel] = [
                (np.concatenate((t0, t)), np.concatenate((v0, v)))
                for (t0, v0), (t, v) in zip(kept, series, strict=True)
            ]

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
            pins = np.stack((goal[new], goal[new] + [0.0, 0.0, PIN]), axis=1)
            send("world/goal_pin", rr.LineStrips3D.columns(strips=pins), new)
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

    def _path(
        self, rows: np.ndarray, points_of: np.ndarray, track: list, entity: str, send
    ) -> None:  # type: ignore[no-untyped-def,type-arg]
        """Each episode's whole path of ``points_of`` ((rows, 3) m: the vehicle's, a
        moving target's) as far as the rows go (``track``: its points already sent),
        thinned to MAX_PATH points, logged at ``entity`` every PATH_EVERY steps:
        whichever episode's vehicle the cursor shows, its path is drawn with it."""
        episodes, steps = rows[:, C_EPISODE], rows[:, C_STEP]
        starts = np.flatnonzero(np.r_[True, episodes[1:] != episodes[:-1]])
        marked = steps % PATH_EVERY == 0
        paths, copies = [], []
        for start, end in zip(starts, np.r_[starts[1:], len(rows)], strict=True):
            if start > 0 or steps[0] == 0:
                track.clear()  # an episode that starts in these rows
            track.append(points_of[start:end].astype(np.float32))
            path = np.concatenate(track)
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
        send(entity, [column], marked)

    def fits(self) -> dict[str, PanelFit]:
        """Each panel's y range and legend corner, fitted to the data sent."""
        shown = panels(self.windy)
        names = {"reward_terms": list(REWARD_TERMS), "wind": ["east", "north", "up", "speed"]}
        fits = {}
        for panel, size in zip(shown, plot_sizes(len(shown), None), strict=True):
            fitted = fit(self.plotted.get(panel, []), names.get(panel, [panel]), size)
            if fitted is not None:
                fits[panel] = fitted
        return fits

    def close(self) -> None:
        """The layout again, the 3-D view framing the episode drawn at the end and its plots
        fitted to the data (a y range with labelled ends, each legend where it hides
        the least), then the recording's end."""
        if self.framed is not None and self.plotted:
            framed = framing(np.vstack((self._last_drawn(), self.framed[0])), least=self.framed[1])
            self.rec.send_blueprint(layout(framed, self.windy, self.fits()), make_active=True)
        self.rec.flush()
        self.rec.disconnect()
