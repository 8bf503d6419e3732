"""``quadsitl sim``'s parsed options (:mod:`quadsitl.command_line.sim_options`) turned into
the configuration that runs: the simulator's SimConfig, or a flight stack's (ArduPilot,
PX4). Each reader raises a one-line ValueError for a value that does not parse or does
not apply. (The collaborators from other packages, the policy autopilot and the viewer,
are composed by :mod:`quadsitl.cli`.)
"""

from __future__ import annotations

import argparse
import math
from typing import Any

from quadsitl.command_line.options import parse_weather, signing_key


def sim_config(args: argparse.Namespace) -> object:
    """The simulator's SimConfig (quadsitl's own flight software and links)."""
    from quadsitl.geo import Home
    from quadsitl.simulator.runner import SimConfig

    def url(value: str) -> str | None:
        return None if value.lower() == "none" else value

    home = parse_home(args.home) or Home()
    params = {"EKF2_EN": 1.0} if args.estimator == "ekf" else {}  # --param may override
    for item in args.param:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise ValueError(f"--param must be NAME=VALUE, got {item!r}")
        try:
            params[name.strip().upper()] = float(value)
        except ValueError:
            raise ValueError(
                f"--param {item!r}: the value {value!r} of {name.strip()} is not a number"
            ) from None
    wind = parse_weather(args.wind, args.turbulence)
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise ValueError(f"--duration must be a positive number of seconds, got {args.duration}")
    return SimConfig(
        gcs_url=url(args.gcs),
        api_url=url(args.api),
        extra_urls=args.link,
        hil_url=url(args.hil) if args.hil else None,
        lockstep=args.lockstep,
        signing_key=signing_key(args),
        system_id=args.sysid,
        vehicles=args.vehicles,
        spacing=args.spacing,
        autopilot_id=args.autopilot_id,
        home=home,
        airframe=args.airframe or "paper",
        physics_rate=args.physics_rate,
        control_rate=args.control_rate,
        speed=args.speed,
        log_dir=None if args.logs.lower() == "none" else args.logs,
        duration=args.duration,
        params=params,
        quiet=args.quiet,
        flown_by=f"the policy in {args.autopilot}" if args.autopilot else None,
        wind=wind,
        sensor_noise=args.sensor_noise,
        motor_faults=parse_motor_faults(args.fail_motor),
        wind_seed=args.seed,
        episodes=parse_episodes(args.delay, args.randomize, args.airframe_scale, args.seed),
    )


def parse_motor_faults(items: list[str]) -> dict[int, float]:
    """``--fail-motor N[:EFFICIENCY]`` (repeatable) as {motor: efficiency}; a one-line
    ValueError for what does not parse."""
    faults = {}
    for item in items:
        motor, sep, efficiency = item.partition(":")
        try:
            faults[int(motor)] = float(efficiency) if sep else 0.0
        except ValueError:
            raise ValueError(
                f"--fail-motor must be N or N:EFFICIENCY (e.g. 2 or 2:0.6), got {item!r}"
            ) from None
    return faults


def parse_home(value: str | None) -> Any:
    """``--home LAT,LON,ALT`` as a Home (None when not given); ValueError in one line."""
    from quadsitl.geo import Home

    if value is None:
        return None
    try:
        lat, lon, alt = (float(x) for x in value.split(","))
    except ValueError:
        raise ValueError(f"--home must be LAT,LON,ALT, got {value!r}") from None
    return Home(lat, lon, alt)


def flight_stack_config(args: argparse.Namespace) -> Any:
    """``quadsitl sim --flight-stack ardupilot|px4``'s configuration; ValueError for
    options that belong to quadsitl's own flight software, which is off in this mode."""
    from quadsitl.bridges.ardupilot_json import PORT
    from quadsitl.bridges.ardupilot_udp import ArduPilotConfig
    from quadsitl.bridges.px4_hil import PORT as PX4_PORT
    from quadsitl.bridges.px4_tcp import Px4Config
    from quadsitl.physics.sensors.suite import check_noise_scale

    px4 = args.flight_stack == "px4"

    own = {  # given with a value other than its default
        "--autopilot": args.autopilot,
        "--lockstep": args.lockstep,
        "--hil": args.hil,
        "--link": args.link,
        "--param": args.param,
        "--signing-key": args.signing_key or args.signing_passphrase,
        "--home": args.home and not px4,  # ArduCopter's own (--home); PX4's comes from GPS
        "--speed": args.speed != 1.0,  # lockstep: the autopilot sets the pace
        "--physics-rate": args.physics_rate != 1000.0,  # one step per autopilot frame
        "--control-rate": args.control_rate != 250.0,
        "--sysid": args.sysid != 1,
        "--fail-motor": bool(args.fail_motor),  # quadsitl's failure injection, not yet here
        "--sensor-noise": args.sensor_noise != 1.0 and not px4,  # ArduCopter's own models
        "--delay": args.delay,  # of quadsitl's lockstep motor path
        "--randomize": args.randomize,
        "--airframe-scale": args.airframe_scale,
        "--estimator": args.estimator != "truth",  # the autopilot's own estimator
    }
    for option, value in own.items():
        if value:
            raise ValueError(
                f"{option} has no effect with --flight-stack: the {args.flight_stack} "
                "autopilot flies the vehicle, sets the pace in lockstep and serves MAVLink"
            )
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise ValueError(f"--duration must be a positive number of seconds, got {args.duration}")
    common: dict[str, Any] = dict(  # what both stacks' simulators take
        vehicles=args.vehicles,
        airframe=args.airframe or "iris",
        bind=args.flight_stack_bind,
        duration=args.duration,
        quiet=args.quiet,
        wind=parse_weather(args.wind, args.turbulence),
    )
    if px4:
        return Px4Config(
            **common,
            port=PX4_PORT if args.flight_stack_port is None else args.flight_stack_port,
            home=parse_home(args.home),
            sensor_noise=check_noise_scale(args.sensor_noise),
        )
    port = PORT if args.flight_stack_port is None else args.flight_stack_port
    return ArduPilotConfig(**common, port=port)


def parse_episodes(delay: str | None, randomize: bool, scale: str | None, seed: int) -> Any:
    """``--delay``, ``--randomize``, ``--airframe-scale`` and ``--seed`` as
    EpisodeOptions (None: none given); a one-line ValueError for what does not parse."""
    from quadsitl.flight_software.episodes import EpisodeOptions
    from quadsitl.perturbations.randomization import airframe_scale_row

    if delay is None and not randomize and scale is None:
        return None
    steps = [(0, 0), (0, 0)]
    if delay is not None:
        parts = delay.split(",")
        try:
            if len(parts) != 2:
                raise ValueError
            bounds = [part.split(":") for part in parts]
            steps = [(int(b[0]), int(b[-1])) for b in bounds if 1 <= len(b) <= 2]
            if len(steps) != 2:
                raise ValueError
        except ValueError:
            raise ValueError(
                f"--delay must be OBS,ACT in whole physics steps, each K or LOW:HIGH, got {delay!r}"
            ) from None
    factors: dict[str, float] = {}
    for item in (scale or "").split(",") if scale else []:
        name, sep, value = item.partition("=")
        try:
            factors[name.strip()] = float(value) if sep else math.nan
        except ValueError:
            factors[name.strip()] = math.nan
    try:
        airframe_scale_row(factors)  # the delays are checked against the physics rate
    except ValueError as error:
        raise ValueError(str(error).replace("airframe_scale", "--airframe-scale")) from None
    return EpisodeOptions(steps[0], steps[1], randomize, factors, seed)
