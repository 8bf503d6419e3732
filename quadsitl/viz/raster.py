"""One vehicle drawn with numpy alone: the frames of the envs' ``render_mode="rgb_array"``
(what Stable-Baselines3's ``VecVideoRecorder`` and the RL Zoo's ``--record`` save).

A frame is two square panels side by side, SPAN metres across and centred on the goal:
the top view (east right, north up) and the side view from the south (east right, up
up), then a bar along the bottom that fills as the episode's time runs out. Drawn to
scale: a grid line every metre, the goal a green ring of the task's goal radius, the
vehicle its arms (grey) from the centre to each rotor hub, its rotor discs (blue) and
its nose (red, the body x axis), the ground (tasks with one) brown in the side view; a
vehicle farther than SPAN/2 from the goal is off the picture. No plotting library and no
window: a few array writes.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from quadsitl import frames
from quadsitl.physics import layout as L

PANEL = 400  # px, each view's width and height
SPAN = 8.0  # m across a view: hover's ±3 m box, landing's start up to 3.5 m above its pad
PX_PER_M = PANEL / SPAN
BAR = 8  # px, the episode-time bar's height
MIN_DISC = 3.0  # px: a rotor disc smaller than this is drawn this big

BACKGROUND = (246, 246, 246)
GRID = (214, 214, 214)
GROUND = (150, 110, 70)
GOAL = (30, 150, 60)
ARM = (70, 70, 70)
ROTOR = (50, 100, 210)
NOSE = (210, 40, 40)
TIME = (120, 120, 120)
SEPARATOR = (150, 150, 150)

VIEWS = ((0, 1), (0, 2))  # world axes (horizontal, vertical) of the top and side views

Pixel = tuple[float, float]  # (column, row), fractional


def draw(
    state: NDArray[np.float64],
    params: NDArray[np.float64],
    goal: NDArray[np.float64],
    goal_radius: float,
    elapsed: float,
) -> NDArray[np.uint8]:
    """The frame, (PANEL + BAR, 2·PANEL, 3) uint8, of one vehicle.

    Args:
        state: its state row (``layout``: position m ENU, attitude quaternion w, x, y, z).
        params: its parameter row (rotor hubs, rotor radius, ground height).
        goal: the goal position, m ENU (the views' centre).
        goal_radius: m, the goal ring's radius.
        elapsed: the fraction of the episode flown, 0..1.
    """
    frame = np.empty((PANEL + BAR, 2 * PANEL, 3), np.uint8)
    frame[:] = BACKGROUND
    position = state[L.POS]
    rotation = frames.quat_to_matrix(state[L.QUAT])  # body FLU -> world ENU
    hubs_body = np.stack(
        [params[L.P_ROTOR_X], params[L.P_ROTOR_Y], np.zeros(L.N_ROTORS)], axis=1
    )  # (4, 3) m
    hubs = position + hubs_body @ rotation.T
    arm = float(np.max(np.hypot(hubs_body[:, 0], hubs_body[:, 1])))
    nose = position + rotation[:, 0] * arm
    rotor_px = max(params[L.P_ROTOR_RADIUS] * PX_PER_M, MIN_DISC)
    points = np.vstack([position, nose, goal, hubs])  # (7, 3) m: what is drawn
    ground_z = params[L.P_GROUND_Z]
    for index, axes in enumerate(VIEWS):
        view = frame[:PANEL, index * PANEL : (index + 1) * PANEL]
        centre = goal[list(axes)]
        centre_px, nose_px, goal_px, *hubs_px = _pixels(points[:, list(axes)], centre)
        _grid(view, centre)
        if axes[1] == 2 and math.isfinite(ground_z):
            row = PANEL / 2 - (ground_z - centre[1]) * PX_PER_M
            view[max(0, math.ceil(row)) :] = GROUND
        _ring(view, goal_px, max(goal_radius * PX_PER_M, MIN_DISC), GOAL)
        for hub_px in hubs_px:
            _line(view, centre_px, hub_px, ARM)
        for hub_px in hubs_px:
            _disc(view, hub_px, rotor_px, ROTOR)
        _line(view, centre_px, nose_px, NOSE)
    frame[:PANEL, PANEL - 1 : PANEL + 1] = SEPARATOR
    frame[PANEL:, : round(min(max(elapsed, 0.0), 1.0) * 2 * PANEL)] = TIME
    return frame


def _pixels(points: NDArray[np.float64], centre: NDArray[np.float64]) -> list[Pixel]:
    """A view's (horizontal, vertical) metres, (K, 2), -> (column, row) each; up is up."""
    columns = PANEL / 2 + (points[:, 0] - centre[0]) * PX_PER_M
    rows = PANEL / 2 - (points[:, 1] - centre[1]) * PX_PER_M
    return [(float(c), float(r)) for c, r in zip(columns, rows, strict=True)]


def _grid(view: NDArray[np.uint8], centre: NDArray[np.float64]) -> None:
    """A line every whole metre of the world."""
    half = SPAN / 2
    for axis in (0, 1):
        for metre in range(math.ceil(centre[axis] - half), math.floor(centre[axis] + half) + 1):
            offset = (metre - centre[axis]) * PX_PER_M
            if axis == 0:
                column = round(PANEL / 2 + offset)
                if 0 <= column < PANEL:
                    view[:, column] = GRID
            else:
                row = round(PANEL / 2 - offset)
                if 0 <= row < PANEL:
                    view[row, :] = GRID


def _distances(view: NDArray[np.uint8], centre: Pixel, reach: float) -> tuple:
    """(rows, columns, distance in px to ``centre``) of the view's pixels within ``reach``."""
    column, row = centre
    r0, r1 = max(0, math.floor(row - reach)), min(view.shape[0], math.ceil(row + reach) + 1)
    c0, c1 = max(0, math.floor(column - reach)), min(view.shape[1], math.ceil(column + reach) + 1)
    if r0 >= r1 or c0 >= c1:
        return slice(0, 0), slice(0, 0), np.zeros((0, 0))
    rows, columns = np.mgrid[r0:r1, c0:c1]
    return slice(r0, r1), slice(c0, c1), np.hypot(rows - row, columns - column)


def _disc(view: NDArray[np.uint8], centre: Pixel, radius: float, colour: tuple) -> None:
    rows, columns, distance = _distances(view, centre, radius)
    view[rows, columns][distance <= radius] = colour


def _ring(view: NDArray[np.uint8], centre: Pixel, radius: float, colour: tuple) -> None:
    rows, columns, distance = _distances(view, centre, radius + 1)
    view[rows, columns][np.abs(distance - radius) <= 1.0] = colour


def _line(view: NDArray[np.uint8], start: Pixel, end: Pixel, colour: tuple, width: int = 2) -> None:
    """A segment ``width`` px thick (square stamps along it), clipped to the view."""
    length = math.hypot(end[0] - start[0], end[1] - start[1])
    t = np.linspace(0.0, 1.0, max(2, math.ceil(length * 2)))
    columns = np.rint(start[0] + t * (end[0] - start[0])).astype(np.int64)
    rows = np.rint(start[1] + t * (end[1] - start[1])).astype(np.int64)
    for dr in range(-(width // 2), width - width // 2):
        for dc in range(-(width // 2), width - width // 2):
            r, c = rows + dr, columns + dc
            inside = (r >= 0) & (r < view.shape[0]) & (c >= 0) & (c < view.shape[1])
            view[r[inside], c[inside]] = colour
