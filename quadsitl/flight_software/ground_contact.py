"""What the flight software does about the ground: landing and crash events, and the
automatic disarms on the ground (PX4's COM_DISARM_LAND and COM_DISARM_PRFLT)."""

from __future__ import annotations

from quadsitl.flight_software.navigator import Land
from quadsitl.flight_software.results import Severity
from quadsitl.flight_software.view import VehicleView
from quadsitl.physics import layout as L


def on_ground_timers(v: VehicleView) -> None:
    """Disarm after landing (COM_DISARM_LAND) or without a take-off (COM_DISARM_PRFLT)."""
    activity = v.flight.activity
    if isinstance(activity, Land) and v.armed:
        activity.done = True
        if v.landed_at is None:
            v.landed_at = v.time
        if v.time - v.landed_at >= v.params["COM_DISARM_LAND"]:
            v.disarm()
            v.event(Severity.INFO, "landed: disarmed")
            v.flight.landing_done()
        return
    limit = v.params["COM_DISARM_PRFLT"]
    if v.armed and limit > 0 and v.time - v.armed_at > limit and not v.flew:
        v.disarm()
        v.event(Severity.NOTICE, f"disarmed: no take-off within {limit:g} s")


def watch_contact(v: VehicleView, before: int) -> None:
    """Events and flight state when the ground contact changes (after a physics step)."""
    after = int(v.fleet.contact[0])
    if after == before:
        return
    if after == L.CRASHED:
        v.armed = False
        v.rotor_cmd[:] = 0.0
        speed = float(v.fleet.touchdown_speed[0])
        v.event(Severity.CRITICAL, f"crashed (touchdown {speed:.1f} m/s): reboot to fly again")
    elif after == L.ON_GROUND:
        v.landed_at = v.time
        v.event(Severity.INFO, "landed")
    elif after == L.AIRBORNE:
        v.flew = True
        v.landed_at = None
        v.event(Severity.INFO, "took off")
