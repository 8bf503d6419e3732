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
start under the autopilot's own position control (:mod:`.offboard_fleet`), in simulated
time, and says in ``info["reset"]`` what it cost and how close it came. An autopilot that
failed (exited, disconnected, stalled) ends its episode truncated, with
``info["autopilot_failure"]`` saying why, and is started again at the next reset; so is
one reset with a seed: only a new autopilot process (its vehicle at rest at home, its
sensors' noise seeded again) makes an episode reproducible, as Gymnasium asks of
``reset(seed=...)``; a learner seeds its first reset only
(``info["reset"]["restarted"]`` says why). :mod:`.offboard_vector` flies N autopilots on
one batched physics behind one vector env.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import ArrayLike, NDArray

from quadsitl.envs import setpoints
from quadsitl.envs.autopilot_commands import STACKS, autopilot_command
from quadsitl.envs.autopilot_link import Autopilots
from quadsitl.envs.lockstep_sides import SIDES
from quadsitl.envs.offboard_fleet import OffboardFleet
from quadsitl.physics import get_airframe
from quadsitl.tasks import TaskEngine, TaskOptions, get_task
from quadsitl.tasks.engine import OUTCOME_NAME_ARRAY

ALTITUDE = 5.0  # m above the ground: the task's origin (the vehicle takes off to it)
SEEDED = "seeded: a reproducible episode starts from a new autopilot"


CONTROL_RATE = 50.0  # Hz: env steps per simulated second, by default
AIRFRAME = "iris"  # the airframe preset flown, by default (PX4's quad X, with its parameters)


def flight_stack_timing(control_rate: float = CONTROL_RATE, stack: str = "px4") -> dict[str, float]:
    """The task options of an env step through an autopilot of ``stack``: the control
    period, a whole number of its lockstep frames (PX4's 4 ms rounds, ArduPilot's
    1/800 s physics frames), and the frame as the physics step."""
    if stack not in STACKS:
        raise ValueError(f"stack must be one of {', '.join(STACKS)}, got {stack!r}")
    frame = SIDES[stack].frame_us * 1e-6
    if not (math.isfinite(control_rate) and 1e-3 < control_rate <= 1.0 / frame):
        raise ValueError(f"control_rate {control_rate} is not within (0, {1 / frame:g}] Hz")
    frames = 1.0 / control_rate / frame  # lockstep frames a step
    if abs(frames - round(frames)) > 1e-6 * frames:
        near = sorted({1.0 / (n * frame) for n in (math.floor(frames), math.ceil(frames))})
        raise ValueError(
            f"control_rate {control_rate:g} Hz is not a whole number of {SIDES[stack].title}'s "
            f"lockstep frames of {frame * 1e3:g} ms ({frames:.2f}); the nearest rates that are: "
            f"{' and '.join(f'{r:.4g}' for r in near)} Hz"
        )
    return {"physics_dt": frame, "control_period": round(frames) * frame}


@dataclass
class Offboard:
    """What an env that flies N autopilots is made of: their processes and physics, the
    vehicles as the task sees them, the task's engine, and the setpoints' scale."""

    autopilots: Autopilots
    fleet: OffboardFleet
    engine: TaskEngine
    level: str
    hover_thrust: float

    @classmethod
    def build(
        cls,
        task: str,
        n: int,
        action_level: str,
        autopilot: Any,
        first_instance: int,
        airframe: str,
        control_rate: float,
        task_options: dict[str, Any],
        sensor_noise: float = 1.0,
        stack: str = "px4",
    ) -> Offboard:
        level = setpoints.check_level(action_level)
        spec = get_task(task)
        options = TaskOptions.from_kwargs(
            airframe=airframe, **flight_stack_timing(control_rate, stack), **task_options
        )
        hover = get_airframe(airframe).hover_thrust_fraction
        command = autopilot_command(autopilot, airframe, stack, sensor_noise)
        if not (math.isfinite(sensor_noise) and sensor_noise >= 0):
            raise ValueError(f"sensor_noise must be a number ≥ 0, got {sensor_noise!r}")
        autopilots = Autopilots(command, n, first_instance, airframe, sensor_noise, stack)
        try:
            failed = autopilots.start()
            if failed:
                why = {row: autopilots.pilots[row].failure for row in failed}
                raise RuntimeError(f"autopilots did not start (row: why): {why}")
            fleet = OffboardFleet(autopilots, options.control_period, ALTITUDE)
            engine = TaskEngine(spec, n, options, fleet=fleet)  # type: ignore[arg-type]
        except BaseException:
            autopilots.close()
            raise
        return cls(autopilots, fleet, engine, level, hover)

    def send(self, actions: NDArray[np.float64], rows: Any) -> None:
        """Each row's action (N, 4) in [−1, 1] as its autopilot's setpoint."""
        for row in rows:
            pilot = self.autopilots.pilots[row]
            ms = self.autopilots.time_us(row) // 1000
            pilot.send(setpoints.message(pilot.mav, self.level, actions[row], ms,
                                         self.hover_thrust, pilot.system_id))  # fmt: skip

    def observe(self, out: NDArray[np.float32]) -> NDArray[np.float32]:
        """The task's observation of each autopilot's estimate, into ``out`` (N, size)."""
        n = self.fleet.n
        dist, tilt = np.zeros((n, 4)), np.zeros(n)
        state = self.fleet.estimated_state()
        self.engine.task.observe(state, self.fleet.params, self.engine.goal, out, dist, tilt)
        return out

    def row_info(self, row: int) -> dict[str, Any]:
        """What a step says of env ``row`` beyond the observation."""
        e, now_s = self.autopilots.pilots[row].estimate, self.autopilots.time_us(row) * 1e-6
        info = {
            "truth_obs": self.engine.obs[row].copy(),
            "simulated_s": now_s,
            "estimate_age_s": max(0.0, now_s - e.position_time_ms * 1e-3),
            "outcome": str(OUTCOME_NAME_ARRAY[self.engine.outcome[row]]),
        }
        if self.fleet.failed[row] is not None:
            info["autopilot_failure"] = self.fleet.failed[row]
        return info

    def close(self) -> None:
        self.autopilots.close()


def checked_actions(actions: ArrayLike, n: int) -> NDArray[np.float64]:
    """(n, 4) finite actions clipped to [−1, 1]; ValueError otherwise."""
    a = np.asarray(actions, dtype=np.float64)
    if a.size != 4 * n or not np.all(np.isfinite(a)):
        raise ValueError(f"actions must be {n}×4 finite numbers, got {actions!r}")
    return np.clip(a.reshape(n, 4), -1.0, 1.0)


class OffboardEnv(gym.Env):
    """Task ``task`` flown through ``stack``, PX4 (OFFBOARD) or ArduPilot (ArduCopter's
    GUIDED), at action level ``action_level`` (``"velocity"``, ``"attitude"`` or
    ``"rates"``). ``autopilot``: instance ``instance`` from a SITL build (PX4's
    ``build/px4_sitl_default``, ArduPilot's ``build/sitl``); None: the in-repository
    fake (:mod:`quadsitl.fake_stacks`); a list: the command that starts one (``{port}``,
    ``{instance}`` and ``{link}`` in it are filled in).
    ``control_rate``: env steps per simulated second. ``sensor_noise``: the scale of the
    sensor models' noise the autopilot's estimator works with (1: a hobby-grade GPS,
    barometer and IMU; 0: exact readings). Other keyword arguments are the task's options
    (e.g. ``init_position_noise``)."""

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012

    def __init__(
        self,
        task: str = "hover",
        action_level: str = "velocity",
        autopilot: str | os.PathLike[str] | list[str] | None = None,
        instance: int = 0,
        airframe: str = AIRFRAME,
        control_rate: float = CONTROL_RATE,
        sensor_noise: float = 1.0,
        render_mode: str | None = None,
        stack: str = "px4",
        **task_options: Any,
    ) -> None:
        if render_mode is not None:
            raise ValueError(f"render_mode {render_mode!r} is not supported (use None)")
        self.offboard = Offboard.build(task, 1, action_level, autopilot, instance, airframe,
                                       control_rate, task_options, sensor_noise,
                                       stack)  # fmt: skip
        self.autopilots, self.fleet = self.offboard.autopilots, self.offboard.fleet
        self.engine = self.offboard.engine
        size = self.engine.obs_size
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (size,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (4,), np.float32)
        self._obs = np.zeros((1, size), np.float32)
        self._seeded = False

    @property
    def pilot(self) -> Any:
        """The autopilot this env flies (its process, link and estimate)."""
        return self.autopilots.pilots[0]

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        super().reset(seed=seed)
        if seed is not None or not self._seeded:
            self.engine.seed([seed if seed is not None else int(self.np_random.integers(2**62))])
            self._seeded = True
        if seed is not None:
            self.fleet.restart[0] = SEEDED
        self.engine.reset_envs(np.ones(1, bool))
        info = self.offboard.row_info(0)
        info["reset"] = self.fleet.reports[0]
        return self.offboard.observe(self._obs)[0].copy(), info

    def step(
        self, action: ArrayLike
    ) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        a = checked_actions(action, 1)
        self.offboard.send(a, [0])
        reward, terminated, truncated = self.engine.step(a)
        info = self.offboard.row_info(0)
        # A failed autopilot's vehicle was put back on the ground by the simulator: the
        # episode was cut short, the task did not end it.
        failed = "autopilot_failure" in info
        return (
            self.offboard.observe(self._obs)[0].copy(),
            float(reward[0]),
            bool(terminated[0]) and not failed,
            bool(truncated[0]) or failed,
            info,
        )

    def close(self) -> None:
        offboard = getattr(self, "offboard", None)
        if offboard is not None:
            offboard.close()
            self.offboard = None  # type: ignore[assignment]
