"""The robustness ladder's rungs: along each axis, the task options of each rung.

A rung is an env configuration built only from the documented task options
(docs/tasks.md): ``wind``, ``randomize``'s wind draw, ``delay``, ``airframe_scale``,
``faults`` and ``sensor_noise``. Each axis starts from (or passes through) the nominal
world, still air with perfect state, so the axes share that rung. This module knows no
torch: the command line reads the axis names from here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

FAULTY_MOTOR = 1  # the motor that loses thrust on the motor axis (1-based, as PX4)


@dataclass(frozen=True)
class Rung:
    """One rung: a label for tables and plots, and the task options that make it."""

    label: str
    options: dict[str, Any] = field(default_factory=dict)  # {} is the nominal world


def _mean_wind(speed: float, turbulence: str | None = None) -> dict[str, Any]:
    """A mean wind of ``speed`` m/s, with ``turbulence`` (a MIL-F-8785C severity) or
    none, from a direction drawn per episode uniformly over 0–360° (from each env's
    seeded generator): a waypoint task meets head, tail and cross winds, not one
    direction."""
    if speed == 0 and turbulence is None:
        return {}
    draw = {"speed": (speed, speed), "from_deg": (0.0, 360.0), "turbulence": [turbulence]}
    return {"randomize": {"wind": draw}}


def _delay(ms: int) -> dict[str, Any]:
    """``ms`` of observation delay and as much actuation delay (whole physics steps)."""
    return {"delay": {"observation": ms / 1000, "action": ms / 1000}} if ms else {}


def _mass(percent: int) -> dict[str, Any]:
    return {"airframe_scale": {"mass": 1 + percent / 100}} if percent else {}


def _motor(percent: int) -> dict[str, Any]:
    """Motor FAULTY_MOTOR at ``percent`` % of its thrust and torque from the first step."""
    if percent == 100:
        return {}
    return {"faults": {"motor": FAULTY_MOTOR, "efficiency": percent / 100, "at": 0.0}}


# Axis name: (what it varies, its rungs in order). Turbulence is Dryden turbulence of
# MIL-F-8785C's severities (σ_w = 0.1·W20, W20 = 15, 30, 45 kt) in no mean wind, so that
# the wind axis alone measures the mean wind.
LADDER: dict[str, tuple[str, list[Rung]]] = {
    "turbulence": (
        "Dryden turbulence, no mean wind",
        [Rung("none")]
        + [
            Rung(level, {"wind": {"turbulence": level}})
            for level in ("light", "moderate", "severe")
        ],
    ),
    "wind": (
        "mean wind, direction drawn per episode",
        [Rung(f"{speed} m/s", _mean_wind(speed)) for speed in (0, 3, 6, 9)],
    ),
    "delay": (
        "observation and actuation delay, each",
        [Rung(f"{ms} ms", _delay(ms)) for ms in (0, 10, 20, 40)],
    ),
    "mass": (
        "mass, against the nominal airframe",
        [Rung(f"{p:+d} %" if p else "0 %", _mass(p)) for p in (-30, -15, 0, 15, 30)],
    ),
    "motor": (
        f"motor {FAULTY_MOTOR}'s thrust, from the start",
        [Rung(f"{p} %", _motor(p)) for p in (100, 80, 60)],
    ),
    "noise": (
        "sensor noise on the observation",
        [Rung("off"), Rung("default", {"sensor_noise": 1.0}), Rung("3x", {"sensor_noise": 3.0})],
    ),
    # The robust policies' target, all at once: what a robust checkpoint must keep 90 %
    # success in (docs/results.md).
    "target": (
        "moderate turbulence in a 6 m/s mean wind, 20 ms delay each way",
        [
            Rung("none"),
            Rung("moderate, 6 m/s, 20 ms", {**_mean_wind(6.0, "moderate"), **_delay(20)}),
        ],
    ),
}
AXES = tuple(LADDER)
# Task options a ladder sets (or a robust training run may have set): removed from a
# policy's trained options before it climbs, so every policy meets the same rungs.
DISTURBANCES = (
    "wind",
    "delay",
    "randomize",
    "param_randomization",
    "airframe_scale",
    "faults",
    "sensor_noise",
)


def check_axes(axes: list[str] | tuple[str, ...] | None) -> tuple[str, ...]:
    """The axes asked for, in the order given, once each (None: all); a one-line
    ValueError naming an unknown one."""
    if axes is None:
        return AXES
    unknown = [a for a in axes if a not in LADDER]
    if unknown:
        raise ValueError(f"unknown axis {unknown[0]!r}; axes: {', '.join(AXES)}")
    if not axes:
        raise ValueError(f"no axes given; axes: {', '.join(AXES)}")
    return tuple(dict.fromkeys(axes))
