"""How a time-series panel is fitted to its data: a y range whose ends carry tick labels,
and the corner for the legend where it covers no data.

Rerun's plots label their axes at powers of ten only (1, 10, 100 ...: no 2 or 5 steps),
and only where two labels are far enough apart on screen; a panel 80 px tall
showing -8..8 m/s labels nothing but 0. So the range is widened to whole multiples of
the finest power of ten whose labels fit (:func:`nice_range`): its ends, at least, are
labelled. The legend sits in a corner of the plot, over the lines, and Rerun chooses
none by itself: :func:`fit` takes the corner where its box covers no sample, and where
every corner is taken makes room for it, above the data (a higher y range) or after it
(a time axis that runs on past the data's end), whichever leaves the data more of the
plot.

Only a recording whose data is known when its layout is made uses this (a replay; an
episode recording once it closes); a live view keeps Rerun's automatic ranges.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

LABEL_SPACING = 32.0  # px between two y labels for Rerun to draw both in full
LEGEND_ROW = 21.0  # px, one legend entry's height (Rerun's default font)
LEGEND_PADDING = 14.0  # px, the legend box's margins, top and bottom together
LEGEND_CHAR = 7.5  # px, a legend label's character
LEGEND_MARKER = 34.0  # px, the colour dot, its margins and the box's
# Corners in the order of preference where several are free: the top ones first (a
# flight's plots start and end on the ground, or near a goal: low).
Corner = Literal["RightTop", "LeftTop", "RightBottom", "LeftBottom"]  # Rerun's names
CORNERS: tuple[Corner, ...] = ("RightTop", "LeftTop", "RightBottom", "LeftBottom")
EDGE = 0.04  # of the range beyond each labelled end: Rerun draws no label on the edge
ROOM_AT_MOST = 0.6  # of a plot's height (or width) given up beside the data for its legend
MARGIN = 0.03  # of the plot, kept clear between the legend box and the data


@dataclass(frozen=True)
class PanelFit:
    """A panel's y range (its ends labelled), its legend's corner (Rerun's names) and,
    where the legend's room is after the data, where its time axis ends (s on the
    plot's timeline, as the data's times were given; None: at the data's end)."""

    y_range: tuple[float, float]
    corner: Corner
    time_end: float | None = None


def nice_range(low: float, high: float, height: float) -> tuple[float, float]:
    """[low, high] widened to whole multiples of the finest power of ten whose labels
    are LABEL_SPACING apart or more on a plot ``height`` px tall (and EDGE beyond)."""
    bottom, top, _ = _labelled(low, high, height)
    edge = EDGE * (top - bottom)
    return (bottom - edge, top + edge)


def _labelled(low: float, high: float, height: float) -> tuple[float, float, float]:
    """(bottom, top, step) of :func:`nice_range`, before the EDGE."""
    if not (math.isfinite(low) and math.isfinite(high)):
        return (0.0, 1.0, 1.0)
    if high - low < 1e-9 * max(1.0, abs(low), abs(high)):  # a constant: a unit around it
        step = 10.0 ** math.floor(math.log10(abs(low))) if low else 1.0
        return (low - step, high + step, step)
    step = 10.0 ** math.floor(math.log10(high - low))
    while True:
        bottom, top = math.floor(low / step) * step, math.ceil(high / step) * step
        if round((top - bottom) / step) <= fitting(height):
            return (_tidy(bottom, step), _tidy(top, step), step)
        step *= 10.0


def fitting(height: float) -> int:
    """How many label intervals a plot ``height`` px tall shows."""
    return max(1, int(height // LABEL_SPACING))


def _tidy(value: float, step: float) -> float:
    """``value`` (a multiple of ``step``) without the float noise of the product."""
    digits = max(0, -math.floor(math.log10(step)))
    return round(value, digits) + 0.0  # + 0.0: never -0.0


def legend_size(names: Sequence[str], width: float, height: float) -> tuple[float, float]:
    """The legend box of ``names`` as fractions of a ``width`` x ``height`` px plot."""
    longest = max((len(name) for name in names), default=0)
    box_width = LEGEND_MARKER + LEGEND_CHAR * longest
    box_height = LEGEND_PADDING + LEGEND_ROW * len(names)
    return min(1.0, box_width / width), min(1.0, box_height / height)


def covered(
    corner: str, box: tuple[float, float], points: np.ndarray, margin: float = MARGIN
) -> int:
    """How many ``points`` ((K, 2): time and value as fractions of the plot, 0..1, y
    up) the legend box hides in ``corner``, with ``margin`` around it."""
    box_width, box_height = box[0] + margin, box[1] + margin
    x, y = points[:, 0], points[:, 1]
    across = x >= 1.0 - box_width if corner.startswith("Right") else x <= box_width
    up = y >= 1.0 - box_height if corner.endswith("Top") else y <= box_height
    return int(np.count_nonzero(across & up))


def fit(
    series: Sequence[tuple[np.ndarray, np.ndarray]],
    names: Sequence[str],
    size: tuple[float, float],
    time_range: tuple[float, float] | None = None,
) -> PanelFit | None:
    """The fit of a panel drawing ``series`` ((times s, values) each) with a legend of
    ``names`` on a plot of ``size`` (width, height) px, over ``time_range`` (None: the
    series' own); None where it has no finite value."""
    values = [np.asarray(v, np.float64) for _, v in series]
    finite = np.concatenate([v[np.isfinite(v)] for v in values]) if values else np.zeros(0)
    if finite.size == 0:
        return None
    times = np.concatenate([np.asarray(t, np.float64) for t, _ in series])
    samples = np.concatenate(values)
    keep = np.isfinite(samples) & np.isfinite(times)
    times, samples = times[keep], samples[keep]
    start, end = time_range if time_range is not None else (times.min(), times.max())
    width, height = size
    box = legend_size(names, width, height)
    shown = nice_range(float(finite.min()), float(finite.max()), height)
    corner = _least_hidden(box, _fractions(times, samples, (start, end), shown))
    if corner[1] == 0:
        return PanelFit(shown, corner[0])
    # Every corner hides data: room for the legend above the data (the y range raised
    # by its height, where the labels still fit) or after it (the time axis run on by
    # its width), whichever leaves the data more of the plot; neither where the legend
    # would take more than ROOM_AT_MOST (then the corner that hides the least).
    raised = _raised(finite, shown, box[1], height)
    after = box[0] + MARGIN
    kept_raised = 1.0 - box[1] if raised is not None else 0.0
    kept_after = 1.0 - after if after <= ROOM_AT_MOST else 0.0
    if raised is not None and kept_raised >= kept_after:
        corner = _least_hidden(box, _fractions(times, samples, (start, end), raised))
        return PanelFit(raised, corner[0])
    if kept_after > 0.0:
        time_end = start + (end - start) / (1.0 - after - 0.01)
        return PanelFit(shown, "RightTop", time_end)
    return PanelFit(shown, corner[0])


def _raised(
    finite: np.ndarray, shown: tuple[float, float], box_height: float, height: float
) -> tuple[float, float] | None:
    """``shown`` raised by a legend ``box_height`` tall (a fraction of the plot) above
    the data; None where the legend is taller than ROOM_AT_MOST or the raised range's
    labels would no longer fit."""
    if box_height > ROOM_AT_MOST:
        return None
    bottom, top, step = _labelled(float(finite.min()), float(finite.max()), height)
    raised = (shown[0], shown[1] + (shown[1] - shown[0]) * box_height / (1.0 - box_height))
    if (raised[1] - raised[0]) / step > fitting(height) + 2 * EDGE * (top - bottom) / step:
        return None
    return raised


def _least_hidden(box: tuple[float, float], points: np.ndarray) -> tuple[Corner, int]:
    """The corner whose legend box hides the fewest points, and how many."""
    hidden = {corner: covered(corner, box, points) for corner in CORNERS}
    best = min(CORNERS, key=lambda c: (hidden[c], CORNERS.index(c)))
    return best, hidden[best]


def _fractions(
    times: np.ndarray, values: np.ndarray, time_range: tuple[float, float], y_range: tuple
) -> np.ndarray:
    """(K, 2) positions of the samples in the plot, as fractions of its width and height."""
    (start, end), (low, high) = time_range, y_range
    x = (times - start) / max(end - start, 1e-12)
    y = (values - low) / max(high - low, 1e-12)
    return np.column_stack((x, y))
