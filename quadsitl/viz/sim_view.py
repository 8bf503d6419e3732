"""``quadsitl sim --rerun``: the simulated vehicle streamed to Rerun as it flies.

At most 30 times a wall-clock second, the telemetry the vehicle would send (attitude,
local position, rotor speeds, battery) is built by the same builders as the MAVLink
telemetry and logged through :class:`LiveLogger`; vehicle events go to the text log.
"""

from __future__ import annotations

from collections.abc import Callable

from quadsitl.mavlink import telemetry as T
from quadsitl.vehicle.vehicle import Vehicle
from quadsitl.viz.live import LiveLogger
from quadsitl.viz.scene import open_recording

RATE = 30.0  # Hz of wall time
BUILDERS = (
    T.build_attitude,
    T.build_attitude_quaternion,
    T.build_local_position_ned,
    T.build_actuator_output_status,
    T.build_battery_status,
)


class SimView:
    """Spawns a viewer, or saves to ``save`` (an .rrd path); ``notice`` takes the message
    saying where the recording goes when no viewer can be shown."""

    def __init__(
        self,
        vehicle: Vehicle,
        save: str | None = None,
        notice: Callable[[str], None] | None = None,
    ) -> None:
        self.vehicle = vehicle
        self.rec = open_recording("quadsitl_sim", save, spawn=save is None, notice=notice)
        self.logger = LiveLogger(self.rec)
        self.next_due = 0.0

    def tick(self, wall_now: float) -> None:
        if wall_now < self.next_due:
            return
        self.next_due = wall_now + 1.0 / RATE
        snapshot = T.Snapshot(self.vehicle)
        for build in BUILDERS:
            self.logger.message(build(snapshot), own=True)

    def event(self, text: str) -> None:
        self.logger.text(text)

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()
