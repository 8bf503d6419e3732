"""The mission executor: which item is current, what flying it means, when it is done.

PX4 keeps its commander, navigator and mission apart; here the vehicle's
:class:`~quadsitl.flight_software.flight_state.FlightState` owns modes and activities and this
class sequences a mission's items for it: a flown item becomes an activity (a leg, a
take-off, a landing, an orbit, a return), jumps and speed changes act at once, payload
items are skipped with a message. State for the ground station: ``current``,
``started``, ``finished``, and the reached items the vehicle reports.
"""

from __future__ import annotations

import math

import numpy as np

from quadsitl import frames
from quadsitl.flight_software import guidance as G
from quadsitl.flight_software import mission as M
from quadsitl.flight_software.controller import Vec
from quadsitl.flight_software.navigator import Hold, Land, Leg, Orbit
from quadsitl.flight_software.results import ACCEPTED, Result, Severity, denied
from quadsitl.flight_software.view import VehicleView


class MissionRunner:
    """Runs ``items`` on ``vehicle`` while it is in MISSION mode."""

    def __init__(self, vehicle: VehicleView) -> None:
        self.v = vehicle
        self.items: list[M.MissionItem] = []
        self.current = 0
        self.started = False  # MISSION mode entered since the items were set
        self.finished = False  # the last item done
        self.jumps_done: dict[int, int] = {}  # DO_JUMP item -> jumps taken
        self.land_after_leg = False
        self.hold_until: float | None = None  # s, simulated: end of the item's hold
        self.target: Vec | None = None  # (3,) m, ENU, of the item being flown

    # --- what the ground station changes ------------------------------------------------
    def set_items(self, items: list[M.MissionItem]) -> Result:
        problem = M.check_mission(items)
        if problem:
            return denied(problem)
        self.items = list(items)
        self.restart()
        self.started = False
        return ACCEPTED

    def set_current(self, seq: int) -> Result:
        if not 0 <= seq < max(len(self.items), 1):
            return denied(f"mission item {seq} does not exist")
        self.current = seq
        self.finished = False
        return ACCEPTED

    def restart(self) -> None:
        self.current = 0
        self.finished = False
        self.jumps_done = {}

    def reset_flight(self) -> None:
        """After a reboot: the items stay, their progress does not."""
        self.started = False
        self.finished = False
        self.jumps_done = {}
        self.land_after_leg = False
        self.hold_until = None
        self.target = None

    # --- flying -------------------------------------------------------------------------
    def start_item(self) -> None:
        """Make the current item the vehicle's activity (after acting on the items that
        are not flown); at the end, finish."""
        v = self.v
        here = v.nav_position.copy()
        self.hold_until = None
        self._run_sequence_items()
        if self.current >= len(self.items):
            self._finish(here)
            return
        item = self.items[self.current]
        gear = v.airframe.gear_height
        home_up = float(v.home_position[2])
        east, north, up = item.target(v.origin, home_up, (here[0], here[1], here[2] - gear))
        target = np.array([east, north, up + gear])
        yaw_deg = item.param(4, math.nan)
        yaw = None if math.isnan(yaw_deg) else float(frames.yaw_ned_to_enu(math.radians(yaw_deg)))
        radius = item.param(2) if item.command == M.NAV_WAYPOINT and item.param(2) > 0 else None
        limits, acceptance = G.limits(v), v.params["NAV_ACC_RAD"]
        if item.command == M.NAV_TAKEOFF:
            target[:2] = here[:2]
            limits = G.limits(v, climb=v.params["MPC_TKO_SPEED"])
            v.flight.fly(Leg(here, target, limits, 0.2, yaw))
        elif item.command == M.NAV_LAND:
            target[2] = here[2]
            start = self._leg_start(here)
            v.flight.fly(Leg(start, target, limits, acceptance, yaw, face_travel=True))
        elif item.command == M.NAV_RETURN_TO_LAUNCH:
            v.flight.plan_return(here, 0.0)
        else:  # waypoints and loiters fly there first
            start = self._leg_start(here)
            v.flight.fly(Leg(start, target, limits, radius or acceptance, yaw, True))
        self.land_after_leg = item.command == M.NAV_LAND
        self.target = target

    def progress(self) -> None:
        """Each control tick in MISSION mode: move on when the current item is done."""
        v = self.v
        item = self.items[self.current]
        if item.command == M.NAV_RETURN_TO_LAUNCH:
            v.flight.next_return_stage()
            return  # landing completes it (the flight state calls item_reached)
        activity = v.flight.activity
        if not activity.done or isinstance(activity, Land):
            return
        if self.land_after_leg and isinstance(activity, Leg):
            v.flight.fly(Land(activity.end, v.params["MPC_LAND_SPEED"], activity.yaw))
            return
        if isinstance(activity, Leg) and item.command == M.NAV_LOITER_TURNS:
            cruise = G.limits(v).cruise_xy
            here = v.nav_position
            v.flight.fly(Orbit(activity.end, item.param(3, 1.0), item.param1, cruise, here))
            return
        if item.command == M.NAV_LOITER_UNLIM:
            return  # holds until the mission is changed
        hold = item.param(1) if item.command in (M.NAV_WAYPOINT, M.NAV_LOITER_TIME) else 0.0
        if self.hold_until is None:
            self.hold_until = v.time + max(hold, 0.0)
            end = activity.end if isinstance(activity, Leg) else v.nav_position.copy()
            stay = Hold(end, activity.yaw)
            stay.done = True
            v.flight.fly(stay)
        if v.time >= self.hold_until:
            self.item_reached()

    def item_reached(self) -> None:
        self.v.items_reached.append(self.current)
        self.current += 1
        if self.current < len(self.items) or (self.v.armed and not self.v.on_ground):
            self.start_item()  # the next item, or (at the end, in the air) hold
        else:
            self._finish(self.v.nav_position.copy())

    def _run_sequence_items(self) -> None:
        """Act on the items that are not flown (jumps, speed changes, payload) until the
        current item is one to fly or the mission ends."""
        v = self.v
        steps = 0
        while self.current < len(self.items):
            seq = self.current
            item = self.items[seq]
            if item.command in M.FLOWN:
                return
            steps += 1
            if steps > len(self.items) + 1:  # a loop of jumps with nothing to fly
                v.event(Severity.WARNING, "mission loops without a flown item: stopped")
                self.current = len(self.items)
                return
            if item.command == M.DO_JUMP and self._jump(seq, item):
                continue
            if item.command == M.DO_CHANGE_SPEED:
                v.flight.change_speed(item.param2)
            elif item.command in M.PAYLOAD:
                v.event(Severity.INFO, f"mission item {seq}: {item.name} skipped (no payload)")
            v.items_reached.append(seq)
            self.current += 1

    def _jump(self, seq: int, item: M.MissionItem) -> bool:
        """Take the jump if it has repeats left; False when they are used up."""
        done, repeats = self.jumps_done.get(seq, 0), M.jump_repeats(item)
        if done >= repeats:
            return False
        self.jumps_done[seq] = done + 1
        target = round(item.param1)
        self.v.event(Severity.INFO, f"mission item {seq}: jump to {target} ({done + 1}/{repeats})")
        self.current = target
        return True

    def _finish(self, here: Vec) -> None:
        v = self.v
        self.current = max(len(self.items) - 1, 0)
        self.finished = True
        if v.armed and not v.on_ground:  # hold at the last item's point, as PX4 does
            v.event(Severity.INFO, "mission finished: holding")
            v.flight.hold(self._leg_start(here))
        else:
            v.event(Severity.INFO, "mission finished")

    def _near_target(self, here: Vec) -> bool:
        return self.target is not None and float(np.linalg.norm(self.target - here)) < 2.0

    def _leg_start(self, here: Vec) -> Vec:
        """Where the leg starts: the last item's target if the vehicle is near it (so the
        track follows the planned line, as PX4 does), else the vehicle's position."""
        target = self.target
        return target if target is not None and self._near_target(here) else here
