"""The sensor models through the wire: ``quadsitl sim`` on real UDP sends HIGHRES_IMU,
SCALED_PRESSURE and GPS_RAW_INT with noisy, plausible values, and exact ones with
``--sensor-noise 0``."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from quadsitl.geo import Home
from quadsitl.physics.sensors import environment as E
from quadsitl.wire.dialect import mavlink as mav
from tests.conftest import sim_with_client

HOME = Home()
PRESSURE_AT_REST = float(E.isa_pressure(np.array([HOME.altitude]))[0]) / 100  # hPa


def _collect(noise: float) -> dict[str, list]:
    """40 HIGHRES_IMU, 20 SCALED_PRESSURE and 10 GPS_RAW_INT (from the first fix on) of a
    vehicle at rest."""
    with sim_with_client("--logs none --speed 5 --sensor-noise", noise) as (client, _):
        for message_id, hz in (
            (mav.MAVLINK_MSG_ID_HIGHRES_IMU, 50.0),
            (mav.MAVLINK_MSG_ID_SCALED_PRESSURE, 25.0),
            (mav.MAVLINK_MSG_ID_GPS_RAW_INT, 10.0),
        ):
            client.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, message_id, 1e6 / hz)
        wanted = {"HIGHRES_IMU": 40, "SCALED_PRESSURE": 20, "GPS_RAW_INT": 10}
        got: dict[str, list] = {kind: [] for kind in wanted}

        def enough() -> bool:
            return all(len(got[kind]) >= count for kind, count in wanted.items())

        def file(msg) -> None:  # type: ignore[no-untyped-def]
            if msg is None or msg.get_type() not in got:
                return
            kind = msg.get_type()
            # A receiver has no fix until its first measurement comes through the
            # delay line: GPS_RAW_INT says so (fix type 1, lat/lon 0). Collect from the
            # first fix on; once there, the fix must hold at rest.
            if kind == "GPS_RAW_INT" and not got[kind] and msg.fix_type < mav.GPS_FIX_TYPE_3D_FIX:
                return
            got[kind].append(msg)

        deadline = time.monotonic() + 60
        while not enough():
            assert time.monotonic() < deadline, f"timed out waiting for the sensor messages: {got}"
            file(client.pump())
        return got


def test_sim_sends_noisy_plausible_sensor_messages():
    got = _collect(1.0)
    imu = got["HIGHRES_IMU"]
    accel = np.array([(m.xacc, m.yacc, m.zacc) for m in imu])
    gyro = np.array([(m.xgyro, m.ygyro, m.zgyro) for m in imu])
    mag = np.array([(m.xmag, m.ymag, m.zmag) for m in imu])
    # At rest: specific force (0, 0, −g) body FRD, with the IMU's noise (σ ≈ 0.03 m/s²).
    np.testing.assert_allclose(accel.mean(axis=0), [0.0, 0.0, -9.81], atol=0.1)
    assert 0.005 < accel[:, 2].std() < 0.2
    assert 0.0005 < gyro.std() < 0.02  # rad/s (σ ≈ 0.003)
    # The Earth's field at home (WMM): 0.48 gauss, 63° down, with noise (σ ≈ 0.004 G).
    strength = np.linalg.norm(mag, axis=1)
    assert strength.mean() == pytest.approx(0.482, abs=0.02) and strength.std() > 0.0005
    assert math.degrees(math.asin(mag[:, 2].mean() / strength.mean())) == pytest.approx(63.1, abs=2)
    assert all(m.fields_updated & 0x3F for m in imu)  # accel and gyro: sampled at 250 Hz
    pressure = np.array([m.press_abs for m in got["SCALED_PRESSURE"]])  # hPa
    assert pressure.mean() == pytest.approx(PRESSURE_AT_REST, abs=0.3)  # ≈ 2.5 m
    assert pressure.std() > 0.001  # 1 Pa noise
    gps = got["GPS_RAW_INT"]
    assert all(m.fix_type == mav.GPS_FIX_TYPE_3D_FIX for m in gps)
    lat = np.array([m.lat for m in gps]) * 1e-7
    lon = np.array([m.lon for m in gps]) * 1e-7
    north = np.radians(lat - HOME.latitude) * 6_378_137.0
    east = np.radians(lon - HOME.longitude) * 6_378_137.0 * math.cos(math.radians(HOME.latitude))
    assert np.all(np.hypot(north, east) < 15.0)  # within 6 σ of the settling accuracy
    assert len(set(lat)) > 1  # noisy
    for m in gps:
        assert 6 <= m.satellites_visible <= 14
        assert 400 <= m.h_acc <= 2600 and m.v_acc > m.h_acc  # mm, settling from 2.5 m
        assert m.eph == pytest.approx(m.h_acc / 6, abs=2)  # HDOP × 100 = σ/UERE × 100


def test_sensor_noise_zero_sends_the_truth():
    got = _collect(0.0)
    for m in got["HIGHRES_IMU"]:
        assert (m.xacc, m.yacc, m.zacc) == pytest.approx((0.0, 0.0, -9.81), abs=1e-5)  # float32
        assert (m.xgyro, m.ygyro, m.zgyro) == (0.0, 0.0, 0.0)
    for m in got["SCALED_PRESSURE"]:
        assert m.press_abs == pytest.approx(PRESSURE_AT_REST, abs=1e-4)  # float32 hPa
    for m in got["GPS_RAW_INT"]:
        assert (m.lat, m.lon) == (round(HOME.latitude * 1e7), round(HOME.longitude * 1e7))
        assert m.h_acc == 0
