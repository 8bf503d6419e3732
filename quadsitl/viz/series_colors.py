"""Which colour each time series of the Rerun scene is drawn in: the series of one
panel never share one (each panel's take :mod:`quadsitl.viz.palette`'s colours in
order), a name keeps its colour across panels, and each flight mode's band has its own.
Data and pure functions: :func:`quadsitl.viz.scene.series_style` logs them.
"""

from __future__ import annotations

import zlib

from quadsitl.viz import palette

# The goal errors the reward is made of (the columns of the task engine's ``dist``), with
# their units: the legend of the goal-error panel.
REWARD_TERMS = ("position (m)", "attitude (sin/cos)", "velocity (m/s)", "rates (rad/s)")

# Each panel's series in legend order (entity ``plots/<panel>/<name>``): the k-th takes
# the palette's k-th colour, so that the series of a panel never share one, and a name
# keeps its colour across panels (east, roll, x: blue; north, pitch, y: orange ...). A
# setpoint (``setpoint``, ``roll_setpoint`` ...) is its series' colour, lighter; the
# ground truth (``altitude_truth``, ``roll_truth`` ...: the simulator's own state, where a
# log has it) darker.
SETPOINT, TRUTH = "setpoint", "truth"
SERIES_NAMES: dict[str, tuple[str, ...]] = {
    "altitude": ("altitude",),
    "climb_rate": ("climb",),
    "velocity": ("east", "north"),
    "attitude": ("roll", "pitch", "yaw"),
    "rates": ("roll", "pitch", "yaw"),
    "rotors": tuple(f"rotor_{i}" for i in range(1, 9)),
    "servo_pwm": tuple(str(i) for i in range(1, 9)),
    "battery_voltage": ("voltage",),
    "battery_remaining": ("percent",),
    "gps": ("fix_type", "satellites"),
    "mission_item": ("seq",),
    "reward": ("reward",),
    "reward_terms": REWARD_TERMS,
    "distance_to_goal": ("distance",),
    "height_above_goal": ("height",),
    "speed": ("speed",),
    "wind": ("east", "north", "up", "speed"),
    "accelerometer": ("x", "y", "z"),
    "gyroscope": ("x", "y", "z"),
    "barometer": ("pressure",),
    "vibration": ("x", "y", "z", "accel", "gyro"),
}
# The vibration panel's threshold lines: the stack's own warning and too-high levels.
THRESHOLD_COLORS: dict[str, palette.RGB] = {"warning": palette.OLIVE, "bad": palette.RED}

# The flight modes' bands, each mode its own colour (none red: armed is red); PX4's and
# quadsitl's names, and ArduPilot's where they differ. A mode not named here takes one
# by its name's hash.
MODE_COLORS: dict[str, palette.RGB] = {
    "MANUAL": palette.GREY,
    "STABILIZED": palette.PINK,
    "STABILIZE": palette.PINK,
    "ACRO": palette.CYAN,
    "ALTCTL": palette.PURPLE,
    "ALT_HOLD": palette.PURPLE,
    "POSCTL": palette.BLUE,
    "POSHOLD": palette.BLUE,
    "TAKEOFF": palette.GREEN,
    "LOITER": palette.OLIVE,
    "MISSION": palette.BROWN,
    "AUTO": palette.BROWN,
    "RTL": palette.ORANGE,
    "LAND": palette.CYAN,
    "OFFBOARD": palette.PINK,
    "GUIDED": palette.PINK,
}


def series_color(entity: str) -> palette.RGB:
    """The colour of the time series at ``entity`` (``plots/<panel>/<name>``)."""
    _, panel, name = [*entity.split("/", 2), "", ""][:3]
    if panel == "vibration" and name in THRESHOLD_COLORS:
        return THRESHOLD_COLORS[name]
    role = trace_role(name)
    base = name.removesuffix(role).removesuffix("_") if role else name
    names = SERIES_NAMES.get(panel, ())
    if base in names:
        color = palette.series(names.index(base))
    elif not base and names:  # ``setpoint``, ``truth``: of the panel's first series
        color = palette.series(0)
    else:
        color = palette.series(zlib.crc32(base.encode()))
    if role == SETPOINT:
        return palette.lighter(color)
    return palette.darker(color) if role == TRUTH else color


def trace_role(name: str) -> str:
    """Which trace of its quantity a series is: SETPOINT, TRUTH or "" (the estimate,
    what the vehicle measured or believed)."""
    for role in (SETPOINT, TRUTH):
        if name == role or name.endswith(f"_{role}"):
            return role
    return ""


def mode_color(mode: str) -> palette.RGB:
    """The colour of flight mode ``mode``'s band."""
    return MODE_COLORS.get(mode) or palette.series(zlib.crc32(mode.encode()))
