"""Where :func:`quadsitl.viz.scene.arrange` puts the time-series plots, and about how
big each is in the window the documentation's pictures are taken at: what a plot's
legend and y labels have room for (:mod:`quadsitl.viz.plot_fit`).
"""

from __future__ import annotations

from typing import Any

import rerun.blueprint as rrb


def grid_columns(plots: int) -> int:
    """The plots' grid: one column up to four plots, two up to eight, then three."""
    return 1 if plots <= 4 else 2 if plots <= 8 else 3


def column_lengths(plots: int) -> list[int]:
    """Plots per column of the grid, the shorter columns first (their taller plots:
    the panels with more series, rotors and attitude, come early in PANELS)."""
    columns = grid_columns(plots)
    return sorted(plots // columns + (k < plots % columns) for k in range(columns))


def plot_grid(plots: list[Any]) -> Any:
    """The plots in :func:`grid_columns` columns: a grid, or beyond eight three columns
    filled top to bottom (a grid's last row would leave cells empty)."""
    if grid_columns(len(plots)) < 3:
        return rrb.Grid(*plots, grid_columns=grid_columns(len(plots)))
    columns, start = [], 0
    for length in column_lengths(len(plots)):
        columns.append(rrb.Vertical(*plots[start : start + length]))
        start += length
    return rrb.Horizontal(*columns)


def column_shares(plots: int) -> tuple[float, float]:
    """Widths of the left (3-D view, map, events) and right (plots) columns: the plots
    take two thirds beyond eight (three columns of them)."""
    return (1.0, 2.0) if grid_columns(plots) == 3 else (1.0, 1.0)


WINDOW = (1600.0, 900.0)  # px: the window the plots are fitted for (the docs' pictures)
CHROME = 70.0  # px of the window's height outside the views (top and time bars)
VIEW_TITLE = 24.0  # px of a view's height above its plot: its title bar
AXIS_LABELS = (44.0, 22.0)  # px of a plot's width (y labels) and height (x labels)


def plot_sizes(plots: int, state_share: float | None = 1.0) -> list[tuple[float, float]]:
    """(width, height) px of each plot of :func:`arrange`'s grid of ``plots``, in
    order, in WINDOW, about (``state_share``: the state band's, None without one):
    what a legend and the labels of a y axis have room for."""
    left, right = column_shares(plots)
    height = WINDOW[1] - CHROME
    if state_share is not None:
        height *= 6.0 / (6.0 + state_share)
    columns = grid_columns(plots)
    width = WINDOW[0] * right / (left + right) / columns - AXIS_LABELS[0]
    if columns < 3:
        rows = -(-plots // columns)
        return [(width, height / rows - VIEW_TITLE - AXIS_LABELS[1])] * plots
    return [
        (width, height / length - VIEW_TITLE - AXIS_LABELS[1])
        for length in column_lengths(plots)
        for _ in range(length)
    ]
