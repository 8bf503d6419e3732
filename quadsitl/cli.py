"""The ``quadsitl`` command line. Subcommands parse their options here and nowhere else."""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Callable, Sequence
from typing import Any

from quadsitl import __version__
from quadsitl.bridges import FLIGHT_STACKS


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="quadsitl",
        description="A MAVLink-speaking software-in-the-loop quadrotor simulator.",
    )
    parser.add_argument("--version", action="version", version=f"quadsitl {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")

    demo = commands.add_parser(
        "demo",
        help="start the simulator and fly a mission through MAVLink, printing the tracking "
        "error (with --physics: a physics-only take-off, hover and landing table)",
    )
    demo.add_argument(
        "--physics", action="store_true", help="physics-only table, no simulator process"
    )
    demo.add_argument(
        "--speed", type=float, default=4.0, help="simulator speed factor (default: 4)"
    )
    demo.add_argument("--logs", default="logs", help="telemetry log folder (default: logs)")
    demo.add_argument("--airframe", default="paper", help="airframe preset (default: paper)")
    demo.add_argument(
        "--altitude", type=float, default=2.0, help="hover altitude above ground, m (default: 2)"
    )
    demo.add_argument(
        "--print-every", type=float, default=0.5, help="seconds between table rows (default: 0.5)"
    )
    _add_weather_options(demo)
    _add_sim_parser(commands)
    _add_fly_parser(commands)
    try:  # training needs torch; the simulator does not
        from policies.cli import add_parsers as add_policy_parsers
    except ImportError:
        pass
    else:
        add_policy_parsers(commands)
    replay = commands.add_parser(
        "replay",
        help="turn a MAVLink telemetry log (.tlog) into a Rerun recording (as gcs-replay)",
    )
    replay.add_argument("tlog", help="the telemetry log")
    replay.add_argument(
        "-o", "--output", metavar="RRD", help="write the recording here (default: open the viewer)"
    )
    replay.add_argument(
        "--web", action="store_true", help="serve it with the web viewer on this host instead"
    )
    return parser


def _add_sim_parser(commands: argparse._SubParsersAction) -> None:
    sim = commands.add_parser(
        "sim",
        help="run the simulated vehicle in real time, speaking MAVLink over UDP/TCP",
        description="Run the simulated quadrotor as a MAVLink vehicle. Ground stations "
        "connect on the --gcs link, MAVSDK-style API clients on the --api link.",
    )
    sim.add_argument(
        "--gcs",
        default="udpout:127.0.0.1:14550",
        metavar="URL",
        help="ground-station link (default: udpout:127.0.0.1:14550, where QGroundControl "
        "listens); 'none' disables it",
    )
    sim.add_argument(
        "--api",
        default="udpout:127.0.0.1:14540",
        metavar="URL",
        help="API/offboard link (default: udpout:127.0.0.1:14540, where MAVSDK listens "
        "with udpin://0.0.0.0:14540); 'none' disables it",
    )
    sim.add_argument(
        "--hil",
        default=None,
        metavar="URL",
        help="motor-command link for external controllers (HIL_ACTUATOR_CONTROLS): no "
        "telemetry streams, not logged; e.g. udpin:127.0.0.1:4560 (default: none; motor "
        "commands are accepted on every link)",
    )
    sim.add_argument(
        "--lockstep",
        action="store_true",
        help="simulated time moves only with motor commands, one control period each",
    )
    _add_signing_options(sim, "require MAVLink 2 signing")
    sim.add_argument(
        "--link",
        action="append",
        default=[],
        metavar="URL",
        help="an extra link (repeatable): udpout:HOST:PORT, udpin:HOST:PORT or tcpin:HOST:PORT",
    )
    sim.add_argument(
        "--sysid",
        type=int,
        default=1,
        help="MAVLink system id (of the first vehicle; vehicle i has SYSID+i) (default: 1)",
    )
    sim.add_argument(
        "--vehicles",
        type=int,
        default=1,
        metavar="N",
        help="vehicles in this process, their physics stepped as one batch; each is a "
        "complete MAVLink vehicle on every link (with --flight-stack: the aircraft of one "
        "autopilot instance each) (default: 1)",
    )
    _add_weather_options(sim)
    sim.add_argument(
        "--sensor-noise",
        type=float,
        default=1.0,
        metavar="SCALE",
        help="scale of the sensor models' noise in HIGHRES_IMU, SCALED_IMU, RAW_IMU, "
        "SCALED_PRESSURE and GPS_RAW_INT (with --flight-stack px4: in HIL_SENSOR and "
        "HIL_GPS): 0 the truth, 1 the defaults of docs/physics.md, "
        "3 three times as much (default: 1)",
    )
    sim.add_argument(
        "--fail-motor",
        action="append",
        default=[],
        metavar="N[:EFFICIENCY]",
        help="motor N (1-4) fails on every vehicle from power-on: off, or left EFFICIENCY "
        "(0..1) of its thrust, e.g. 2:0.6 (repeatable; default: healthy motors)",
    )
    sim.add_argument(
        "--delay",
        metavar="OBS,ACT",
        help="observation and actuation delay of lockstep motor commands, in physics steps, "
        "each K or LOW:HIGH (drawn per vehicle and reset), e.g. 2,0:5 (needs --lockstep; "
        "default: none)",
    )
    sim.add_argument(
        "--randomize",
        action="store_true",
        help="draw each vehicle's airframe (mass, inertia, rotor coefficients, motor rate, "
        "drag) at start and at each reset, from the task envs' default spreads",
    )
    sim.add_argument(
        "--airframe-scale",
        metavar="NAME=F,...",
        help="exact airframe scales, e.g. mass=1.3 (names as the task envs' airframe_scale)",
    )
    sim.add_argument(
        "--seed",
        type=int,
        default=0,
        help="seed of the draws (delays, airframes, turbulence); vehicle i draws from "
        "SEED+i (default: 0)",
    )
    sim.add_argument(
        "--estimator",
        choices=("truth", "ekf"),
        default="truth",
        help="what the flight software flies on and reports: the true state, or the onboard "
        "EKF's estimate from the sensors (the EKF2_EN parameter; default: truth)",
    )
    sim.add_argument(
        "--spacing",
        type=float,
        default=2.0,
        metavar="M",
        help="metres between the vehicles' start positions, a grid east then north (default: 2)",
    )
    sim.add_argument(
        "--autopilot-id",
        choices=("px4", "generic"),
        default="px4",
        help="what the vehicle presents itself as: px4 (QGroundControl's PX4 plugin, MAVSDK's "
        "and MAVProxy's PX4 paths; take-off param7 AMSL) or generic (a plain MAVLink vehicle; "
        "take-off param7 relative to home) (default: px4)",
    )
    sim.add_argument(
        "--home",
        default=None,
        metavar="LAT,LON,ALT",
        help="home position: degrees, degrees, metres above sea level "
        "(default: 47.397742,8.545594,488)",
    )
    sim.add_argument(
        "--airframe",
        default=None,
        help="airframe preset (default: paper; with --flight-stack: iris)",
    )
    sim.add_argument(
        "--flight-stack",
        choices=FLIGHT_STACKS,
        default=None,
        help="be only the aircraft of a real autopilot, which serves MAVLink itself: "
        "ardupilot (ArduCopter's JSON backend) or px4 (PX4's simulator_mavlink), in "
        "lockstep; quadsitl's own flight software and links are off (docs/autopilots.md)",
    )
    sim.add_argument(
        "--flight-stack-port",
        type=int,
        default=None,
        metavar="PORT",
        help="port of the first autopilot instance; instance i uses PORT + 10 i "
        "(ardupilot; px4: PORT + i) (default: UDP 9002 for ardupilot, TCP 4560 for px4)",
    )
    sim.add_argument(
        "--flight-stack-bind",
        default="127.0.0.1",
        metavar="ADDR",
        help="address the autopilot ports listen on (default: 127.0.0.1; 0.0.0.0 lets "
        "autopilots on other hosts in)",
    )
    sim.add_argument(
        "--physics-rate",
        type=float,
        default=1000.0,
        help="physics steps per simulated second (default: 1000)",
    )
    sim.add_argument(
        "--control-rate",
        type=float,
        default=250.0,
        help="onboard controller rate, Hz (default: 250)",
    )
    sim.add_argument(
        "--speed",
        type=float,
        default=1.0,
        help="speed factor: simulated seconds per wall second (default: 1)",
    )
    sim.add_argument(
        "--logs",
        default="logs",
        metavar="DIR",
        help="folder for the telemetry log of the run (default: logs); 'none' disables it",
    )
    sim.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set a vehicle parameter at start (repeatable), e.g. MPC_XY_CRUISE=3",
    )
    sim.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="stop after S wall-clock seconds (default: run until Ctrl-C / SIGTERM)",
    )
    sim.add_argument(
        "--autopilot",
        metavar="CHECKPOINT",
        help="fly with a trained hover/waypoint policy instead of the cascaded controller "
        "(e.g. policies/checkpoints/random_waypoint.pt, or its export: a .onnx file or a C .h "
        "header with its .contract.json)",
    )
    sim.add_argument(
        "--rerun",
        action="store_true",
        help="stream the vehicle (every vehicle of a fleet) to a Rerun viewer (spawned)",
    )
    sim.add_argument(
        "--rerun-save",
        metavar="RRD",
        help="stream the vehicle to this Rerun recording file instead of a viewer",
    )
    sim.add_argument(
        "--rerun-web",
        action="store_true",
        help="serve the Rerun web viewer and the vehicle's stream on this host (loopback; "
        "QUADSITL_WEB_BIND, QUADSITL_WEB_PORT=9090, QUADSITL_GRPC_PORT=9876) and print its URL",
    )
    sim.add_argument("--quiet", action="store_true", help="do not print vehicle events")


def _add_fly_parser(commands: argparse._SubParsersAction) -> None:
    fly = commands.add_parser(
        "fly",
        help="fly a mission file (QGroundControl .plan or a waypoint list) against a running "
        "quadsitl sim and print the tracking error",
        description="Connect to a running vehicle as a ground station does, upload the "
        "mission, arm, fly it in MISSION mode until it is done, and print the tracking error. "
        "MISSION is a QGroundControl .plan (JSON) or a text file of waypoints, one "
        "'EAST NORTH UP [HOLD]' line each, in m (and s) from home (docs/connecting.md).",
    )
    fly.add_argument("mission", metavar="MISSION", help="the .plan or waypoint file")
    fly.add_argument(
        "--connect",
        default="udpin:127.0.0.1:14540",
        metavar="URL",
        help="where to meet the vehicle (default: udpin:127.0.0.1:14540, where quadsitl "
        "sim's API link sends)",
    )
    fly.add_argument(
        "--sysid",
        type=int,
        default=1,
        metavar="N",
        help="system id of the vehicle to fly (default: 1)",
    )
    fly.add_argument(
        "--timeout",
        type=float,
        default=600.0,
        metavar="S",
        help="give up when the mission is not done after S seconds (default: 600)",
    )
    _add_signing_options(fly, "sign every message (for a vehicle with signing on)")


def _add_signing_options(parser: argparse.ArgumentParser, what: str) -> None:
    """--signing-key FILE | --signing-passphrase TEXT, read by :func:`_signing_key`;
    ``what`` says what the key is for."""
    signing = parser.add_mutually_exclusive_group()
    signing.add_argument(
        "--signing-key",
        metavar="FILE",
        help=f"{what} with the key in FILE (64 hex digits or 32 bytes; "
        "environment: QUADSITL_SIGNING_KEY=64 hex digits)",
    )
    signing.add_argument(
        "--signing-passphrase",
        metavar="TEXT",
        help=f"{what} with key SHA-256(TEXT), as MAVProxy's 'signing setup TEXT' "
        "(environment: QUADSITL_SIGNING_PASSPHRASE)",
    )


def _signing_key(args: argparse.Namespace) -> bytes | None:
    """The key from the options or the environment; a variable that is set but empty is an
    error (an empty secret must never quietly mean "no signing")."""
    from quadsitl.mavlink.signing import key_from_file, key_from_hex, key_from_passphrase

    if args.signing_key is not None:
        return key_from_file(args.signing_key)
    if args.signing_passphrase is not None:
        return key_from_passphrase(args.signing_passphrase, "--signing-passphrase")
    passphrase = os.environ.get("QUADSITL_SIGNING_PASSPHRASE")
    if passphrase is not None:
        return key_from_passphrase(passphrase, "QUADSITL_SIGNING_PASSPHRASE")
    key_hex = os.environ.get("QUADSITL_SIGNING_KEY")  # 64 hex digits, off the command line
    if key_hex is not None:
        return key_from_hex(key_hex, "QUADSITL_SIGNING_KEY")
    return None


def _sim_config(args: argparse.Namespace) -> object:
    from quadsitl.mavlink.runner import SimConfig
    from quadsitl.vehicle.geo import Home

    def url(value: str) -> str | None:
        return None if value.lower() == "none" else value

    home = _home(args.home) or Home()
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
    wind = _weather(args.wind, args.turbulence)
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise ValueError(f"--duration must be a positive number of seconds, got {args.duration}")
    return SimConfig(
        gcs_url=url(args.gcs),
        api_url=url(args.api),
        extra_urls=args.link,
        hil_url=url(args.hil) if args.hil else None,
        lockstep=args.lockstep,
        signing_key=_signing_key(args),
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
        motor_faults=_motor_faults(args.fail_motor),
        wind_seed=args.seed,
        episodes=_episodes(args.delay, args.randomize, args.airframe_scale, args.seed),
    )


def _add_weather_options(parser: argparse.ArgumentParser) -> None:
    """``--wind`` and ``--turbulence``, of ``sim`` and ``demo`` alike."""
    parser.add_argument(
        "--wind",
        metavar="SPEED,FROM",
        help="mean wind: SPEED m/s blowing from FROM degrees (clockwise from north, as "
        "weather reports give it), e.g. 5,270 (default: still air)",
    )
    parser.add_argument(
        "--turbulence",
        metavar="SEVERITY",
        help="Dryden turbulence (MIL-F-8785C): light, moderate, severe, or its sigma in "
        "m/s (default: none)",
    )


def _motor_faults(items: list[str]) -> dict[int, float]:
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


def _home(value: str | None) -> Any:
    """``--home LAT,LON,ALT`` as a Home (None when not given); ValueError in one line."""
    from quadsitl.vehicle.geo import Home

    if value is None:
        return None
    try:
        lat, lon, alt = (float(x) for x in value.split(","))
    except ValueError:
        raise ValueError(f"--home must be LAT,LON,ALT, got {value!r}") from None
    return Home(lat, lon, alt)


def _flight_stack_config(args: argparse.Namespace) -> Any:
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
        "--rerun": args.rerun or args.rerun_save or args.rerun_web,
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
        wind=_weather(args.wind, args.turbulence),
    )
    if px4:
        return Px4Config(
            **common,
            port=PX4_PORT if args.flight_stack_port is None else args.flight_stack_port,
            home=_home(args.home),
            sensor_noise=check_noise_scale(args.sensor_noise),
        )
    port = PORT if args.flight_stack_port is None else args.flight_stack_port
    return ArduPilotConfig(**common, port=port)


def _weather(wind: str | None, turbulence: str | None) -> Any:
    """``--wind SPEED,FROM`` and ``--turbulence SEVERITY|SIGMA`` as a Wind (None: still
    air); a one-line ValueError for what does not parse or is not weather."""
    from quadsitl.physics.wind import Wind

    if wind is None and turbulence is None:
        return None
    speed, from_deg = 0.0, 0.0
    if wind is not None:
        try:
            speed, from_deg = (float(x) for x in wind.split(","))
        except ValueError:
            raise ValueError(f"--wind must be SPEED,FROM (m/s, degrees), got {wind!r}") from None
    level: str | float | None = turbulence
    if turbulence is not None:
        try:
            level = float(turbulence)
        except ValueError:
            level = turbulence.lower()
    return Wind(speed=speed, from_deg=from_deg, turbulence=level)


def _episodes(delay: str | None, randomize: bool, scale: str | None, seed: int) -> Any:
    """``--delay``, ``--randomize``, ``--airframe-scale`` and ``--seed`` as
    EpisodeOptions (None: none given); a one-line ValueError for what does not parse."""
    from quadsitl.tasks.randomization import airframe_scale_row
    from quadsitl.vehicle.episodes import EpisodeOptions

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


def _sim_collaborators(args: argparse.Namespace) -> tuple[Any, Any]:
    """(make_autopilot, make_view) of ``quadsitl sim``: composed here, so that the
    simulator itself needs neither the policies package (torch) nor the viewer."""
    make_autopilot = make_view = None
    if args.autopilot:
        try:
            from policies.autopilot import PolicyAutopilot
        except ImportError as error:
            raise ValueError(f"--autopilot needs the training extra ({error})") from None
        path = args.autopilot

        def make_autopilot(airframe: Any) -> Any:
            return PolicyAutopilot.from_checkpoint(path, airframe)

    if args.rerun or args.rerun_save or args.rerun_web:
        from quadsitl.viz.sim_view import SimView

        def make_view(vehicles: Any) -> Any:
            return SimView(vehicles, args.rerun_save, notice=_say("sim"), web=args.rerun_web)

    return make_autopilot, make_view


def _say(command: str) -> Callable[[str], None]:
    """A one-line notice on stderr, prefixed as the command's errors are."""

    def say(text: str) -> None:
        print(f"quadsitl {command}: {text}", file=sys.stderr, flush=True)

    return say


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``quadsitl`` console script."""
    try:
        return _main(argv)
    except KeyboardInterrupt:  # Ctrl-C before a command set up its own handling
        print("quadsitl: interrupted", file=sys.stderr)
        return 130


def _main(argv: Sequence[str] | None = None) -> int:
    parser = _build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    if args.command == "demo" and not args.physics:
        from gcs_tools.demo import run_demo as run_mission_demo

        try:
            _weather(args.wind, args.turbulence)  # a bad value: an error before any flight
        except ValueError as error:
            parser.exit(2, f"quadsitl demo: error: {error}\n")
        weather = [*("--wind", args.wind)] if args.wind else []
        weather += [*("--turbulence", args.turbulence)] if args.turbulence else []
        return run_mission_demo(speed=args.speed, logs=args.logs, sim_args=tuple(weather))
    if args.command == "demo" and (args.wind or args.turbulence):
        parser.exit(
            2,
            "quadsitl demo: error: --wind and --turbulence fly the simulator's "
            "demo, not --physics\n",
        )
    if args.command == "demo":
        from quadsitl.demo import run_demo

        try:
            return run_demo(
                airframe=args.airframe, altitude=args.altitude, print_every=args.print_every
            )
        except ValueError as error:
            parser.exit(2, f"quadsitl demo: error: {error}\n")
    if args.command in ("train", "eval", "robustness", "plot", "sweep", "export"):
        from policies.cli import run as run_policy_command

        try:
            return run_policy_command(args)
        except (ValueError, OSError) as error:  # OSError: a file or folder that cannot be used
            parser.exit(2, f"quadsitl {args.command}: error: {error}\n")
    if args.command == "fly":
        from gcs_tools.fly import run_fly

        try:
            key = _signing_key(args)
            return run_fly(args.mission, args.connect, args.sysid, args.timeout, key)
        except ValueError as error:
            parser.exit(2, f"quadsitl fly: error: {error}\n")
    if args.command == "replay":
        from gcs_tools.replay import main as replay_main

        options = (["-o", args.output] if args.output else []) + (["--web"] if args.web else [])
        return replay_main([args.tlog, *options], prog="quadsitl replay")
    if args.command == "sim" and args.flight_stack:
        from quadsitl.bridges.ardupilot_udp import run_ardupilot
        from quadsitl.bridges.px4_tcp import run_px4

        run = run_px4 if args.flight_stack == "px4" else run_ardupilot
        try:
            return run(_flight_stack_config(args))
        except (ValueError, OSError) as error:
            parser.exit(2, f"quadsitl sim: error: {error}\n")
    if args.command == "sim":
        from quadsitl.mavlink.runner import run_simulator

        try:
            make_autopilot, make_view = _sim_collaborators(args)
            return run_simulator(_sim_config(args), make_autopilot, make_view)  # type: ignore[arg-type]
        except (ValueError, OSError) as error:
            parser.exit(2, f"quadsitl sim: error: {error}\n")
    parser.error(f"unknown command {args.command!r}")  # unreachable: argparse checks
    return 2


if __name__ == "__main__":
    sys.exit(main())
