"""The Gymnasium faces under mistakes and faults: rendering without a screen, bad
options, a closed env, an env made in a thread, a simulator that dies."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "policies" / "checkpoints" / "hover.pt"


# --- 6. rendering works wherever the env works ------------------------------------------
def test_check_env_with_render_check_passes_headless_without_the_venv_on_path(tmp_path):
    code = (
        "import gymnasium as gym, quadsitl, warnings\n"
        "from gymnasium.utils.env_checker import check_env\n"
        "warnings.simplefilter('ignore')\n"
        "for name in ('Hover', 'StaticWaypoint', 'RandomWaypoint', 'Land', 'TargetFollow'):\n"
        "    env = gym.make(f'QuadSITL/{name}-v0')\n"
        "    check_env(env.unwrapped)\n"
        "    env.close()\n"
        "print('ok')\n"
    )
    env = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path), "QUADSITL_RERUN_DIR": str(tmp_path)}
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300, cwd=ROOT
    )
    assert result.returncode == 0 and "ok" in result.stdout, result.stderr
    assert len(list(tmp_path.glob("quadsitl_episodes-*.rrd"))) == 5  # one per task


# --- 7-10. the Gymnasium faces under mistakes and faults --------------------------------
@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"episode_seconds": float("inf")}, "episode_seconds must be in"),
        ({"physics_dt": 1e-9, "control_period": 1e-9}, r"physics_dt must be in \[0.0001"),
        ({"backend": "mavlink", "timeout": 0}, "timeout must be in"),
        ({"backend": "mavlink", "timeout": -1.0}, "timeout must be in"),
        ({"backend": "mavlink", "sim_address": "127.0.0.1:99999"}, "port must be 1..65535"),
        ({"backend": "mavlink", "signing_key": "secret"}, "signing_key must be 32 bytes"),
        ({"backend": "mavlink", "signing_key": b"short"}, "signing_key must be 32 bytes"),
        ({"backend": "mavlink", "gcs": "udpout:127.0.0.1"}, "expected KIND:HOST:PORT"),
    ],
)
def test_bad_env_options_raise_at_construction(options, message):
    import gymnasium as gym

    before = _children()
    with pytest.raises(ValueError, match=message):
        gym.make("QuadSITL/Hover-v0", **options)
    assert _children() <= before  # refused before any simulator starts


def _children() -> set[int]:
    """This process's child processes (a simulator would be one)."""
    found: set[int] = set()
    for task in os.listdir("/proc/self/task"):
        with open(f"/proc/self/task/{task}/children") as f:
            found.update(int(pid) for pid in f.read().split())
    return found


def test_more_mavlink_envs_than_memory_holds_is_refused():
    import gymnasium as gym

    with pytest.raises(ValueError, match=r"free memory holds \d+"):
        gym.make_vec(
            "QuadSITL/Hover-v0", 100_000, vectorization_mode="vector_entry_point", backend="mavlink"
        )


def test_complex_actions_are_refused():
    import gymnasium as gym
    import numpy as np

    env = gym.make("QuadSITL/Hover-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="real numbers"):
        env.step(np.array([1 + 2j, 0, 0, 0]))


def test_step_or_reset_after_close_says_the_env_is_closed():
    import gymnasium as gym
    import numpy as np
    from gymnasium.error import ClosedEnvironmentError

    env = gym.make("QuadSITL/Hover-v0", backend="mavlink")
    env.reset(seed=0)
    env.close()
    with pytest.raises(ClosedEnvironmentError, match="env is closed"):
        env.step(np.zeros(4, np.float32))
    with pytest.raises(ClosedEnvironmentError, match="env is closed"):
        env.reset()


def test_an_env_made_in_a_worker_thread_keeps_its_simulator():
    import gymnasium as gym
    import numpy as np

    made = {}
    # A generous timeout: this is about the thread, and a loaded machine's freshly started
    # simulator has missed the default 2 s for its first reset answer.
    worker = threading.Thread(
        target=lambda: made.update(
            env=gym.make("QuadSITL/Hover-v0", backend="mavlink", timeout=10.0)
        )
    )
    worker.start()
    worker.join()
    env = made["env"]
    try:
        time.sleep(1.0)  # the parent-death signal would have arrived by now
        assert env.unwrapped.backend.processes[0].alive
        env.reset(seed=0)
        obs, *_ = env.step(np.zeros(4, np.float32))
        assert np.isfinite(obs).all()
    finally:
        env.close()


def test_mavlink_vector_env_recovers_after_a_simulator_dies():
    import numpy as np

    from quadsitl.envs.parallel import mavlink_vector_env
    from quadsitl.lockstep_client.motor_client import SimulatorError

    envs = mavlink_vector_env("QuadSITL/Hover-v0", 2, timeout=1.0)
    try:
        envs.reset(seed=0)
        envs.unwrapped.backend.processes[1].process.kill()
        with pytest.raises(SimulatorError):
            for _ in range(5):
                envs.step(np.zeros((2, 4), np.float32))
        with pytest.warns(RuntimeWarning, match="starting new ones"):
            obs, _ = envs.reset(seed=0)
        obs, *_ = envs.step(np.zeros((2, 4), np.float32))
        assert obs.shape == (2, 34) and np.isfinite(obs).all()
    finally:
        envs.close()
