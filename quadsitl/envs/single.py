"""One Gymnasium env per task: a TaskEngine with one vehicle."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.error import ClosedEnvironmentError

from quadsitl.envs import docs
from quadsitl.envs.factory import build_engine
from quadsitl.envs.mavlink_backend import (
    reset_envs,
)
from quadsitl.mavlink.motor_client import SimulatorError
from quadsitl.physics import layout as L
from quadsitl.tasks import TaskEngine
from quadsitl.viz.episode_view import EpisodeView

EQ18 = (
    "Per step (Eq. 18, Δd = previous − current distance to the goal): "
    "{weights} − 0.01·‖a‖²{time}{bonus}."
)


def make_spaces(engine: TaskEngine) -> tuple[gym.spaces.Box, gym.spaces.Box]:
    """Single-env observation and action spaces of an engine."""
    obs = gym.spaces.Box(-np.inf, np.inf, (engine.obs_size,), np.float32)
    act = gym.spaces.Box(
        np.float32(engine.action_low), np.float32(engine.action_high), (L.N_ROTORS,), np.float32
    )
    return obs, act


def check_no_render(render_mode: str | None) -> None:
    if render_mode is not None:
        raise ValueError(f"render_mode {render_mode!r} is not supported (use None)")


def check_open(closed: bool) -> None:
    """After ``close()`` an env neither resets nor steps, whatever its backend."""
    if closed:
        raise ClosedEnvironmentError("env is closed: make a new one")


RENDER_MODES = ("rerun",)


class QuadEnv(gym.Env):
    """Base of the five task envs; subclasses set ``task_name`` and the docstring.

    ``backend="inprocess"`` (default) steps the physics here; ``backend="mavlink"`` flies
    a ``quadsitl sim --lockstep`` process over MAVLink with the same task code (see
    docs/tasks.md): ``sim_address`` ("HOST:PORT") connects to a running one instead of
    starting one, ``gcs`` gives the spawned one a ground-station link (a URL),
    ``system_id`` its MAVLink id, ``timeout`` bounds every wait (s), ``signing_key``
    signs the traffic (32 bytes).
    """

    metadata: dict[str, Any] = {"render_modes": list(RENDER_MODES), "render_fps": 20}  # noqa: RUF012
    task_name = "hover"

    def __init__(
        self, render_mode: str | None = None, rerun_save: str | None = None, **options: Any
    ) -> None:
        if render_mode not in (None, *RENDER_MODES):
            raise ValueError(f"render_mode {render_mode!r} is not supported: None or 'rerun'")
        self.render_mode = render_mode
        self.engine, self.backend = build_engine(self.task_name, 1, options)
        self.observation_space, self.action_space = make_spaces(self.engine)
        self._all = np.ones(1, bool)
        self._closed = False
        self.view: EpisodeView | None = None
        if render_mode == "rerun":  # episodes logged as they are flown; see quadsitl.viz
            engine = self.engine
            drawn = engine.randomization is not None and engine.randomization.wind is not None
            windy = engine.options.wind is not None or drawn
            self.view = EpisodeView(f"{self.task_name}", rerun_save, windy=windy)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        check_open(self._closed)
        super().reset(seed=seed)
        if options:
            raise ValueError(f"reset options are not supported, got {sorted(options)}")
        if seed is not None:
            self.engine.seed([seed])
        reset_envs(self.engine, self.backend, self._all)
        if self.view is not None:
            self.view.reset(self.engine)
        return self.engine.obs[0].copy(), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        check_open(self._closed)
        engine = self.engine
        try:
            reward, terminated, truncated = engine.step(action)
        except SimulatorError as error:
            raise self._explain(error) from None
        if self.view is not None:
            self.view.step(engine, float(reward[0]))
        ended_early, timed_out = bool(terminated[0]), bool(truncated[0])
        info: dict[str, Any] = {}
        if ended_early or timed_out:
            metrics = engine.episode_metrics(np.zeros(1, np.int64))
            info = {key: value[0].item() for key, value in metrics.items()}
        return engine.obs[0].copy(), float(reward[0]), ended_early, timed_out, info

    def _explain(self, error: SimulatorError) -> SimulatorError:
        return self.backend.explain(error) if self.backend is not None else error

    def render(self) -> None:
        """Nothing to do: with ``render_mode="rerun"`` every reset and step is logged."""

    def close(self) -> None:
        self._closed = True
        if self.backend is not None:
            self.backend.close()
        if self.view is not None:
            self.view.close()
            self.view = None
        super().close()


class HoverEnv(QuadEnv):
    task_name = "hover"
    __doc__ = docs.env_doc(
        "# QuadSITL/Hover-v0",
        "Hold position at the origin, level, heading yaw 0 (east).",
        EQ18.format(
            weights="100·Δd_pos + 10·Δd_att + 0.1·Δd_vel + 0.1·Δd_rate", time=" + 10", bonus=""
        ),
        "At the goal (origin), level, at rest, rotors at hover speed; add noise with init_*.",
        "Terminated when any |x|, |y|, |z| > 3 m (out_of_bounds) or |roll| or |pitch| > 90° "
        "(flipped); truncated after 5 s (100 steps). Success: flown to the end and within "
        "0.1 m of the goal.",
        5.0,
    )


class StaticWaypointEnv(QuadEnv):
    task_name = "static_waypoint"
    __doc__ = docs.env_doc(
        "# QuadSITL/StaticWaypoint-v0",
        "Fly from the origin to the waypoint (1.5, 0, 0) m and stay there.",
        EQ18.format(
            weights="100·Δd_pos + 10·Δd_att + 0.1·Δd_vel + 0.1·Δd_rate",
            time=" + 0.1",
            bonus=" + 100 while within 0.05 m of the goal",
        ),
        "At the origin, level, at rest, rotors at hover speed.",
        "Terminated more than 2 m from the goal (a flip does not end it, as in the paper); "
        "truncated after 3 s "
        "(60 steps). Success: within 0.1 m at the end.",
        3.0,
    )


class RandomWaypointEnv(QuadEnv):
    task_name = "random_waypoint"
    __doc__ = docs.env_doc(
        "# QuadSITL/RandomWaypoint-v0",
        "Fly to a goal drawn each episode at radius U(1, 2.5) m in a uniformly random direction.",
        EQ18.format(
            weights="100·Δd_pos + 10·Δd_att + 0.1·Δd_vel + 0.1·Δd_rate",
            time=" + 0.1",
            bonus=" + 100 while within 0.05 m of the goal",
        ),
        "At the origin, level, at rest, rotors at hover speed.",
        "Terminated more than 5 m from the goal (a flip does not end it); truncated after "
        "3.5 s (70 steps). Success: within 0.1 m at the end.",
        3.5,
    )


class LandEnv(QuadEnv):
    task_name = "land"
    __doc__ = docs.env_doc(
        "# QuadSITL/Land-v0",
        "Descend onto the pad at the origin (ground z = 0) at about 0.5 m/s without crashing.",
        EQ18.format(
            weights="100·Δd_pos + 10·Δd_att + 1·Δ‖v − (0, 0, −0.5)‖ + 5·Δd_rate",
            time="",
            bonus="; +500 on landing on the pad (within 0.5 m), −500 on a crash (rotor "
            "strike, touchdown faster than 1 m/s or tilted more than 15°) or a descent faster "
            "than 2 m/s",
        ),
        "x, y ~ U(−1.5, 1.5) m, z = 3 m, level, at rest, rotors at hover speed.",
        "Terminated on landing (landed / landed_off_pad), crash or more than 6 m from the pad "
        "(a flip in the air does not end it); truncated after 6 s (120 steps). Success: "
        "landed on the pad.",
        6.0,
    )


class TargetFollowEnv(QuadEnv):
    task_name = "target_follow"
    __doc__ = docs.env_doc(
        "# QuadSITL/TargetFollow-v0",
        "Follow a target moving at 1 m/s along chained quadratic Bézier curves through random "
        "points in [−2, 2]³ m, staying within 2 m of it.",
        EQ18.format(
            weights="100·Δd_pos + 10·Δd_att + 0.1·Δd_vel + 0.1·Δd_rate (goal = the target)",
            time="",
            bonus=" + 5·(1 + t/T) while within 2 m (scaled up over the episode); −500 on "
            "leaving the region",
        ),
        "Vehicle and target at the origin, level, at rest, rotors at hover speed.",
        "Terminated when any |x|, |y|, |z| > 4 m or beyond 90° roll/pitch; truncated after "
        "25 s (500 steps). Success: flown to the end, within 2 m for ≥ 80 % of it.",
        25.0,
        extra="| 34–36 | target − position | m |\n| 37 | distance to the target | m |\n"
        "| 38–40 | target velocity, world | m/s |",
    )


ENV_CLASSES: dict[str, type[QuadEnv]] = {
    "Hover": HoverEnv,
    "StaticWaypoint": StaticWaypointEnv,
    "RandomWaypoint": RandomWaypointEnv,
    "Land": LandEnv,
    "TargetFollow": TargetFollowEnv,
}
