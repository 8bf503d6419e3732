"""The vehicles that autopilots fly, as the task engine sees a fleet: their state in the
task's frame, stepped by letting the autopilots fly, reset by flying each to its
episode's start under the autopilot's own position control.

A reset does not restart an autopilot: it arms and enters offboard if need be (a stream
of setpoints first, as PX4 asks), then streams position setpoints to the drawn start
until the vehicle has settled there, in simulated time; every vehicle being reset flies
at once, the others wait (in lockstep, they are paused). An autopilot that failed, or
one the env asks to start again (a seeded reset), gets a new process first: the one
fallback, said in each vehicle's ``reports``.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from quadsitl import frames
from quadsitl.envs import setpoints
from quadsitl.envs.autopilot_link import AutopilotError, Autopilots
from quadsitl.physics import get_airframe
from quadsitl.physics import layout as L
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.modes import MAIN_OFFBOARD, Mode

RESET_LIMIT_S = 30.0  # simulated s a reset may fly before it starts the episode anyway
STREAM_FIRST_S = 1.0  # simulated s of setpoints before asking for OFFBOARD (PX4 >= 1.14)
SETTLED_POSITION = 0.05  # m from the drawn start by the autopilot's estimate ...
SETTLED_SPEED = 0.1  # ... and m/s, rad/s: the start is reached ...
SETTLED_FOR_S = 0.2  # ... for this long
ARM_LIMIT_S = 60.0  # simulated s a new autopilot may refuse to arm (its estimator converging)
START_TRIES = 2  # new processes a reset tries before it gives up on an autopilot
CLIMB_BEFORE_TURN_M = 0.5  # m below its start: a reset's flight holds the heading it had
TILT_REACHED = 0.03  # rad from the drawn attitude, by the estimate: the start is reached
TILT_LIMIT_S = 1.0  # simulated s a reset may tilt before the episode starts anyway
ARDUCOPTER_GUIDED = 4  # ArduCopter's mode number (ArduCopter/mode.h)
TAKEOFF_BELOW_M = 0.3  # m above its local origin: an ArduCopter lower is taken off first
TAKEOFF_NEAR_M = 0.5  # m below the take-off height: GUIDED's setpoints may come from there
LEVEL = np.zeros(L.STATE_SIZE)
LEVEL[L.I_QW] = 1.0  # a start state with no attitude drawn: level, facing east


class OffboardFleet:
    """The vehicles of ``autopilots`` in the task's frame (origin ``altitude`` above the
    ground where each took off). The env sets ``active`` (the rows the next step flies)
    and ``restart`` (row -> why its next reset starts a new autopilot)."""

    def __init__(self, autopilots: Autopilots, control_period: float, altitude: float) -> None:
        self.autopilots, self.physical = autopilots, autopilots.fleet
        self.n = self.physical.n
        self.control_period = control_period
        self.origin = np.array([0.0, 0.0, altitude])
        self.params = self.physical.params
        self.contact = self.physical.contact
        self.touchdown_speed = self.physical.touchdown_speed
        self.wind_state = self.physical.wind_state
        self.state = np.zeros_like(self.physical.state)
        self.active = np.ones(self.n, bool)
        self.restart: dict[int, str] = {}
        self.reports: list[dict[str, Any]] = [{} for _ in range(self.n)]
        self.sync()

    @property
    def hover_rotor_speed(self) -> NDArray[np.float64]:
        return self.physical.hover_rotor_speed

    @property
    def failed(self) -> list[str | None]:
        """Why each row's autopilot failed (None: it flies); a reset starts it again."""
        return [pilot.failure for pilot in self.autopilots.pilots]

    @property
    def windy(self) -> bool:
        return False

    def sync(self) -> None:
        self.state[:] = self.physical.state
        self.state[:, L.POS] -= self.origin

    def step(self, rotor_cmd: ArrayLike, n_substeps: int = 1) -> None:
        """The setpoints were sent (the env's step); the autopilots of the active rows fly
        ``n_substeps`` rounds. The engine's rotor commands are not used: theirs are."""
        span = n_substeps * self.autopilots.side.frame_us * 1e-6
        self.autopilots.advance(span, np.flatnonzero(self.active).tolist())
        self.sync()

    # --- the estimate -------------------------------------------------------------------
    def estimated_state(self) -> NDArray[np.float64]:
        """The state rows of what each autopilot estimates (in the task's frame); the
        rotor speeds, which it does not report, from the simulator (as ESC telemetry)."""
        state = self.state.copy()
        for row, pilot in enumerate(self.autopilots.pilots):
            e = pilot.estimate
            state[row, L.POS] = self.autopilots.estimated_position(row) - self.origin
            state[row, L.VEL] = frames.ned_to_enu(np.array(e.velocity))
            state[row, L.QUAT] = frames.quat_ned_frd_to_enu_flu(np.array(e.quaternion))
            state[row, L.RATES] = frames.frd_to_flu(np.array(e.rates))
        return state

    # --- resets ---------------------------------------------------------------------
    def reset(
        self, state: ArrayLike | None = None, contact: Any = L.AIRBORNE, mask: Any = None
    ) -> None:
        rows = list(range(self.n)) if mask is None else np.flatnonzero(mask).tolist()
        drawn = np.tile(LEVEL, (len(rows), 1)) if state is None else np.asarray(state)
        starts = np.zeros((len(rows), 3)) if state is None else drawn[:, L.POS]
        targets = dict(zip(rows, starts + self.origin, strict=True))
        attitudes = dict(zip(rows, drawn[:, L.QUAT], strict=True))
        wall = time.monotonic()
        began = {row: self.autopilots.time_us(row) for row in rows}
        restarted = self._restart_failed(rows)
        for row in rows:
            if row in restarted:
                began[row] = self.autopilots.time_us(row)
        yaws = {row: float(frames.euler_from_quat(q)[2]) for row, q in attitudes.items()}
        settled = self._fly_to(targets, began, yaws)
        tilted = self._tilt_to(attitudes)
        for row in rows:
            position = self.physical.state[row, L.POS]
            self.reports[row] = {
                "simulated_s": (self.autopilots.time_us(row) - began[row]) * 1e-6,
                "wall_s": time.monotonic() - wall,
                "position_error_m": float(np.linalg.norm(position - targets[row])),
                "attitude_error_rad": _angle(self.physical.state[row, L.QUAT], attitudes[row]),
                "estimate_error_m": float(
                    np.linalg.norm(self.autopilots.estimated_position(row) - position)
                ),
                "reached": settled[row] >= SETTLED_FOR_S and tilted[row],
                "restarted": restarted.get(row),
            }
        self.sync()

    def _restart_failed(self, rows: list[int]) -> dict[int, str]:
        """Start new autopilots for the rows that failed or are asked to; row -> why."""
        why: dict[int, str] = {}
        for row in rows:
            pilot = self.autopilots.pilots[row]
            failure = pilot.failure or pilot.exited()
            reason = self.restart.pop(row, None)
            if not self.autopilots.pilots[row].flown:
                reason = None  # a new process already: it has not flown since it started
            if failure or reason:
                why[row] = str(failure or reason)
        todo = list(why)
        for _ in range(START_TRIES):
            todo = self.autopilots.start(todo) if todo else []
        if todo:
            failures = {row: self.autopilots.pilots[row].failure for row in todo}
            raise AutopilotError(f"autopilots could not be started again: {failures}")
        return why

    def _fly_to(
        self, targets: dict[int, NDArray], began: dict[int, int], yaws: dict[int, float]
    ) -> dict[int, float]:
        """Fly each row to its target (the simulator's ENU, m), facing its yaw (ENU, rad),
        until settled there; how long each was settled at the end (simulated s)."""
        self._offboard(list(targets))
        if self.autopilots.stack == "ardupilot":
            self._take_off(targets)
        settled = dict.fromkeys(targets, 0.0)
        flying = list(targets)
        heading = {row: self._estimated_yaw(row) for row in flying}  # held while climbing
        while flying:
            for row in flying:
                local = targets[row] - self.autopilots.pilots[row].local_origin
                # Climb first, then turn: PX4 aligns its heading to the magnetometer again
                # once airborne, and a vehicle turning fast meanwhile (90°/s) was left with
                # a heading 7° off, which its in-flight fusion did not take back.
                below = targets[row][2] - self.autopilots.estimated_position(row)[2]
                yaw = heading[row] if below > CLIMB_BEFORE_TURN_M else yaws[row]
                self._send(row, setpoints.position_message, local, yaw)
            self._fly_period(flying, "while a reset flew them")
            for row in flying:
                # There by the autopilot's own estimate (all its position control can
                # reach), and still in truth.
                s, there = self.physical.state[row], self.autopilots.estimated_position(row)
                still = max(np.linalg.norm(s[L.VEL]), np.linalg.norm(s[L.RATES]))
                near = np.linalg.norm(there - targets[row]) < SETTLED_POSITION
                ok = near and still < SETTLED_SPEED
                settled[row] = settled[row] + self.control_period if ok else 0.0
            flying = [
                row for row in flying
                if settled[row] < SETTLED_FOR_S
                and (self.autopilots.time_us(row) - began[row]) * 1e-6 < RESET_LIMIT_S
            ]  # fmt: skip
        return settled

    def _tilt_to(self, attitudes: dict[int, NDArray]) -> dict[int, bool]:
        """Tilt each row settled at its start to its drawn attitude (body FLU in ENU) by
        attitude setpoints at hover thrust (more as it tilts: its height held) until its
        estimate is within TILT_REACHED of it, at most TILT_LIMIT_S of simulated time;
        whether each got there (a level start has nothing to do)."""
        hover = get_airframe(self.autopilots.airframe).hover_thrust_fraction
        reached = {row: _tilt(q) < TILT_REACHED for row, q in attitudes.items()}
        tilting = [row for row in attitudes if not reached[row]]
        began = {row: self.autopilots.time_us(row) for row in tilting}
        while tilting:
            for row in tilting:
                q = attitudes[row]
                lift = hover / max(math.cos(_tilt(q)), 0.5)
                self._send(row, setpoints.attitude_message, q, min(lift, 1.0))
            self._fly_period(tilting, "while a reset tilted them")
            for row in tilting:
                estimate = np.array(self.autopilots.pilots[row].estimate.quaternion)
                seen = frames.quat_ned_frd_to_enu_flu(estimate)
                reached[row] = _angle(seen, attitudes[row]) < TILT_REACHED
            tilting = [
                row for row in tilting
                if not reached[row]
                and (self.autopilots.time_us(row) - began[row]) * 1e-6 < TILT_LIMIT_S
            ]  # fmt: skip
        return reached

    def _estimated_yaw(self, row: int) -> float:
        """The heading row's autopilot estimates (ENU yaw, rad)."""
        q = np.array(self.autopilots.pilots[row].estimate.quaternion)
        return float(frames.euler_from_quat(frames.quat_ned_frd_to_enu_flu(q))[2])

    def _send(self, row: int, make: Any, *args: Any) -> None:
        pilot = self.autopilots.pilots[row]
        ms = self.autopilots.time_us(row) // 1000
        pilot.send(make(pilot.mav, *args, ms, pilot.system_id))

    def _offboard(self, rows: list[int]) -> None:
        """Armed and in the offboard mode (PX4's OFFBOARD, ArduCopter's GUIDED), holding
        where each is: a stream of setpoints first (PX4 enters OFFBOARD only while they
        come), then the mode and arming asked for each simulated second until every
        autopilot takes them (one just started refuses until its estimator has
        converged: PX4's in ~15 s, ArduCopter's once it uses GPS, ~45 s)."""
        pilots = self.autopilots.pilots
        ardupilot = self.autopilots.stack == "ardupilot"
        custom = ARDUCOPTER_GUIDED if ardupilot else Mode.OFFBOARD.custom_mode
        mode_params = (float(ARDUCOPTER_GUIDED), 0.0) if ardupilot else (MAIN_OFFBOARD, 0.0)
        began = {row: self.autopilots.time_us(row) for row in rows}
        accepted = mav.MAV_RESULT_ACCEPTED
        results: dict[int, tuple[int, int]] = {}
        rows = [
            r for r in rows
            if not (pilots[r].estimate.armed and pilots[r].estimate.custom_mode == custom)
        ]  # fmt: skip
        while rows:
            late = [r for r in rows if self.autopilots.time_us(r) - began[r] > ARM_LIMIT_S * 1e6]
            if late:
                raise AutopilotError(
                    f"autopilots refused offboard or arming for {ARM_LIMIT_S:g} simulated s "
                    f"(row: (mode, arm) results): { {r: results.get(r) for r in late} }"
                )
            for _ in range(math.ceil(STREAM_FIRST_S / self.control_period)):
                for row in rows:
                    here = self.physical.state[row, L.POS] - pilots[row].local_origin
                    self._send(row, setpoints.position_message, here, self._estimated_yaw(row))
                self.autopilots.advance(self.control_period, rows)
            for row in rows:
                if not pilots[row].estimate.armed:  # at rest on the ground: measure again
                    self.autopilots.measure_origin(row)
            mode = self.autopilots.command(
                rows, mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, *mode_params
            )
            arm = self.autopilots.command(rows, mav.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
            results = {r: (mode[r], arm[r]) for r in rows}
            rows = [r for r in rows if results[r] != (accepted, accepted)]

    def _take_off(self, targets: dict[int, NDArray]) -> None:
        """ArduCopter flies GUIDED's position setpoints only once airborne, and a setpoint
        sent while it takes off ends the take-off on the ground: each row on the ground
        (less than TAKEOFF_BELOW_M above its local origin, by its estimate) is sent
        MAV_CMD_NAV_TAKEOFF to its target's height above home, and flown without
        setpoints until it is within TAKEOFF_NEAR_M of that height (at most
        RESET_LIMIT_S)."""
        climbs: dict[int, float] = {}
        for row, target in targets.items():
            origin = self.autopilots.pilots[row].local_origin
            if self.autopilots.estimated_position(row)[2] - origin[2] < TAKEOFF_BELOW_M:
                climbs[row] = float(target[2] - origin[2])
                self.autopilots.command([row], mav.MAV_CMD_NAV_TAKEOFF, *[0.0] * 6, climbs[row])
        began = {row: self.autopilots.time_us(row) for row in climbs}
        rising = list(climbs)
        while rising:
            self._fly_period(rising, "while taking off")
            rising = [
                row for row in rising
                if self._height(row) < climbs[row] - TAKEOFF_NEAR_M
                and (self.autopilots.time_us(row) - began[row]) * 1e-6 < RESET_LIMIT_S
            ]  # fmt: skip

    def _fly_period(self, rows: list[int], doing: str) -> None:
        """Let ``rows`` fly one control period; AutopilotError naming those that failed
        ``doing`` it (a reset cannot finish without them)."""
        failed = self.autopilots.advance(self.control_period, rows)
        if failed:
            failures = {row: self.autopilots.pilots[row].failure for row in failed}
            raise AutopilotError(f"autopilots failed {doing}: {failures}")

    def _height(self, row: int) -> float:
        """Row's height above its local origin, by its autopilot's estimate (m)."""
        return float(
            self.autopilots.estimated_position(row)[2] - self.autopilots.pilots[row].local_origin[2]
        )

    def set_wind(self, *args: Any, **kwargs: Any) -> None:
        raise ValueError("weather is not available through an autopilot yet")

    def set_ground_effect(self, on: bool, mask: Any = None) -> None:
        raise ValueError("ground effect is not available through an autopilot yet")

    def set_motor_efficiency(self, efficiency: ArrayLike, mask: Any = None) -> None:
        raise ValueError("motor faults are not available through an autopilot yet")


def _tilt(q: NDArray) -> float:
    """How far (rad) the attitude ``q`` (body FLU in ENU) tilts the body's up from up."""
    x, y = float(q[L.I_QX - L.I_QW]), float(q[L.I_QY - L.I_QW])
    up_z = 1.0 - 2.0 * (x * x + y * y)  # the body's up, seen from the world's up
    return math.acos(min(1.0, max(-1.0, up_z)))


def _angle(p: NDArray, q: NDArray) -> float:
    """The angle (rad) of the rotation between the attitudes ``p`` and ``q``."""
    return 2.0 * math.acos(min(1.0, abs(float(np.dot(p, q)))))
