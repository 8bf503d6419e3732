"""The ``backend="mavlink"`` of the task envs: simulator processes, lockstep clients,
and the :class:`RemoteFleet` the task engine is built with instead of the in-process
physics.

Faults: a simulator that dies or stops answering makes ``step``/``reset`` raise
:class:`SimulatorError` within ``timeout`` seconds (the process's own exit message
included); the next ``reset`` starts fresh processes and warns that it did.
"""

from __future__ import annotations

import math
import secrets
import time
import warnings
from typing import Any

from quadsitl.envs.memory import available_bytes
from quadsitl.envs.ray_simulators import LOCAL, RaySimulator, join_ray, place_simulators
from quadsitl.envs.remote_fleet import RemoteFleet
from quadsitl.envs.sim_process import SimProcess
from quadsitl.lockstep_client.fleet_client import FleetClient
from quadsitl.lockstep_client.motor_client import SimulatorError
from quadsitl.perturbations import faults as FT
from quadsitl.perturbations.delay import DELAY_KINDS, Delay
from quadsitl.perturbations.randomization import Randomization
from quadsitl.physics import AIRFRAMES, get_airframe
from quadsitl.tasks import TaskEngine, TaskOptions, TaskSpec
from quadsitl.wire.addresses import parse_url
from quadsitl.wire.ids import MAX_SYSTEM_ID
from quadsitl.wire.signing import checked_key

START_TIMEOUT = 60.0  # s for a new simulator's vehicles to beat once its link is open (or,
# where the host cannot tell when it opened, to answer at all)
START_LIMIT = 600.0  # s a live simulator may take to open its link: a hang guard, not a
# speed (imports and compiled kernels; on a loaded machine a Ray worker took over 60 s)
START_POLL = 0.05  # s between looks at whether it has
MAX_TIMEOUT = 3600.0  # s: longer than this, a stuck simulator looks like a hang
SIM_PROCESS_BYTES = 200 * 2**20  # memory of one `quadsitl sim` process, measured
MAX_SIMULATORS = MAX_SYSTEM_ID  # one MAVLink system id each
BACKENDS = ("inprocess", "mavlink")
BACKEND_OPTIONS = (
    "sim_address",
    "gcs",
    "system_id",
    "timeout",
    "signing_key",
    "vehicles_per_sim",
    "simulators",
    "ray",
)


def reset_envs(engine: TaskEngine, backend: MavlinkBackend | None, mask: Any) -> None:
    """``engine.reset_envs(mask)``; through the wire, first restart a simulator that died
    (with a warning), and give errors the process's exit message."""
    if backend is None:
        engine.reset_envs(mask)
        return
    backend.check_alive()
    try:
        engine.reset_envs(mask)
    except SimulatorError as error:
        raise backend.explain(error) from None


def split_backend_options(options: dict[str, Any]) -> dict[str, Any]:
    """Remove ``backend`` and BACKEND_OPTIONS from an env's keyword options; return them."""
    return {k: options.pop(k) for k in ("backend", *BACKEND_OPTIONS) if k in options}


def make_backend(
    task: TaskSpec, n: int, options: TaskOptions, backend_options: dict[str, Any]
) -> MavlinkBackend | None:
    """For ``backend="mavlink"``, the simulator processes ``n`` vehicles of ``task`` fly
    in (its ``fleet`` goes into the engine); None for the in-process physics."""
    kwargs = dict(backend_options)
    backend = kwargs.pop("backend", "inprocess")
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; choose one of {BACKENDS}")
    if backend == "inprocess":
        if kwargs:
            raise ValueError(f"{sorted(kwargs)} need backend='mavlink'")
        return None
    return MavlinkBackend(task, n, options, **kwargs)


def parse_address(address: str) -> tuple[str, int]:
    if not isinstance(address, str):
        raise ValueError(f"sim_address must be a 'HOST:PORT' string, got {address!r}")
    host, _, port_text = address.rpartition(":")
    try:
        port = int(port_text)
    except ValueError:
        raise ValueError(f"sim_address must be HOST:PORT, got {address!r}") from None
    if not 1 <= port <= 65535:
        raise ValueError(f"sim_address {address!r}: port must be 1..65535, got {port}")
    return host or "127.0.0.1", port


def max_spawned_simulators() -> int:
    """How many simulator processes this machine's free memory holds."""
    available = available_bytes()
    if math.isinf(available):  # not known on this platform: do not guess low
        return MAX_SIMULATORS
    return max(1, min(MAX_SIMULATORS, int(available // SIM_PROCESS_BYTES)))


def fleet_sizes(n: int, vehicles_per_sim: Any, simulators: Any) -> list[int]:
    """Vehicles of each simulator process: ``vehicles_per_sim`` each (the last one the
    rest), or ``n`` spread over ``simulators`` processes."""
    for name, value in (("vehicles_per_sim", vehicles_per_sim), ("simulators", simulators)):
        if value is not None and (
            isinstance(value, bool) or not isinstance(value, int) or value < 1
        ):
            raise ValueError(f"{name} must be a positive integer, got {value!r}")
    if vehicles_per_sim is not None and simulators is not None:
        raise ValueError("give vehicles_per_sim or simulators, not both")
    if simulators is not None:
        if simulators > n:
            raise ValueError(f"{simulators} simulators for {n} envs: at most one per env")
        per = -(-n // simulators)
    else:
        per = vehicles_per_sim or 1
    sizes = [per] * (n // per) + ([n % per] if n % per else [])
    return sizes


def ray_address(ray: Any, sim_address: Any) -> str | None:
    """The ``ray`` option as an address to join (``"local"`` for True), or None."""
    if ray is None or ray is False:
        return None
    if ray is not True and (not isinstance(ray, str) or not ray.strip()):
        raise ValueError(
            f"ray must be True or a Ray cluster address such as 10.0.0.1:6379, got {ray!r}"
        )
    if sim_address is not None:
        raise ValueError("give sim_address (running simulators) or ray (place them), not both")
    return LOCAL if ray is True else ray.strip()


def _check_wire_options(options: TaskOptions, task: TaskSpec) -> None:
    """One-line ValueError for the task options that cannot cross the wire. Airframes
    (``airframe_scale``, ``randomize``'s airframe draws) go to the simulator with each
    reset; a delay stays in this process and steps whole control periods, as the
    simulator answers once a period."""
    randomization = options.randomize
    if isinstance(randomization, Randomization) and randomization.wind is not None:
        raise ValueError(
            "randomize['wind'] is not available with backend='mavlink' yet (the simulator "
            "process flies in still air); use the in-process backend"
        )
    delay = options.delay
    if delay is None and isinstance(randomization, Randomization):
        delay = randomization.delay
    if isinstance(delay, Delay):
        period = options.control_period
        for kind in DELAY_KINDS:
            low, high = getattr(delay, kind)
            periods = high / period
            if low != high or abs(periods - round(periods)) > 1e-9:
                raise ValueError(
                    f"{kind} delay {low:g}..{high:g} s: backend='mavlink' steps whole control "
                    f"periods ({period:g} s), so its delays are fixed whole periods (finer or "
                    "drawn ones: the in-process backend, or quadsitl sim --delay)"
                )


def _check_options(
    sizes: list[int], spawned_here: bool, gcs: Any, system_id: Any, timeout: Any, signing_key: Any
) -> None:
    """A clear ValueError at construction for any option the backend cannot use."""
    n = sum(sizes)
    if spawned_here:
        limit = max_spawned_simulators()
        if len(sizes) > limit:
            raise ValueError(
                f"{n} envs would start {len(sizes)} simulator processes (about "
                f"{SIM_PROCESS_BYTES // 2**20} MB each); this machine's free memory holds "
                f"{limit}; put more vehicles in each (vehicles_per_sim), use fewer envs or "
                "start simulators elsewhere (sim_address, or ray=True for a Ray cluster)"
            )
    if (
        isinstance(timeout, bool)
        or not isinstance(timeout, (int, float))
        or not (math.isfinite(timeout) and 0 < timeout <= MAX_TIMEOUT)
    ):
        raise ValueError(f"timeout must be in (0, {MAX_TIMEOUT:g}] s, got {timeout!r}")
    if isinstance(system_id, bool) or not isinstance(system_id, int):
        raise ValueError(f"system_id must be an integer, got {system_id!r}")
    if not (system_id >= 1 and system_id + n - 1 <= MAX_SYSTEM_ID):  # unique across processes
        raise ValueError(
            f"system ids {system_id}..{system_id + n - 1} must lie in 1..{MAX_SYSTEM_ID}"
        )
    if signing_key is not None:
        if not isinstance(signing_key, (bytes, bytearray)):
            raise ValueError(
                f"signing_key must be 32 bytes (e.g. bytes.fromhex(...)), got "
                f"{type(signing_key).__name__}"
            )
        checked_key(bytes(signing_key), "signing_key")
    if gcs is not None:
        if not isinstance(gcs, str):
            raise ValueError(f"gcs must be a link URL such as udpout:127.0.0.1:14550, got {gcs!r}")
        parse_url(gcs)


class MavlinkBackend:
    """Runs a task's vehicles in ``quadsitl sim`` processes, ``vehicles_per_sim`` in each
    (one lockstep round trip per process steps all of them); ``fleet`` is the
    RemoteFleet the engine steps (it stays the same object across restarts).

    Args:
        task, n, options: the task, the number of vehicles, the task options.
        sim_address: "HOST:PORT" of a running ``quadsitl sim --lockstep --hil udpin:...``
            for each simulator process (a list; one string for one process) or None:
            start them here. A running one must host the vehicles this backend expects of
            it: process k the system ids ``system_id + k·vehicles_per_sim`` onwards.
        gcs: ground-station link URL of the spawned simulators (None: none).
        system_id: MAVLink system id of the first vehicle (then +1 each).
        timeout: seconds without progress before raising SimulatorError.
        signing_key: 32-byte MAVLink 2 key (the spawned simulators require it too).
        vehicles_per_sim: vehicles in each simulator process (default 1).
        simulators: instead, the number of simulator processes (vehicles spread evenly).
        ray: start the simulator processes as Ray actors spread over a cluster
            (:mod:`quadsitl.envs.ray_simulators`): True (the Ray this process joined, or
            a new local one, or RAY_ADDRESS) or a cluster address. Without a
            ``signing_key`` a random one is made for the run: simulators on a network
            accept only this env's commands.
    """

    def __init__(
        self,
        task: TaskSpec,
        n: int,
        options: TaskOptions,
        sim_address: str | list[str] | None = None,
        gcs: str | None = None,
        system_id: int = 1,
        timeout: float = 2.0,
        signing_key: bytes | None = None,
        vehicles_per_sim: int | None = None,
        simulators: int | None = None,
        ray: bool | str | None = None,
    ) -> None:
        _check_wire_options(options, task)
        if options.wind is not None:
            raise ValueError(
                "wind is not available with backend='mavlink' yet (the simulator process "
                "flies in still air); use the in-process backend"
            )
        if options.ground_effect or FT.motor_faults(options.faults):
            raise ValueError(
                "ground_effect and motor faults are not available with backend='mavlink' yet; use "
                "the in-process backend (or quadsitl sim --fail-motor, MAV_CMD_INJECT_FAILURE)"
            )
        airframe = get_airframe(options.airframe)  # type: ignore[arg-type]
        if AIRFRAMES.get(airframe.name) != airframe:
            raise ValueError(
                f"backend='mavlink' needs a preset airframe ({sorted(AIRFRAMES)}), "
                f"got a custom one named {airframe.name!r}"
            )
        addresses = [sim_address] if isinstance(sim_address, str) else sim_address
        if addresses is not None and vehicles_per_sim is None and simulators is None:
            simulators = len(addresses)  # one address per process
        self.sizes = fleet_sizes(n, vehicles_per_sim, simulators)
        self.ray = ray_address(ray, sim_address)
        spawned_here = sim_address is None and self.ray is None
        _check_options(self.sizes, spawned_here, gcs, system_id, timeout, signing_key)
        if self.ray is not None:
            join_ray(self.ray)
            if signing_key is None:
                signing_key = secrets.token_bytes(32)
        if addresses is not None and len(addresses) != len(self.sizes):
            raise ValueError(
                f"got {len(addresses)} simulator addresses for {len(self.sizes)} simulators"
            )
        self.n, self.options, self.airframe = n, options, airframe
        randomization = options.randomize
        varies = bool(options.airframe_scale) or bool(
            isinstance(randomization, Randomization) and randomization.airframe
        )
        self.fleet = RemoteFleet(
            n, airframe, options.physics_dt, options.control_period, task.ground, varies
        )
        self.addresses = [parse_address(a) for a in addresses] if addresses else None
        self.timeout = timeout
        self.signing_key = bytes(signing_key) if signing_key is not None else None
        self.gcs = gcs
        self.system_id = system_id
        self.first_ids = [system_id + sum(self.sizes[:k]) for k in range(len(self.sizes))]
        self.processes: list[SimProcess | RaySimulator] = []
        self.clients: list[FleetClient] = []
        self._connect()

    def _sim_args(self, index: int) -> list[str]:
        o = self.options
        return [
            "--physics-rate",
            f"{1 / o.physics_dt:.12g}",
            "--control-rate",
            f"{1 / o.control_period:.12g}",
            "--airframe",
            self.airframe.name,
            "--sysid",
            str(self.first_ids[index]),
            "--vehicles",
            str(self.sizes[index]),
            "--gcs",
            self.gcs or "none",
            "--api",
            "none",
        ]

    def _connect(self) -> None:
        try:
            if self.addresses is None:
                key = {"QUADSITL_SIGNING_KEY": self.signing_key.hex()} if self.signing_key else {}
                commands = [self._sim_args(i) for i in range(len(self.sizes))]
                if self.ray is None:
                    self.processes = [SimProcess(args, env=key) for args in commands]
                else:
                    self.processes = list(place_simulators(commands, key))
                addresses = [p.address for p in self.processes]
            else:
                addresses = self.addresses
            for k, (host, port) in enumerate(addresses):
                client = FleetClient(
                    host, port, self.sizes[k], self.first_ids[k], self.timeout, self.signing_key
                )
                self.clients.append(client)
                self._wait_for_heartbeats(k)
        except BaseException:
            self._release()
            raise
        self.fleet.connect(self.clients)

    def _wait_for_heartbeats(self, index: int) -> None:
        """Wait until simulator ``index`` (where this backend started it) has opened its
        link, however long its start takes while it lives, then for its vehicles'
        heartbeats."""
        process = self.processes[index] if self.processes else None
        if process is not None:
            _wait_until_listening(process)
        deadline = time.monotonic() + (START_TIMEOUT if process else self.timeout)
        while True:
            if process is not None and not process.alive:
                raise SimulatorError(f"quadsitl sim {process.exit_message()}")
            try:
                self.clients[index].connect()
                return
            except SimulatorError:
                if time.monotonic() > deadline:
                    raise

    def check_alive(self) -> None:
        """Before a reset: restart simulator processes if one has died, with a warning."""
        self.fleet.check_open()
        dead = [p for p in self.processes if not p.alive]
        if dead:
            reason = dead[0].exit_message()
            self._release()
            warnings.warn(f"quadsitl sim {reason}; starting new ones", RuntimeWarning, 3)
            self._connect()

    def explain(self, error: SimulatorError) -> SimulatorError:
        """The error, with a dead process's exit message."""
        dead = [p for p in self.processes if not p.alive]
        if dead:
            return SimulatorError(f"{error} (quadsitl sim {dead[0].exit_message()})")
        return error

    def close(self) -> None:
        self.fleet.close()
        self._release()

    def _release(self) -> None:
        for client in self.clients:
            client.close()
        for process in self.processes:
            process.stop()
        self.clients, self.processes = [], []


def _wait_until_listening(process: SimProcess | RaySimulator) -> None:
    """Until ``process`` has opened its link; SimulatorError if it dies first or is still
    starting after START_LIMIT."""
    started = time.monotonic()
    while not process.listening:
        if not process.alive:
            raise SimulatorError(f"quadsitl sim {process.exit_message()}")
        if time.monotonic() - started > START_LIMIT:
            host, port = process.address
            raise SimulatorError(
                f"quadsitl sim at {host}:{port} is running but did not open its link within "
                f"{START_LIMIT:g} s of starting"
            )
        time.sleep(START_POLL)
