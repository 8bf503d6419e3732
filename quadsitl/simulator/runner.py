"""The simulator process: its options, and what it is made of: vehicles, links, log,
view, signals.

:class:`SimConfig` is everything ``quadsitl sim`` can be told, checked before anything
starts; :class:`Simulator` builds the vehicles' group, the links, the telemetry log and
a server per vehicle from it, and hands them to the real-time loop
(:mod:`.realtime_loop`: when the physics steps, and what it waits on);
:func:`run_simulator` runs it until a signal and says what it flies.
"""

from __future__ import annotations

import math
import os
import signal
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from quadsitl.flight_software.controller import Autopilot, Setpoint
from quadsitl.flight_software.episodes import EpisodeOptions
from quadsitl.flight_software.group import VehicleGroup
from quadsitl.flight_software.param_binding import show_weather
from quadsitl.flight_software.results import Severity
from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.geo import Home
from quadsitl.perturbations.motor_faults import check_efficiency, check_motor
from quadsitl.physics import Airframe, get_airframe
from quadsitl.physics import layout as L
from quadsitl.physics.wind import Wind
from quadsitl.simulator.fleet_server import FleetServer
from quadsitl.simulator.identity import get_identity
from quadsitl.simulator.links import Link
from quadsitl.simulator.realtime_loop import RealTimeLoop
from quadsitl.simulator.server import MavlinkServer
from quadsitl.simulator.tlog import TlogWriter
from quadsitl.wire import batch_frames
from quadsitl.wire.addresses import is_loopback, parse_url
from quadsitl.wire.ids import MAX_SYSTEM_ID


@dataclass
class SimConfig:
    """Everything ``quadsitl sim`` can be told; see ``quadsitl sim --help``."""

    gcs_url: str | None = "udpout:127.0.0.1:14550"
    api_url: str | None = "udpout:127.0.0.1:14540"
    hil_url: str | None = None  # motor-command link: no telemetry streams, not logged
    extra_urls: list[str] = field(default_factory=list)
    lockstep: bool = False  # simulated time moves only with motor commands
    signing_key: bytes | None = None  # MAVLink 2 signing key (32 bytes)
    system_id: int = 1  # of the first vehicle; vehicle i has system_id + i
    vehicles: int = 1  # in this process, their physics stepped as one batch
    spacing: float = 2.0  # m between the vehicles' start positions (a grid)
    autopilot_id: str = "px4"  # what the vehicle presents itself as: "px4" or "generic"
    home: Home = field(default_factory=Home)
    airframe: str = "paper"
    physics_rate: float = 1000.0  # Hz
    control_rate: float = 250.0  # Hz
    speed: float = 1.0  # simulated seconds per wall second
    log_dir: str | None = "logs"
    duration: float | None = None  # wall seconds, None: until a signal
    params: dict[str, float] = field(default_factory=dict)
    quiet: bool = False
    flown_by: str | None = None  # what flies instead of the cascaded controller (banner)
    wind: Wind | None = None  # the weather every vehicle flies in (None: still air)
    wind_seed: int = 0  # of the turbulence (vehicle i: the i-th stream of this seed)
    sensor_noise: float = 1.0  # scale of the sensor models' noise (0: the truth)
    sensor_seed: int = 0  # of the sensors' noise
    # motor (1-based) -> its efficiency, on every vehicle from power-on (--fail-motor)
    motor_faults: dict[int, float] = field(default_factory=dict)
    episodes: EpisodeOptions | None = None  # delays, airframe draws (motor path)

    def validate(self) -> None:
        get_identity(self.autopilot_id)
        if not 1 <= self.system_id <= MAX_SYSTEM_ID:
            raise ValueError(f"system id must be 1..{MAX_SYSTEM_ID}, got {self.system_id}")
        if self.vehicles < 1:
            raise ValueError(f"--vehicles must be at least 1, got {self.vehicles}")
        if self.system_id + self.vehicles - 1 > MAX_SYSTEM_ID:
            raise ValueError(
                f"{self.vehicles} vehicles from system id {self.system_id} need ids up to "
                f"{self.system_id + self.vehicles - 1}; MAVLink system ids end at {MAX_SYSTEM_ID}"
            )
        if not (math.isfinite(self.spacing) and self.spacing >= 0):
            raise ValueError(f"--spacing must be a distance ≥ 0 m, got {self.spacing}")
        if not (math.isfinite(self.physics_rate) and 100 <= self.physics_rate <= 10_000):
            raise ValueError(f"physics rate must be 100..10000 Hz, got {self.physics_rate}")
        if not (math.isfinite(self.control_rate) and 10 <= self.control_rate <= self.physics_rate):
            raise ValueError(
                f"control rate must be 10 Hz .. the physics rate, got {self.control_rate}"
            )
        ratio = self.physics_rate / self.control_rate  # physics steps per control period
        if abs(ratio - round(ratio)) > 1e-9 * ratio:
            raise ValueError(
                f"physics rate {self.physics_rate:g} Hz is not a whole multiple of the control "
                f"rate {self.control_rate:g} Hz (the controller runs every N physics steps)"
            )
        if not (math.isfinite(self.sensor_noise) and 0 <= self.sensor_noise <= 100):
            raise ValueError(f"--sensor-noise must be a scale 0..100, got {self.sensor_noise}")
        if not (math.isfinite(self.speed) and 0.01 <= self.speed <= 100):
            raise ValueError(f"speed factor must be 0.01..100, got {self.speed}")
        for motor, efficiency in self.motor_faults.items():
            check_motor(motor)
            check_efficiency(efficiency)
        if self.episodes is not None:
            self.episodes.check(1.0 / self.physics_rate)
            if self.episodes.delays and not self.lockstep:
                raise ValueError("--delay acts on lockstep motor commands: add --lockstep")
        if not [u for u in (self.gcs_url, self.api_url, self.hil_url, *self.extra_urls) if u]:
            raise ValueError("at least one link is needed")
        if self.lockstep and self.hil_url and self.signing_key is None:
            _, host, _ = parse_url(self.hil_url)
            if not is_loopback(host):
                raise ValueError(
                    f"--lockstep with --hil {self.hil_url} listens beyond this host: sign it "
                    "(--signing-passphrase TEXT, --signing-key FILE, or QUADSITL_SIGNING_KEY / "
                    "QUADSITL_SIGNING_PASSPHRASE in the environment; the env then needs "
                    "signing_key=) or listen on 127.0.0.1"
                )


def compile_for_sim(vehicles: int, airframe: str, wind: Wind | None = None) -> None:
    """Load (or compile) the physics and the controller before the clock starts: their
    first calls take milliseconds to seconds, which real time cannot absorb. The physics'
    world build too: a motor failure injected in flight switches to it; and a fleet's
    answer framing."""
    group = VehicleGroup(vehicles, airframe)
    group.step()
    group.physics.set_motor_efficiency((1.0, 1.0, 1.0, 0.5))
    if wind is not None and not wind.calm:
        group.physics.set_wind(wind)
    group.step()
    vehicle = group.vehicles[0]
    vehicle.cascade.rotor_command(vehicle.state, Setpoint(position=np.zeros(3)), 0.004)
    batch_frames.warm_up()  # long datagrams are scanned, a fleet's answers framed, compiled


class View(Protocol):
    """Something that shows the flight (e.g. :class:`quadsitl.viz.sim_view.SimView`)."""

    def tick(self, wall_now: float, spare: float = math.inf) -> None:
        """``spare``: wall s until the next physics step is due (work that would take
        longer makes it late)."""

    def event(self, text: str) -> None: ...

    def close(self) -> None: ...


MakeAutopilot = Callable[[Airframe], Autopilot]  # an autopilot for the airframe flown
MakeView = Callable[[dict[int, Vehicle]], View]  # system id -> vehicle, all of them


class Simulator:
    """The vehicle, its links and log. Collaborators come in from the caller (the command
    line composes them): ``make_autopilot`` flies instead of the cascaded controller (a
    trained policy), ``make_view`` shows the flight (Rerun)."""

    def __init__(
        self,
        config: SimConfig,
        make_autopilot: MakeAutopilot | None = None,
        make_view: MakeView | None = None,
    ) -> None:
        config.validate()
        self.config = config
        self.view: View | None = None
        airframe = get_airframe(config.airframe)
        self.group = VehicleGroup(
            config.vehicles,
            config.airframe,
            config.home,
            physics_dt=1.0 / config.physics_rate,
            control_period=1.0 / config.control_rate,
            spacing=config.spacing,
            make_autopilot=(lambda: make_autopilot(airframe)) if make_autopilot else None,
            sensor_noise=config.sensor_noise,
            sensor_seed=config.sensor_seed,
            episodes=config.episodes,
        )
        self.vehicle = self.group.vehicles[0]
        if config.wind is not None and not config.wind.calm:
            self.group.physics.set_wind(config.wind, seed=config.wind_seed)
        compile_for_sim(config.vehicles, config.airframe, config.wind)
        fitted = np.ones(L.N_ROTORS)
        for motor, efficiency in config.motor_faults.items():
            fitted[motor - 1] = efficiency
        for vehicle in self.group.vehicles:
            vehicle.motors.fit(fitted)
        for vehicle in self.group.vehicles:
            show_weather(vehicle)
            for name, value in config.params.items():
                vehicle.set_param(name, value)
        self.links: list[Link] = []
        try:
            named = (("gcs", config.gcs_url), ("api", config.api_url), ("hil", config.hil_url))
            for name, url in named:
                if url:
                    self.links.append(Link(url, name, config.system_id, 1))
            for i, url in enumerate(config.extra_urls):
                self.links.append(Link(url, f"link{i + 2}", config.system_id, 1))
        except OSError:
            self.close()
            raise
        self.tlog: TlogWriter | None = None
        if config.log_dir:
            stamp = time.strftime("%Y%m%d-%H%M%S")
            self.tlog = TlogWriter(Path(config.log_dir) / f"quadsitl-{stamp}-{os.getpid()}.tlog")
        self.servers = [
            MavlinkServer(
                vehicle,
                self.links,
                self.tlog,
                config.system_id + i,
                1,
                echo=self._printer(config.system_id + i),
                lockstep=config.lockstep,
                signing_key=config.signing_key,
                identity=get_identity(config.autopilot_id),
            )
            for i, vehicle in enumerate(self.group.vehicles)
        ]
        self.server = FleetServer(self.group, self.servers, self.tlog)
        self.loop = RealTimeLoop(
            self.group, self.server, self.links, config.speed, config.duration, self._housekeeping
        )
        if make_view is not None:
            self.view = make_view(
                {config.system_id + i: v for i, v in enumerate(self.group.vehicles)}
            )

    def _printer(self, system_id: int) -> Callable[[str], None]:
        """Vehicle events on the console; with several vehicles, each says who it is."""
        if self.config.vehicles == 1:
            return self._print
        return lambda text: self._print(f"[system {system_id}] {text}")

    def _print(self, text: str) -> None:
        if not self.config.quiet:
            print(text, flush=True)
        view = getattr(self, "view", None)
        if view is not None:
            view.event(text)

    def stop(self, *_: object) -> None:
        self.loop.stop()

    def run(self) -> None:
        """Until stopped (a signal, ``duration``)."""
        self.loop.run()

    def _housekeeping(self, now: float, spare: float) -> None:
        """The log and the view (with the telemetry: not on every poll in lockstep);
        ``spare``: wall s until the next physics step is due."""
        if self.tlog is not None:
            self._flush_log(self.tlog)
        if self.view is not None:
            self.view.tick(now, spare)

    def _flush_log(self, tlog: TlogWriter) -> None:
        """Write the log; if it fails, say so on the console and to every ground station,
        and fly on without it."""
        tlog.flush()
        if tlog.failure is None:
            return
        self.tlog = self.server.tlog = None
        for server in self.servers:
            server.tlog = None
        print(
            f"quadsitl sim: warning: {tlog.failure}; the flight goes on unlogged",
            file=sys.stderr,
            flush=True,
        )
        self.server.statustext(Severity.WARNING, "telemetry log stopped: write failed")

    def close(self) -> None:
        for server in getattr(self, "servers", []):
            server.close()  # keeps the signing timestamps
        for link in self.links:
            link.close()
        tlog = getattr(self, "tlog", None)
        if tlog is not None:
            tlog.close()
        view = getattr(self, "view", None)
        if view is not None:
            view.close()


def run_simulator(
    config: SimConfig,
    make_autopilot: MakeAutopilot | None = None,
    make_view: MakeView | None = None,
) -> int:
    """Run until SIGINT/SIGTERM (or ``config.duration``); returns an exit code."""
    sim = Simulator(config, make_autopilot, make_view)
    signal.signal(signal.SIGINT, sim.stop)
    signal.signal(signal.SIGTERM, sim.stop)
    links = ", ".join(f"{link.name} {link.url} (port {link.local_port})" for link in sim.links)
    signing = "on" if config.signing_key is not None else "off"
    last = config.system_id + config.vehicles - 1
    systems = (
        f"system {config.system_id}"
        if last == config.system_id
        else (f"{config.vehicles} vehicles, systems {config.system_id}..{last}")
    )
    sim._print(
        f"quadsitl sim: {systems} ({config.autopilot_id}), signing {signing}, links: {links}"
    )
    if config.flown_by is not None:
        sim._print(f"quadsitl sim: flown by {config.flown_by}, not the cascaded controller")
    if config.wind is not None and not config.wind.calm:
        sim._print(f"quadsitl sim: {config.wind.describe()}")
    for motor, efficiency in sorted(config.motor_faults.items()):
        state = "off" if efficiency == 0 else f"at {efficiency:.0%} thrust"
        sim._print(f"quadsitl sim: motor {motor} {state} on every vehicle (--fail-motor)")
    if config.episodes is not None:  # what each vehicle drew (again at each reset)
        for i, drawn in enumerate(sim.group.episodes.drawn):
            sim._print(f"quadsitl sim: system {config.system_id + i}: {drawn}")
    exposed = [link for link in sim.links if link.exposed]
    if exposed and config.signing_key is None:
        names = ", ".join(f"{link.name} ({link.url})" for link in exposed)
        print(
            f"quadsitl sim: warning: {names} can be reached from other hosts and signing "
            "is off: anyone there can command the vehicle (docs/security.md)",
            file=sys.stderr,
            flush=True,
        )
    if sim.tlog is not None:
        sim._print(f"quadsitl sim: telemetry log {sim.tlog.path}")
    try:
        sim.run()
    finally:
        sim.close()
        print(sim.loop.timing.summary(), file=sys.stderr, flush=True)
    return 0
