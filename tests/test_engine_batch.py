"""The engine's StepBatch and StepEnd hold the engine's own arrays: compiled ``evaluate``
and ``close_step`` write where the engine and the envs read, through resets, randomised
airframes and steps (and a recorder's buffer, once it has set one)."""

from __future__ import annotations

import gymnasium as gym
import numba
import numpy as np
import pytest

import quadsitl  # noqa: F401  (registers the envs)
from quadsitl.physics import layout as L
from quadsitl.tasks.batch import FIELDS


@numba.njit
def held(b):
    """The batch's fields, read as compiled code reads them."""
    return (
        b.state,
        b.params,
        b.contact,
        b.goal,
        b.action,
        b.steps,
        b.max_steps,
        b.obs,
        b.dist,
        b.prev_dist,
        b.tilt,
        b.reward,
        b.outcome,
    )


def engine_arrays(engine):
    fleet = engine.fleet
    own = {"state": fleet.state, "params": fleet.params, "contact": fleet.contact}
    return {name: own.get(name, getattr(engine, name, None)) for name in FIELDS}


def test_the_batch_holds_the_arrays_the_engine_reads_after_resets_and_steps():
    env = gym.make("QuadSITL/RandomWaypoint-v0", randomize=True)
    engine = env.unwrapped.engine
    for seed in (0, 1):
        env.reset(seed=seed)
        for _ in range(5):
            obs, reward, *_ = env.step(env.action_space.sample())
    fields = dict(zip(FIELDS, held(engine._batch), strict=True))
    for name, array in engine_arrays(engine).items():
        if name == "max_steps":
            assert fields[name] == engine.max_steps
            continue
        assert fields[name].shape == array.shape, name
        assert np.shares_memory(fields[name], array), name
    # what evaluate wrote is what the env returned
    assert np.array_equal(engine.obs[0], obs) and engine.reward[0] == reward
    env.close()


@numba.njit
def ended(e):
    """The StepEnd's array fields, read as compiled code reads them."""
    return (
        e.dist,
        e.prev_dist,
        e.reward,
        e.outcome,
        e.steps,
        e.time_within,
        e.reach_time,
        e.episode_return,
        e.terminated,
        e.truncated,
        e.state,
        e.goal,
        e.wind_state,
        e.recording,
    )


def test_the_step_end_holds_the_arrays_the_engine_reads_and_the_recorders_buffer(tmp_path):
    save = str(tmp_path / "land.rrd")
    env = gym.make("QuadSITL/Land-v0", randomize=True, render_mode="rerun", rerun_save=save)
    engine = env.unwrapped.engine
    for seed in (0, 1):
        env.reset(seed=seed)
        for _ in range(5):
            _, reward, *_ = env.step(env.action_space.sample())
    fleet = engine.fleet
    own = {"state": fleet.state, "wind_state": fleet.wind_state, "recording": engine.recording}
    names = ("dist", "prev_dist", "reward", "outcome", "steps", "time_within", "reach_time")
    names += ("episode_return", "terminated", "truncated", "state", "goal", "wind_state")
    for name, array in zip((*names, "recording"), ended(engine._end), strict=True):
        expected = own.get(name, getattr(engine, name, None))
        assert np.shares_memory(array, expected), name
    assert engine.episode_return[0] != 0.0 and engine.reward[0] == reward
    env.close()


def test_each_struct_is_made_from_its_one_list_of_fields_by_name():
    """The fields of StepBatch and StepEnd are listed once (their FIELDS): a struct is
    given them by name, in any order, and a missing or unknown one is refused."""
    from quadsitl.tasks import step_end
    from quadsitl.tasks.batch import StepBatch

    n = 2
    arrays = {
        "state": np.zeros((n, L.STATE_SIZE)),
        "params": np.zeros((n, L.N_PARAMS)),
        "contact": np.zeros(n, np.int8),
        "goal": np.zeros((n, 6)),
        "action": np.zeros((n, 4)),
        "steps": np.zeros(n, np.int64),
        "max_steps": 7,
        "obs": np.zeros((n, 34), np.float32),
        "dist": np.zeros((n, 4)),
        "prev_dist": np.zeros((n, 4)),
        "tilt": np.zeros(n),
        "reward": np.arange(n, dtype=np.float64),
        "outcome": np.zeros(n, np.int8),
    }
    assert set(arrays) == set(FIELDS)
    batch = StepBatch(**dict(reversed(arrays.items())))
    for name, value in zip(FIELDS, held(batch), strict=True):
        if name == "max_steps":
            assert value == 7
        else:
            assert np.shares_memory(value, arrays[name]), name
    with pytest.raises(TypeError, match="fields"):
        StepBatch(**{k: v for k, v in arrays.items() if k != "tilt"})
    with pytest.raises(TypeError, match="fields"):
        step_end.StepEnd(dist=arrays["dist"])
