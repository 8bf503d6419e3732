"""Training through the wire: env steps per second of the MAVLink envs, fleets, loss.

* ``mavlink_env_steps_per_s``: one ``QuadSITL/Hover-v0`` env with ``backend="mavlink"``
  (gym.make, with Gymnasium's wrappers), each step one lockstep round trip;
* ``mavlink_env_steps_per_s_2proc``: the native vector env over two simulator processes;
* the fleet curve: the native vector env over ONE simulator process hosting 1, 8, 64
  and 254 vehicles (``vehicles_per_sim``; 254 system ids are all MAVLink has), env
  steps/s; ``mavlink_env_steps_per_s_fleet`` is the 64-vehicle point (target ≥ 40,000);
* ``lockstep_vs_udp_limit``: single-vehicle lockstep round trips per second divided by
  a plain Python UDP ping-pong between two processes, measured in the same run
  (target ≥ 0.5);
* ``mavlink_env_loss10_episode_fraction``: 8 vehicles through a relay that drops 10 %
  of the datagrams both ways: the fraction of episodes that complete without an error
  (target ≥ 0.99), and the throughput against the same relay without loss (target ≥ 0.5).

Actions: small random perturbations around hover, so episodes end at the task's own
rate and autoresets are included.
"""

from __future__ import annotations

import multiprocessing
import socket
import sys
import time
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import quadsitl  # noqa: F401  (registers the envs)
from gcs_tools.relay import LossyRelay
from quadsitl.envs.sim_process import SimProcess
from quadsitl.lockstep_client.fleet_client import FleetClient
from quadsitl.lockstep_client.motor_client import SimulatorError
from quadsitl.physics import PAPER
from quadsitl.wire.state import WireState

ENV_ID = "QuadSITL/Hover-v0"
SECONDS = 3.0
FLEET_SIZES = (1, 8, 64, 254)  # 254: every MAVLink system id (256 do not fit)
RATES = ["--physics-rate", "100", "--control-rate", "20", "--gcs", "none", "--api", "none"]


def best_timed_rate(step: Callable[[], int], seconds: float, repeats: int) -> float:
    """The best of ``repeats`` runs of ``seconds`` each, in counts per second: ``step``
    does one piece of work and returns its count (env steps, round trips)."""
    best = 0.0
    for _ in range(repeats):
        count, start = 0, time.perf_counter()
        while time.perf_counter() - start < seconds:
            count += step()
        best = max(best, count / (time.perf_counter() - start))
    return best


def single_rate(env: gym.Env, repeats: int = 3) -> float:
    rng = np.random.default_rng(0)
    env.reset(seed=0)

    def step() -> int:
        action = rng.normal(0, 0.05, 4).astype(np.float32)
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
        return 1

    return best_timed_rate(step, SECONDS, repeats)


def vector_rate(envs: gym.vector.VectorEnv, seconds: float = SECONDS, repeats: int = 2) -> float:
    rng = np.random.default_rng(0)
    envs.reset(seed=0)

    def step() -> int:
        envs.step(rng.normal(0, 0.05, (envs.num_envs, 4)).astype(np.float32))
        return envs.num_envs

    return best_timed_rate(step, seconds, repeats)


def fleet_curve() -> dict[int, float]:
    rates = {}
    for size in FLEET_SIZES:
        options = {"backend": "mavlink", "vehicles_per_sim": size, "timeout": 10.0}
        envs = gym.make_vec(ENV_ID, size, "vector_entry_point", **options)
        rates[size] = vector_rate(envs)
        envs.close()
    return rates


# --- the UDP limit: a plain ping-pong between two processes ------------------------------
def _echo(port: int, ready: multiprocessing.synchronize.Event) -> None:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", port))
    ready.set()
    while True:
        data, peer = sock.recvfrom(65535)
        if data == b"stop":
            return
        sock.sendto(data, peer)


def udp_round_trips() -> float:
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    ready = multiprocessing.Event()
    echo = multiprocessing.Process(target=_echo, args=(port, ready), daemon=True)
    echo.start()
    ready.wait(5)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    payload = bytes(100)  # about one command

    def round_trip() -> int:
        sock.sendto(payload, ("127.0.0.1", port))
        sock.recv(65535)
        return 1

    best = best_timed_rate(round_trip, SECONDS / 2, repeats=3)
    sock.sendto(b"stop", ("127.0.0.1", port))
    echo.join(2)
    return best


def lockstep_round_trips() -> float:
    sim = SimProcess(["--vehicles", "1", *RATES])
    client = FleetClient("127.0.0.1", sim.port, 1, timeout=10.0)
    try:
        deadline = time.monotonic() + 30
        while True:
            try:
                client.connect()
                break
            except SimulatorError:
                if time.monotonic() > deadline:
                    raise
        state = np.zeros((1, 17))
        state[0, 2], state[0, 6], state[0, 13:] = 20.0, 1.0, PAPER.hover_rotor_speed
        wire = WireState.from_physics(state, PAPER.gear_height, 0, None, None)
        client.reset([0], wire, np.zeros((1, 3)))
        hover = np.full((1, 4), PAPER.hover_rotor_speed / PAPER.max_rotor_speed)

        def round_trip() -> int:
            client.step(hover)
            return 1

        return best_timed_rate(round_trip, SECONDS / 2, repeats=3)
    finally:
        client.close()
        sim.stop()


# --- 10 % loss both ways -------------------------------------------------------------------
def through_relay(drop: float, vehicles: int = 8, seconds: float = 10.0) -> tuple[float, int, int]:
    """(env steps/s, episodes completed, episodes cut short by an error)."""
    sim = SimProcess(["--vehicles", str(vehicles), *RATES])
    relay = LossyRelay(("127.0.0.1", sim.port), drop=drop, seed=1)
    address = f"127.0.0.1:{relay.port}"
    options = {"backend": "mavlink", "vehicles_per_sim": vehicles, "sim_address": address}
    envs = gym.make_vec(ENV_ID, vehicles, "vector_entry_point", timeout=20.0, **options)
    rng = np.random.default_rng(0)
    completed = failed = steps = 0
    try:
        envs.reset(seed=0)
        start = time.perf_counter()
        while time.perf_counter() - start < seconds:
            try:
                _, _, terminated, truncated, _ = envs.step(
                    rng.normal(0, 0.05, (vehicles, 4)).astype(np.float32)
                )
            except SimulatorError:
                failed += vehicles  # every episode in flight is lost
                envs.reset()
                continue
            steps += vehicles
            completed += int((terminated | truncated).sum())
        rate = steps / (time.perf_counter() - start)
    finally:
        envs.close()
        relay.close()
        sim.stop()
    return rate, completed, failed


def main() -> None:
    local = gym.make(ENV_ID)
    in_process = single_rate(local)
    local.close()
    remote = gym.make(ENV_ID, backend="mavlink")
    one = single_rate(remote)
    remote.close()
    envs = gym.make_vec(ENV_ID, 2, vectorization_mode="vector_entry_point", backend="mavlink")
    two = vector_rate(envs)
    envs.close()
    print(f"in-process single env: {in_process:,.0f} env steps/s")
    print(f"MAVLink env, 1 simulator process: {one:,.0f} env steps/s")
    print(f"MAVLink envs, 2 simulator processes (native vector env): {two:,.0f} env steps/s")
    print(f"mavlink_env_steps_per_s: {one:.0f}")
    print(f"mavlink_env_steps_per_s_2proc: {two:.0f}")

    curve = fleet_curve()
    print("fleet curve (one simulator process, native vector env):")
    for size, rate in curve.items():
        print(f"  {size:4d} vehicles: {rate:10,.0f} env steps/s")
    fleet = curve[64]
    verdict = "meets" if fleet >= 40_000 else "BELOW"
    print(f"mavlink_env_steps_per_s_fleet: {fleet:,.0f} env steps/s (target 40,000, {verdict})")
    print(f"mavlink_env_steps_per_s_fleet: {fleet:.0f}")

    udp, lockstep = udp_round_trips(), lockstep_round_trips()
    ratio = lockstep / udp
    print(f"plain UDP ping-pong: {udp:,.0f} round trips/s; lockstep: {lockstep:,.0f} rounds/s")
    verdict = "meets" if ratio >= 0.5 else "BELOW"
    print(f"lockstep_vs_udp_limit: {ratio:.2f} (target 0.50, {verdict})")

    clean_rate, _, _ = through_relay(0.0)
    lossy_rate, completed, failed = through_relay(0.1)
    fraction = completed / max(1, completed + failed)
    print(
        f"through the relay: {clean_rate:,.0f} env steps/s without loss, {lossy_rate:,.0f} "
        f"with 10 % loss both ways ({lossy_rate / clean_rate:.2f} of it, target 0.50); "
        f"{completed} episodes completed, {failed} cut short"
    )
    verdict = "meets" if fraction >= 0.99 and lossy_rate >= 0.5 * clean_rate else "BELOW"
    print(f"mavlink_env_loss10_episode_fraction: {fraction:.3f} (target 0.99, {verdict})")
    print(f"mavlink_env_loss10_throughput_ratio: {lossy_rate / clean_rate:.2f}")


if __name__ == "__main__":
    main()
