"""The parts of each task's reward beyond Eq. 18, computed by hand: the waypoint bonus,
landing's +500/−500, target following's range bonus and exit penalty.

Each test places one vehicle in a known state, takes one step, and checks that the
reward equals Eq. 18 (written out here from the distances the engine reports) plus the
bonus the task defines: so a wrong bonus, a missing one or one given in the wrong
situation fails.
"""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from quadsitl.physics import PAPER
from quadsitl.physics import layout as L
from quadsitl.tasks import TaskEngine, TaskOptions, get_task
from quadsitl.tasks import spec as S

ACTION_WEIGHT = 0.01


def _engine(task: str, state: np.ndarray, contact: int = L.AIRBORNE) -> TaskEngine:
    engine = TaskEngine(get_task(task), 1, TaskOptions())
    engine.seed([0])
    engine.reset_envs(np.ones(1, bool))
    engine.fleet.reset(state[None, :], contact=contact)
    engine.observe()  # distances of the placed state: the step measures progress from here
    engine.prev_dist[:] = engine.dist
    return engine


def _state(position, velocity=(0.0, 0.0, 0.0)) -> np.ndarray:
    s = np.zeros(L.STATE_SIZE)
    s[L.POS], s[L.VEL], s[L.I_QW] = position, velocity, 1.0
    s[L.ROTORS] = PAPER.hover_rotor_speed
    return s


def _eq18(engine: TaskEngine, before: np.ndarray, action: np.ndarray) -> float:
    """Σ_c α_c (d_before − d_after) − 0.01‖a‖² + the time term."""
    module = importlib.import_module(f"quadsitl.tasks.{engine.task.name}")
    progress = float(np.dot(module.WEIGHTS, before[0] - engine.dist[0]))
    return progress - ACTION_WEIGHT * float(action @ action) + getattr(module, "TIME_REWARD", 0.0)


def _step(engine: TaskEngine, action: np.ndarray | None = None) -> tuple[float, float, int]:
    action = np.zeros(4) if action is None else action
    before = engine.dist.copy()
    reward, _terminated, _truncated = engine.step(action[None, :])
    return float(reward[0]), _eq18(engine, before, action), int(engine.outcome[0])


@pytest.mark.parametrize(("offset", "bonus"), [(0.0, 100.0), (0.04, 100.0), (0.06, 0.0)])
def test_static_waypoint_bonus_within_5_cm(offset, bonus):
    engine = _engine("static_waypoint", _state((1.5 + offset, 0.0, 0.0)))  # goal (1.5, 0, 0)
    reward, shaped, _ = _step(engine)
    assert reward == pytest.approx(shaped + bonus, abs=1e-9)
    assert shaped == pytest.approx(0.1, abs=0.05)  # hovering still: the time term alone


def test_landing_on_the_pad_earns_500_and_a_crash_costs_500():
    gear = PAPER.gear_height
    gentle = _engine("land", _state((0.1, 0.0, gear + 0.01), (0.0, 0.0, -0.3)))
    reward, shaped, outcome = _step(gentle, np.full(4, -2.0))
    assert outcome == S.LANDED and reward == pytest.approx(shaped + 500.0, abs=1e-9)
    beside = _engine("land", _state((1.0, 0.0, gear + 0.01), (0.0, 0.0, -0.3)))
    reward, shaped, outcome = _step(beside, np.full(4, -2.0))
    assert outcome == S.LANDED_OFF_PAD and reward == pytest.approx(shaped, abs=1e-9)
    hard = _engine("land", _state((0.0, 0.0, gear + 0.05), (0.0, 0.0, -3.0)))
    reward, shaped, outcome = _step(hard)
    assert outcome == S.CRASHED and reward == pytest.approx(shaped - 500.0, abs=1e-9)
    vortex = _engine("land", _state((0.0, 0.0, 2.5), (0.0, 0.0, -2.5)))  # in the air
    reward, shaped, outcome = _step(vortex)
    assert outcome == S.CRASHED and reward == pytest.approx(shaped - 500.0, abs=1e-9)


def test_target_following_range_bonus_grows_over_the_episode_and_exit_costs_500():
    engine = _engine("target_follow", _state((0.0, 0.0, 0.0)))
    reward, shaped, outcome = _step(engine)  # step 1 of 500, target within 2 m
    assert outcome == S.RUNNING
    assert reward == pytest.approx(shaped + 5.0 * (1 + 1 / 500), abs=1e-9)
    engine.steps[:] = 399  # the next step is 400 of 500
    reward, shaped, _ = _step(engine)
    assert reward == pytest.approx(shaped + 5.0 * (1 + 400 / 500), abs=1e-9)
    far = _engine("target_follow", _state((3.0, 0.0, 0.0)))  # 3 m away: no bonus
    reward, shaped, outcome = _step(far)
    assert outcome == S.RUNNING and reward == pytest.approx(shaped, abs=1e-9)
    out = _engine("target_follow", _state((3.99, 0.0, 0.0), (2.0, 0.0, 0.0)))  # leaves the box
    reward, shaped, outcome = _step(out)
    assert outcome == S.OUT_OF_BOUNDS and reward == pytest.approx(shaped - 500.0, abs=1e-9)
