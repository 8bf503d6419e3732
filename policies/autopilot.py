"""A trained policy as the simulator's autopilot (``quadsitl sim --autopilot CKPT``).

It implements :class:`quadsitl.vehicle.controller.Autopilot`: given the vehicle state
and the navigator's setpoint (take-off, goto, mission legs), it builds the task
observation and returns the policy's rotor commands, held for the policy's control
period (0.05 s). Waypoint policies learned goals 1–2.5 m away, so a farther target is
approached through a carrot at most ``CARROT`` m ahead on the line to it (by the task
the policy learned), re-anchored as each carrot is reached. The policy always faces the
task's heading (east, yaw 0); setpoint yaw is ignored. Without a position setpoint
(velocity or attitude control) it holds the position where that began. Landing (the
final descent of LAND, RTL and mission land items) is flown by the cascaded controller.
A policy trained with ``observe_integral`` gets its integral from the autopilot, kept
as the env keeps it (quadsitl/tasks/error_integral.py).
"""

from __future__ import annotations

import numpy as np

from policies.export.contract import layout_text, observation_size, trained_options
from policies.export.runtimes import load_policy
from policies.networks import DeterministicPolicy
from quadsitl.physics import Airframe
from quadsitl.physics import layout as L
from quadsitl.tasks import TASKS, TaskOptions
from quadsitl.tasks import error_integral as EI
from quadsitl.tasks import features as F
from quadsitl.tasks.step_kernels import commanded_rotor_speed
from quadsitl.vehicle.controller import CascadedController, Setpoint

# m: the farthest goal shown to the policy, by the task it learned (TaskSpec.carrot);
# the tasks without one cannot fly goto and mission legs.
CARROT = {name: t.carrot for name, t in TASKS.items() if t.carrot is not None}
REANCHOR = 0.5  # fraction of the carrot distance that counts as reached


class PolicyAutopilot:
    def __init__(
        self,
        net: DeterministicPolicy,
        airframe: Airframe,
        options: TaskOptions,
        carrot: float = 2.0,
        goal_at_origin: bool = False,
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
        if config.task not in CARROT:
            raise ValueError(f"a {config.task} policy cannot fly goto and mission legs")
        return cls(
            net,
            airframe,
            trained_options(config),
            CARROT[config.task],
            goal_at_origin=TASKS[config.task].goal_at_origin,
        )

    def reset(self) -> None:
        self.landing.reset()
        self.integral.reset()
        self.elapsed = np.inf
        self.origin: np.ndarray | None = None
        self.target: np.ndarray | None = None

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
        if self.target is None or np.linalg.norm(target - self.target) > 0.01:
            self.target, self.origin = target.copy(), position.copy()
        assert self.origin is not None
        goal = self._carrot(position)
        # The task frame the policy learned: hover has its goal at the origin, the
        # waypoint tasks start at the origin with the goal ahead.
        origin = goal if self.goal_at_origin else self.origin
        local = state.copy()[None, :]
        local[0, L.POS] -= origin
        self.goal[0, F.GOAL_POS] = goal - origin
        F.observe(local, self.params, self.goal, self.obs, self.dist, self.tilt)
        F.hide_position(self.obs, self.observe_position)
        if self.observe_integral:
            self.integral.accumulate(self.obs)
        action = self.net.mean_action(self.obs)[0].astype(np.float64)  # as the envs step it
        omega = commanded_rotor_speed(self.airframe.hover_rotor_speed, self.beta, action)
        self.command = np.clip(omega, 0.0, self.airframe.max_rotor_speed)
        return self.command

    def _carrot(self, position: np.ndarray) -> np.ndarray:
        assert self.origin is not None and self.target is not None
        offset = self.target - self.origin
        distance = float(np.linalg.norm(offset))
        if distance <= self.carrot:
            return self.target
        carrot = self.origin + offset * (self.carrot / distance)
        if np.linalg.norm(carrot - position) < REANCHOR * self.carrot:
            self.origin = position.copy()  # the next segment starts here
            return self._carrot(position)
        return carrot
