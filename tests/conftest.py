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

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from gcs_tools.client import VehicleClient
from gcs_tools.demo import free_udp_port
from quadsitl.client.motor_client import MotorClient, SimulatorError

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


class RunningSim:
    def __init__(self, process: subprocess.Popen[str], port: int, log_dir: str) -> None:
        self.process, self.port, self.log_dir = process, port, log_dir

    def stop(self) -> str:
        """SIGTERM, wait, return the combined output."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
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
    return RunningSim(process, port, log_dir)


class MotorSim:
    """``quadsitl sim`` with a motor link and a ground-station link, both udpin."""

    def __init__(self, *options: str) -> None:
        self.hil_port, self.gcs_port = free_udp_port(), free_udp_port()
        gcs, hil = f"udpin:127.0.0.1:{self.gcs_port}", f"udpin:127.0.0.1:{self.hil_port}"
        self.process = subprocess.Popen(
            cli(f"sim --api none --logs none --gcs {gcs} --hil {hil}", *options),
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )

    def client(self, **kwargs: object) -> MotorClient:
        client = MotorClient("127.0.0.1", self.hil_port, **kwargs)  # type: ignore[arg-type]
        # The process needs a moment to start: on a fresh checkout of a loaded machine it
        # compiles the physics first (over 20 s seen with one core kept busy).
        deadline = time.monotonic() + 60
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
