"""``quadsitl sim --rerun``: the simulated vehicle streamed to Rerun as it flies.

At most 30 times a wall-clock second, the telemetry the vehicle would send (attitude,
local position, rotor speeds, battery, mission item) is built by the same builders as
the MAVLink telemetry and logged through :class:`LiveLogger`, and once a second its
heartbeat (flight mode and armed state); vehicle events go to the text log. Rotor
speeds are shown as multiples of the airframe's hover speed; the 3-D camera follows
the vehicle.
"""

from __future__ import annotations

from collections.abc import Callable

from quadsitl.mavlink import telemetry as T
from quadsitl.vehicle.vehicle import Vehicle
from quadsitl.viz.live import LiveLogger
from quadsitl.viz.scene import LIVE_PANELS, blueprint, open_recording

RATE = 30.0  # Hz of wall time
BUILDERS = (
    T.build_attitude,
    T.build_attitude_quaternion,
    T.build_local_position_ned,
    T.build_actuator_output_status,
    T.build_battery_status,
    T.build_mission_current,
)
PANELS = (*LIVE_PANELS, "battery_remaining", "mission_item")


class SimView:
    """Spawns a viewer, saves to ``save`` (an .rrd path), or (``web``) serves the web
    viewer on this host and prints its URL; ``notice`` takes the message saying where the
    recording goes when no viewer can be shown."""

    def __init__(
        self,
        vehicle: Vehicle,
        save: str | None = None,
        notice: Callable[[str], None] | None = None,
        web: bool = False,
    ) -> None:
        self.vehicle = vehicle
        layout = blueprint(PANELS, follow=True, whole_range=False)
        self.rec = open_recording(
            "quadsitl_sim",
            save,
            spawn=save is None,
            default_blueprint=layout,
            notice=notice,
            web=web,
        )
        self.logger = LiveLogger(self.rec, hover_rotor=vehicle.airframe.hover_rotor_speed)
        self.next_due = 0.0
        self.next_heartbeat = 0.0

    def tick(self, wall_now: float) -> None:
        if wall_now < self.next_due:
            return
        self.next_due = wall_now + 1.0 / RATE
        if wall_now >= self.next_heartbeat:
            self.next_heartbeat = wall_now + 1.0
            self.logger.message(T.build_heartbeat(self.vehicle), own=True)
        snapshot = T.Snapshot(self.vehicle)
        for build in BUILDERS:
            self.logger.message(build(snapshot), own=True)

    def event(self, text: str) -> None:
        self.logger.text(text)

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()
