"""``quadsitl companion``: a setpoint policy, exported to ONNX, flying a vehicle over real
MAVLink as a companion computer, against ``quadsitl sim`` (which speaks as PX4: OFFBOARD,
Hold, EXTENDED_SYS_STATE). The policy is a position controller written into a network's
weights (velocity = the goal offset, 1/s): a frame or sign wrong anywhere between the
autopilot's estimate and its setpoint would fly it away from the goal, not onto it."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch
from pymavlink.dialects.v20 import common as mav

from gcs_tools.client import VehicleClient
from gcs_tools.demo import free_udp_port
from policies import checkpoint
from policies.config import make_config
from policies.export.writer import export
from policies.networks import ActorCritic
from quadsitl.tasks import features as F
from quadsitl.wire.modes import Mode
from tests.conftest import cli, run_cli, running_sim

GAIN = 0.1  # of the hidden units: tanh stays about linear over the offsets flown


def position_controller(folder: Path, level: str = "velocity") -> Path:
    """An ONNX setpoint policy whose velocity action is half the goal offset (the
    setpoint: the offset per second, up at half that), exported as quadsitl export does;
    "trained" on goals up to 2 m away (the companion's carrot shows it no farther one)."""
    config = make_config("hover", "ppo", "fast", backend="px4", action_level=level, num_envs=1)
    config.task_options["init_position_noise"] = 2.0  # the goal offsets it flies directly
    net = ActorCritic(F.OBS_SIZE, 4, config.hidden, True, config.normalize_obs)
    with torch.no_grad():
        body, head = net.actor_body[0], net.policy_head.mean
        for layer in (body, head):
            layer.weight.zero_()
            layer.bias.zero_()
        for axis in range(3):  # east, north, up
            body.weight[axis, F.OBS_GOAL_POS.start + axis] = GAIN
            head.weight[axis, axis] = 0.5 / GAIN
    path = folder / f"controller-{level}.pt"
    checkpoint.save(path, net, config)
    return export(path, "onnx", str(folder) + "/")[0]


@pytest.fixture(scope="module")
def controller(tmp_path_factory) -> Path:
    return position_controller(tmp_path_factory.mktemp("policy"))


def sim_and_link(speed: float = 2.0):  # type: ignore[no-untyped-def]
    """``quadsitl sim`` with a ground station's link and the companion's, both udpin."""
    gcs, api = free_udp_port(), free_udp_port()
    words = f"sim --gcs udpin:127.0.0.1:{gcs} --api udpin:127.0.0.1:{api} --logs none"
    return running_sim(f"{words} --speed {speed}", ports=(gcs, api)), gcs, api


def companion(policy: Path, api: int, *options: str) -> list[str]:
    return cli(f"companion {policy} --connect udpout:127.0.0.1:{api} --timeout 60", *options)


def test_a_disarmed_vehicle_is_refused_and_left_as_it_was(controller):
    sim, gcs, api = sim_and_link()
    with sim:
        ground = VehicleClient(f"udpout:127.0.0.1:{gcs}")
        try:
            ground.connect(timeout=30)
            mode = ground.mode
            done = subprocess.run(companion(controller, api), capture_output=True, text=True,
                                  timeout=120)  # fmt: skip
            assert done.returncode == 2, done.stderr
            assert "refused: the vehicle is disarmed" in done.stderr
            assert "--takeoff" in done.stderr
            ground.drain()
            ground.wait_message("HEARTBEAT", timeout=10)
            assert not ground.armed and ground.mode == mode
        finally:
            ground.close()


def test_the_policy_takes_off_flies_to_its_goal_and_hands_the_vehicle_back(controller):
    """--takeoff, then the policy's setpoints in OFFBOARD until --duration, then Hold:
    armed, in the air, within 0.25 m of the goal by the vehicle's own telemetry."""
    sim, gcs, api = sim_and_link()
    with sim:
        ground = VehicleClient(f"udpout:127.0.0.1:{gcs}")
        try:
            ground.connect(timeout=30)
            done = subprocess.run(
                companion(controller, api, "--takeoff", 2, "--goal", "1.5,-1,3", "--duration", 8),
                capture_output=True, text=True, timeout=300,
            )  # fmt: skip
            assert done.returncode == 0, done.stderr
            assert "OFFBOARD: the policy flies to (1.50, -1.00, 3.00)" in done.stderr
            assert "rotor speeds: the motor outputs (SERVO_OUTPUT_RAW)" in done.stderr
            assert "8 s flown: handed back in Hold (AUTO.LOITER)" in done.stderr
            ground.drain()
            ground.wait_message("HEARTBEAT", timeout=10)
            assert ground.armed and ground.mode == Mode.LOITER.name
            p = ground.wait_message("LOCAL_POSITION_NED", timeout=10)
            here = np.array([p.y, p.x, -p.z])  # east, north, up
            assert np.linalg.norm(here - [1.5, -1.0, 3.0]) < 0.25, here
        finally:
            ground.close()


def test_the_companion_stops_when_the_pilot_takes_the_vehicle_back(controller):
    sim, gcs, api = sim_and_link()
    with sim:
        ground = VehicleClient(f"udpout:127.0.0.1:{gcs}")
        flying = subprocess.Popen(companion(controller, api, "--takeoff", 2),
                                  stderr=subprocess.PIPE, text=True)  # fmt: skip
        try:
            ground.connect(timeout=30)
            assert flying.stderr is not None
            for line in flying.stderr:
                if "the policy flies to" in line:
                    break
            ground.set_mode("POSCTL")
            _, rest = flying.communicate(timeout=60)
            assert flying.returncode == 0, rest
            assert "the vehicle left OFFBOARD (the pilot or a failsafe took it)" in rest
        finally:
            if flying.poll() is None:
                flying.kill()
            ground.close()


def test_a_policy_that_commands_rotor_speeds_is_refused():
    shipped = Path(__file__).resolve().parents[1] / "policies" / "checkpoints" / "hover.pt"
    done = run_cli("companion", str(shipped), "--connect", "udpout:127.0.0.1:9", "--timeout", "1")
    assert done.returncode == 2
    assert "this policy commands rotor speeds" in done.stderr
    assert "quadsitl sim --autopilot" in done.stderr


def test_an_autopilot_that_is_neither_px4_nor_ardupilot_is_refused(controller, tmp_path):
    gcs, api = free_udp_port(), free_udp_port()
    words = f"sim --gcs udpin:127.0.0.1:{gcs} --api udpin:127.0.0.1:{api} --logs none"
    with running_sim(f"{words} --autopilot-id generic", ports=(gcs, api)):
        done = subprocess.run(companion(controller, api), capture_output=True, text=True,
                              timeout=120)  # fmt: skip
    assert done.returncode == 2
    assert "MAV_AUTOPILOT_GENERIC" in done.stderr and "PX4 (OFFBOARD)" in done.stderr


def test_an_exported_setpoint_policy_says_its_setpoints_and_timing(controller):
    """The contract beside the ONNX file: the setpoint message and scales, and the
    flight-stack env's timing (50 Hz, 4 ms rounds), not the rotor-speed task's."""
    import json

    contract = json.loads(controller.with_name(controller.stem + ".contract.json").read_text())
    assert contract["action"]["level"] == "velocity"
    assert "SET_POSITION_TARGET_LOCAL_NED" in contract["action"]["message"]
    assert contract["control"]["rate_hz"] == pytest.approx(50.0)
    assert contract["control"]["physics_dt_s"] == pytest.approx(0.004)
    assert contract["motors"]["airframe"] == "iris"
    assert mav.MAV_FRAME_LOCAL_NED == 1  # the frame the message names


def test_a_setpoint_given_in_a_turned_frame_is_turned_back_into_the_world():
    """A vehicle shown to the policy turned by −θ about up: its velocity setpoint's east
    and north are turned by θ, an attitude's yaw gets θ added (wrapped), rates stay."""
    from policies.companion.flight import unturned

    quarter = np.pi / 2
    east = np.array([0.5, 0.0, 0.1, 0.2])
    np.testing.assert_allclose(unturned(east, "velocity", quarter), [0.0, 0.5, 0.1, 0.2],
                               atol=1e-12)  # fmt: skip
    facing = np.array([0.1, 0.0, 0.75, 0.3])  # yaw 0.75 π
    np.testing.assert_allclose(unturned(facing, "attitude", quarter)[2], -0.75)
    rates = np.array([0.1, 0.2, 0.3, 0.4])
    np.testing.assert_array_equal(unturned(rates, "rates", quarter), rates)


@pytest.mark.parametrize(
    ("url", "says"),
    [("foo:bar", "neither a MAVLink URL"), ("udpin:127.0.0.1:99999", "cannot open --connect")],
)
def test_a_connection_that_cannot_be_opened_is_a_one_line_error(controller, url, says):
    done = run_cli("companion", str(controller), "--connect", url, "--timeout", "1")
    assert done.returncode == 2 and says in done.stderr
    assert "Traceback" not in done.stderr
