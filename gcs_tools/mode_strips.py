"""The flight mode under every time plot of a replay: a strip along each plot's bottom
edge in the mode's band colour, so that a glance at any plot says which mode the
vehicle was in (PX4 Flight Review colours the plots' backgrounds; Rerun's plots have no
background bands, so the strip is the state band's own series drawn again, thick, at
the foot of each plot's fitted y range).

Entities ``plots/<panel>/mode/<MODE>``, each drawn as steps, all named ``mode`` (one
legend entry, not one per mode: the state band's title names the modes' colours).
Only where a plot's y range is known (a replay, :mod:`quadsitl.viz.plot_fit`).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import rerun as rr

from gcs_tools.series_buffer import Series
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
