"""A Gymnasium env whose policy flies a real flight stack by its own setpoints, in
lockstep: the paper's tasks through PX4's offboard mode (docs/autopilots.md, "Training
through the flight stack").

The env owns the autopilot's simulator and clock (:class:`AutopilotLink`), so an env step
is a fixed span of simulated time (the control period) however fast either side runs.
An action is a setpoint at one of three levels (:mod:`quadsitl.envs.setpoints`); the
observation is the task's, computed from what the autopilot itself reports (its
estimate: LOCAL_POSITION_NED, ATTITUDE_QUATERNION; the rotor speeds, which it does not
report, from the simulator as ESC telemetry would give them). Reward, termination and
success are the task's own, from the simulator's truth (:class:`~quadsitl.tasks.TaskEngine`
on the vehicle the autopilot flies): the truth is what the task means, and an
estimator's error must not be rewarded. ``info`` holds the truth's observation too.

A reset does not restart the autopilot: it flies the vehicle to the episode's drawn
start under the autopilot's own position control (arming and entering offboard first
if need be), in simulated time, and says in ``info["reset"]`` what it cost and how close
it came. An autopilot that died is started again, and so is one reset with a seed: only
a new autopilot process (its vehicle at rest at home, its sensors' noise seeded again)
makes an episode reproducible, as Gymnasium asks of ``reset(seed=...)``; a learner
seeds its first reset only (``info["reset"]["restarted"]`` says why).
"""

from __future__ import annotations

import math
import time
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import ArrayLike, NDArray

from quadsitl import frames
from quadsitl.bridges.px4_hil import ROUND_US
from quadsitl.envs import setpoints
from quadsitl.envs.autopilot_link import AutopilotError, AutopilotLink, fake_px4_command
from quadsitl.physics import get_airframe
from quadsitl.physics import layout as L
from quadsitl.tasks import TaskEngine, TaskOptions, get_task
from quadsitl.tasks.engine import OUTCOME_NAME_ARRAY
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.modes import MAIN_OFFBOARD, Mode

ALTITUDE = 5.0  # m above the ground: the task's origin (the vehicle takes off to it)
RESET_LIMIT_S = 30.0  # simulated s a reset may fly before it starts the episode anyway
STREAM_FIRST_S = 1.0  # simulated s of setpoints before asking for OFFBOARD (PX4 >= 1.14)
SETTLED_POSITION = 0.05  # m from the drawn start ...
SETTLED_SPEED = 0.1  # ... and m/s, rad/s: the start is reached


class OffboardFleet:
    """The vehicle the autopilot flies, as the task engine sees a fleet of one: its state
    in the task's frame (origin ALTITUDE above the ground where it took off); ``step``
    lets the autopilot fly, ``reset`` flies to the episode's start."""

    def __init__(self, link: AutopilotLink, control_period: float, altitude: float) -> None:
        self.link, self.physical = link, link.fleet
        self.control_period = control_period
        self.origin = np.array([0.0, 0.0, altitude])
        self.params = self.physical.params
        self.contact = self.physical.contact
        self.touchdown_speed = self.physical.touchdown_speed
        self.wind_state = self.physical.wind_state
        self.state = np.zeros_like(self.physical.state)
        self.sync()
        self.report: dict[str, Any] = {}

    @property
    def hover_rotor_speed(self) -> NDArray[np.float64]:
        return self.physical.hover_rotor_speed

    @property
    def windy(self) -> bool:
        return False

    def sync(self) -> None:
        self.state[:] = self.physical.state
        self.state[:, L.POS] -= self.origin

    def step(self, rotor_cmd: ArrayLike, n_substeps: int = 1) -> None:
        """The setpoint was sent (the env's step); the autopilot flies ``n_substeps``
        rounds. The engine's rotor commands are not used: the autopilot's are."""
        self.link.advance(n_substeps * ROUND_US * 1e-6)
        self.sync()

    def reset(
        self, state: ArrayLike | None = None, contact: Any = L.AIRBORNE, mask: Any = None
    ) -> None:
        start = np.zeros(3) if state is None else np.asarray(state, float)[0, L.POS]
        wall, began = time.monotonic(), self.link.time_us
        self._offboard()
        target = start + self.origin
        local_target = target - self.link.local_origin  # in the autopilot's local frame
        settled_for = 0.0
        while (self.link.time_us - began) * 1e-6 < RESET_LIMIT_S and settled_for < 0.2:
            message = setpoints.position_message(self.link.mav, local_target, 0.0, self._ms())
            self.link.send(message)
            self.link.advance(self.control_period)
            s = self.physical.state[0]
            still = max(np.linalg.norm(s[L.VEL]), np.linalg.norm(s[L.RATES])) < SETTLED_SPEED
            near = np.linalg.norm(s[L.POS] - target) < SETTLED_POSITION
            settled_for = settled_for + self.control_period if (near and still) else 0.0
        self.sync()
        self.report = {
            "simulated_s": (self.link.time_us - began) * 1e-6,
            "wall_s": time.monotonic() - wall,
            "position_error_m": float(np.linalg.norm(self.physical.state[0, L.POS] - target)),
            "reached": settled_for >= 0.2,
        }

    def _ms(self) -> int:
        return self.link.time_us // 1000

    def _offboard(self) -> None:
        """Armed and in OFFBOARD, holding where it is (a stream of setpoints first)."""
        e = self.link.estimate
        if e.armed and e.custom_mode == Mode.OFFBOARD.custom_mode:
            return
        here = self.physical.state[0, L.POS] - self.link.local_origin
        for _ in range(math.ceil(STREAM_FIRST_S / self.control_period)):
            self.link.send(setpoints.position_message(self.link.mav, here, 0.0, self._ms()))
            self.link.advance(self.control_period)
        mode = self.link.command(
            mav.MAV_CMD_DO_SET_MODE,
            mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, MAIN_OFFBOARD,
        )  # fmt: skip
        arm = self.link.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
        accepted = mav.MAV_RESULT_ACCEPTED
        if mode != accepted or arm != accepted:
            raise AutopilotError(f"the autopilot refused offboard ({mode}) or arming ({arm})")

    def set_wind(self, *args: Any, **kwargs: Any) -> None:
        raise ValueError("weather is not available through an autopilot yet")

    def set_ground_effect(self, on: bool, mask: Any = None) -> None:
        raise ValueError("ground effect is not available through an autopilot yet")

    def set_motor_efficiency(self, efficiency: ArrayLike, mask: Any = None) -> None:
        raise ValueError("motor faults are not available through an autopilot yet")


class OffboardEnv(gym.Env):
    """Task ``task`` flown through PX4 (offboard) at action level ``action_level``
    (``"velocity"``, ``"attitude"`` or ``"rates"``). ``autopilot``: the command that
    starts PX4 instance ``instance`` (``{port}`` and ``{instance}`` are filled in;
    None: the in-repository fake, :mod:`quadsitl.fake_stacks.offboard_px4`).
    ``control_rate``: env steps per simulated second. Other keyword arguments are the
    task's options (e.g. ``init_position_noise``)."""

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012

    def __init__(
        self,
        task: str = "hover",
        action_level: str = "velocity",
        autopilot: list[str] | None = None,
        instance: int = 0,
        airframe: str = "iris",
        control_rate: float = 50.0,
        render_mode: str | None = None,
        **task_options: Any,
    ) -> None:
        if render_mode is not None:
            raise ValueError(f"render_mode {render_mode!r} is not supported (use None)")
        self.level = setpoints.check_level(action_level)
        spec = get_task(task)
        period = round(1.0 / control_rate / (ROUND_US * 1e-6)) * ROUND_US * 1e-6
        if period <= 0:
            raise ValueError(f"control_rate {control_rate} is above the autopilot's 250 Hz")
        options = TaskOptions.from_kwargs(
            airframe=airframe, physics_dt=ROUND_US * 1e-6, control_period=period, **task_options
        )
        self.hover_thrust = get_airframe(airframe).hover_thrust_fraction
        self.link = AutopilotLink(autopilot or fake_px4_command(airframe), instance, airframe)
        try:
            self.fleet = OffboardFleet(self.link, period, ALTITUDE)
            self.engine = TaskEngine(spec, 1, options, fleet=self.fleet)  # type: ignore[arg-type]
        except Exception:
            self.link.close()
            raise
        size = self.engine.obs_size
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (size,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (4,), np.float32)
        self._obs = np.zeros((1, size), np.float32)
        self._dist, self._tilt = np.zeros((1, 4)), np.zeros(1)
        self._seeded = False

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        super().reset(seed=seed)
        if seed is not None or not self._seeded:
            self.engine.seed([seed if seed is not None else int(self.np_random.integers(2**62))])
            self._seeded = True
        restarted = None
        if self.link.process is None or self.link.process.poll() is not None:
            restarted = "the autopilot had exited"  # the fallback
        elif seed is not None:
            restarted = "seeded: a reproducible episode starts from a new autopilot"
        if restarted:
            self.link.restart()
        self.engine.reset_envs(np.ones(1, bool))
        info = self._info()
        info["reset"] = {**self.fleet.report, "restarted": restarted}
        return self._observe(), info

    def step(
        self, action: ArrayLike
    ) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != (4,) or not np.all(np.isfinite(a)):
            raise ValueError(f"action must be 4 finite numbers, got {action!r}")
        a = np.clip(a, -1.0, 1.0)
        msg = setpoints.message(self.link.mav, self.level, a, self.link.time_us // 1000,
                                self.hover_thrust)  # fmt: skip
        self.link.send(msg)
        reward, terminated, truncated = self.engine.step(a.reshape(1, 4))
        return (
            self._observe(),
            float(reward[0]),
            bool(terminated[0]),
            bool(truncated[0]),
            self._info(),
        )

    def _observe(self) -> NDArray[np.float32]:
        """The task's observation of the autopilot's estimate (in the task's frame)."""
        e = self.link.estimate
        state = self.fleet.state.copy()
        local = frames.ned_to_enu(np.array(e.position))
        state[0, L.POS] = local + self.link.local_origin - self.fleet.origin
        state[0, L.VEL] = frames.ned_to_enu(np.array(e.velocity))
        state[0, L.QUAT] = frames.quat_ned_frd_to_enu_flu(np.array(e.quaternion))
        state[0, L.RATES] = frames.frd_to_flu(np.array(e.rates))
        task = self.engine.task
        task.observe(state, self.fleet.params, self.engine.goal, self._obs, self._dist, self._tilt)
        return self._obs[0].copy()

    def _info(self) -> dict[str, Any]:
        e = self.link.estimate
        return {
            "truth_obs": self.engine.obs[0].copy(),
            "simulated_s": self.link.time_us * 1e-6,
            "estimate_age_s": max(0.0, self.link.time_us * 1e-6 - e.position_time_ms * 1e-3),
            "outcome": str(OUTCOME_NAME_ARRAY[self.engine.outcome[0]]),
        }

    def close(self) -> None:
        link = getattr(self, "link", None)
        if link is not None:
            link.close()
            self.link = None  # type: ignore[assignment]
