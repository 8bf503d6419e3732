"""Shared fixtures: a real ``quadsitl sim`` process and a pymavlink client talking to it."""

from __future__ import annotations

import contextlib
import io
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from gcs_tools.client import VehicleClient
from gcs_tools.demo import free_udp_port
from quadsitl.envs.mavlink_backend import START_LIMIT, START_POLL
from quadsitl.envs.sim_process import UDP_TABLES, terminate, udp_port_bound
from quadsitl.lockstep_client.motor_client import MotorClient, SimulatorError

# The signing timestamps that simulators keep across restarts go to this session's own
# folder (inherited by every simulator process), never to the user's state folder.
if "QUADSITL_STATE_DIR" not in os.environ:
    _STATE = tempfile.TemporaryDirectory(prefix="quadsitl-test-state-")  # removed at exit
    os.environ["QUADSITL_STATE_DIR"] = _STATE.name

# Tests interrupt the processes they start (Ctrl-C must save and exit cleanly). A suite
# started in the background by a non-interactive shell (`make test &`, nohup) inherits an
# ignored SIGINT, and so would every process it starts: those would never see the
# interrupt. Python's own handler here is reset to the default in each child at exec.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# In-process against through the wire: float32 on the wire, carried through episodes;
# rewards weigh distance changes by up to 100.
OBS_TOLERANCE = 1e-4
REWARD_TOLERANCE = 2e-3


def fly_both(local, remote, rng: np.random.Generator, steps: int, scale: float) -> int:  # type: ignore[no-untyped-def]
    """Step the in-process and the wire vector envs with the same random rotor actions
    (normal, ``scale``) for ``steps`` steps, asserting the same observations, rewards and
    endings at each one (through autoresets); returns how many episodes ended."""
    ended = 0
    for _ in range(steps):
        actions = rng.normal(0, scale, (local.num_envs, 4)).astype(np.float32)
        a, ra, ta, ua, _ = local.step(actions)
        b, rb, tb, ub, _ = remote.step(actions)
        np.testing.assert_allclose(b, a, atol=OBS_TOLERANCE)
        np.testing.assert_allclose(rb, ra, atol=REWARD_TOLERANCE)
        assert (ta == tb).all() and (ua == ub).all()
        ended += int((ta | ua).sum())
    return ended


def reset_both(local, remote, seed: int) -> None:  # type: ignore[no-untyped-def]
    """Reset the in-process and the wire vector envs with ``seed``, asserting the same
    first observations."""
    a, _ = local.reset(seed=seed)
    b, _ = remote.reset(seed=seed)
    np.testing.assert_allclose(b, a, atol=OBS_TOLERANCE)


def step_as_singles(vector, singles, seed: int, actions: np.ndarray) -> None:  # type: ignore[no-untyped-def]
    """Reset the vector env ``vector`` with ``seed`` and step it with ``actions`` (steps ×
    envs × 4), asserting each step the same observations and rewards, exactly, as each
    of the single envs ``singles`` reset with ``seed + i`` and stepped with its own
    action; no episode may end on the way."""
    obs, _ = vector.reset(seed=seed)
    for i, env in enumerate(singles):
        np.testing.assert_array_equal(obs[i], env.reset(seed=seed + i)[0])
    for step in actions:
        obs, reward, terminated, truncated, _ = vector.step(step)
        assert not (terminated | truncated).any()
        for i, env in enumerate(singles):
            single_obs, single_reward, *_ = env.step(step[i])
            np.testing.assert_array_equal(obs[i], single_obs)
            assert reward[i] == single_reward


def wait_until_listening(process: subprocess.Popen[Any], *ports: int) -> None:
    """Until the simulator ``process`` has opened its links: bound every UDP port in
    ``ports`` (its udpin links) or, with none named (udpout links only, each bound to a
    port of the system's choosing), a UDP socket of its own. A simulator opens its links
    last, after its imports and compiled kernels, which a loaded machine stretches past
    any fixed deadline: a test's heartbeat wait starts from here. Fails at once, with the
    process's output, if it exits first; kills it and fails if it is still starting after
    START_LIMIT (a hang). Returns at once where the host cannot tell (not Linux)."""
    started = time.monotonic()
    while True:
        if process.poll() is not None:
            pytest.fail(
                f"quadsitl sim exited with code {process.returncode} before opening its "
                f"links: {_last_words(process)}",
                pytrace=False,
            )
        if _links_open(process.pid, ports):
            return
        if time.monotonic() - started > START_LIMIT:
            process.kill()
            pytest.fail(
                f"quadsitl sim did not open its links within {START_LIMIT:g} s of starting: "
                f"{_last_words(process)}",
                pytrace=False,
            )
        time.sleep(START_POLL)


def _links_open(pid: int, ports: tuple[int, ...]) -> bool:
    if not os.path.exists(UDP_TABLES[0]):
        return True  # cannot tell: no waiting
    if ports:
        return all(udp_port_bound(port) is not False for port in ports)
    try:
        return bool(socket_addresses(pid, ("udp", "udp6")))
    except OSError:  # it has just exited: the next look says so
        return False


def _last_words(process: subprocess.Popen[Any]) -> str:
    """The end of what an ended process wrote to its pipes (stdout, stderr)."""
    said = [
        text.decode(errors="replace") if isinstance(text, bytes) else text
        for text in process.communicate(timeout=30)
        if text
    ]
    return "\n".join(said).strip()[-2000:] or "(no output)"


def socket_addresses(
    pid: int, tables: tuple[str, ...] = ("udp", "tcp", "udp6", "tcp6")
) -> list[str]:
    """Local addresses (hex, as /proc/net shows them) of every socket of ``pid`` in the
    /proc/net ``tables`` (bound ones: a socket is listed once it has an address)."""
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        try:
            target = os.readlink(fd)
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[len("socket:[") : -1])
    addresses = []
    for table in tables:
        path = Path(f"/proc/{pid}/net/{table}")
        if not path.exists():  # udp6, tcp6 without IPv6
            continue
        for line in path.read_text().splitlines()[1:]:
            fields = line.split()
            if fields[9] in inodes:
                addresses.append(fields[1].split(":")[0])
    return addresses


STOP_LIMIT = 20.0  # s a simulator has to end after SIGTERM before it is killed


def stop_process(process: subprocess.Popen[str]) -> tuple[str, str]:
    """SIGTERM (unless it has ended), then what it wrote to its pipes (stdout, stderr;
    "" for one not piped); killed if it is still running STOP_LIMIT later, so that a
    test never leaves a process behind nor hangs on one."""
    if process.poll() is None:
        process.terminate()
    try:
        out, err = process.communicate(timeout=STOP_LIMIT)
    except subprocess.TimeoutExpired:
        process.kill()
        out, err = process.communicate()
    return out or "", err or ""


@dataclass
class SimRun:
    """A ``quadsitl sim`` started by :func:`running_sim`: its process and the ports it
    listens on; once stopped, what it wrote (``output``: stdout, with stderr unless that
    was piped apart into ``errors``)."""

    process: subprocess.Popen[str]
    ports: tuple[int, ...]
    output: str = ""
    errors: str = ""


@contextlib.contextmanager
def running_sim(
    words: str, *args: object, ports: tuple[int, ...] = (), stderr: int = subprocess.STDOUT
) -> Iterator[SimRun]:
    """``quadsitl WORDS ARGS`` (as :func:`cli` reads them) from its start until its links
    are open (:func:`wait_until_listening` on ``ports``) to its stop on leaving
    (:func:`stop_process`, also when the test fails), its output then kept."""
    process = subprocess.Popen(cli(words, *args), stdout=subprocess.PIPE, stderr=stderr, text=True)
    run = SimRun(process, ports)
    try:
        wait_until_listening(process, *ports)
        yield run
    finally:
        run.output, run.errors = stop_process(process)


@contextlib.contextmanager
def sim_with_client(
    options: str, *args: object, connect_timeout: float = 30, stderr: int = subprocess.STDOUT
) -> Iterator[tuple[VehicleClient, SimRun]]:
    """``quadsitl sim --gcs udpin:127.0.0.1:PORT --api none OPTIONS ARGS`` on a free
    ``PORT`` (:func:`running_sim`) and a ground station's :class:`VehicleClient`
    connected to it within ``connect_timeout`` s; the client is closed before the
    simulator is stopped."""
    port = free_udp_port()
    gcs = f"sim --gcs udpin:127.0.0.1:{port} --api none"
    with running_sim(f"{gcs} {options}", *args, ports=(port,), stderr=stderr) as run:
        client = VehicleClient(f"udpout:127.0.0.1:{port}")
        try:
            client.connect(timeout=connect_timeout)
            yield client, run
        finally:
            client.close()


class RunningSim:
    def __init__(self, process: subprocess.Popen[str], port: int, log_dir: str) -> None:
        self.process, self.port, self.log_dir = process, port, log_dir

    def stop(self) -> str:
        """SIGTERM, wait, return the combined output."""
        terminate(self.process, 10.0)
        return self.process.stdout.read() if self.process.stdout else ""


def start_sim(log_dir: str, speed: float = 5.0) -> RunningSim:
    """``quadsitl sim`` listening on a free UDP port (udpin), no API link."""
    port = free_udp_port()
    process = subprocess.Popen(
        cli(f"sim --gcs udpin:127.0.0.1:{port} --api none --speed {speed} --logs", log_dir),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    wait_until_listening(process, port)
    return RunningSim(process, port, log_dir)


class MotorSim:
    """``quadsitl sim`` with a motor link and a ground-station link, both udpin; made
    once both are open."""

    def __init__(self, *options: str) -> None:
        self.hil_port, self.gcs_port = free_udp_port(), free_udp_port()
        gcs, hil = f"udpin:127.0.0.1:{self.gcs_port}", f"udpin:127.0.0.1:{self.hil_port}"
        self.process = subprocess.Popen(
            cli(f"sim --api none --logs none --gcs {gcs} --hil {hil}", *options),
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        wait_until_listening(self.process, self.hil_port, self.gcs_port)

    def client(self, **kwargs: object) -> MotorClient:
        client = MotorClient("127.0.0.1", self.hil_port, **kwargs)  # type: ignore[arg-type]
        deadline = time.monotonic() + 60  # for its vehicles to answer, the link being open
        while True:
            try:
                client.connect()
                return client
            except SimulatorError:
                if time.monotonic() > deadline or self.process.poll() is not None:
                    raise

    def stop(self) -> str:
        self.process.terminate()
        try:
            out, _ = self.process.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            out, _ = self.process.communicate()
        return out


def vector_env(task: str, **options):  # type: ignore[no-untyped-def]
    """Three envs of ``task`` (e.g. "Hover") stepped as training steps them: an episode
    that ends is reset in the same step."""
    return gym.make_vec(
        f"QuadSITL/{task}-v0",
        num_envs=3,
        vectorization_mode="vector_entry_point",
        autoreset_mode=AutoresetMode.SAME_STEP,
        **options,
    )


def cli(words: str, *args: object) -> list[str]:
    """The command line of ``python -m quadsitl.cli``: ``words`` (fixed options, split at
    spaces) then ``args`` (one argument each, e.g. paths)."""
    return [sys.executable, "-m", "quadsitl.cli", *words.split(), *map(str, args)]


def run_cli(*args: str, env: dict[str, str] | None = None, timeout: float = 120):
    """``quadsitl ARGS`` to completion, output captured."""
    return subprocess.run(
        [sys.executable, "-m", "quadsitl.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, **(env or {})},
    )


def refused_here(*args: str) -> subprocess.CompletedProcess[str]:
    """``quadsitl ARGS`` run in this process, output captured: for a command that must be
    refused before it starts anything (a process of its own costs seconds of imports,
    and the console entry point is the same ``main``)."""
    from quadsitl.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(list(args))
        except SystemExit as exit_:  # argparse's own refusals
            code = exit_.code if isinstance(exit_.code, int) else 1
    return subprocess.CompletedProcess(list(args), code, out.getvalue(), err.getvalue())


def start_quiet_sim(*args: str) -> subprocess.Popen[str]:
    """``quadsitl sim --logs none ARGS``; its first stdout line is the banner."""
    return subprocess.Popen(
        [sys.executable, "-m", "quadsitl.cli", "sim", "--logs", "none", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def interrupt(process: subprocess.Popen[str]) -> tuple[str, str]:
    """Ctrl-C, then (stdout, stderr)."""
    process.send_signal(signal.SIGINT)
    return process.communicate(timeout=15)


@pytest.fixture
def sim(tmp_path) -> Iterator[RunningSim]:
    """The simulator at 5x real time."""
    running = start_sim(str(tmp_path))
    yield running
    running.stop()


@pytest.fixture
def client(sim: RunningSim) -> Iterator[VehicleClient]:
    vehicle = VehicleClient(f"udpout:127.0.0.1:{sim.port}")
    vehicle.connect(timeout=30)
    yield vehicle
    vehicle.close()


# PX4 instances for the flight-stack envs' tests: their ports (TCP 4560 + i, UDP
# 14540 + i, 14580 + i, the payload link's 14030 + i) must be free. Instances 37..76
# keep the two UDP ranges apart (i and i + 40 would share one); each pytest-xdist
# worker takes ten of them, in turn.
_WORKER = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw") or 0) % 4
_FIRST_PX4, _PX4_PER_WORKER = 37 + 10 * _WORKER, 10
_next_px4 = [0]


def free_px4_instances(n: int = 1) -> int:
    """The first of ``n`` consecutive PX4 instances whose ports are all free now."""
    import socket

    tcp, udp = socket.SOCK_STREAM, socket.SOCK_DGRAM
    ports = ((tcp, 4560), (udp, 14540), (udp, 14580), (udp, 14030))
    return _free_instances(n, _FIRST_PX4, _next_px4, ports, 1, "PX4")


def _free_instances(
    n: int, first_of_worker: int, turn: list[int], ports: tuple, stride: int, stack: str
) -> int:
    """The first of ``n`` consecutive instances of this worker's ten, taken in turn,
    whose ``ports`` ((socket kind, port of instance 0); instance i: + stride · i) are
    all free now."""
    import socket

    def free(instance: int) -> bool:
        try:
            for kind, port in ports:
                with socket.socket(socket.AF_INET, kind) as probe:
                    probe.bind(("127.0.0.1", port + stride * instance))
        except OSError:
            return False
        return True

    for _ in range(100):
        first = first_of_worker + turn[0] % (_PX4_PER_WORKER - n + 1)
        turn[0] += n
        if all(free(first + i) for i in range(n)):
            return first
    raise AssertionError(f"no {n} consecutive {stack} instances with free ports")


# ArduPilot instances for the flight-stack envs' tests: UDP 9002 + 10 i (JSON) and
# 5760 + 10 i (its MAVLink) must be free; instances 100 .. 139, ten per worker.
_FIRST_ARDUPILOT = 100 + 10 * _WORKER
_next_ardupilot = [0]


def free_ardupilot_instances(n: int = 1) -> int:
    """The first of ``n`` consecutive ArduPilot instances whose ports are all free now."""
    import socket

    ports = ((socket.SOCK_DGRAM, 9002), (socket.SOCK_DGRAM, 5760))
    return _free_instances(n, _FIRST_ARDUPILOT, _next_ardupilot, ports, 10, "ArduPilot")


@pytest.fixture(scope="module")
def two_ray_nodes():  # type: ignore[no-untyped-def]
    """A two-node Ray cluster on this machine, joined: a head that takes no work, and a
    second node with 2 CPUs; (cluster, that node)."""
    ray = pytest.importorskip("ray")
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0})
    worker = cluster.add_node(num_cpus=2)
    ray.init(address=cluster.address, include_dashboard=False, log_to_driver=False)
    try:
        yield cluster, worker
    finally:
        ray.shutdown()
        cluster.shutdown()
