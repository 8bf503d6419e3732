"""Simulator processes placed on a Ray cluster: one Ray actor owns one ``quadsitl sim``.

With ``backend="mavlink", ray=...`` the envs' simulators are not started here but by
actors that Ray spreads over the cluster's nodes (``scheduling_strategy="SPREAD"``, one
CPU each). Each actor starts its simulator on its node, listening on the node's address,
and reports where; the env then flies the vehicles over UDP exactly as it does with
local processes. The actor is the simulator's lifetime: when the actor or its node is
lost, the simulator goes with it, the env raises ``SimulatorError`` (saying so) and the
next ``reset`` places new actors.

Ray is an optional dependency (the ``sweep`` extra); nothing here imports it until a
simulator is placed.
"""

from __future__ import annotations

import contextlib
import os
import socket
import sys
from typing import Any

from quadsitl.envs.sim_process import SimProcess
from quadsitl.lockstep_client.motor_client import SimulatorError

PLACE_LIMIT = 600.0  # s for Ray to place the actors and their simulators to start: a hang
# guard only (a loaded two-core machine took minutes to start Ray's workers); a cluster
# with too few CPUs in all is said at once
SLOW_PLACE = 60.0  # s after which a placement still under way is said, once
CALL_TIMEOUT = 5.0  # s for an actor to answer a question about its simulator
LOCAL = "local"  # ray=True: a Ray started here, or the cluster named by RAY_ADDRESS


def ray_target(address: str | None) -> tuple[str, str]:
    """(the address for ``ray.init``, what it is in words). Joining a cluster is explicit:
    ``address`` (other than ``"local"``), else the environment's RAY_ADDRESS; otherwise
    ``"local"``, a private Ray started here. Never Ray's own default, which joins the
    cluster that its ``ray_current_cluster`` file names — even one long dead."""
    if address and address != LOCAL:
        return address, f"the Ray cluster at {address}"
    named = os.environ.get("RAY_ADDRESS", "").strip()
    if named:
        return named, f"the Ray cluster at {named} (from RAY_ADDRESS)"
    return LOCAL, "a private local Ray"


def check_ray_address(address: str) -> None:
    """An unreachable cluster is an error now (``ray.init`` would wait a long time).
    ``"local"`` and Ray's ``"auto"`` need no check."""
    if address in (LOCAL, "auto"):
        return
    host, _, port = address.removeprefix("ray://").rpartition(":")
    try:
        with socket.create_connection((host or "127.0.0.1", int(port)), timeout=3):
            return
    except (OSError, ValueError) as error:
        raise ValueError(f"no Ray cluster answers at {address!r} ({error})") from None


def import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise ValueError(
            "simulators on Ray need Ray: pip install 'quadsitl[sweep]' (ray[tune])"
        ) from None
    return ray


def join_ray(address: str) -> None:
    """Use the Ray this process already joined, or join ``address`` (``"local"``: start
    a private one here unless RAY_ADDRESS names a cluster; :func:`ray_target`)."""
    ray = import_ray()
    if ray.is_initialized():
        return
    target, _ = ray_target(address)
    check_ray_address(target)
    ray.init(
        address=target,
        include_dashboard=False,
        log_to_driver=False,
        configure_logging=False,
    )


class SimulatorHost:
    """The actor: starts ``quadsitl sim`` on its node and answers for it."""

    def __init__(self, args: list[str], env: dict[str, str]) -> None:
        import ray

        self.node_id = ray.get_runtime_context().get_node_id()
        self.process = SimProcess(args, env=env, host=ray.util.get_node_ip_address())

    def address(self) -> tuple[str, int, str]:
        return self.process.host, self.process.port, self.node_id

    def alive(self) -> bool:
        return self.process.alive

    def listening(self) -> bool:
        return self.process.listening

    def exit_message(self) -> str:
        return self.process.exit_message()

    def stop(self) -> None:
        self.process.stop()


def place_simulators(commands: list[list[str]], env: dict[str, str]) -> list[RaySimulator]:
    """One simulator per list of ``quadsitl sim`` options, placed by Ray all at once
    (they start in parallel); SimulatorError when Ray cannot place or start them: at
    once when the cluster has fewer CPUs than simulators, else after PLACE_LIMIT s
    (a slow start is waited for, and said after SLOW_PLACE s)."""
    ray = import_ray()
    total = ray.cluster_resources().get("CPU", 0)
    if total < len(commands):
        raise SimulatorError(
            f"the Ray cluster has {total:g} CPUs in all; {len(commands)} simulators need "
            "1 each: put more vehicles in each simulator (vehicles_per_sim) or add nodes"
        )
    actor_class = ray.remote(num_cpus=1, max_restarts=0)(SimulatorHost)
    actors = [
        actor_class.options(scheduling_strategy="SPREAD").remote(args, env) for args in commands
    ]
    try:
        where = _wait_for_addresses(ray, actors)
    except ray.exceptions.GetTimeoutError:
        free = ray.available_resources().get("CPU", 0)
        error = SimulatorError(
            f"Ray placed {len(actors)} simulators not within {PLACE_LIMIT:g} s (the "
            f"cluster has {free:g} of {total:g} CPUs free; each simulator needs 1)"
        )
    except ray.exceptions.RayError as failure:
        error = SimulatorError(f"a Ray simulator actor failed to start: {failure}")
    else:
        return [RaySimulator(actor, *address) for actor, address in zip(actors, where, strict=True)]
    for actor in actors:
        ray.kill(actor)
    raise error


def _wait_for_addresses(ray: Any, actors: list[Any]) -> list[tuple[str, int, str]]:
    """Each actor's (host, port, node) once its simulator listens; says once on stderr
    when that takes longer than SLOW_PLACE s; GetTimeoutError after PLACE_LIMIT s."""
    pending = [actor.address.remote() for actor in actors]
    try:
        return ray.get(pending, timeout=SLOW_PLACE)
    except ray.exceptions.GetTimeoutError:
        print(
            f"quadsitl: Ray is still placing or starting {len(actors)} simulators after "
            f"{SLOW_PLACE:g} s (waiting up to {PLACE_LIMIT:g} s)",
            file=sys.stderr,
            flush=True,
        )
    return ray.get(pending, timeout=PLACE_LIMIT - SLOW_PLACE)


class RaySimulator:
    """A simulator placed by Ray (:func:`place_simulators`), with :class:`SimProcess`'s
    face (``address``, ``alive``, ``listening``, ``exit_message``, ``stop``) for the
    backend."""

    def __init__(self, actor: Any, host: str, port: int, node_id: str) -> None:
        self.actor, self.host, self.port, self.node_id = actor, host, port, node_id
        self.ray = import_ray()

    @property
    def address(self) -> tuple[str, int]:
        return self.host, self.port

    @property
    def alive(self) -> bool:
        ray = self.ray
        try:
            return bool(ray.get(self.actor.alive.remote(), timeout=CALL_TIMEOUT))
        except ray.exceptions.RayError:  # the actor, its node or the call is lost
            return False

    @property
    def listening(self) -> bool:
        """Whether its simulator has opened its link (False while that is not known:
        ``alive`` tells a lost actor)."""
        ray = self.ray
        try:
            return bool(ray.get(self.actor.listening.remote(), timeout=CALL_TIMEOUT))
        except ray.exceptions.RayError:
            return False

    def exit_message(self) -> str:
        ray = self.ray
        where = f"on {self.host} (Ray node {self.node_id[:12]})"
        try:
            return f"{where} {ray.get(self.actor.exit_message.remote(), timeout=CALL_TIMEOUT)}"
        except ray.exceptions.RayError as error:
            return f"{where} was lost with its Ray actor ({type(error).__name__})"

    def stop(self) -> None:
        ray = self.ray
        with contextlib.suppress(ray.exceptions.RayError):  # already gone
            ray.get(self.actor.stop.remote(), timeout=CALL_TIMEOUT)
        ray.kill(self.actor)
