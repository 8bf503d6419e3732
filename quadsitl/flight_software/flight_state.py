"""The flight state: the mode flown and its activity, and every transition between them.

This is the one place that changes the mode and the activity (PX4 splits it between its
commander and its navigator). The ground station's commands, the mission runner, the
failsafes, ground contact and external motor control all ask for a transition by what
it means (:meth:`FlightState.enter`, :meth:`~FlightState.hold`,
:meth:`~FlightState.fly`, :meth:`~FlightState.plan_return`, ...); what each mode flies
comes from :mod:`.guidance`, a mission's activities from :mod:`.mission_runner`.
"""

from __future__ import annotations

import math

from quadsitl import frames
from quadsitl.flight_software import external_control as X
from quadsitl.flight_software import ground_contact as GC
from quadsitl.flight_software import guidance as G
from quadsitl.flight_software.controller import Setpoint, Vec
from quadsitl.flight_software.mission_runner import MissionRunner
from quadsitl.flight_software.navigator import Activity, Hold, Land, Leg
from quadsitl.flight_software.results import ACCEPTED, LandedState, Result, Severity, denied
from quadsitl.flight_software.view import VehicleView
from quadsitl.physics import layout as L
from quadsitl.wire.modes import NEEDS_PILOT, Mode


class FlightState:
    """Mode, activity and the plan around them of ``vehicle``, whose ``missions`` run
    its MISSION mode; it starts holding ``position``."""

    def __init__(self, vehicle: VehicleView, missions: MissionRunner, position: Vec) -> None:
        self.v = vehicle
        self.missions = missions
        self.reset(position)

    def reset(self, position: Vec) -> None:
        """At power-on: holding ``position``, nothing planned."""
        self.mode = Mode.LOITER
        self.activity: Activity = Hold(position)
        self.rtl_stages: list[Activity] = []  # the return's activities after this one
        self.takeoff_altitude: float | None = None  # m above home, of the pending take-off
        self.mission_speed: float | None = None  # m/s, set by DO_CHANGE_SPEED
        self.offboard: Setpoint | None = None  # the latest offboard setpoint
        self.offboard_time = -math.inf  # s, simulated, when it came

    @property
    def landed_state(self) -> int:
        if self.v.on_ground:
            return LandedState.ON_GROUND
        if isinstance(self.activity, Land):
            return LandedState.LANDING
        if self.mode is Mode.TAKEOFF:
            return LandedState.TAKING_OFF
        return LandedState.IN_AIR

    # --- what the ground station asks -------------------------------------------------
    def set_mode(self, mode: Mode) -> Result:
        v = self.v
        if mode in NEEDS_PILOT:
            return denied(f"mode {mode.name} denied: needs a pilot (RC)")
        if mode is Mode.MISSION and not self.missions.items:
            return denied("mission mode denied: no mission uploaded")
        if mode is Mode.MISSION and self.missions.finished:
            self.missions.restart()
        if mode is Mode.OFFBOARD and not self.offboard_alive():
            return denied("offboard denied: stream setpoints first")
        if mode is Mode.RTL and v.on_ground:
            return denied("return denied: vehicle is on the ground")
        if mode is Mode.LAND and v.on_ground and not v.armed:
            return denied("land denied: vehicle is on the ground")
        if v.motor_control:
            X.release_motors(v, f"mode {mode.name} requested")
        if mode is not self.mode:
            v.event(Severity.INFO, f"mode {mode.name}")
        self.enter(mode)
        return ACCEPTED

    def takeoff(self, altitude: float | None) -> Result:
        """Climb above the current position to ``altitude`` m above home (None: the
        MIS_TAKEOFF_ALT parameter). Disarmed on the ground, the vehicle switches to
        TAKEOFF and climbs once armed (PX4's behaviour, which QGroundControl relies on)."""
        v = self.v
        if not v.armed and not v.on_ground:
            return denied("take-off denied: not armed")
        if altitude is not None:
            above_ground = altitude + float(v.home_position[2])
            if not (math.isfinite(altitude) and above_ground >= 0.3 and altitude <= 500):
                return denied(
                    f"take-off denied: {altitude:.1f} m above home is below the ground or "
                    "above 500 m"
                )
        self.takeoff_altitude = altitude
        result = self.set_mode(Mode.TAKEOFF)
        if result.ok and not v.armed:
            v.event(Severity.INFO, "take-off ready: arm to climb")
        return result

    def reposition(
        self, east: float, north: float, up: float, speed: float | None, yaw: float | None
    ) -> Result:
        """Go to a local point (m above the ground; NaN keeps the current coordinate) and
        hold there."""
        if not self.v.armed:
            return denied("reposition denied: not armed")
        leg = G.reposition(self.v, east, north, up, speed, yaw)
        if leg is None:
            return denied("reposition denied: target not finite or too far")
        if self.mode is not Mode.LOITER:
            self.v.event(Severity.INFO, "mode LOITER")
        self.mode, self.activity, self.rtl_stages = Mode.LOITER, leg, []
        return ACCEPTED

    def stream_offboard(self, setpoint: Setpoint) -> None:
        """Latest offboard target (world ENU); kept until the next one or a timeout."""
        self.offboard = setpoint
        self.offboard_time = self.v.time

    def offboard_alive(self) -> bool:
        """Offboard setpoints came within COM_OF_LOSS_T."""
        return (
            self.offboard is not None
            and self.v.time - self.offboard_time <= self.v.params["COM_OF_LOSS_T"]
        )

    def change_speed(self, speed: float) -> None:
        """The cruise speed of the legs from now on (DO_CHANGE_SPEED), m/s."""
        self.mission_speed = speed

    # --- transitions --------------------------------------------------------------------
    def enter(self, mode: Mode) -> None:
        """Fly ``mode`` from where the vehicle is now."""
        self.mode = mode
        state = self.v.nav_state
        here = state[L.POS].copy()
        yaw = float(frames.euler_from_quat(state[L.QUAT])[2])
        self.rtl_stages = []
        if mode is Mode.MISSION:
            self.missions.started = True
            self.missions.start_item()
        elif mode is Mode.RTL:
            self.plan_return(here, yaw)
        else:
            self.activity = G.activity_for(self.v, mode, here, yaw)
        if mode is Mode.OFFBOARD:
            self.v.controller.reset()

    def hold(self, point: Vec, yaw: float | None = None) -> None:
        """Hold (LOITER) at ``point``, heading ``yaw`` (None: as it is)."""
        self.mode, self.activity, self.rtl_stages = Mode.LOITER, Hold(point, yaw), []

    def fly(self, activity: Activity) -> None:
        """The next activity of the current mode (a mission's legs, landings, orbits)."""
        self.activity = activity

    def plan_return(self, here: Vec, yaw: float) -> None:
        """Return to launch from ``here``: its first activity now, the others staged."""
        self.activity, self.rtl_stages = G.return_to_launch(self.v, here, yaw)
        self.v.event(Severity.INFO, "returning to launch")

    def next_return_stage(self) -> None:
        """On a return, the next stage once the current one is done."""
        if self.activity.done and self.rtl_stages:
            self.activity = self.rtl_stages.pop(0)

    def take_motors(self) -> None:
        """An external controller took the rotors: the mode reads OFFBOARD; the activity
        stays (nothing flies it until the rotors are handed back)."""
        self.mode = Mode.OFFBOARD

    def landing_done(self) -> None:
        """Landed and disarmed: a mission's landing item is reached; then hold."""
        if self.mode is Mode.MISSION:
            self.missions.item_reached()
        self.enter(Mode.LOITER)

    # --- each control tick --------------------------------------------------------------
    def navigate(self) -> None:
        """Mode logic at the controller rate: timeouts, ground timers, take-off and
        return stages, mission progress."""
        v = self.v
        if self.mode is Mode.OFFBOARD and not self.offboard_alive():
            v.event(Severity.WARNING, "offboard setpoints lost: holding position")
            self.enter(Mode.LOITER)
        if v.on_ground and not v.crashed:
            GC.on_ground_timers(v)
        if self.mode is Mode.TAKEOFF and self.activity.done:
            v.event(Severity.INFO, "take-off complete: holding")
            climb = self.activity
            if isinstance(climb, Leg):  # hold the take-off target, not where it is now
                self.hold(climb.end, climb.yaw)
            else:
                self.enter(Mode.LOITER)
        elif self.mode is Mode.RTL:
            self.next_return_stage()
        elif self.mode is Mode.MISSION:
            self.missions.progress()

    def setpoint(self, state: Vec) -> Setpoint:
        """What the controller flies to from ``state`` (the flight software's)."""
        v = self.v
        if self.mode is Mode.OFFBOARD and self.offboard is not None:
            return self.offboard
        setpoint = self.activity.setpoint(state[L.POS], state[L.VEL], v.time)
        if v.on_ground and G.stays_on_ground(self.activity, v.airframe.gear_height):
            return Setpoint(idle=True)
        return setpoint
