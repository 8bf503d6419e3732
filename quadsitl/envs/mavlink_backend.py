"""The ``backend="mavlink"`` of the task envs: a simulator process, a lockstep client,
and a :class:`RemoteFleet` in the task engine in place of the in-process physics.

Faults: a simulator that dies or stops answering makes ``step``/``reset`` raise
:class:`SimulatorError` within ``timeout`` seconds (the process's own exit message
included); the next ``reset`` starts a fresh process and warns that it did.
"""

from __future__ import annotations

import time
import warnings

from quadsitl.envs.remote_fleet import RemoteFleet
from quadsitl.envs.sim_process import SimProcess
from quadsitl.mavlink.motor_client import MotorClient, SimulatorError
from quadsitl.physics import AIRFRAMES
from quadsitl.tasks import TaskEngine

START_TIMEOUT = 30.0  # s for a new simulator process to answer (imports, kernel load)


def parse_address(address: str) -> tuple[str, int]:
    host, _, port = address.rpartition(":")
    try:
        return host or "127.0.0.1", int(port)
    except ValueError:
        raise ValueError(f"sim_address must be HOST:PORT, got {address!r}") from None


class MavlinkBackend:
    """Runs an engine's single vehicle in ``quadsitl sim`` (spawned, or at ``address``).

    Args:
        engine: a one-env TaskEngine; its fleet is replaced by a RemoteFleet.
        address: "HOST:PORT" of a running ``quadsitl sim --lockstep --hil udpin:...``
            (None: start one).
        gcs: ground-station link URL for a spawned simulator (None: no GCS link).
        system_id: MAVLink system id of a spawned simulator.
        timeout: seconds to wait for any answer before raising SimulatorError.
        signing_key: 32-byte MAVLink 2 key (the spawned simulator requires it too).
    """

    def __init__(
        self,
        engine: TaskEngine,
        address: str | None = None,
        gcs: str | None = None,
        system_id: int = 1,
        timeout: float = 2.0,
        signing_key: bytes | None = None,
    ) -> None:
        options = engine.options
        if options.param_randomization:
            raise ValueError("param_randomization is not available with backend='mavlink'")
        airframe = engine.airframe
        if AIRFRAMES.get(airframe.name) != airframe:
            raise ValueError(
                f"backend='mavlink' needs a preset airframe ({sorted(AIRFRAMES)}), "
                f"got a custom one named {airframe.name!r}"
            )
        self.engine = engine
        self.address = parse_address(address) if address else None
        self.timeout = timeout
        self.signing_key = signing_key
        self.sim_args = [
            "--physics-rate", f"{1 / options.physics_dt:.12g}",
            "--control-rate", f"{1 / options.control_period:.12g}",
            "--airframe", airframe.name, "--sysid", str(system_id),
            "--gcs", gcs or "none", "--api", "none",
        ]  # fmt: skip
        self.process: SimProcess | None = None
        self.client: MotorClient | None = None
        self._connect()

    def _connect(self) -> None:
        if self.address is not None:
            host, port = self.address
        else:
            key = {"QUADSITL_SIGNING_KEY": self.signing_key.hex()} if self.signing_key else {}
            self.process = SimProcess(self.sim_args, env=key)
            host, port = "127.0.0.1", self.process.port
        self.client = MotorClient(host, port, self.timeout, self.signing_key)
        deadline = time.monotonic() + (START_TIMEOUT if self.process else self.timeout)
        while True:
            if self.process is not None and not self.process.alive:
                raise SimulatorError(f"quadsitl sim {self.process.exit_message()}")
            try:
                self.client.connect()
                break
            except SimulatorError:
                if time.monotonic() > deadline:
                    self.close()
                    raise
        o = self.engine.options
        self.engine.fleet = RemoteFleet(
            self.client,
            self.engine.airframe,
            o.physics_dt,
            o.control_period,
            self.engine.task.ground,
        )

    def check_alive(self) -> None:
        """Before a reset: restart a simulator process that has died, with a warning."""
        if self.process is not None and not self.process.alive:
            reason = self.process.exit_message()
            self.close()
            warnings.warn(f"quadsitl sim {reason}; starting a new one", RuntimeWarning, 2)
            self._connect()

    def explain(self, error: SimulatorError) -> SimulatorError:
        """The error, with the process's exit message when it has died."""
        if self.process is not None and not self.process.alive:
            return SimulatorError(f"{error} (quadsitl sim {self.process.exit_message()})")
        return error

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
            self.client = None
        if self.process is not None:
            self.process.stop()
            self.process = None
