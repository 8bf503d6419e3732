"""MAVLink system ids: each vehicle needs its own, and they end at 254 (255 is, by
convention, a ground station's), so no simulator, fleet or training run through the
wire has more vehicles than that."""

MAX_SYSTEM_ID = 254
