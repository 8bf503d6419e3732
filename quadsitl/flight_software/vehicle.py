"""One simulated quadrotor with its flight software: arming, modes, missions, offboard,
stick input and failsafes.

Pure: no sockets, no files, no clocks. The MAVLink server calls the command methods
(each returns a :class:`Result`) and :meth:`Vehicle.step`, and reads state, events and
reached mission items back. Local frame ENU, SI units: its origin (``origin``, fixed) is
the start position on the flat ground; home (``home_position``, where RTL returns and
what relative altitudes count from) starts there and can be moved (DO_SET_HOME).

The vehicle assembles its flight software's parts; the mode and the activity flown are
its :class:`~quadsitl.flight_software.flight_state.FlightState`'s, which alone changes them.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from quadsitl import frames
from quadsitl.flight_software import external_control as X
from quadsitl.flight_software import failsafe as FS
from quadsitl.flight_software import mission as M
from quadsitl.flight_software import param_binding as P
from quadsitl.flight_software.battery import Battery
from quadsitl.flight_software.controller import Autopilot, CascadedController, Setpoint, Vec
from quadsitl.flight_software.episodes import MotorEpisodes
from quadsitl.flight_software.estimator import Estimator, EstimatorSlot
from quadsitl.flight_software.failsafe import Failsafes
from quadsitl.flight_software.flight_state import FlightState
from quadsitl.flight_software.mission_runner import MissionRunner
from quadsitl.flight_software.navigator import Activity, Sticks
from quadsitl.flight_software.params import AIRFRAME_NAMES, PARAMETERS, ParameterStore
from quadsitl.flight_software.results import ACCEPTED, Result, Severity, denied
from quadsitl.flight_software.stepping import Stepping, physics_steps_per_period
from quadsitl.geo import MAX_LOCAL_DISTANCE, Home
from quadsitl.perturbations.motor_faults import MotorFaults
from quadsitl.physics import Fleet, get_airframe
from quadsitl.physics import layout as L
from quadsitl.physics.fleet_slot import FleetSlot
from quadsitl.physics.sensors import SensorSlot, SensorSuite
from quadsitl.wire.modes import NEEDS_PILOT, Mode

MOTOR_TIMEOUT = 0.5  # s (simulated) without motor commands: the onboard controller resumes
STICK_TIMEOUT = 0.5  # s (simulated) without MANUAL_CONTROL: sticks centred (COM_RC_LOSS_T)


class Vehicle:
    """The simulated quadrotor. See the module docstring.

    Args:
        airframe: preset name (also settable with the SIM_AIRFRAME parameter).
        home: the start position on the globe: origin of the local frame, and the first
            home position.
        physics_dt: physics step, s.
        control_period: onboard controller period, s (a multiple of ``physics_dt``).
        batch, row: for a vehicle of a group (:mod:`quadsitl.flight_software.group`), the
            group's batch and this vehicle's row in it: its physics, sensors and motor
            command are that row of the group's. Alone (None), it is a batch of one, with
            a physics of its own and sensors at the default noise.
        control_phase: physics steps by which this vehicle's controller runs early (a
            group spreads its vehicles' controllers over the steps of a period).
        estimator: for a vehicle of a group, its row of the group's estimator; alone,
            an estimator of its own. It runs, and the flight software flies on it, when
            the EKF2_EN parameter is 1 (:attr:`nav_state`).
    """

    # Flight state, (re)set by _reset_flight_state.
    armed: bool
    armed_at: float  # s, simulated
    flew: bool  # left the ground since arming
    landed_at: float | None
    motor_control: bool  # rotors commanded by an external controller, not the onboard one
    motor_command_time: float  # s, simulated, of the last external motor command
    sticks: Vec  # (4,) forward, right, up, yaw in [-1, 1], from MANUAL_CONTROL
    stick_time: float  # s, simulated, of the last stick input

    def __init__(
        self,
        airframe: str = "paper",
        home: Home | None = None,
        physics_dt: float = 0.001,
        control_period: float = 0.004,
        autopilot: Autopilot | None = None,
        batch: Stepping | None = None,
        row: int = 0,
        control_phase: int = 0,
        estimator: EstimatorSlot | None = None,
    ) -> None:
        self.origin = home or Home()
        self.home_position = np.zeros(3)  # m, ENU: where home is in the local frame
        self.params = ParameterStore()
        self.params.values["SIM_AIRFRAME"] = float(
            AIRFRAME_NAMES.index(get_airframe(airframe).name)
        )
        self.airframe = get_airframe(airframe)
        self.substeps = physics_steps_per_period(control_period, physics_dt)
        self.batch, self.row = batch or self._batch_of_one(physics_dt), row
        self.fleet: Fleet | FleetSlot = (
            self.batch.physics if batch is None else FleetSlot(batch.physics, row)
        )
        self.sensors = SensorSlot(self.batch.sensors, row)
        self.rotor_cmd = self.batch.rotor_cmd[row]  # rad/s, last command to the motors
        self.control_phase = control_phase % self.substeps
        self.control_period = self.substeps * physics_dt
        # The cascade always exists: the gain parameters tune it, and it flies unless
        # another autopilot (e.g. a trained policy) is passed in.
        self.cascade = CascadedController(self.airframe)
        self.controller: Autopilot = autopilot or self.cascade
        self.estimator = estimator or EstimatorSlot(
            Estimator(self.sensors.suite, self.airframe.gear_height, self.airframe.gravity), 0
        )
        self.battery = Battery()
        self.motors = MotorFaults(self.fleet)
        self.failsafes = Failsafes()
        self.missions = MissionRunner(self)
        self.flight = FlightState(self, self.missions, self.position.copy())
        self.events: deque[tuple[int, str]] = deque(maxlen=100)
        self.items_reached: deque[int] = deque(maxlen=100)
        for spec in PARAMETERS:
            P.apply(self, spec.name)
        self._reset_flight_state()
        self.batch.join(self)

    def _batch_of_one(self, physics_dt: float) -> Stepping:
        physics = Fleet(1, self.airframe, dt=physics_dt)
        sensors = SensorSuite(
            1,
            self.origin.latitude,
            self.origin.longitude,
            self.origin.altitude - self.airframe.gear_height,  # the ground is at z = gear
        )
        hover = self.airframe.hover_rotor_speed
        episodes = MotorEpisodes(physics, self.substeps, hover, None)
        return Stepping(physics, sensors, np.zeros((1, L.N_ROTORS)), self.substeps, episodes)

    # --- state, read by telemetry -----------------------------------------------------
    @property
    def time(self) -> float:
        """Simulated seconds since boot."""
        return self.fleet.time

    @property
    def state(self) -> Vec:
        """(17,) physics state row (layout in :mod:`quadsitl.physics.layout`)."""
        return self.fleet.state[0]

    @property
    def position(self) -> Vec:
        return self.fleet.state[0, L.POS]

    @property
    def nav_state(self) -> Vec:
        """(17,) the state the flight software flies on and reports: the estimate when
        EKF2_EN is 1, else the truth (:attr:`state` itself)."""
        if self.estimator.enabled:
            return self.estimator.state_row(self.state)
        return self.state

    @property
    def nav_position(self) -> Vec:
        """(3,) m, world ENU: the position the flight software knows (:attr:`nav_state`)."""
        return self.nav_state[L.POS]

    @property
    def crashed(self) -> bool:
        return int(self.fleet.contact[0]) == L.CRASHED

    @property
    def on_ground(self) -> bool:
        return int(self.fleet.contact[0]) != L.AIRBORNE

    @property
    def altitude(self) -> float:
        """m above home ground level (centre of mass minus gear height)."""
        return float(self.position[2]) - self.airframe.gear_height

    @property
    def mode(self) -> Mode:
        return self.flight.mode

    @property
    def activity(self) -> Activity:
        return self.flight.activity

    @property
    def mission(self) -> list[M.MissionItem]:
        return self.missions.items

    @property
    def mission_current(self) -> int:
        return self.missions.current

    @property
    def home_altitude(self) -> float:
        """m above mean sea level of home."""
        return self.origin.altitude + float(self.home_position[2])

    @property
    def landed_state(self) -> int:
        return self.flight.landed_state

    # --- commands ---------------------------------------------------------------------
    def arm(self, force: bool = False) -> Result:
        if self.armed:
            return ACCEPTED
        if self.crashed:
            return denied("arming denied: vehicle crashed, reboot or reset it first")
        if not self.on_ground and not force:
            return denied("arming denied: not on the ground")
        if self.mode in NEEDS_PILOT:
            return denied(f"arming denied: {self.mode.name} needs a pilot (RC)")
        self.armed = True
        self.armed_at = self.time
        self.flew = False
        self.controller.reset()
        self.flight.enter(self.mode)
        self.event(Severity.INFO, "armed")
        return ACCEPTED

    def disarm(self, force: bool = False) -> Result:
        if not self.armed:
            return ACCEPTED
        if not self.on_ground and not force:
            return denied("disarming denied: vehicle is flying (use force)")
        self.armed = False
        self.event(Severity.INFO, "disarmed")
        return ACCEPTED

    def set_mode(self, mode: Mode) -> Result:
        return self.flight.set_mode(mode)

    def takeoff(self, altitude: float | None = None) -> Result:
        """Climb to ``altitude`` m above home (None: MIS_TAKEOFF_ALT); see
        :meth:`FlightState.takeoff`."""
        return self.flight.takeoff(altitude)

    def land(self) -> Result:
        return self.set_mode(Mode.LAND)

    def set_home(self, east: float, north: float, up: float) -> Result:
        """Move home to a local point (m; ``up`` above the ground)."""
        point = np.array([east, north, up], dtype=np.float64)
        if not np.isfinite(point).all() or abs(point).max() > MAX_LOCAL_DISTANCE:
            return denied("set home denied: position not finite or too far")
        if up < -1e-6:
            return denied("set home denied: below the ground")
        self.home_position = point
        lat, lon, alt = self.origin.to_global(east, north, up)
        self.event(Severity.INFO, f"home set to {lat:.7f}, {lon:.7f}, {alt:.1f} m")
        return ACCEPTED

    def stick_input(self, forward: float, right: float, up: float, yaw: float) -> None:
        """Joystick deflections (MANUAL_CONTROL, normalised to [-1, 1]); they fly the
        vehicle in POSCTL and ALTCTL and are ignored in the other modes."""
        self.sticks = np.clip(np.nan_to_num([forward, right, up, yaw]), -1.0, 1.0)
        self.stick_time = self.time

    def datalink_lost(self, silence: float) -> None:
        """The ground station went silent (the server measures it on the wall clock)."""
        FS.react(self, Failsafes.datalink_lost(silence, self.params.values))

    def datalink_regained(self) -> None:
        self.event(Severity.INFO, "ground station link regained")

    def return_to_launch(self) -> Result:
        return self.set_mode(Mode.RTL)

    def reposition(
        self, east: float, north: float, up: float, speed: float | None, yaw: float | None
    ) -> Result:
        """Go to a local point (m above the ground; NaN keeps the current coordinate) and
        hold there."""
        return self.flight.reposition(east, north, up, speed, yaw)

    def offboard_setpoint(self, setpoint: Setpoint) -> None:
        """Latest offboard target (world ENU); kept until the next one or a timeout."""
        self.flight.stream_offboard(setpoint)

    def set_param(self, name: str, value: float) -> float:
        """Set a parameter; returns the value stored. ParamError when refused."""
        value = P.check(self, name, value)
        self.params.values[name] = value
        P.apply(self, name)
        return value

    def set_mission(self, items: list[M.MissionItem]) -> Result:
        """Replace the mission (a refused one leaves the old one in place)."""
        result = self.missions.set_items(items)
        if result.ok and self.mode is Mode.MISSION and self.armed:
            self.flight.enter(Mode.LOITER)
        return result

    def set_mission_current(self, seq: int) -> Result:
        result = self.missions.set_current(seq)
        if result.ok and self.mode is Mode.MISSION:
            self.missions.start_item()
        return result

    def reboot(self) -> None:
        """Back to power-on: on the ground at home, disarmed, charged; mission kept."""
        self.fleet.time = 0.0
        self._reset_flight_state()
        self.battery.recharge()
        self.follow_battery()
        self.motors.reset()
        self.failsafes.reset()
        self.sensors.reset()
        self.estimator.restart()
        self.event(Severity.INFO, "rebooted")

    # --- stepping ---------------------------------------------------------------------
    def step(self) -> None:
        """Advance one physics step; the controller runs every ``substeps`` of them."""
        self._alone().step()

    def advance(self) -> None:
        """One control period under external motor control, in one call of the physics
        (:meth:`Stepping.advance <quadsitl.flight_software.stepping.Stepping.advance>`)."""
        self._alone().advance()

    def _alone(self) -> Stepping:
        """The batch, which this vehicle steps for itself when it is alone in it (a
        vehicle of a group of several is stepped by its group, with the others)."""
        if len(self.batch.vehicles) > 1:
            raise RuntimeError("a vehicle of a group is stepped with its group")
        return self.batch

    def drain_battery(self, shaft_power: float, seconds: float) -> None:
        """The rotors drew ``shaft_power`` (W) for ``seconds``: drain the battery, and let
        the rotors' top speed follow its voltage (SIM_BAT_SAG)."""
        self.battery.drain(shaft_power, seconds)
        if self.params["SIM_BAT_SAG"]:
            self.follow_battery()

    def follow_battery(self) -> None:
        """Ω_max of the physics: the airframe's times V / V_full with SIM_BAT_SAG, else the
        airframe's own."""
        scale = self.battery.rotor_speed_scale() if self.params["SIM_BAT_SAG"] else 1.0
        self.fleet.params[0, L.P_OMEGA_MAX] = self.airframe.max_rotor_speed * scale

    def control(self) -> None:
        if self.motor_control and self.time - self.motor_command_time > MOTOR_TIMEOUT:
            X.release_motors(self, "no motor commands")
        if self.estimator.enabled:
            self.estimator.estimator.update()  # at every period, armed or not
        if not self.armed:
            self.rotor_cmd[:] = 0.0
            return
        if self.motor_control:
            return  # the external controller's command stands
        FS.check(self, self.failsafes)
        self.flight.navigate()
        state, activity = self.nav_state, self.flight.activity
        if isinstance(activity, Sticks):
            fresh = self.time - self.stick_time <= STICK_TIMEOUT
            heading = float(frames.euler_from_quat(state[L.QUAT])[2])
            activity.update(self.sticks if fresh else np.zeros(4), heading)
        setpoint = self.flight.setpoint(state)
        self.rotor_cmd[:] = self.controller.rotor_command(state, setpoint, self.control_period)

    # --- helpers ----------------------------------------------------------------------
    def event(self, severity: int, text: str) -> None:
        self.events.append((severity, text))

    def _reset_flight_state(self) -> None:
        rest = np.zeros(L.STATE_SIZE)
        rest[L.I_PZ] = self.airframe.gear_height
        rest[L.I_QW] = 1.0
        self.fleet.reset(rest, contact=L.ON_GROUND)
        self.armed = False
        self.armed_at = 0.0
        self.flew = False
        self.landed_at = None
        self.motor_control = False
        self.motor_command_time = -math.inf
        self.missions.reset_flight()
        self.sticks = np.zeros(4)
        self.stick_time = -math.inf
        self.rotor_cmd[:] = 0.0
        self.controller.reset()
        self.flight.reset(self.position.copy())
