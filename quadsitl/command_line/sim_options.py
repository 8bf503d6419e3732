"""The options of ``quadsitl sim``: parsed here, read into a configuration by
:mod:`quadsitl.command_line.sim_setup`."""

from __future__ import annotations

import argparse

from quadsitl.bridges import FLIGHT_STACKS
from quadsitl.command_line.options import add_signing_options, add_weather_options


def add_sim_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``quadsitl sim`` and its options, in the order ``--help`` lists them."""
    sim = commands.add_parser(
        "sim",
        help="run the simulated vehicle in real time, speaking MAVLink over UDP/TCP",
        description="Run the simulated quadrotor as a MAVLink vehicle. Ground stations "
        "connect on the --gcs link, MAVSDK-style API clients on the --api link.",
    )
    _add_link_options(sim)
    _add_world_options(sim)
    _add_vehicle_options(sim)
    _add_flight_stack_options(sim)
    _add_run_options(sim)
    _add_viewer_options(sim)


def _add_link_options(sim: argparse.ArgumentParser) -> None:
    """The links: ground station, API, motor-command, lockstep, signing, extra links,
    system ids and the number of vehicles."""
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
    add_signing_options(sim, "require MAVLink 2 signing")
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


def _add_world_options(sim: argparse.ArgumentParser) -> None:
    """The world the vehicles fly in: weather, sensor noise, motor failures, delay,
    airframe randomisation and the seed of the draws."""
    add_weather_options(sim)
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


def _add_vehicle_options(sim: argparse.ArgumentParser) -> None:
    """The vehicle: estimator, fleet spacing, autopilot identity, home and airframe."""
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


def _add_flight_stack_options(sim: argparse.ArgumentParser) -> None:
    """Being only the aircraft of a real autopilot (ArduPilot or PX4)."""
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


def _add_run_options(sim: argparse.ArgumentParser) -> None:
    """The run: physics and control rates, speed, log folder, parameters, duration and
    a trained autopilot policy."""
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


def _add_viewer_options(sim: argparse.ArgumentParser) -> None:
    """The Rerun viewer and printing of vehicle events."""
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
    sim.add_argument(
        "--rerun-focus",
        type=int,
        metavar="SYSID",
        help="the vehicle of a fleet of more than 8 drawn in full colour (and logged at "
        "30 Hz) while the others are dimmed (default: the first)",
    )
    sim.add_argument("--quiet", action="store_true", help="do not print vehicle events")
