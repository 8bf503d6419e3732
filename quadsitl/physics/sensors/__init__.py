"""Seeded, batched sensor models: IMU, barometer, magnetometer and GPS, each at its own
rate (equations, parameters and sources: docs/physics.md, "Sensors")."""

from quadsitl.physics.sensors.barometer import BarometerParams
from quadsitl.physics.sensors.gps import GpsParams
from quadsitl.physics.sensors.imu import ImuParams
from quadsitl.physics.sensors.magnetometer import MagnetometerParams
from quadsitl.physics.sensors.suite import SensorParams, SensorSlot, SensorSuite

__all__ = [
    "BarometerParams",
    "GpsParams",
    "ImuParams",
    "MagnetometerParams",
    "SensorParams",
    "SensorSlot",
    "SensorSuite",
]
