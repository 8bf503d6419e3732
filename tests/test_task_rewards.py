"""The parts of each task's reward beyond Eq. 18, computed by hand: the waypoint bonus,
landing's +500/−500, target following's range bonus and exit penalty.

Each test places one vehicle in a known state, takes one step, and checks that the
reward equals Eq. 18 (written out here from the distances the engine reports) plus the
bonus the task defines: so a wrong bonus, a missing one or one given in the wrong
situation fails.
"""

from __future__ import annotations

import numpy as np
import pytest

from quadsitl.physics import PAPER
from quadsitl.physics import layout as L
from quadsitl.tasks import TaskEngine, TaskOptions, get_task
from quadsitl.tasks import spec as S

ACTION_WEIGHT = 0.01
# Eq. 18's weights α (position, attitude, velocity, rates) and the time term per step of
# each task, as docs/tasks.md tables them: written here, not read from the tasks.
PAPER_TERMS = {
    "hover": ((100.0, 10.0, 0.1, 0.1), 10.0),
    "static_waypoint": ((100.0, 10.0, 0.1, 0.1), 0.1),
    "random_waypoint": ((100.0, 10.0, 0.1, 0.1), 0.1),
    "land": ((100.0, 10.0, 1.0, 5.0), 0.0),
    "target_follow": ((100.0, 10.0, 0.1, 0.1), 0.0),
}


def _engine(task: str, state: np.ndarray, contact: int = L.AIRBORNE) -> TaskEngine:
    engine = TaskEngine(get_task(task), 1, TaskOptions())
    engine.seed([0])
    engine.reset_envs(np.ones(1, bool))
    engine.fleet.reset(state[None, :], contact=contact)
    engine.observe()  # distances of the placed state: the step measures progress from here
    engine.prev_dist[:] = engine.dist
    return engine


def _state(position, velocity=(0.0, 0.0, 0.0), roll=0.0, rates=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Level (or rolled by ``roll`` rad), at ``position`` m ENU with ``velocity`` m/s
    and body ``rates`` rad/s, rotors at hover speed."""
    s = np.zeros(L.STATE_SIZE)
    s[L.POS], s[L.VEL], s[L.RATES] = position, velocity, rates
    s[L.QUAT] = [np.cos(roll / 2), np.sin(roll / 2), 0.0, 0.0]
    s[L.ROTORS] = PAPER.hover_rotor_speed
    return s


def _eq18(engine: TaskEngine, before: np.ndarray, action: np.ndarray) -> float:
    """Σ_c α_c (d_before − d_after) − 0.01‖a‖² + the time term."""
    weights, time_term = PAPER_TERMS[engine.task.name]
    progress = float(np.dot(weights, before[0] - engine.dist[0]))
    return progress - ACTION_WEIGHT * float(action @ action) + time_term


def _step(engine: TaskEngine, action: np.ndarray | None = None) -> tuple[float, float, int]:
    action = np.zeros(4) if action is None else action
    before = engine.dist.copy()
    reward, _terminated, _truncated = engine.step(action[None, :])
    return float(reward[0]), _eq18(engine, before, action), int(engine.outcome[0])


@pytest.mark.parametrize(
    ("task", "position"),
    [
        ("hover", (0.3, -0.2, 0.1)),
        ("static_waypoint", (0.3, -0.2, 0.1)),  # 1.2 m from its goal: no bonus
        ("random_waypoint", (0.3, -0.2, 0.1)),
        ("land", (0.3, -0.2, 1.5)),  # in the air, descending slower than 2 m/s
        ("target_follow", (2.8, 0.0, 0.0)),  # beyond 2 m of the target: no range bonus
    ],
)
def test_each_task_weighs_every_distance_with_the_papers_weights(task, position):
    """Moving, rolled and rotating, so that all four distances change in the step: a
    wrong weight on any of them, or a wrong time term, changes the reward."""
    state = _state(position, (0.4, -0.3, -0.5), roll=0.2, rates=(0.5, -0.4, 0.3))
    engine = _engine(task, state)
    before = engine.dist.copy()
    reward, shaped, outcome = _step(engine, np.array([0.5, -0.5, 1.0, 0.0]))
    assert outcome == S.RUNNING
    assert np.all(np.abs(before - engine.dist) > 1e-3), before - engine.dist
    assert reward == pytest.approx(shaped, abs=1e-9)


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
