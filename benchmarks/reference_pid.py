"""What a classical controller achieves where the robust policies are measured: the
built-in cascaded PID controller (quadsitl/flight_software/controller.py, the simulator's own
flight software) flying the hover and random waypoint tasks on the robustness ladder's
rungs, its setpoint the task's goal.

It is given every advantage a policy lacks: the true state (no observation delay, no
noise), at 100 Hz instead of the policies' 20 Hz, with its position, velocity and
attitude loops and their integral terms. Actuation delay, where a rung has it, is
applied as the env applies it. Each rung: 100 episodes from the task's evaluation starts
(hover: ±0.3 m, ±0.2 rad; random waypoint: anywhere in a 3 m box, the goal 1-2.5 m away
from there), seeds 0-99; success as the task's: within 0.1 m at the end (hover 5 s,
random waypoint 3.5 s).

Prints one line per rung: success, median and 90th-percentile final position error; then
the target rungs again with the position and velocity loops 1.5 times as stiff as the
defaults, the horizontal acceleration limit 3 times and the tilt limit 1.5 times theirs
(the stiffest of a sweep that stayed stable: twice the gains flip vehicles): what the
same controller achieves when tuned for this weather.
"""

from __future__ import annotations

import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks._common import pin_to_one_core
from policies.config import STARTS
from policies.ladder import LADDER
from quadsitl.flight_software.controller import CascadedController, ControllerGains, Setpoint
from quadsitl.physics import PAPER
from quadsitl.registration import task_env_id

EPISODES = 100
RATE_PERIOD = 0.01  # s: the controller's period (the physics step)
RUNGS = (
    ("hover", "turbulence", "moderate"),
    ("hover", "wind", "6 m/s"),
    ("hover", "delay", "20 ms"),
    ("hover", "target", None),
    ("random_waypoint", "target", "none"),
    ("random_waypoint", "target", None),
)


def stiff_gains() -> ControllerGains:
    """The default gains with the outer loops stiffened for gusts (module docstring)."""
    gains = ControllerGains.defaults()
    for name in ("pos_xy", "pos_z", "vel_xy", "vel_z"):
        setattr(gains, name, 1.5 * getattr(gains, name))
    gains.max_accel_xy *= 3.0
    gains.max_tilt_deg *= 1.5
    return gains


def fly(
    task: str, options: dict, gains: ControllerGains | None = None, episodes: int = EPISODES
) -> tuple[float, float, float]:
    """Success rate, median and 90th-percentile final error of ``episodes`` episodes."""
    env = gym.make(task_env_id(task), control_period=RATE_PERIOD, **STARTS[task], **options)
    engine = env.unwrapped.engine  # type: ignore[attr-defined]
    controller = CascadedController(PAPER, gains)
    beta = engine.options.beta
    success, errors = [], []
    for episode in range(episodes):
        env.reset(seed=episode)
        controller.reset()
        done = False
        while not done:
            state = engine.fleet.state[0].copy()
            setpoint = Setpoint(position=engine.goal[0, :3].copy(), yaw=0.0)
            command = controller.rotor_command(state, setpoint, RATE_PERIOD)
            action = (command - engine.hover_speed) / beta  # Eq. 19 inverted
            _, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        success.append(bool(info["success"]))
        errors.append(float(info["final_distance"]))
    env.close()
    return float(np.mean(success)), float(np.median(errors)), float(np.percentile(errors, 90))


def main() -> None:
    pin_to_one_core()
    target = LADDER["target"][1][-1]
    runs = [("cascaded PID", task, axis, label, None) for task, axis, label in RUNGS]
    runs += [
        ("cascaded PID, stiff", task, "target", None, stiff_gains())
        for task in ("hover", "random_waypoint")
    ]
    for name, task, axis, label, gains in runs:
        rung = target if label is None else next(r for r in LADDER[axis][1] if r.label == label)
        rate, median, p90 = fly(task, rung.options, gains)
        print(
            f"{name}, {task}, {axis} {rung.label}: success {rate:.0%}, final error "
            f"median {median:.3f} m, 90th percentile {p90:.3f} m",
            flush=True,
        )


if __name__ == "__main__":
    main()
