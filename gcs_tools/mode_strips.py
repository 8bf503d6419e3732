"""The flight's modes and events on the time axes of a replay.

The flight mode under every time plot: a strip along each plot's bottom
edge in the mode's band colour, so that a glance at any plot says which mode the
vehicle was in (PX4 Flight Review colours the plots' backgrounds; Rerun's plots have no
background bands, so the strip is the state band's own series drawn again, thick, at
the foot of each plot's fitted y range).

Entities ``plots/<panel>/mode/<MODE>``, each drawn as steps, all named ``mode`` (one
legend entry, not one per mode: the state band's title names the modes' colours).
Only where a plot's y range is known (a replay, :mod:`quadsitl.viz.plot_fit`).

The events (arming, mode changes, the autopilot's messages, parameter changes, the
vibration verdict) as marks on the state band's time axis, between the armed line and
the mode band (``plots/state/events``): a diamond per event, red for errors, orange
for warnings; the event log lists them at the time cursor.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import rerun as rr

from gcs_tools.series_buffer import Series
from quadsitl.viz import palette
from quadsitl.viz.plot_fit import PanelFit
from quadsitl.viz.scene import STATE_PANEL, TIMELINE
from quadsitl.viz.series_colors import mode_color

STRIP_WIDTH = 6.0  # UI points
STRIP_HEIGHT = 0.025  # of the plot's y range above its bottom: the strip's centre
STRIP_ALPHA = 200


def send_mode_strips(
    rec: rr.RecordingStream, series: Mapping[tuple[str, str], Series], fits: Mapping[str, PanelFit]
) -> dict[str, int]:
    """Each flight mode's band (``plots/state/mode/<MODE>``) as a strip in every fitted
    panel; rows logged per entity."""
    prefix = f"plots/{STATE_PANEL}/mode/"
    bands = {
        entity.removeprefix(prefix): band
        for (entity, kind), band in series.items()
        if kind == "scalar" and entity.startswith(prefix)
    }
    rows: dict[str, int] = {}
    for panel, fit in fits.items():
        low, high = fit.y_range
        foot = low + STRIP_HEIGHT * (high - low)
        for mode, band in bands.items():
            times, values = band.arrays()
            path = f"plots/{panel}/mode/{mode}"
            r, g, b = mode_color(mode)
            style = rr.SeriesLines(
                colors=[[r, g, b, STRIP_ALPHA]],
                widths=[STRIP_WIDTH],
                names=["mode"],
                interpolation_mode="StepAfter",
            )
            rec.log(path, style, static=True)
            strip = np.where(np.isfinite(values), foot, np.nan)
            index = rr.TimeColumn(TIMELINE, timestamp=times.astype("datetime64[us]"))
            rec.send_columns(path, indexes=[index], columns=rr.Scalars.columns(scalars=strip))
            rows[path] = len(times)
    return rows


EVENT_HEIGHT = 1.5  # on the state band's axis: between armed (0/1) and the modes (2)
EVENT_COLORS = {"CRITICAL": palette.RED, "ERROR": palette.RED, "WARN": palette.ORANGE}
EVENT_COLOR = (220, 220, 220)


def send_event_marks(rec: rr.RecordingStream, series: Mapping[tuple[str, str], Series]) -> int:
    """A mark per event on the state band; how many."""
    events = series.get(("events", "text"))
    if events is None:
        return 0
    times, _ = events.arrays()
    colors = [list(EVENT_COLORS.get(level, EVENT_COLOR)) for level in events.levels()]
    path = f"plots/{STATE_PANEL}/events"
    rec.log(
        path, rr.SeriesPoints(markers="Diamond", marker_sizes=[4.0], names=["events"]), static=True
    )
    index = rr.TimeColumn(TIMELINE, timestamp=times.astype("datetime64[us]"))
    heights = np.full(len(times), EVENT_HEIGHT)
    rec.send_columns(
        path,
        indexes=[index],
        columns=[*rr.Scalars.columns(scalars=heights), *rr.SeriesPoints.columns(colors=colors)],
    )
    return len(times)
