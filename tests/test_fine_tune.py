"""A run that starts from another run's weights (``quadsitl train --init``)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from policies import checkpoint
from policies.config import make_config
from policies.fine_tune import start_from
from policies.networks import ActorCritic
from policies.train import train
from quadsitl.tasks import error_integral as EI
from tests.conftest import refused_here

OBS_SIZE = 34  # hover's observation without option blocks


def _saved(tmp_path, task="land", algo="ppo", hidden=32, obs_size=OBS_SIZE, fine=0.0, **options):
    """A checkpoint of a random network (running observation statistics not at 0/1)."""
    config = make_config(task, algo, "fast", hidden=hidden, fine_offset_scale=fine)
    config.task_options.update(options)
    torch.manual_seed(1)
    net = ActorCritic(obs_size, 4, hidden, algo != "trpo", config.normalize_obs, 0.0, fine)
    with torch.no_grad():
        net.norm.mean.uniform_(-1, 1)
        net.norm.var.uniform_(0.5, 2)
        net.norm.count.fill_(1e6)
    path = tmp_path / f"{task}-{algo}-{hidden}.pt"
    checkpoint.save(path, net, config)
    return path, net


def _fresh(config, obs_size):
    torch.manual_seed(2)
    return ActorCritic(
        obs_size,
        4,
        config.hidden,
        config.algo != "trpo",
        config.normalize_obs,
        fine_offset_scale=config.fine_offset_scale,
    )


def test_a_run_that_observes_the_integral_starts_computing_what_the_checkpoint_computed(tmp_path):
    path, old = _saved(tmp_path)
    config = make_config("land", "ppo", "fast", hidden=32)
    config.task_options["observe_integral"] = True
    net = _fresh(config, OBS_SIZE + EI.SIZE)
    start_from(net, path, config)
    rng = np.random.default_rng(0)
    obs = torch.as_tensor(rng.normal(size=(64, OBS_SIZE)), dtype=torch.float32)
    integral = torch.as_tensor(rng.uniform(-2, 2, size=(64, EI.SIZE)), dtype=torch.float32)
    wider = torch.cat([obs, integral], 1)
    with torch.no_grad():
        assert torch.allclose(net.distribution(wider).mean, old.distribution(obs).mean, atol=1e-6)
        assert torch.allclose(net.distribution(wider).stddev, old.distribution(obs).stddev)
        assert torch.allclose(net.value(wider), old.value(obs), atol=1e-5)
        # The new columns: zero weights, the normaliser's neutral statistics.
        assert not net.actor_body[0].weight[:, OBS_SIZE:].any()
        assert torch.equal(net.norm.mean[:OBS_SIZE], old.norm.mean)
        assert not net.norm.mean[OBS_SIZE:].any() and (net.norm.var[OBS_SIZE:] == 1).all()
        assert net.norm.count == old.norm.count


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"hidden": 64}, "hidden layer has 32 units, this run's 64"),
        ({"algo": "trpo"}, "one shared hidden layer (GAE, PPO), this run's has two"),
        ({"task": "hover"}, "trained for land, this run is hover"),
        ({"normalize_obs": False}, "normalises its observations and the other does not"),
        ({"observe_position": False}, "observes its position and the other does not"),
        (
            {"backend": "px4", "action_level": "rates", "num_envs": 4},
            "its actions are rotor commands, this run's rates setpoints to an autopilot",
        ),
    ],
)
def test_a_checkpoint_that_does_not_fit_is_refused_and_changes_nothing(tmp_path, change, message):
    path, _ = _saved(tmp_path)
    change = dict(change)
    observe_position = change.pop("observe_position", None)
    task, algo = change.pop("task", "land"), change.pop("algo", "ppo")
    config = make_config(task, algo, "fast", **{"hidden": 32, **change})
    if observe_position is not None:
        config.task_options["observe_position"] = observe_position
    net = _fresh(config, OBS_SIZE)
    before = {k: v.clone() for k, v in net.state_dict().items()}
    with pytest.raises(ValueError, match=f"cannot start from {path}: .*{_escaped(message)}"):
        start_from(net, path, config)
    assert all(torch.equal(before[k], v) for k, v in net.state_dict().items())


@pytest.mark.parametrize("old_fine", [0.0, 0.25])
def test_a_run_with_a_fine_view_of_the_goal_starts_computing_what_the_checkpoint_computed(
    tmp_path, old_fine
):
    """The fine view's columns follow the observation's: new ones start at 0 weight,
    a checkpoint's own move past the blocks the run appends (here the integral)."""
    path, old = _saved(tmp_path, fine=old_fine)
    config = make_config("land", "ppo", "fast", hidden=32, fine_offset_scale=0.25)
    config.task_options["observe_integral"] = True
    net = _fresh(config, OBS_SIZE + EI.SIZE)
    start_from(net, path, config)
    rng = np.random.default_rng(0)
    obs = torch.as_tensor(rng.normal(scale=0.3, size=(64, OBS_SIZE)), dtype=torch.float32)
    integral = torch.as_tensor(rng.uniform(-2, 2, size=(64, EI.SIZE)), dtype=torch.float32)
    wider = torch.cat([obs, integral], 1)
    with torch.no_grad():
        assert torch.allclose(net.distribution(wider).mean, old.distribution(obs).mean, atol=1e-6)
        assert torch.allclose(net.value(wider), old.value(obs), atol=1e-5)
        fine_weights = net.actor_body[0].weight[:, OBS_SIZE + EI.SIZE :]
        assert fine_weights.shape[1] == 3 and bool(fine_weights.any()) == bool(old_fine)


def test_a_checkpoint_with_another_fine_view_is_refused(tmp_path):
    path, _ = _saved(tmp_path, fine=0.25)
    for scale in (0.0, 0.5):
        config = make_config("land", "ppo", "fast", hidden=32, fine_offset_scale=scale)
        with pytest.raises(ValueError, match=f"scale 0.25 m, this run's {scale:g} m"):
            start_from(_fresh(config, OBS_SIZE), path, config)


def test_a_checkpoint_that_observes_more_than_the_run_is_refused(tmp_path):
    path, _ = _saved(tmp_path, obs_size=OBS_SIZE + EI.SIZE, observe_integral=True)
    config = make_config("land", "ppo", "fast", hidden=32)
    with pytest.raises(ValueError, match="its observation is not the start of this run's"):
        start_from(_fresh(config, OBS_SIZE), path, config)


def _escaped(text: str) -> str:
    import re

    return re.escape(text)


def test_training_from_a_checkpoint_starts_from_its_weights_and_records_it(tmp_path):
    path, old = _saved(tmp_path, task="hover")
    # A learning rate too small to move anything: what the run saves is where it began.
    config = make_config(
        "hover",
        "ppo",
        "fast",
        hidden=32,
        total_steps=2048,
        num_envs=8,
        steps_per_env=256,
        learning_rate=1e-12,
        eval_every=0,
        init_from=str(path),
    )
    train(config, tmp_path / "run", progress=False)
    net, saved, _ = checkpoint.load(tmp_path / "run" / "checkpoints" / "last.pt")
    assert saved.init_from == str(path)
    assert json.loads((tmp_path / "run" / "config.json").read_text())["init_from"] == str(path)
    for name, value in old.state_dict().items():
        if not name.startswith("norm."):  # the normaliser goes on counting what it sees
            assert torch.allclose(net.state_dict()[name], value, atol=1e-6), name


def test_train_init_from_a_missing_checkpoint_is_one_line_and_writes_nothing(tmp_path):
    runs = tmp_path / "runs"
    result = refused_here(
        "train",
        "--task",
        "hover",
        "--algo",
        "ppo",
        "--preset",
        "fast",
        "--quiet",
        "--steps",
        "8192",
        "--runs",
        str(runs),
        "--init",
        str(tmp_path / "missing.pt"),
    )
    assert result.returncode == 2, result.stderr
    assert f"no checkpoint at {tmp_path / 'missing.pt'}" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not runs.exists() or not any(runs.iterdir())


def test_robust_landing_starts_flying_as_the_shipped_still_air_landing_policy():
    config = make_config("land", "ppo", "robust")
    still_air, _, _ = checkpoint.load(config.init_from)
    net = _fresh(config, OBS_SIZE + EI.SIZE)  # the robust preset observes the integral
    start_from(net, config.init_from, config)
    obs = torch.as_tensor(np.random.default_rng(3).normal(size=(16, OBS_SIZE)), dtype=torch.float32)
    wider = torch.cat([obs, torch.ones(16, EI.SIZE)], 1)
    with torch.no_grad():
        assert np.allclose(
            net.mean_action(wider.numpy()), still_air.mean_action(obs.numpy()), atol=1e-6
        )
