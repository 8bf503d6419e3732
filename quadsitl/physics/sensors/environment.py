"""What the sensors measure besides the vehicle's motion: the standard atmosphere and the
Earth's magnetic field at the home position.

The field is the World Magnetic Model (WMM-2020 at epoch 2023.6) on PX4's 10° grid
(``wmm_grid.txt``), interpolated bilinearly as PX4 interpolates it for its estimator: a
flight stack that checks the magnetometer against its own WMM tables sees the field it
expects (EKF2 checks declination, inclination and strength). The grid's own
interpolation error against the full model is about 1° in declination at mid latitudes.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from quadsitl.physics.sensors.processes import Array

# The International Standard Atmosphere, troposphere (ICAO Doc 7488).
ISA_SEA_LEVEL_PRESSURE = 101_325.0  # Pa
ISA_SEA_LEVEL_TEMPERATURE = 288.15  # K
ISA_LAPSE = 0.0065  # K/m
ISA_EXPONENT = 5.25588  # g·M/(R·L)
AIR_GAS_CONSTANT = 287.053  # J/(kg·K)

GRID_STEP = 10.0  # degrees
_GRID = np.loadtxt(Path(__file__).with_name("wmm_grid.txt"))
DECLINATION_GRID = _GRID[0:19] * 1e-4  # rad, east of true north; [latitude, longitude]
INCLINATION_GRID = _GRID[19:38] * 1e-4  # rad, below the horizontal
STRENGTH_GRID = _GRID[38:57] * 1e-4  # gauss


def isa_pressure(altitude: Array) -> Array:
    """Static pressure, Pa, at ``altitude`` m above mean sea level."""
    temperature = isa_temperature(altitude)
    return ISA_SEA_LEVEL_PRESSURE * (temperature / ISA_SEA_LEVEL_TEMPERATURE) ** ISA_EXPONENT


def isa_temperature(altitude: Array) -> Array:
    """Air temperature, K, at ``altitude`` m above mean sea level."""
    return ISA_SEA_LEVEL_TEMPERATURE - ISA_LAPSE * np.asarray(altitude, dtype=np.float64)


def pressure_altitude(pressure: Array) -> Array:
    """m above mean sea level at which the ISA has ``pressure`` Pa (inverse of
    :func:`isa_pressure`)."""
    ratio = (np.asarray(pressure) / ISA_SEA_LEVEL_PRESSURE) ** (1.0 / ISA_EXPONENT)
    return ISA_SEA_LEVEL_TEMPERATURE * (1.0 - ratio) / ISA_LAPSE


def _grid_value(grid: Array, latitude: float, longitude: float) -> float:
    """Bilinear interpolation in a [latitude, longitude] grid, as PX4's
    ``get_table_data``."""
    lat = min(max(latitude, -90.0), 90.0)
    lon = (longitude + 180.0) % 360.0 - 180.0
    row = min(int((lat + 90.0) // GRID_STEP), grid.shape[0] - 2)
    col = min(int((lon + 180.0) // GRID_STEP), grid.shape[1] - 2)
    lat_frac = (lat + 90.0) / GRID_STEP - row
    lon_frac = (lon + 180.0) / GRID_STEP - col
    south = grid[row, col] + lon_frac * (grid[row, col + 1] - grid[row, col])
    north = grid[row + 1, col] + lon_frac * (grid[row + 1, col + 1] - grid[row + 1, col])
    return float(south + lat_frac * (north - south))


def magnetic_elements(latitude: float, longitude: float) -> tuple[float, float, float]:
    """(declination rad, inclination rad, strength gauss) at a place (degrees)."""
    return (
        _grid_value(DECLINATION_GRID, latitude, longitude),
        _grid_value(INCLINATION_GRID, latitude, longitude),
        _grid_value(STRENGTH_GRID, latitude, longitude),
    )


def magnetic_field_enu(latitude: float, longitude: float) -> Array:
    """(3,) gauss, world ENU: the Earth's field at a place (degrees)."""
    declination, inclination, strength = magnetic_elements(latitude, longitude)
    horizontal = strength * math.cos(inclination)
    return np.array(
        [
            horizontal * math.sin(declination),  # east
            horizontal * math.cos(declination),  # north
            -strength * math.sin(inclination),  # up (a positive inclination points down)
        ]
    )
