"""``quadsitl companion``: a setpoint policy flying any PX4 or ArduPilot over MAVLink, as
a companion computer would (docs/autopilots.md, "Fly a trained policy as a companion")."""
