"""The contract of an exported policy: what a flight controller must feed it and how to
use what it returns, written beside the ONNX file or C header (``NAME.contract.json``).

Every fact is read from the code that defines it (the observation layout of
``quadsitl.tasks.features``, the airframe, the task options the policy was trained
with), so the contract cannot drift from the simulator. It answers the convention
mismatches users report: quaternion order, velocity frames, motor order, the action's
scale.
"""

from __future__ import annotations

import hashlib
import importlib
from pathlib import Path
from typing import Any

from policies.config import FLIGHT_STACKS, TrainConfig
from quadsitl.frames import __doc__ as FRAMES_DOC
from quadsitl.physics import Airframe, get_airframe
from quadsitl.physics import layout as L
from quadsitl.tasks import TASKS, TaskOptions, TaskSpec
from quadsitl.tasks import features as F
from quadsitl.tasks.observation_layout import observation_layout, observation_size

FORMAT = "quadsitl-policy-contract-1"
ONNX_INPUT, ONNX_OUTPUT = "obs", "action"  # tensor names of the ONNX graph
C_FORWARD = "void policy_forward(const float *obs, float *action)"
C_ROTOR_SPEEDS = "void policy_rotor_speeds(const float *action, float *rotor_speed)"
NORM_CLIP = 10.0  # normalised observations are clipped to ±this (networks.RunningNorm)


def contract_path(exported: Path) -> Path:
    """``policy.onnx`` and ``policy.h`` → ``policy.contract.json`` (one contract: both
    forms of a checkpoint compute the same function)."""
    return exported.with_name(exported.stem + ".contract.json")


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def trained_options(config: TrainConfig) -> TaskOptions:
    """The task options a policy was trained with, less its start noise (init_*); through
    an autopilot (backend px4 or ardupilot), its env step's timing
    (quadsitl/envs/offboard_env.py)."""
    options = {k: v for k, v in config.task_options.items() if not k.startswith("init_")}
    if config.backend in FLIGHT_STACKS:
        from quadsitl.envs.offboard_env import AIRFRAME, flight_stack_timing

        timing = flight_stack_timing(config.control_rate, config.backend)
        options = {"airframe": AIRFRAME, **timing, **options}
    return TaskOptions.from_kwargs(**options)


def layout_text(task_name: str, options: TaskOptions | None = None) -> str:
    """One line: ``[0:3] position ... (world ENU, m); ...`` (for error messages)."""
    blocks = observation_layout(TASKS[task_name], options)
    return "; ".join(f"[{s.start}:{s.stop}] {meaning} ({unit})" for s, meaning, unit in blocks)


def fine_offset_scale(contract: dict[str, Any]) -> float:
    """The scale (m) of the policy's fine view of the goal offset, 0 for none
    (policies/networks.py), as its training config (checked by TrainConfig) gives it."""
    return float(TrainConfig.from_dict(contract["checkpoint"]["config"]).fine_offset_scale)


def _hidden(columns: slice, options: TaskOptions) -> str:
    """What to feed in the position slots of a policy trained without them."""
    if columns == F.OBS_POS and not options.observe_position:
        return ": NOT USED by this policy (trained with observe_position false): feed 0"
    return ""


def build_contract(config: TrainConfig, checkpoint: Path, act_size: int) -> dict[str, Any]:
    """The contract of the policy in ``checkpoint`` (trained with ``config``)."""
    task = TASKS[config.task]
    options = trained_options(config)
    airframe = get_airframe(options.airframe)  # type: ignore[arg-type]
    obs_size = observation_size(task, options)
    return {
        "format": FORMAT,
        "task": _task_section(task, config),
        "checkpoint": {
            "file": checkpoint.name,
            "sha256": sha256(checkpoint),
            "algorithm": config.algo,
            "preset": config.preset,
            "seed": config.seed,
            "config": config.to_dict(),
        },
        "conventions": _conventions(),
        "observation": _observation_section(task, config, options, obs_size),
        "action": (
            _setpoint_section(config.action_level, airframe, act_size)
            if config.backend in FLIGHT_STACKS
            else _action_section(airframe, options, act_size)
        ),
        "motors": _motors_section(airframe),
        "control": {
            "rate_hz": 1.0 / options.control_period,
            "period_s": options.control_period,
            "physics_dt_s": options.physics_dt,
            "hold": "each command is held for one control period",
        },
        "forms": {
            "onnx": {
                "input": ONNX_INPUT,
                "output": ONNX_OUTPUT,
                "shapes": [["batch", obs_size], ["batch", act_size]],
            },
            "c": {
                "forward": C_FORWARD,
                "rotor_speeds": C_ROTOR_SPEEDS + " (Eq. 19, clipped)",
                "needs": "a C99 compiler and libm's tanhf",
            },
        },
    }


def _task_section(task: TaskSpec, config: TrainConfig) -> dict[str, Any]:
    """The contract's ``task``: its name, description, episode length, start and goal."""
    return {
        "name": task.name,
        "description": _task_description(task.name),
        "episode_seconds": task.episode_seconds,
        "start_position_enu_m": _fixed_or_drawn(task.start),
        "goal_position_velocity_enu": _fixed_or_drawn(task.goal),
        "training_start_noise": {
            k: v for k, v in config.task_options.items() if k.startswith("init_")
        },
    }


def _observation_section(
    task: TaskSpec, config: TrainConfig, options: TaskOptions, obs_size: int
) -> dict[str, Any]:
    """The contract's ``observation``: size, what normalisation is inside, the layout."""
    return {
        "size": obs_size,
        "dtype": "float32",
        "normalisation": (
            "inside the exported policy: feed raw observations. "
            + (
                f"(obs − mean) / sqrt(var + 1e-8) with the training's running mean and "
                f"variance, clipped to ±{NORM_CLIP:g}"
                if config.normalize_obs
                else "none (trained on raw observations)"
            )
            + (
                f"; the network also sees tanh(obs[{F.OBS_GOAL_POS.start}:"
                f"{F.OBS_GOAL_POS.stop}] / {config.fine_offset_scale:g} m), computed "
                "inside from the raw goal offset"
                if config.fine_offset_scale
                else ""
            )
        ),
        "layout": [
            {
                "columns": [s.start, s.stop],
                "meaning": meaning + _hidden(s, options),
                "frame_unit": unit,
            }
            for s, meaning, unit in observation_layout(task, options)
        ],
    }


def _action_section(airframe: Airframe, options: TaskOptions, act_size: int) -> dict[str, Any]:
    """The contract's ``action``: what the network returns and Eq. 19's constants."""
    hover, top = airframe.hover_rotor_speed, airframe.max_rotor_speed
    return {
        "size": act_size,
        "dtype": "float32",
        "meaning": (
            "a: the network's mean action, one value per motor in motor order, not "
            "clipped; the rotor speed command is Eq. 19 below"
        ),
        "rotor_speed_command": (
            "Ω_c[i] = clip(hover_rotor_speed + beta · a[i], 0, max_rotor_speed), rad/s "
            "(equivalently: clip a to action_bounds first)"
        ),
        "hover_rotor_speed_rad_s": hover,
        "beta_rad_s": options.beta,
        "max_rotor_speed_rad_s": top,
        "action_bounds": [-hover / options.beta, (top - hover) / options.beta],
    }


def _setpoint_section(level: str, airframe: Airframe, act_size: int) -> dict[str, Any]:
    """The contract's ``action`` of a policy that flies an autopilot by its setpoints
    (quadsitl/envs/setpoints.py: its scales are read from there)."""
    from quadsitl.envs import setpoints as S

    meanings = {
        "velocity": (
            f"a[0:3] east, north, up velocity × ({S.MAX_SPEED_XY:g}, {S.MAX_SPEED_XY:g}, "
            f"{S.MAX_SPEED_Z:g}) m/s; a[3] yaw rate about up × {S.MAX_YAW_RATE:g} rad/s",
            "SET_POSITION_TARGET_LOCAL_NED, MAV_FRAME_LOCAL_NED, velocity and yaw rate "
            "(north = a[1], east = a[0], down = −a[2]; yaw rate about down = −a[3])",
        ),
        "attitude": (
            f"a[0:2] roll, pitch × {S.MAX_TILT:g} rad, a[2] yaw × π rad (ENU: 0 faces "
            "east), body FLU in world ENU; a[3] collective thrust",
            "SET_ATTITUDE_TARGET, quaternion FRD→NED and thrust, body rates ignored",
        ),
        "rates": (
            f"a[0:2] body roll, pitch rates × {S.MAX_RATE_RP:g} rad/s, a[2] yaw rate × "
            f"{S.MAX_RATE_YAW:g} rad/s, body FLU; a[3] collective thrust",
            "SET_ATTITUDE_TARGET, body rates FRD and thrust, the attitude ignored",
        ),
    }
    meaning, message = meanings[level]
    section: dict[str, Any] = {
        "size": act_size,
        "dtype": "float32",
        "level": level,
        "meaning": meaning + "; every a clipped to [−1, 1] first",
        "message": message,
    }
    if level != "velocity":
        section["thrust"] = (
            "normalised collective thrust 0..1: a[3] = 0 the airframe's hover thrust "
            f"({airframe.hover_thrust_fraction:g}), −1 none, +1 full (linear between)"
        )
    section["sent_by"] = "quadsitl companion, or quadsitl.envs.setpoints.message"
    return section


def _motors_section(airframe: Airframe) -> dict[str, Any]:
    """The contract's ``motors``: the airframe, each motor's place and spin, in order."""
    return {
        "airframe": airframe.name,
        "order": [
            {
                "motor": i + 1,
                "position_body_flu_m": [float(v) for v in position],
                "spin_seen_from_above": _spin(sign),
                "reaction_torque_sign_z": sign,
            }
            for i, (position, sign) in enumerate(
                zip(airframe.rotor_positions(), airframe.rotor_yaw_sign, strict=True)
            )
        ],
        "thrust_coeff_n_per_rad_s_sq": airframe.thrust_coeff,
        "motor_time_constant_s": 1.0 / airframe.motor_rate,
        "mass_kg": airframe.mass,
    }


def _conventions() -> dict[str, str]:
    """The frame conventions, quoted from the simulator's one statement of them."""
    assert FRAMES_DOC is not None
    bullets = FRAMES_DOC.split("Conventions used everywhere in quadsitl:")[1]
    bullets = bullets.split("Every function accepts")[0]
    quaternion, frames, euler = (
        " ".join(item.split()) for item in bullets.split("* ")[1:4]
    )  # as stated in quadsitl/frames.py
    frames = frames.split("; convert only at the wire")[0] + "."
    columns = {L.I_QW: "w", L.I_QX: "x", L.I_QY: "y", L.I_QZ: "z"}
    return {
        "quaternion": quaternion,
        "quaternion_order_in_state": "(" + ", ".join(columns[k] for k in sorted(columns)) + ")",
        "frames": frames,
        "euler_angles": euler,
        "observation_attitude": "no quaternion: the sines and cosines of the Euler angles",
    }


def _spin(reaction_sign: float) -> str:
    # A rotor spinning counter-clockwise seen from above (+z) pushes the body to −z.
    return "counter-clockwise" if reaction_sign < 0 else "clockwise"


def _fixed_or_drawn(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else "drawn each episode (docs/tasks.md)"


def _task_description(name: str) -> str:
    doc = importlib.import_module(f"quadsitl.tasks.{name}").__doc__ or ""
    return " ".join(doc.split("\n\n")[0].split())
