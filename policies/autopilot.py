"""A trained policy as the simulator's autopilot (``quadsitl sim --autopilot CKPT``).

It implements :class:`quadsitl.flight_software.controller.Autopilot`: given the vehicle state
and the navigator's setpoint (take-off, goto, mission legs), it builds the task
observation and returns the policy's rotor commands, held for the policy's control
period (0.05 s). A policy learned goals only so far away (:class:`TrainedRange`: hover
its start offsets, ±0.3 m per axis; the waypoint tasks goals 1–2.5 m away), so a farther
target is approached through a carrot (:func:`carrot`): a point on the line from where
the leg began to the target, set that far ahead of the vehicle and never farther from
it, so the policy always sees an offset it was trained on. The carrot steps on when the
vehicle is halfway to it along the leg, or when it has come no nearer for ``SETTLE`` s
(a policy that settles short of its goal, sinking or held off by wind, still moves on).
The policy always faces the task's heading (east, yaw 0); setpoint yaw is ignored, and
a vehicle whose yaw has drifted beyond the trained headings is shown to the policy at
their edge (the task frame turned with it). Without a position setpoint
(velocity or attitude control) it holds the position where that began. Landing (the
final descent of LAND, RTL and mission land items) is flown by the cascaded controller.
A policy trained with ``observe_integral`` gets its integral from the autopilot, kept
as the env keeps it (quadsitl/tasks/error_integral.py).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from policies.config import TrainConfig
from policies.export.contract import layout_text, observation_size, trained_options
from policies.export.runtimes import load_policy
from policies.networks import DeterministicPolicy
from quadsitl.flight_software.controller import CascadedController, Setpoint
from quadsitl.frames import euler_from_quat, quat_from_axis_angle, quat_multiply, quat_rotate
from quadsitl.physics import Airframe
from quadsitl.physics import layout as L
from quadsitl.tasks import TASKS, TaskOptions
from quadsitl.tasks import error_integral as EI
from quadsitl.tasks import features as F
from quadsitl.tasks.step_kernels import commanded_rotor_speed

REANCHOR = 0.5  # the carrot steps on when the vehicle is this fraction of its reach from it
SETTLE = 1.0  # s: ... or when the vehicle has come no nearer it (by 1 cm) for this long


@dataclass(frozen=True)
class TrainedRange:
    """What a policy was trained for, as the autopilot reads it: its task, the farthest
    goal offset it saw (m: the carrot's reach) and its start speeds (m/s per axis)."""

    task: str
    offset: float
    speed: float
    source: str  # where the offset comes from
    heading: float = 0.0  # rad: the start attitude noise (yaw within ±heading of east)

    def describe(self) -> str:
        speeds = f"start speeds ±{self.speed:g} m/s" if self.speed else "starts at rest"
        return (
            f"a {self.task} policy, trained for goal offsets up to {self.offset:g} m "
            f"({self.source}), headings within ±{self.heading:g} rad of east and {speeds}: "
            f"farther setpoints are flown through a carrot at most {self.offset:g} m from "
            "the vehicle, a heading beyond that is shown to it at the edge"
        )


def trained_range(config: TrainConfig) -> TrainedRange:
    """The range of a policy trained with ``config``; ValueError for a task whose policy
    cannot fly goto and mission legs. Hover's offsets are its start noise (a carrot that
    close lies inside the trained box whatever its direction); without one in the config
    (a foreign export), the task's documented training start. The waypoint tasks draw
    their goals 1–2.5 m away: TaskSpec.carrot."""
    task = TASKS[config.task]
    if task.carrot is None:
        raise ValueError(
            f"a {task.name} policy cannot fly goto and mission legs (it was trained to: "
            f"{task.doc.description.rstrip('.')}); --autopilot takes a hover or waypoint policy"
        )
    start: Mapping[str, Any] = config.task_options
    if not any(key.startswith("init_") for key in start):
        start = task.train_start  # a foreign export: as the task's policies are trained
    speed = float(start.get("init_velocity_noise", 0.0))
    heading = float(start.get("init_attitude_noise", 0.0))
    if not task.goal_at_origin:
        return TrainedRange(task.name, task.carrot, speed, "the goals its task draws", heading)
    noise = config.task_options.get("init_position_noise")
    if noise:
        source = "its training start, per axis"
        return TrainedRange(task.name, float(noise), speed, source, heading)
    documented = float(task.train_start.get("init_position_noise", task.carrot))
    source = "its export carries no start noise: the task's documented training start"
    return TrainedRange(task.name, documented, speed, source, heading)


def carrot(
    origin: np.ndarray, target: np.ndarray, along: float, position: np.ndarray, reach: float
) -> np.ndarray:
    """The goal shown to the policy: the point ``along`` m from ``origin`` on the leg to
    ``target`` (the target at most), pulled in to ``reach`` m from the vehicle when
    farther (a vehicle blown off the line, or fallen behind)."""
    leg = target - origin
    length = float(np.linalg.norm(leg))
    point = target.copy() if length < 1e-9 else origin + leg * (min(along, length) / length)
    offset = point - position
    distance = float(np.linalg.norm(offset))
    if distance > reach:
        point = position + offset * (reach / distance)
    return point


class PolicyAutopilot:
    def __init__(
        self,
        net: DeterministicPolicy,
        airframe: Airframe,
        options: TaskOptions,
        carrot: float = 2.0,
        goal_at_origin: bool = False,
        heading: float = np.pi,
    ) -> None:
        expected = observation_size(TASKS["hover"], options)  # the waypoint tasks' too
        if net.obs_size != expected:
            raise ValueError(
                f"this policy needs {net.obs_size} observations; only the hover and waypoint "
                f"policies ({expected}: {layout_text('hover', options)}) can fly as the "
                "autopilot"
            )
        self.net = net
        self.carrot = carrot
        self.heading = heading  # rad: the yaw shown to the policy stays within ±heading
        self.turned = 0.0  # rad about up the last observation's frame was turned by
        self.goal_at_origin = goal_at_origin
        self.airframe = airframe
        self.period = options.control_period
        self.beta = options.beta
        self.observe_position = options.observe_position  # as the policy was trained
        self.observe_integral = options.observe_integral
        # Kept across setpoints and carrots, as a PID's integral term is (it holds what
        # the wind and the airframe need: held while climbing to a carrot, a steady wind
        # would push the vehicle off the line); zero again at reset and while idle.
        self.integral = EI.ErrorIntegral(1, options.control_period)
        self.params = airframe.to_params(-np.inf)[None, :]
        self.obs, self.dist, self.tilt = F.empty_buffers(1, expected)
        self.goal = np.zeros((1, 6))
        self.command = np.zeros(L.N_ROTORS)
        self.landing = CascadedController(airframe)  # flies the final descent
        self.reset()

    @classmethod
    def from_checkpoint(cls, path: str, airframe: Airframe) -> PolicyAutopilot:
        """From a checkpoint (.pt) or its export (.onnx, or a C .h with its contract)."""
        net, config = load_policy(path)
        trained = trained_range(config)
        return cls(
            net,
            airframe,
            trained_options(config),
            trained.offset,
            goal_at_origin=TASKS[config.task].goal_at_origin,
            heading=trained.heading or np.pi,
        )

    def reset(self) -> None:
        self.landing.reset()
        self.integral.reset()
        self.elapsed = np.inf
        self.origin: np.ndarray | None = None  # where the leg to the target began
        self.frame: np.ndarray | None = None  # the waypoint tasks' start, near the vehicle
        self.target: np.ndarray | None = None
        self.along = 0.0  # m along the leg: where the carrot is
        self.clock = 0.0  # s of policy steps on this leg
        self.nearest = (np.inf, 0.0)  # (gap m, clock s) when the vehicle last came nearer

    def rotor_command(self, state: np.ndarray, setpoint: Setpoint, dt: float) -> np.ndarray:
        if setpoint.landing:  # the waypoint policies never learned to touch down
            self.target = None
            return self.landing.rotor_command(state, setpoint, dt)
        self.elapsed += dt
        if self.elapsed < self.period - 1e-9:
            return self.command
        self.elapsed = 0.0
        if setpoint.idle:
            self.integral.reset()
            self.command = np.zeros(L.N_ROTORS)
            return self.command
        position = state[L.POS]
        goal = setpoint.destination if setpoint.destination is not None else setpoint.position
        target = position.copy() if goal is None else np.asarray(goal, dtype=np.float64)
        if goal is None and self.target is not None:
            target = self.target  # hold where position control ended
        action = self.action(state, target)
        omega = commanded_rotor_speed(self.airframe.hover_rotor_speed, self.beta, action)
        self.command = np.clip(omega, 0.0, self.airframe.max_rotor_speed)
        return self.command

    def action(self, state: np.ndarray, target: np.ndarray) -> np.ndarray:
        """The policy's action (its mean, as the envs step it) for the vehicle in
        ``state`` (a state row, world ENU) flying to ``target`` (ENU, m) through the
        carrot; one control period on."""
        position = state[L.POS]
        if self.target is None or np.linalg.norm(target - self.target) > 0.01:
            self.target, self.origin = target.copy(), position.copy()
            self.frame, self.along, self.clock = position.copy(), -np.inf, 0.0
        self._step_carrot(position)
        assert self.origin is not None and self.frame is not None
        goal = carrot(self.origin, self.target, self.along, position, self.carrot)
        # The task frame the policy learned: hover has its goal at the origin, the
        # waypoint tasks start at the origin (where the carrot last stepped on) with the
        # goal ahead.
        origin = goal if self.goal_at_origin else self.frame
        local = state.copy()[None, :]
        local[0, L.POS] -= origin
        self.goal[0, F.GOAL_POS] = goal - origin
        self._turn_heading(local[0])
        F.observe(local, self.params, self.goal, self.obs, self.dist, self.tilt)
        F.hide_position(self.obs, self.observe_position)
        if self.observe_integral:
            self.integral.accumulate(self.obs)
        return self.net.mean_action(self.obs)[0].astype(np.float64)

    def _step_carrot(self, position: np.ndarray) -> None:
        """Move the carrot on to ``carrot`` m ahead of the vehicle's place along the leg
        when it is near the carrot along the leg or has settled short of it (SETTLE);
        never back (a vehicle sinking away from it is pulled back to it)."""
        assert self.origin is not None and self.target is not None
        leg = self.target - self.origin
        length = float(np.linalg.norm(leg))
        if self.along >= length:
            return  # the carrot is the target
        self.clock += self.period
        done = 0.0 if length < 1e-9 else float((position - self.origin) @ leg) / length
        gap = self.along - done
        if gap < self.nearest[0] - 0.01:
            self.nearest = (gap, self.clock)
        if gap < REANCHOR * self.carrot or self.clock - self.nearest[1] > SETTLE:
            self.along = max(self.along, min(length, done + self.carrot))  # never back
            self.frame = position.copy()
            self.nearest = (np.inf, self.clock)

    def _turn_heading(self, local: np.ndarray) -> None:
        """Show a vehicle yawed beyond the trained headings at the edge of them: the task
        frame turned about up by the excess (the flight is the same in any heading),
        position, velocity and goal with it, in place."""
        yaw = float(euler_from_quat(local[L.QUAT])[2])
        excess = yaw - float(np.clip(yaw, -self.heading, self.heading))
        self.turned = excess
        if excess == 0.0:
            return
        turn = quat_from_axis_angle((0.0, 0.0, 1.0), -excess)
        local[L.QUAT] = quat_multiply(turn, local[L.QUAT])
        local[L.POS] = quat_rotate(turn, local[L.POS])
        local[L.VEL] = quat_rotate(turn, local[L.VEL])
        self.goal[0, F.GOAL_POS] = quat_rotate(turn, self.goal[0, F.GOAL_POS])
