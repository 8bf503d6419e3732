"""``quadsitl sim --flight-stack px4|ardupilot --rerun``: what each autopilot believes
beside what its vehicle really does, as they fly.

The estimate, setpoints, mode and armed state are the autopilot's own MAVLink telemetry
(:mod:`quadsitl.bridges.autopilot_telemetry`), drawn by the same
:class:`~quadsitl.viz.live.LiveLogger` as ``sim --rerun`` and a replayed ``.tlog``; the
truth is the physics' state, drawn darker in the estimate's colour
(``altitude_truth``, ``roll_truth`` …, and the true track ``world/trajectory_truth``),
the colour convention of a replayed ULog or DataFlash log. The timeline is simulated
time (the autopilots set the pace in lockstep, often several times real time): each
message is stamped with the physics time at which it was sent (:class:`MessageClock`),
so that estimate and truth line up however fast the flight runs.

Each vehicle's truth is taken at most TRUTH_RATE times a wall second, and each kind of
message of each vehicle logged at most MESSAGE_RATE times a wall second (PX4 streams
hundreds): the view costs the lockstep loop little. Positions are from where each
vehicle started, where its autopilot's estimator starts too. A fleet's vehicles stand
GRID_SPACING m apart in the 3-D view, each under its system id (:mod:`quadsitl.viz.fleet`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import rerun as rr

from quadsitl import frames
from quadsitl.physics.fleet import Fleet
from quadsitl.viz.fleet import fleet_of
from quadsitl.viz.flight_view import Sample
from quadsitl.viz.live import MAX_TRACK, TRACK_REDRAW, open_live

TRUTH_RATE = 60.0  # Hz of wall time, per vehicle
MESSAGE_RATE = 60.0  # Hz of wall time, per vehicle and kind of message
GRID_SPACING = 4.0  # m between a fleet's vehicles in the 3-D view
# The autopilot's motor outputs as PWM (its SERVO_OUTPUT_RAW), not the rotor speeds of
# quadsitl's own flight software; no battery (the autopilot simulates its own).
PANELS = ("altitude", "climb_rate", "velocity", "attitude", "rates", "servo_pwm")


def grid_offsets(n: int, spacing: float = GRID_SPACING) -> list[tuple[float, float, float]]:
    """Where n vehicles stand in the scene (ENU m): rows of ceil(sqrt n) eastwards."""
    columns = max(1, math.ceil(math.sqrt(n)))
    return [((i % columns) * spacing, (i // columns) * spacing, 0.0) for i in range(n)]


def truth_samples(
    position_enu: np.ndarray,
    velocity_enu: np.ndarray,
    q_enu_flu: np.ndarray,
    rates_flu: np.ndarray,
    last_yaw: float | None,
) -> list[Sample]:
    """One vehicle's true state as the views' ``_truth`` series: altitude, climb rate,
    horizontal velocity, attitude (degrees, NED/FRD as its autopilot reports it; yaw
    unwrapped from ``last_yaw``) and body rates (deg/s, FRD)."""
    roll, pitch, yaw = np.degrees(frames.euler_from_quat(frames.quat_enu_flu_to_ned_frd(q_enu_flu)))
    if last_yaw is not None:
        yaw = last_yaw + (yaw - last_yaw + 180.0) % 360.0 - 180.0
    rates = np.degrees(frames.flu_to_frd(rates_flu))
    values = {
        "plots/altitude/altitude_truth": position_enu[2],
        "plots/climb_rate/climb_truth": velocity_enu[2],
        "plots/velocity/east_truth": velocity_enu[0],
        "plots/velocity/north_truth": velocity_enu[1],
        "plots/attitude/roll_truth": roll,
        "plots/attitude/pitch_truth": pitch,
        "plots/attitude/yaw_truth": yaw,
        "plots/rates/roll_truth": rates[0],
        "plots/rates/pitch_truth": rates[1],
        "plots/rates/yaw_truth": rates[2],
    }
    return [Sample(entity, "scalar", float(value)) for entity, value in values.items()]


WRAP_S = 2**32 / 1e6  # SERVO_OUTPUT_RAW's time_usec is 32 bits: it wraps every 71.6 min


class MessageClock:
    """Each vehicle's autopilot messages on its physics clock. A message is stamped with
    its own time (``time_boot_ms``; SERVO_OUTPUT_RAW's ``time_usec``) plus the autopilot's
    offset from the physics: the least (physics time at arrival − message time) seen,
    since a message arrives after it was sent and both clocks run in lockstep. The view
    looks only every few ms of wall time, a good part of a simulated second faster than
    real time, so the time of arrival alone would draw the estimate late. Messages
    without a time (HEARTBEAT) take the time of arrival; a clock that goes back (the
    autopilot restarted) starts the offset again."""

    def __init__(self) -> None:
        self.offset: float | None = None  # s, physics time - autopilot time
        self.last = -math.inf  # s, the autopilot's latest time

    def stamp(self, message: Any, arrival_s: float) -> float:
        """The physics time (s) at which ``message`` was sent, about."""
        own = message_time_s(message, self.last)
        if own is None:
            return arrival_s
        if own < self.last - 1.0:  # a new boot
            self.offset = None
        self.last = max(self.last, own) if self.offset is not None else own
        if self.offset is None or arrival_s - own < self.offset:
            self.offset = arrival_s - own
        return min(own + self.offset, arrival_s)


def message_time_s(message: Any, near: float) -> float | None:
    """The autopilot's clock in ``message`` (s; None where it carries none), a wrapped
    32-bit microsecond clock put back in the wrap nearest ``near``."""
    boot_ms = getattr(message, "time_boot_ms", None)
    if boot_ms is not None:
        return float(boot_ms) / 1e3
    usec = getattr(message, "time_usec", None)
    if usec is None:
        return None
    own = float(usec) / 1e6
    if math.isfinite(near):
        own += round((near - own) / WRAP_S) * WRAP_S
    return own


class FlightStackView:
    """The fleet's vehicles (their ``fleet``, at rest at their starts now) in Rerun:
    spawns a viewer, saves to ``save`` (an .rrd path) or (``web``) serves the web viewer;
    ``notice`` takes the message saying where the recording goes when no viewer can be
    shown; ``focus``: the vehicle (1 … n) a crowd shows in full."""

    def __init__(
        self,
        fleet: Fleet,
        stack: str,
        save: str | None = None,
        notice: Callable[[str], None] | None = None,
        web: bool = False,
        focus: int | None = None,
    ) -> None:
        self.fleet = fleet
        self.start_position = fleet.position.copy()  # each vehicle's estimator starts here
        n = fleet.n
        members = fleet_of(list(range(1, n + 1)), grid_offsets(n), focus=focus) if n > 1 else []
        self.rec, self.loggers = open_live(
            f"quadsitl_{stack}",
            members,
            PANELS,
            fleet.hover_rotor_speed,
            save,
            notice,
            web,
            subject=f"{n} {stack} vehicles (estimate; truth: the darker track)",
        )
        self.epoch = time.time()  # the timeline's simulated 0 s
        self.clocks = [MessageClock() for _ in range(n)]
        self.last_yaw: list[float | None] = [None] * n
        self.truth_tracks: list[list[np.ndarray]] = [[] for _ in range(n)]
        self.last_truth_s = [-1.0] * n  # simulated s of each vehicle's last truth
        self.next_truth = 0.0  # wall s
        self.next_track = 0.0
        self.next_message: dict[tuple[int, int], float] = {}  # (vehicle, msgid) -> wall s

    def show(
        self, wall_now: float, times_s: Sequence[float], messages: Sequence[tuple[int, Any]]
    ) -> None:
        """Log what arrived (``messages``: vehicle index, autopilot message) and, when
        due, each vehicle's truth; ``times_s``: each vehicle's physics time now."""
        for index, message in messages:
            key = (index, message.get_msgId())
            if wall_now < self.next_message.get(key, 0.0):
                continue
            self.next_message[key] = wall_now + 1.0 / MESSAGE_RATE
            sent_s = self.clocks[index].stamp(message, times_s[index])
            self.loggers[index].message(message, now=self.epoch + sent_s)
        if wall_now >= self.next_truth:
            self.next_truth = wall_now + 1.0 / TRUTH_RATE
            self._log_truth(times_s)
        if wall_now >= self.next_track:
            self.next_track = wall_now + TRACK_REDRAW
            self._draw_truth_tracks()

    def _log_truth(self, times_s: Sequence[float]) -> None:
        fleet = self.fleet
        position = fleet.position - self.start_position
        velocity, quaternion, rates = fleet.velocity, fleet.quaternion, fleet.body_rates
        for index, logger in enumerate(self.loggers):
            now = times_s[index]
            if now == self.last_truth_s[index]:
                continue  # its autopilot has not moved it (paused, or not yet connected)
            if now < self.last_truth_s[index]:  # its autopilot restarted: a new flight
                self.truth_tracks[index].clear()
                self.last_yaw[index] = None
            self.last_truth_s[index] = now
            samples = truth_samples(
                position[index],
                velocity[index],
                quaternion[index],
                rates[index],
                self.last_yaw[index],
            )
            self.last_yaw[index] = samples[6].value
            logger.log_samples(samples, self.epoch + now)
            track = self.truth_tracks[index]
            track.append(position[index].copy())
            del track[:-MAX_TRACK]

    def _draw_truth_tracks(self) -> None:
        for index, track in enumerate(self.truth_tracks):
            if len(track) < 2:
                continue
            color = [self.loggers[index].truth_color]
            self.rec.log(
                self.loggers[index].path("world/trajectory_truth"),
                rr.LineStrips3D([np.asarray(track)], colors=color),
            )

    def close(self) -> None:
        self._draw_truth_tracks()  # to the end of the flight
        self.rec.flush()
        self.rec.disconnect()
