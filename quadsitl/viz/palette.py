"""The project's one palette, for every plot it draws: Rerun's panels and the PNG figures.

Tableau 10 (matplotlib's ``tab10``, readable on Rerun's dark background and on white):
the series of one plot take its colours in order, so that no two of them share one.
Red is kept for what must stand out (armed, the front rotors, a crash), grey for what
was commanded rather than flown (a moving target's track). A quantity's three traces
share its colour: the estimate as it is, the setpoint lighter, the truth darker. No Rerun and no
matplotlib here: both sides import it.
"""

from __future__ import annotations

RGB = tuple[int, int, int]

BLUE: RGB = (31, 119, 180)
ORANGE: RGB = (255, 127, 14)
GREEN: RGB = (44, 160, 44)
RED: RGB = (214, 39, 40)
PURPLE: RGB = (148, 103, 189)
BROWN: RGB = (140, 86, 75)
PINK: RGB = (227, 119, 194)
GREY: RGB = (127, 127, 127)
OLIVE: RGB = (188, 189, 34)
CYAN: RGB = (23, 190, 207)

NAMES: dict[RGB, str] = {
    BLUE: "blue",
    ORANGE: "orange",
    GREEN: "green",
    RED: "red",
    PURPLE: "purple",
    BROWN: "brown",
    PINK: "pink",
    GREY: "grey",
    OLIVE: "olive",
    CYAN: "cyan",
}  # what a title calls a colour where a legend has no room

TRACK: RGB = (90, 90, 200)  # one vehicle's trajectory in 3-D (a fleet's: each its colour)

# The series of one plot, in order: first blue, then orange ... (no red, no grey).
SERIES: tuple[RGB, ...] = (BLUE, ORANGE, GREEN, PURPLE, CYAN, PINK, OLIVE, BROWN)


def series(index: int) -> RGB:
    """The colour of a plot's ``index``-th series (from 0; wraps after eight)."""
    return SERIES[index % len(SERIES)]


def lighter(color: RGB, amount: float = 0.55) -> RGB:
    """``color`` moved ``amount`` of the way to white: what was asked of a series (its
    setpoint) beside what it did."""
    r, g, b = (round(c + (255 - c) * amount) for c in color)
    return (r, g, b)


def darker(color: RGB, amount: float = 0.45) -> RGB:
    """``color`` moved ``amount`` of the way to black: what the vehicle really did (the
    simulator's ground truth) beside what its estimator believed."""
    r, g, b = (round(c * (1.0 - amount)) for c in color)
    return (r, g, b)


def dim(color: RGB, amount: float = 0.6) -> RGB:
    """``color`` moved ``amount`` of the way to the viewer's dark grey: one of a crowd,
    kept in the background of the one looked at."""
    r, g, b = (round(c + (48 - c) * amount) for c in color)
    return (r, g, b)


def hex_color(color: RGB) -> str:
    """``#rrggbb``, as matplotlib takes a colour."""
    return "#{:02x}{:02x}{:02x}".format(*color)
