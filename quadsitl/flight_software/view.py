"""The vehicle as its flight-software parts see it: what they read of it and what they
may ask of it.

:class:`~quadsitl.flight_software.vehicle.Vehicle` assembles the parts (flight state, guidance,
mission runner, failsafes, ground contact, external control, parameter binding), so
they type against these protocols instead of importing it back: the vehicle module
stays the only one that knows them all, and no import ring runs through it.
"""

from __future__ import annotations

from collections import deque
from typing import Protocol

from quadsitl.flight_software.battery import Battery
from quadsitl.flight_software.controller import Autopilot, CascadedController, Vec
from quadsitl.flight_software.estimator import EstimatorSlot
from quadsitl.flight_software.navigator import Activity
from quadsitl.flight_software.params import ParameterStore
from quadsitl.flight_software.results import Result
from quadsitl.geo import Home
from quadsitl.perturbations.motor_faults import MotorFaults
from quadsitl.physics import Airframe, Fleet
from quadsitl.physics.fleet_slot import FleetSlot
from quadsitl.wire.modes import Mode


class Flight(Protocol):
    """The flight mode and the activity flown in it, and the transitions the other parts
    request (:class:`~quadsitl.flight_software.flight_state.FlightState` carries them out)."""

    @property
    def mode(self) -> Mode: ...
    @property
    def activity(self) -> Activity: ...
    @property
    def mission_speed(self) -> float | None: ...
    @property
    def takeoff_altitude(self) -> float | None: ...
    def enter(self, mode: Mode) -> None: ...
    def hold(self, point: Vec, yaw: float | None = None) -> None: ...
    def fly(self, activity: Activity) -> None: ...
    def plan_return(self, here: Vec, yaw: float) -> None: ...
    def next_return_stage(self) -> None: ...
    def take_motors(self) -> None: ...
    def change_speed(self, speed: float) -> None: ...
    def landing_done(self) -> None: ...


class VehicleView(Protocol):
    """The vehicle's state and commands that its parts use."""

    origin: Home
    home_position: Vec
    params: ParameterStore
    airframe: Airframe
    cascade: CascadedController
    controller: Autopilot
    estimator: EstimatorSlot
    battery: Battery
    motors: MotorFaults
    items_reached: deque[int]
    rotor_cmd: Vec
    substeps: int
    control_period: float
    armed: bool
    armed_at: float
    flew: bool
    landed_at: float | None
    motor_control: bool
    motor_command_time: float

    @property
    def fleet(self) -> Fleet | FleetSlot: ...
    @property
    def flight(self) -> Flight: ...
    @property
    def time(self) -> float: ...
    @property
    def nav_state(self) -> Vec: ...
    @property
    def nav_position(self) -> Vec: ...
    @property
    def on_ground(self) -> bool: ...
    @property
    def crashed(self) -> bool: ...
    def event(self, severity: int, text: str) -> None: ...
    def disarm(self, force: bool = False) -> Result: ...
    def follow_battery(self) -> None: ...
