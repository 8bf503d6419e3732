"""GAE, PPO, TRPO: hand-worked pieces, learning on a tiny budget, reproducibility,
checkpoints and the commands."""

from __future__ import annotations

import csv
import json
import math
import pickle
import re
import shlex
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch

from policies import checkpoint
from policies.algos.ppo import PPO, clipped_surrogate
from policies.algos.trpo import conjugate_gradient
from policies.config import make_config
from policies.evaluate import evaluate
from policies.rollout import compute_gae, make_vector_env
from policies.train import train
from quadsitl.physics import PAPER
from quadsitl.physics import layout as L
from tests.conftest import refused_here, run_cli, sim_with_client

CHECKPOINTS = Path(__file__).resolve().parents[1] / "policies" / "checkpoints"


def _metrics(run_dir) -> list[dict[str, str]]:  # type: ignore[no-untyped-def]
    with open(run_dir / "metrics.csv") as f:
        return list(csv.DictReader(f))


def test_gae_matches_hand_computed_values_with_truncation_and_termination():
    rewards = np.array([[1.0], [2.0], [3.0]])
    values = np.array([[0.5], [1.0], [1.5]])
    none = np.zeros((3, 1), bool)
    truncated = none.copy()
    truncated[1] = True  # time limit at step 1: bootstrap with the final observation's value
    final_values = np.array([[0.0], [4.0], [0.0]])
    adv, ret = compute_gae(
        rewards, values, none, truncated, final_values, np.array([2.0]), 0.9, 0.8
    )
    # t=2: 3 + 0.9·2 − 1.5 = 3.3; t=1: 2 + 0.9·4 − 1 = 4.6 (episode ends: no carry);
    # t=0: (1 + 0.9·1 − 0.5) + 0.9·0.8·4.6 = 4.712
    np.testing.assert_allclose(adv[:, 0], [4.712, 4.6, 3.3])
    np.testing.assert_allclose(ret, adv + values)
    terminated = none.copy()
    terminated[1] = True  # a crash: no value after it
    adv, _ = compute_gae(rewards, values, terminated, none, final_values, np.array([2.0]), 0.9, 0.8)
    np.testing.assert_allclose(adv[:, 0], [1.4 + 0.72 * 1.0, 1.0, 3.3])


def test_conjugate_gradient_solves_a_known_spd_system():
    a = torch.tensor([[4.0, 1.0], [1.0, 3.0]], dtype=torch.float64)
    x = conjugate_gradient(lambda v: a @ v, torch.tensor([1.0, 2.0], dtype=torch.float64), 10)
    np.testing.assert_allclose(x.numpy(), [1 / 11, 7 / 11], rtol=1e-10)


def test_clipped_surrogate_matches_a_hand_worked_case():
    old = torch.zeros(2)
    new = torch.full((2,), math.log(1.5))  # ratio 1.5 for both samples
    advantages = torch.tensor([1.0, -1.0])
    # A=+1: min(1.5, 1.2) = 1.2; A=−1: min(−1.5, −1.2) = −1.5; loss = −mean = 0.15
    loss = clipped_surrogate(new, old, advantages, clip=0.2)
    assert loss.item() == pytest.approx(0.15)


def test_paper_preset_is_table_one():
    gae, ppo, trpo = (make_config("hover", a, "paper") for a in ("gae", "ppo", "trpo"))
    for c in (gae, ppo, trpo):
        assert (c.hidden, c.gamma, c.learning_rate, c.batch_size, c.iterations, c.num_envs) == (
            128,
            0.99,
            1e-4,
            256,
            5000,
            1,
        )
    assert (gae.gae_lambda, gae.epochs) == (0.92, 2)
    assert (ppo.gae_lambda, ppo.epochs, ppo.clip_coef, ppo.minibatches) == (0.92, 4, 0.1, 1)
    assert (trpo.gae_lambda, trpo.max_kl, trpo.cg_damping, trpo.cg_iters) == (0.97, 0.01, 0.1, 10)
    assert (trpo.line_search_steps, trpo.line_search_shrink) == (10, 0.5)
    with pytest.raises(ValueError, match="unknown training option"):
        make_config("hover", "ppo", "paper", learning_rat=1e-3)
    with pytest.raises(ValueError, match="fine_offset_scale reads a quadsitl task's goal offset"):
        make_config("Pendulum-v1", "ppo", "fast", fine_offset_scale=0.25)


def test_robust_preset_is_fast_in_a_randomised_world(tmp_path):
    """The robust preset: the fast learner, twice the budget, a world drawn per episode
    (airframe, wind up to 8 m/s with up to moderate turbulence, 0-30 ms delays) and the
    goal offset's integral observed, which a short real run flies and its checkpoint
    carries."""
    fast = make_config("static_waypoint", "ppo", "fast")
    robust = make_config("static_waypoint", "ppo", "robust")
    assert robust.total_steps == 2 * fast.total_steps
    assert {**robust.to_dict(), "preset": "fast", "total_steps": fast.total_steps} == {
        **fast.to_dict(),
        "task_options": robust.task_options,
    }
    drawn = robust.task_options["randomize"]
    assert drawn["wind"]["turbulence"] == [None, "light", "moderate"]
    assert set(fast.task_options) < set(robust.task_options)  # the task's start kept
    assert robust.task_options["observe_integral"] is True  # integral action
    hover = make_config("hover", "ppo", "robust")  # its own learner and weather
    assert (hover.hidden, hover.entropy_coef, hover.total_steps) == (256, 0.003, 6_000_000)
    assert hover.task_options["randomize"]["wind"]["speed"] == [2.0, 8.0]
    assert hover.task_options["proximity_reward"] == {"weight": 15.0, "radius": 0.5}
    waypoint = make_config("random_waypoint", "ppo", "robust")
    assert (waypoint.hidden, waypoint.total_steps) == (256, 24_000_000)
    assert waypoint.fine_offset_scale == 0.25  # a fine view of the goal (policies/networks.py)
    assert hover.fine_offset_scale == 0.0
    assert waypoint.task_options["proximity_reward"] == {"weight": 120.0, "radius": 0.5}
    assert waypoint.task_options["observe_position"] is False  # the task's start kept
    land = make_config("land", "ppo", "robust")  # from the still-air policy, its budget
    assert (land.hidden, land.entropy_coef, land.total_steps) == (128, 0.003, 12_000_000)
    assert land.init_from == str(checkpoint.shipped_checkpoints()["land"])
    assert "proximity_reward" not in land.task_options  # Eq. 18 alone lands 94 %
    assert make_config("land", "trpo", "robust").init_from == ""  # no TRPO policy shipped
    harder = ["light", "moderate", "moderate"]
    assert land.task_options["randomize"]["wind"]["turbulence"] == harder
    assert make_config("static_waypoint", "ppo", "robust").hidden == 128  # untouched
    assert "wind" not in make_config("hover", "ppo", "fast").task_options  # untouched
    with pytest.raises(ValueError, match="choose one of paper, fast, robust"):
        make_config("hover", "ppo", "sturdy")
    torch.set_num_threads(1)
    short = make_config("hover", "ppo", "robust", total_steps=4_096, checkpoint_every=1)
    train(short, tmp_path, progress=False)
    net, loaded, _ = checkpoint.load(tmp_path / "checkpoints" / "last.pt")
    assert loaded == short and net.obs_size == 34 + 3  # the integral observed
    assert sum(evaluate(net, loaded, episodes=4).outcomes.values()) == 4  # in that world
    env = make_vector_env("hover", 16, "inprocess", **loaded.task_options)
    try:
        env.reset(seed=0)
        params, winds = env.engine.fleet.params, env.engine.fleet.winds
        assert len(np.unique(params[:, L.P_MASS])) == 16  # every env its own airframe
        assert len({w.speed for w in winds}) == 16 and max(w.speed for w in winds) <= 8.0
    finally:
        env.close()


@pytest.mark.parametrize("algo", ["gae", "ppo", "trpo"])
def test_each_algorithm_improves_the_return_on_a_short_budget(algo, tmp_path):
    torch.set_num_threads(1)
    config = make_config("hover", algo, "fast", seed=1, total_steps=120_000, num_envs=64)
    result = train(config, tmp_path, progress=False)
    returns = [float(r["mean_return"]) for r in _metrics(tmp_path)]
    returns = [r for r in returns if math.isfinite(r)]
    assert not result.diverged
    assert np.mean(returns[-5:]) > 1.3 * np.mean(returns[:5]), (returns[:5], returns[-5:])


def test_same_seed_gives_identical_metrics(tmp_path):
    torch.set_num_threads(1)
    runs = []
    for name in ("a", "b"):
        config = make_config(
            "random_waypoint",
            "ppo",
            "fast",
            seed=3,
            total_steps=20_000,
            num_envs=32,
            steps_per_env=32,
        )
        train(config, tmp_path / name, progress=False)
        rows = _metrics(tmp_path / name)
        runs.append(
            [
                {k: v for k, v in r.items() if k not in ("wall_seconds", "steps_per_second")}
                for r in rows
            ]
        )
    assert runs[0] == runs[1] and len(runs[0]) >= 4


def test_checkpoints_load_evaluate_and_refuse_the_wrong_task(tmp_path):
    config = make_config("hover", "trpo", "fast", total_steps=8_192, checkpoint_every=1)
    train(config, tmp_path, progress=False)
    net, loaded, payload = checkpoint.load(tmp_path / "checkpoints" / "last.pt")
    assert loaded == config and payload["iteration"] == 2
    result = evaluate(net, loaded, episodes=10)
    assert result.episodes == 10 and sum(result.outcomes.values()) == 10
    successes = result.success_rate * 10  # whole episodes, each flown to its time limit
    assert successes == round(successes) and successes <= result.outcomes.get("timed_out", 0)
    assert "success_rate: " in result.lines()[-1]
    with pytest.raises(ValueError, match="trained for task 'hover'"):
        evaluate(net, loaded, task="land", episodes=2)
    with pytest.raises(ValueError, match="expects 34 observations"):
        evaluate(net, loaded.__class__(**{**loaded.to_dict(), "task": "target_follow"}), episodes=2)
    (tmp_path / "junk.pt").write_text("not a checkpoint")
    with pytest.raises(ValueError, match="not a quadsitl checkpoint"):
        checkpoint.load(tmp_path / "junk.pt")
    with pytest.raises(ValueError, match="no checkpoint"):
        checkpoint.load(tmp_path / "missing.pt")


def test_a_diverging_run_stops_and_keeps_the_last_good_checkpoint(tmp_path, monkeypatch, capsys):
    original = PPO.update
    calls = {"n": 0}

    def update(self, rollout):  # type: ignore[no-untyped-def]
        calls["n"] += 1
        stats = original(self, rollout)
        if calls["n"] == 3:
            with torch.no_grad():
                next(self.net.parameters()).fill_(float("nan"))
        return stats

    monkeypatch.setattr(PPO, "update", update)
    config = make_config("hover", "ppo", "fast", total_steps=40_000, checkpoint_every=1)
    result = train(config, tmp_path, progress=False)
    assert result.diverged and result.iterations == 2  # completed before the NaN
    assert "diverged" in capsys.readouterr().err
    net, _, payload = checkpoint.load(tmp_path / "checkpoints" / "last.pt")
    assert payload["iteration"] == 2
    assert all(torch.isfinite(p).all() for p in net.parameters())


def _train(options: str, runs: Path, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    """``quadsitl train OPTIONS --preset fast --steps 8192 --runs RUNS`` to completion,
    output captured: a short run of the command as a user types it."""
    words = [*options.split(), "--preset", "fast", "--steps", "8192", "--runs", str(runs)]
    return run_cli("train", *words, timeout=timeout)


def test_train_and_eval_commands(tmp_path):
    run = _train("--task land --algo gae --quiet", tmp_path)
    assert run.returncode == 0, run.stderr
    ckpt = tmp_path / "land-gae-fast-seed0" / "checkpoints" / "last.pt"
    assert (tmp_path / "land-gae-fast-seed0" / "config.json").is_file()
    out = run_cli("eval", str(ckpt), "--episodes", "5")
    assert out.returncode == 0, out.stderr
    assert "touchdown speed" in out.stdout and "success_rate: " in out.stdout
    bad = refused_here("train", "--task", "hover", "--algo", "ddpg")
    assert bad.returncode == 2 and "unknown algorithm" in bad.stderr


def test_train_sets_other_options_and_names_a_bad_one(tmp_path):
    """``--set KEY=VALUE`` reaches the run's configuration; a wrong key, value or an
    option with its own flag is a one-line error before anything runs."""
    run = _train("--task hover --algo ppo --quiet --set entropy_coef=0.02 steps_per_env=64 "
                 "anneal_lr=true", tmp_path)  # fmt: skip
    assert run.returncode == 0, run.stderr
    config = json.loads((tmp_path / "hover-ppo-fast-seed0" / "config.json").read_text())
    assert (config["entropy_coef"], config["steps_per_env"], config["anneal_lr"]) == (
        0.02,
        64,
        True,
    )
    for words, said in (
        (["--set", "entropy_coefficient=0.1"], "unknown option"),
        (["--set", "steps_per_env=many"], "not an int"),
        (["--set", "seed=3"], "has an option of its own"),
        (["--set", "entropy_coef=2000"], "entropy_coef"),
    ):
        bad = refused_here("train", "--task", "hover", "--algo", "ppo", "--preset", "fast", *words)
        assert bad.returncode == 2 and said in bad.stderr, (words, bad.stderr)
        assert "Traceback" not in bad.stderr


def test_seed_band_by_hand():
    from policies.plots import seed_band

    steps = np.array([0.0, 10.0, 20.0])
    curves = [
        (steps, np.array([0.0, 10.0, 20.0])),
        (steps, np.array([2.0, 12.0, 22.0])),
        (steps[:2], np.array([4.0, 14.0])),
    ]  # this seed stopped early: grid ends at 10
    grid, mean, std = seed_band(curves, points=3)
    np.testing.assert_allclose(grid, [0.0, 5.0, 10.0])
    np.testing.assert_allclose(mean, [2.0, 7.0, 12.0])
    np.testing.assert_allclose(std, [np.sqrt(8 / 3)] * 3)


def test_learning_curves_average_seeds_and_add_a_success_panel(tmp_path):
    from PIL import Image

    from policies.plots import learning_curves

    fields = ["iteration", "env_steps", "mean_return", "eval_success"]
    for algo, seeds, evaluated in (("ppo", 3, True), ("trpo", 2, False)):
        for seed in range(seeds):
            run = tmp_path / f"hover-{algo}-fast-seed{seed}"
            run.mkdir()
            config = make_config("hover", algo, "fast", seed=seed)
            (run / "config.json").write_text(json.dumps(config.to_dict()))
            with open(run / "metrics.csv", "w", newline="") as f:
                writer = csv.DictWriter(f, fields)
                writer.writeheader()
                for it in range(1, 41):
                    success = it / 40 if evaluated and it % 5 == 0 else float("nan")
                    row = [it, 4096 * it, 10.0 * it + seed, success]
                    writer.writerow(dict(zip(fields, row, strict=True)))
    paths = learning_curves(sorted(tmp_path.glob("hover-*")), tmp_path / "png")
    assert [p.name for p in paths] == ["learning_hover_fast.png"]
    with Image.open(paths[0]) as image:
        width, height = image.size
    assert width > 1.8 * height  # two panels: returns, validation success


@pytest.mark.parametrize(
    "task", ["hover", "static_waypoint", "random_waypoint", "land", "target_follow"]
)
def test_shipped_checkpoints_load_and_succeed(task):
    torch.set_num_threads(1)
    net, config, _ = checkpoint.load(CHECKPOINTS / f"{task}.pt")
    assert config.task == task
    result = evaluate(net, config, episodes=20)
    assert result.success_rate >= 0.9, result.lines()


def test_training_through_the_wire_flies_the_preset_envs_as_fleets():
    config = make_config("hover", "ppo", "fast", backend="mavlink")
    assert config.num_envs == 128 and config.vehicles_per_sim == 64  # two processes
    with pytest.raises(ValueError, match="would start 32 simulator processes; at most 16"):
        make_config("hover", "ppo", "fast", backend="mavlink", vehicles_per_sim=4)


def test_waypoint_policy_flies_take_off_and_goto_as_autopilot():
    from policies.autopilot import PolicyAutopilot
    from quadsitl.flight_software.vehicle import Vehicle

    torch.set_num_threads(1)
    policy = PolicyAutopilot.from_checkpoint(CHECKPOINTS / "random_waypoint.pt", PAPER)
    vehicle = Vehicle(autopilot=policy)
    assert vehicle.arm().ok and vehicle.takeoff(3.0).ok
    for _ in range(6_000):
        vehicle.step()
    assert vehicle.reposition(6.0, 4.0, 3.0, None, None).ok  # a 7.2 m leg: carrots
    for _ in range(10_000):
        vehicle.step()
    target = np.array([6.0, 4.0, 3.0 + vehicle.airframe.gear_height])
    assert np.linalg.norm(vehicle.position - target) < 0.2 and not vehicle.crashed


def test_waypoint_policy_flies_a_whole_mission_as_autopilot():
    from gcs_tools.scripted_flight import DEFAULT_WAYPOINTS
    from policies.autopilot import PolicyAutopilot
    from quadsitl.flight_software import mission as M
    from quadsitl.flight_software.vehicle import Vehicle
    from quadsitl.wire.modes import Mode

    torch.set_num_threads(1)
    policy = PolicyAutopilot.from_checkpoint(CHECKPOINTS / "random_waypoint.pt", PAPER)
    vehicle = Vehicle(autopilot=policy)
    items = []
    for k, w in enumerate(DEFAULT_WAYPOINTS):  # take-off, a 15 m square with a climb
        lat, lon, _ = vehicle.origin.to_global(w.east, w.north, 0.0)
        command = M.NAV_TAKEOFF if k == 0 else M.NAV_WAYPOINT
        items.append(
            M.MissionItem(command, param1=w.hold, x=round(lat * 1e7), y=round(lon * 1e7), z=w.up)
        )
    items.append(M.MissionItem(M.NAV_LAND))  # land where it is
    assert vehicle.set_mission(items).ok and vehicle.arm().ok
    assert vehicle.set_mode(Mode.MISSION).ok
    for _ in range(60_000):  # 60 s
        vehicle.step()
    assert list(vehicle.items_reached) == [0, 1, 2, 3, 4]
    assert not vehicle.armed and not vehicle.crashed
    assert np.linalg.norm(vehicle.position[:2] - [0.0, 15.0]) < 0.3


def test_ground_station_mission_flown_by_the_policy_autopilot(tmp_path):
    from gcs_tools.scripted_flight import fly_mission

    options = "--logs none --speed 4 --autopilot"
    checkpoint = CHECKPOINTS / "random_waypoint.pt"
    with sim_with_client(options, checkpoint, connect_timeout=40) as (client, _):
        report = fly_mission(client, timeout=60)  # take-off, 15 m square with a climb, land
    assert report.landed
    assert max(report.waypoint_errors) < 0.3


# --- the command line's small print -------------------------------------------------------
def test_train_shows_an_eta_and_ends_naming_best_pt_and_the_command_to_run_next(tmp_path):
    run = _train("--task hover --algo ppo", tmp_path)
    assert run.returncode == 0, run.stderr
    assert re.search(r"ETA \d+:\d\d", run.stderr), run.stderr  # the progress bar's
    best = tmp_path / "hover-ppo-fast-seed0" / "checkpoints" / "best.pt"
    assert f"best checkpoint: {best} (validation success" in run.stdout, run.stdout
    assert "last checkpoint: " in run.stdout and "last.pt" in run.stdout
    command = next(line for line in run.stdout.splitlines() if line.startswith("next: "))
    words = shlex.split(command.removeprefix("next: "))
    assert words[:2] == ["quadsitl", "eval"] and words[2] == str(best)
    # the printed command runs as printed (five episodes, to be quick)
    evaluated = run_cli(*words[1:], "--episodes", "5")
    assert evaluated.returncode == 0, evaluated.stderr
    # hover's success is an outcome named timed_out: the output says so
    outcomes = next(line for line in evaluated.stdout.splitlines() if line.startswith("outcomes"))
    assert "a success is timed_out within 0.1 m of the goal at the end" in outcomes, outcomes


def test_eval_explains_every_outcome_name_and_each_tasks_success():
    from policies.evaluate import OUTCOME_MEANINGS, Evaluation, success_rule
    from quadsitl.tasks import OUTCOME_NAMES

    assert set(OUTCOME_NAMES.values()) - {"running"} == set(OUTCOME_MEANINGS)
    assert success_rule("land") == "landed"
    result = Evaluation("land", 3, 1 / 3, 0.0, 0.0, "touchdown speed", "m/s", 0.2, 1.0)
    result.outcomes = {"landed": 1, "crashed": 2}
    line = next(x for x in result.lines() if x.startswith("outcomes"))
    assert line == (
        "outcomes: crashed 2, landed 1 (crashed: hit the ground too hard; landed: touched "
        "down gently on the pad); a success is landed"
    )


def test_eval_of_zero_episodes_is_a_message_about_episodes(tmp_path):
    result = refused_here("eval", str(CHECKPOINTS / "hover.pt"), "--episodes", "0")
    assert result.returncode == 2 and "--episodes: must be ≥ 1" in result.stderr, result.stderr
    assert "num_envs" not in result.stderr
    with pytest.raises(ValueError, match="episodes must be an integer ≥ 1"):
        net, config, _ = checkpoint.load(CHECKPOINTS / "hover.pt")
        evaluate(net, config, episodes=0)


def test_a_run_through_the_wire_has_its_own_folder_beside_the_in_process_one(tmp_path):
    assert make_config("land", "ppo", "fast").run_name == "land-ppo-fast-seed0"  # unchanged
    wire = make_config("land", "ppo", "fast", backend="mavlink")
    assert wire.run_name == "land-ppo-fast-seed0-mavlink"
    tiny = "train --task hover --algo ppo --preset fast --num-envs 2 --steps 64 --quiet --runs"
    local = run_cli(*tiny.split(), str(tmp_path))
    assert local.returncode == 0, local.stderr
    wired = run_cli(*tiny.split(), str(tmp_path), "--backend", "mavlink", "--vehicles-per-sim", "2")
    assert wired.returncode == 0, wired.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "hover-ppo-fast-seed0",
        "hover-ppo-fast-seed0-mavlink",
    ]
    saved = json.loads((tmp_path / "hover-ppo-fast-seed0-mavlink" / "config.json").read_text())
    assert saved["backend"] == "mavlink"


def _unwritable_folder(tmp_path: Path) -> Path:
    """A folder this process cannot create files in: a read-only folder, or (as root,
    whom permissions do not stop) sysfs's root, which refuses new files to everyone."""
    folder = tmp_path / "read-only"
    folder.mkdir()
    folder.chmod(0o555)
    for candidate in (folder, Path("/sys")):
        try:
            (candidate / "probe").touch()
        except OSError:
            return candidate
        (candidate / "probe").unlink()
    pytest.skip("no folder here refuses this user's writes")


def test_training_into_an_unwritable_folder_is_one_line_before_any_work(tmp_path):
    runs = _unwritable_folder(tmp_path) / "runs"
    result = _train("--task hover --algo ppo --quiet", runs, timeout=60)
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith("quadsitl train: error: cannot write the run to "), (
        result.stderr
    )
    assert "not writable" in result.stderr and len(result.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize(
    ("steps", "message"),
    [
        ("1e19", "at most 10,000,000,000"),
        ("10000000000000000000", "at most 10,000,000,000"),
        ("2.5", "not a whole number of steps"),
    ],
)
def test_step_budgets_beyond_the_maximum_are_refused(tmp_path, steps, message):
    train = "train --task hover --algo ppo --preset fast --quiet --steps"
    result = refused_here(*train.split(), steps, "--runs", str(tmp_path))
    assert result.returncode == 2 and message in result.stderr, result.stderr
    assert not any(tmp_path.iterdir())
    with pytest.raises(ValueError, match="total_steps must be at most 10,000,000,000"):
        make_config("hover", "ppo", "fast", total_steps=10**19)


def test_control_rate_sets_the_autopilots_setpoint_rate_in_whole_lockstep_frames(tmp_path):
    from policies.config import TrainConfig, flight_stack_options
    from policies.export.contract import trained_options

    config = make_config("static_waypoint", "ppo", "fast", backend="px4", num_envs=2,
                         control_rate=10.0)  # fmt: skip
    assert trained_options(config).control_period == pytest.approx(0.1)
    assert flight_stack_options(config)["control_rate"] == 10.0
    older = config.to_dict()
    del older["control_rate"]  # a checkpoint saved before the option: PX4's 50 Hz
    assert TrainConfig.from_dict(older).control_rate == 50.0
    with pytest.raises(ValueError, match="control_rate is the rate of an autopilot's setpoint"):
        make_config("hover", "ppo", "fast", control_rate=10.0)  # in process
    with pytest.raises(ValueError, match=r"control_rate must be a number in \[5, 800\]"):
        make_config("hover", "ppo", "fast", backend="px4", num_envs=2, control_rate=2.0)
    train = "train --task hover --algo ppo --preset fast --backend px4 --num-envs 2 --quiet"
    result = refused_here(*train.split(), "--control-rate", "30", "--runs", str(tmp_path))
    assert result.returncode == 2, result.stderr
    assert "not a whole number of PX4's lockstep frames of 4 ms" in result.stderr
    assert "27.78 and 31.25 Hz" in result.stderr and not any(tmp_path.iterdir())


def test_steps_in_scientific_notation_are_whole_numbers_of_steps():
    from policies.cli import _steps

    assert _steps("2e6") == 2_000_000 and _steps("8192") == 8192


@pytest.mark.parametrize(
    ("kind", "reason"),
    [
        ("text", "not a file written by torch.save"),
        ("pickle", "it holds something other than tensors"),  # a bare pickle, no torch file
        ("numpy", "it names the Python object numpy."),  # torch's file, with an object
    ],
)
def test_a_file_that_is_not_a_checkpoint_gets_one_line_without_torchs_advice(
    tmp_path, kind, reason
):
    path = tmp_path / "not-a-checkpoint.pt"
    if kind == "text":
        path.write_text("hello\n")
    elif kind == "pickle":
        path.write_bytes(pickle.dumps({"weights": [0.0, 1.0]}, protocol=4))
    else:
        torch.save({"weights": np.zeros(3)}, path)
    with pytest.raises(ValueError) as caught:
        checkpoint.load(path)
    message = str(caught.value)
    assert message.startswith(f"{path} is not a quadsitl checkpoint"), message
    assert reason in message, message
    # never torch's advice to load it unsafely, nor its "if you trust the source"
    assert "weights_only" not in message and "trust" not in message and "\n" not in message
    result = run_cli("eval", str(path))
    assert result.returncode == 2 and "weights_only" not in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and "Warning" not in result.stderr


def test_plot_refuses_to_replace_existing_pngs_without_force(tmp_path):
    run = tmp_path / "hover-ppo-fast-seed0"
    run.mkdir()
    (run / "config.json").write_text(json.dumps(make_config("hover", "ppo", "fast").to_dict()))
    (run / "metrics.csv").write_text(
        "iteration,env_steps,mean_return,eval_success\n1,4096,1.0,nan\n2,8192,2.0,0.5\n"
    )
    out = tmp_path / "images"
    out.mkdir()
    png = out / "learning_hover_fast.png"
    png.write_bytes(b"a tracked picture")
    refused = run_cli("plot", str(run), "-o", str(out))
    assert refused.returncode == 2 and "already exist" in refused.stderr, refused.stderr
    assert "--force" in refused.stderr and png.read_bytes() == b"a tracked picture"
    replaced = run_cli("plot", str(run), "-o", str(out), "--force")
    assert replaced.returncode == 0, replaced.stderr
    assert png.read_bytes().startswith(b"\x89PNG")


def test_eval_from_the_tasks_own_start_or_the_trained_spread():
    from policies.commands import start_options

    net, config, _ = checkpoint.load(CHECKPOINTS / "hover.pt")
    assert start_options(config.task_options, "trained") == {}
    paper = start_options(config.task_options, "task")
    assert paper == {"init_position_noise": 0.0, "init_attitude_noise": 0.0}
    spread = evaluate(net, config, episodes=4, keep_trajectories=4)
    own = evaluate(net, config, episodes=4, keep_trajectories=4, env_options=paper)
    assert all(np.abs(track[0]).max() > 0.01 for track in spread.trajectories)
    assert all(np.abs(track[0]).max() < 1e-9 for track in own.trajectories)  # the origin
    shown = run_cli("eval", str(CHECKPOINTS / "hover.pt"), "--episodes", "2", "--start", "task")
    assert shown.returncode == 0 and "success_rate: 1.0000" in shown.stdout, shown.stderr
