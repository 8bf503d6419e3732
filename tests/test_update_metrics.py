"""What an update logs (CleanRL's per-update statistics), to metrics.csv and TensorBoard,
and PPO's minibatches covering every sample (the remainder included, as in SB3)."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
import torch

from policies.algos.ppo import PPO
from policies.config import make_config
from policies.rollout import explained_variance, make_vector_env
from policies.train import train


def test_explained_variance_by_hand():
    returns = np.array([1.0, 2.0, 3.0, 6.0])
    assert explained_variance(returns, returns) == 1.0
    assert explained_variance(np.full(4, returns.mean()), returns) == pytest.approx(0.0)
    # Var(R) = 3.5, residual R - V = (0, 0, 0, 2): Var = 0.75 -> 1 - 0.75 / 3.5
    values = np.array([1.0, 2.0, 3.0, 4.0])
    assert explained_variance(values, returns) == pytest.approx(1 - 0.75 / 3.5)
    assert math.isnan(explained_variance(values, np.ones(4)))


def test_ppo_minibatches_cover_every_sample_including_the_remainder(monkeypatch):
    torch.set_num_threads(1)
    config = make_config(
        "hover",
        "ppo",
        "fast",
        num_envs=16,
        steps_per_env=10,
        minibatches=3,
        epochs=2,
        total_steps=160,
    )
    env = make_vector_env("hover", 16)
    algo = PPO(config, 34, 4)
    algo.start(env, seed=0)
    rollout = algo.collect(env)
    sizes: list[int] = []
    original = algo.critic_loss

    def counting(obs, returns):  # type: ignore[no-untyped-def]
        sizes.append(obs.shape[0])
        return original(obs, returns)

    monkeypatch.setattr(algo, "critic_loss", counting)
    stats = algo.update(rollout)
    env.close()
    assert sizes == [53, 53, 53, 1] * 2  # 160 samples in chunks of 160 // 3, twice
    assert stats["approx_kl"] >= 0.0 and 0.0 <= stats["clip_fraction"] <= 1.0


def test_metrics_csv_and_tensorboard_carry_the_update_statistics(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    torch.set_num_threads(1)
    config = make_config(
        "hover", "ppo", "fast", total_steps=16_384, num_envs=64, steps_per_env=64, eval_every=0
    )
    train(config, tmp_path, progress=False, tensorboard=True)
    with open(tmp_path / "metrics.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 4
    for row in rows:
        assert float(row["approx_kl"]) >= 0.0 and 0.0 <= float(row["clip_fraction"]) <= 1.0
        assert float(row["explained_variance"]) <= 1.0
    # The critic learns: it explains more of the returns at the end than at the start.
    assert float(rows[-1]["explained_variance"]) > float(rows[0]["explained_variance"])
    events = EventAccumulator(str(tmp_path / "tensorboard"))
    events.Reload()
    scalars = events.Scalars("hover/mean_return")
    assert [s.step for s in scalars] == [int(r["env_steps"]) for r in rows]
    assert [s.value for s in scalars] == pytest.approx([float(r["mean_return"]) for r in rows])
    assert "hover/clip_fraction" in events.Tags()["scalars"]


def test_trpo_has_no_ppo_statistics(tmp_path):
    torch.set_num_threads(1)
    config = make_config("hover", "trpo", "fast", total_steps=8_192, eval_every=0)
    train(config, tmp_path, progress=False)
    with open(tmp_path / "metrics.csv") as f:
        row = next(csv.DictReader(f))
    assert row["approx_kl"] == "nan" and math.isfinite(float(row["explained_variance"]))


def test_any_registered_gymnasium_env_with_a_box_action_space_trains(tmp_path):
    torch.set_num_threads(1)
    config = make_config(
        "Pendulum-v1", "ppo", "fast", total_steps=16_384, num_envs=16, steps_per_env=256
    )
    assert config.eval_every == 0 and config.task_options == {}
    result = train(config, tmp_path, progress=False)
    with open(tmp_path / "metrics.csv") as f:
        rows = list(csv.DictReader(f))
    finished = [float(r["mean_return"]) for r in rows if r["episodes"] != "0"]
    assert len(rows) == 4 and finished and all(-2000 < x < 0 for x in finished)  # Pendulum
    assert result.env_steps == 16_384 and (tmp_path / "checkpoints" / "last.pt").is_file()


def test_unknown_tasks_and_other_action_spaces_are_refused():
    with pytest.raises(ValueError, match="registered Gymnasium env id"):
        make_config("NoSuchEnv-v0", "ppo", "fast")
    with pytest.raises(ValueError, match="Discrete action space; the algorithms need a Box"):
        make_vector_env("CartPole-v1", 2)
