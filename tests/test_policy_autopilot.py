"""A trained policy as ``quadsitl sim --autopilot``: it is shown goals only as far as it
was trained for (a carrot on the leg, kept within that range of the vehicle), the
simulator says at start what it was trained for or refuses it, and ``quadsitl fly``
reports progress and gives up on a vehicle that makes none."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch

from policies import checkpoint
from policies.autopilot import PolicyAutopilot, carrot, trained_range
from policies.config import TrainConfig
from quadsitl.flight_software.controller import Setpoint
from quadsitl.physics import PAPER
from quadsitl.physics import layout as L
from quadsitl.tasks import features as F
from quadsitl.wire.addresses import free_udp_port
from tests.conftest import run_cli, running_sim

HOVER = checkpoint.SHIPPED / "hover.pt"


def _state(position: tuple[float, float, float]) -> np.ndarray:
    state = np.zeros(L.STATE_SIZE)
    state[L.POS] = position
    state[L.QUAT] = (1.0, 0.0, 0.0, 0.0)
    return state


def test_the_hover_policy_is_shown_offsets_within_its_training_start_on_a_far_leg():
    """A 10 m leg: wherever the vehicle is (on the line, settled short of its goal, blown
    a metre off it), the goal the policy sees is at most its trained 0.3 m away and
    leads on towards the setpoint, so a policy that settles short still progresses."""
    torch.set_num_threads(1)
    pilot = PolicyAutopilot.from_checkpoint(str(HOVER), PAPER)
    assert pilot.carrot == pytest.approx(0.3)  # its start noise, ±0.3 m per axis
    setpoint = Setpoint(position=np.array([10.0, 0.0, 2.0]))
    pilot.rotor_command(_state((0.0, 0.0, 2.0)), setpoint, pilot.period)  # the leg begins
    for position in [(0.1, 0.0, 2.0), (0.2, 0.0, 1.95), (5.0, 0.0, 2.0), (3.0, 1.0, 2.0)]:
        pilot.rotor_command(_state(position), setpoint, pilot.period)
        offset = pilot.obs[0, F.OBS_GOAL_POS]
        assert np.linalg.norm(offset) <= 0.3 + 1e-6, (position, offset)
        assert offset[0] > 0.05, (position, offset)  # on towards the setpoint
    assert pilot.obs[0, F.OBS_GOAL_POS][1] < -0.1  # and back towards the line
    pilot.rotor_command(_state((9.9, 0.0, 2.0)), setpoint, pilot.period)
    np.testing.assert_allclose(pilot.obs[0, F.OBS_GOAL_POS], [0.1, 0.0, 0.0], atol=1e-6)


def test_a_policy_that_settles_short_of_its_carrot_still_moves_on():
    """The stall of a policy that holds short of its goal (sinking, or a droop): the
    carrot steps on within SETTLE s, still within the trained offset."""
    torch.set_num_threads(1)
    pilot = PolicyAutopilot.from_checkpoint(str(HOVER), PAPER)
    setpoint = Setpoint(position=np.array([0.0, 0.0, 10.0]))
    pilot.rotor_command(_state((0.0, 0.0, 2.0)), setpoint, pilot.period)
    for _ in range(round(2.0 / pilot.period)):  # 2 s held 0.2 m below the first carrot
        pilot.rotor_command(_state((0.0, 0.0, 2.1)), setpoint, pilot.period)
    np.testing.assert_allclose(pilot.obs[0, F.OBS_GOAL_POS], [0.0, 0.0, 0.3], atol=1e-6)


def test_a_heading_beyond_the_trained_ones_is_shown_at_their_edge():
    """Yawed 1 rad (a hover policy drifts in yaw on a long flight; it learned ±0.2 rad),
    the policy sees 0.2 rad, and the goal turned with the frame: the same flight."""
    from quadsitl.frames import quat_from_euler

    torch.set_num_threads(1)
    pilot = PolicyAutopilot.from_checkpoint(str(HOVER), PAPER)
    state = _state((0.0, 0.0, 2.0))
    state[L.QUAT] = quat_from_euler(0.0, 0.0, 1.0)
    pilot.rotor_command(state, Setpoint(position=np.array([0.0, 0.3, 2.0])), pilot.period)
    assert pilot.obs[0, F.OBS_SIN][2] == pytest.approx(np.sin(0.2), abs=1e-6)
    turned = 1.0 - 0.2  # the goal, due north, as seen from a frame turned back by 0.8 rad
    expected = [0.3 * np.sin(turned), 0.3 * np.cos(turned), 0.0]
    np.testing.assert_allclose(pilot.obs[0, F.OBS_GOAL_POS], expected, atol=1e-6)


def test_carrot_is_on_the_leg_and_never_beyond_its_reach_of_the_vehicle():
    origin, target = np.zeros(3), np.array([10.0, 0.0, 0.0])
    rng = np.random.default_rng(0)
    for position in rng.uniform(-3.0, 13.0, size=(200, 3)):
        point = carrot(origin, target, rng.uniform(0.0, 12.0), position, 0.5)
        assert np.linalg.norm(point - position) <= 0.5 + 1e-9
    np.testing.assert_allclose(carrot(origin, target, 4.5, np.array([4.0, 0, 0]), 0.5), [4.5, 0, 0])
    np.testing.assert_allclose(carrot(origin, target, 12.0, np.array([9.8, 0, 0]), 0.5), target)
    np.testing.assert_allclose(
        carrot(origin, origin, 0.0, np.array([3.0, 4, 0]), 0.5), [2.7, 3.6, 0]
    )


def test_trained_range_comes_from_the_policys_config_or_its_task():
    _, config, _ = checkpoint.load(HOVER)
    hover = trained_range(config)
    assert (hover.task, hover.offset, hover.speed, hover.heading) == ("hover", 0.3, 0.0, 0.2)
    bare = trained_range(TrainConfig(task="hover", task_options={}))
    assert bare.offset == 0.3 and "documented training start" in bare.describe()
    assert trained_range(TrainConfig(task="random_waypoint")).offset == 2.0
    with pytest.raises(ValueError, match="a land policy cannot fly goto and mission legs"):
        trained_range(TrainConfig(task="land"))


def test_sim_says_what_the_policy_was_trained_for_or_refuses_it():
    flown = run_cli("sim", "--logs", "none", "--duration", "0.5", "--autopilot", str(HOVER))
    assert flown.returncode == 0, flown.stderr
    assert "a hover policy, trained for goal offsets up to 0.3 m" in flown.stderr
    land = checkpoint.SHIPPED / "land.pt"
    refused = run_cli("sim", "--logs", "none", "--duration", "0.5", "--autopilot", str(land))
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1, refused.stderr
    assert "a land policy cannot fly goto and mission legs" in refused.stderr


def _fly(
    mission: Path, sim_args: str, *fly_args: str
) -> tuple[subprocess.CompletedProcess[str], str]:
    port = free_udp_port()
    with running_sim(f"sim --gcs none --api udpout:127.0.0.1:{port} --logs none {sim_args}") as sim:
        flown = run_cli("fly", str(mission), "--connect", f"udpin:127.0.0.1:{port}", *fly_args)
    return flown, sim.output


def test_shipped_hover_policy_flies_legs_longer_than_its_training_range(tmp_path):
    mission = tmp_path / "two_legs.txt"
    mission.write_text("0 0 2\n2 0 2\n2 2 2\n")  # 2 m legs: its offsets were ±0.3 m
    flown, sim_output = _fly(mission, f"--speed 8 --autopilot {HOVER}", "--timeout", "90")
    assert flown.returncode == 0, flown.stdout + flown.stderr + sim_output
    assert "item 3/4 (waypoint) reached" in flown.stdout
    assert "landed: True" in flown.stdout
    assert "trained for goal offsets up to 0.3 m" in sim_output


def test_fly_reports_a_stall_and_gives_up_long_before_its_timeout(tmp_path):
    mission = tmp_path / "hop.txt"
    mission.write_text("0 0 2\n2 0 2\n")
    flown, sim_output = _fly(
        mission, "--speed 8 --fail-motor 1", "--timeout", "600", "--stall-after", "10"
    )
    assert flown.returncode == 1, flown.stdout + flown.stderr + sim_output
    assert "quadsitl fly: failed: stalled: no progress for 10 s (simulated)" in flown.stderr
    assert "on item 1/3 (take-off): 2.0" in flown.stderr  # it never left the ground
    assert "timed out" not in flown.stderr


def test_a_negative_stall_time_is_refused_in_one_line():
    from tests.conftest import refused_here

    refused = refused_here("fly", "docs/missions/square.txt", "--stall-after", "-5")
    assert refused.returncode == 2
    assert (
        refused.stderr == "quadsitl fly: error: --stall-after must be 0 (never) or more s, not -5\n"
    )
