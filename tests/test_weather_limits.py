"""Weather has physical limits, wherever it enters (the Python API, the envs' options and
their randomisation, the command line), and the telemetry never overflows a wire field,
whatever the physics holds."""

from __future__ import annotations

import math
import re

import gymnasium as gym
import numpy as np
import pytest

import quadsitl  # noqa: F401  (registers the envs)
from quadsitl.cli import _build_parser
from quadsitl.command_line.sim_setup import flight_stack_config, sim_config
from quadsitl.flight_software.params import SPECS
from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.perturbations.randomization import WindDraw
from quadsitl.physics import layout as L
from quadsitl.physics.wind import MAX_GUST_SPEED, MAX_SIGMA_W, MAX_WIND_SPEED, Gust, Wind
from quadsitl.simulator import telemetry as T
from quadsitl.simulator.snapshot import Snapshot
from quadsitl.simulator.telemetry_status import build_heartbeat
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.dialect import mavlink as mav
from tests.conftest import refused_here

# --- the limits -------------------------------------------------------------------------


def test_weather_beyond_its_limits_is_refused_naming_the_limit():
    for make, limit in (
        (lambda: Wind(speed=1e9), f"at most {MAX_WIND_SPEED:g} m/s"),
        (lambda: Wind(speed=MAX_WIND_SPEED + 0.1), f"at most {MAX_WIND_SPEED:g} m/s"),
        (lambda: Wind(turbulence=1e9), f"at most {MAX_SIGMA_W:g} m/s"),
        (lambda: Gust(amplitude=(0.0, 0.0, 1e9), length=5.0), f"at most {MAX_GUST_SPEED:g}"),
        (lambda: Gust(amplitude=(40.0, 40.0, 0.0), length=5.0), f"at most {MAX_GUST_SPEED:g}"),
        (lambda: WindDraw(speed=(0.0, 1e9)), f"at most {MAX_WIND_SPEED:g} m/s"),
    ):
        with pytest.raises(ValueError, match=re.escape(limit)) as error:
            make()
        assert "\n" not in str(error.value)
    # the limits themselves are weather
    Wind(speed=MAX_WIND_SPEED, turbulence=MAX_SIGMA_W, gust=Gust((MAX_GUST_SPEED, 0, 0), 5.0))
    WindDraw(speed=(0.0, MAX_WIND_SPEED))
    # a ground station's SIM_WIND_* range is the same
    assert SPECS["SIM_WIND_SPD"].maximum == MAX_WIND_SPEED
    assert SPECS["SIM_WIND_TURB"].maximum == MAX_SIGMA_W


@pytest.mark.parametrize(
    ("options", "says"),
    [
        ({"wind": {"speed": 1e9}}, f"at most {MAX_WIND_SPEED:g} m/s"),
        ({"wind": {"turbulence": 1e9}}, f"at most {MAX_SIGMA_W:g} m/s"),
        ({"randomize": {"wind": {"speed": (0, 1e9)}}}, f"at most {MAX_WIND_SPEED:g} m/s"),
        ({"randomize": {"wind": {"turbulence": [None, 1e9]}}}, f"at most {MAX_SIGMA_W:g}"),
    ],
    ids=["speed", "turbulence", "randomized-speed", "randomized-turbulence"],
)
def test_env_options_beyond_the_limits_are_refused_at_make(options, says):
    """``gym.make(..., wind={"speed": 1e9})`` used to be accepted and its first step
    returned inf observations."""
    with pytest.raises(ValueError, match=re.escape(says)):
        gym.make("QuadSITL/Hover-v1", **options)


def test_the_strongest_weather_accepted_flies_finite():
    """At the limits (the strongest mean wind, turbulence and gust; randomised, the
    strongest wind speed) the first steps' observations stay finite."""
    gust = Gust(amplitude=(0.0, 0.0, MAX_GUST_SPEED), length=0.5, hold=math.inf)
    strongest = {
        "speed": MAX_WIND_SPEED,
        "from_deg": 90.0,
        "turbulence": MAX_SIGMA_W,
        "gust": gust,
    }
    for options in (
        {"wind": strongest},
        {"randomize": {"wind": {"speed": (MAX_WIND_SPEED, MAX_WIND_SPEED)}}},
    ):
        env = gym.make("QuadSITL/Hover-v1", **options)
        obs, _ = env.reset(seed=1)
        for _ in range(50):
            obs, *_ = env.step(np.zeros(4, np.float32))
            assert np.isfinite(obs).all()
        env.close()


# --- the command line -------------------------------------------------------------------


@pytest.mark.parametrize(
    ("option", "value", "says"),
    [
        ("--wind", "1e9,0", f"at most {MAX_WIND_SPEED:g} m/s"),
        ("--turbulence", "1e9", f"at most {MAX_SIGMA_W:g} m/s"),
    ],
)
def test_sim_refuses_weather_beyond_the_limits_before_it_starts(option, value, says):
    """``quadsitl sim --wind 1e9,0`` used to start and then die in telemetry packing."""
    result = refused_here("sim", "--logs", "none", "--duration", "1", option, value)
    assert result.returncode == 2
    assert says in result.stderr and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_a_negative_wind_speed_is_a_value_not_an_option():
    """``--wind -3,90`` (argparse took "-3,90" for an option): a wind of 3 m/s from the
    other side, 270 degrees; a southern home's negative latitude is a value too."""
    parser = _build_parser()
    args = parser.parse_args(["sim", "--wind", "-3,90", "--home", "-33.86,151.21,30"])
    assert args.wind == "-3,90" and args.home == "-33.86,151.21,30"
    config = sim_config(args)
    assert config.wind == Wind(speed=3.0, from_deg=270.0)  # type: ignore[attr-defined]
    assert config.home.latitude == pytest.approx(-33.86)  # type: ignore[attr-defined]
    stack = parser.parse_args(["sim", "--flight-stack", "px4", "--wind", "-3,90"])
    assert flight_stack_config(stack).wind == Wind(speed=3.0, from_deg=270.0)  # type: ignore[attr-defined]
    demo = parser.parse_args(["demo", "--wind", "-3.5,0", "--turbulence", "light"])
    assert demo.wind == "-3.5,0"
    # a word after "--" is never joined; an option that takes no value is left alone
    assert parser.parse_known_args(["sim", "--quiet", "--", "-3,90"])[1] == ["--", "-3,90"]


# --- telemetry --------------------------------------------------------------------------

_INT_RANGES = {
    f"{sign}int{bits}_t": (0, 2**bits - 1) if sign else (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
    for sign in ("", "u")
    for bits in (8, 16, 32, 64)
}
FLOAT32_MAX = float(np.finfo(np.float32).max)


def _vehicle_in(value: float) -> Vehicle:
    """A vehicle whose whole physics state was ``value`` before its last step."""
    v = Vehicle()
    v.step()
    v.fleet.state[0, :] = value
    v.step()
    return v


@pytest.mark.parametrize("value", [1e6, 1e30, 1e300, math.inf, -math.inf, math.nan])
def test_every_telemetry_message_packs_whatever_the_physics_holds(value):
    """A state far out of range, infinite or NaN: each telemetry message is packed (no
    struct.error, no OverflowError), its integer fields saturated to their wire types, and
    the pose and motion it reports finite."""
    v = _vehicle_in(value)
    snapshot = Snapshot(v)
    messages = [build(snapshot) for build in T.BUILDERS.values()]
    messages.append(build_heartbeat(v))
    decoder = mav.MAVLink(None)
    for message in messages:
        frame = FC.pack_message(message, 0, 1, 1)
        decoded = decoder.decode(bytearray(frame))
        kinds = dict(zip(decoded.fieldnames, decoded.fieldtypes, strict=True))
        for name, kind in kinds.items():
            if kind in _INT_RANGES:
                values = getattr(decoded, name)
                low, high = _INT_RANGES[kind]
                for x in values if isinstance(values, list) else [values]:
                    assert low <= x <= high
    position = messages[list(T.BUILDERS).index(mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED)]
    attitude = messages[list(T.BUILDERS).index(mav.MAVLINK_MSG_ID_ATTITUDE)]
    for x in (position.x, position.y, position.z, position.vx, position.vy, position.vz):
        assert math.isfinite(x) and abs(x) <= FLOAT32_MAX
    assert all(math.isfinite(x) for x in (attitude.roll, attitude.pitch, attitude.yaw))


def test_out_of_range_positions_saturate_the_integer_fields():
    """GLOBAL_POSITION_INT of a vehicle 1e30 m north and climbing at 1e30 m/s: the
    latitude, altitude and velocity saturate at int32 / int16 (their wire types)."""
    v = Vehicle()
    v.step()
    v.fleet.state[0, L.I_PY] = 1e30  # m north
    v.fleet.state[0, L.I_PZ] = 1e30  # m up
    v.fleet.state[0, L.I_VZ] = 1e30  # m/s up
    message = T.BUILDERS[mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT](Snapshot(v))
    decoded = mav.MAVLink(None).decode(bytearray(FC.pack_message(message, 0, 1, 1)))
    assert decoded.lat == 2**31 - 1 and decoded.alt == 2**31 - 1
    assert decoded.relative_alt == 2**31 - 1 and decoded.vz == -(2**15)  # NED: up is −
