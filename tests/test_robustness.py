"""The robustness ladder: its rungs are the env configurations they name, its tables have
every rung and column, its figures are rates and repeat on the same seeds, and bad input
is refused with one line before anything is written."""

from __future__ import annotations

import csv
import dataclasses
import io
import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import torch

from policies import checkpoint
from policies.evaluate import EVAL_SEED, evaluate
from policies.ladder import AXES, LADDER
from policies.robustness import COLUMNS, climb, csv_text, json_text, markdown, write
from policies.rollout import SEED_SPACING, make_vector_env
from quadsitl.cli import main
from quadsitl.physics import layout as L

HOVER = Path(__file__).resolve().parents[1] / "policies" / "checkpoints" / "hover.pt"


@pytest.fixture(scope="module")
def hover():
    torch.set_num_threads(1)
    net, config, _ = checkpoint.load(HOVER)
    return net, config


def _first_step(net, config, options):
    """What the env of a rung looks like at the first step of its first episode."""
    seen = {}

    def on_step(engine, reward, outcome=None):
        if reward is not None and not seen:
            fleet = engine.fleet
            seen.update(
                mass=fleet.params[:, L.P_MASS].copy(),
                efficiency=fleet.motor_efficiency.copy(),
                wind=np.linalg.norm(fleet.air_velocity, axis=1),  # m/s
                stirred=fleet.stirred.copy(),
                delay=None
                if engine.delay is None
                else (engine.delay.observation_steps.copy(), engine.delay.action_steps.copy()),
                noise=None if engine.observation_noise is None else engine.observation_noise.scale,
            )

    evaluate(net, config, episodes=4, num_envs=4, env_options=options, on_step=on_step)
    return seen


def test_every_rung_flies_the_world_it_names(hover):
    net, config = hover
    nominal = _first_step(net, config, {})
    assert nominal["delay"] is None and nominal["noise"] is None
    assert not nominal["stirred"].any() and np.all(nominal["efficiency"] == 1.0)
    for axis, (_, rungs) in LADDER.items():
        for rung in rungs:
            seen = _first_step(net, config, rung.options)
            label = f"{axis} {rung.label}"
            if axis == "mass":
                percent = float(rung.label.split()[0])
                np.testing.assert_allclose(seen["mass"], nominal["mass"] * (1 + percent / 100))
            else:
                np.testing.assert_array_equal(seen["mass"], nominal["mass"], err_msg=label)
            combined = axis == "target" and rung.label != "none"  # all at once
            if (axis == "delay" and rung.label != "0 ms") or combined:
                steps = 2 if combined else int(rung.label.split()[0]) // 10  # 10 ms steps
                assert all((s == steps).all() for s in seen["delay"]), label
            else:
                assert seen["delay"] is None, label
            if axis == "motor":
                want = float(rung.label.split()[0]) / 100
                np.testing.assert_allclose(seen["efficiency"][:, 0], want, err_msg=label)
                assert np.all(seen["efficiency"][:, 1:] == 1.0), label
            else:
                assert np.all(seen["efficiency"] == 1.0), label
            if axis == "wind" and rung.label != "0 m/s":  # no turbulence: exactly the mean
                np.testing.assert_allclose(seen["wind"], float(rung.label.split()[0]), atol=1e-9)
            if combined:  # 6 m/s of mean wind and moderate turbulence (σ_u ≈ 3 m/s) on it
                assert 1.0 < seen["wind"].mean() < 11.0 and np.ptp(seen["wind"]) > 0.1, label
            moving_air = (
                (axis == "wind" and rung.label != "0 m/s")
                or (axis == "turbulence" and rung.label != "none")
                or combined
            )
            assert seen["stirred"].all() == moving_air and seen["stirred"].any() == moving_air
            want_noise = {"default": 1.0, "3x": 3.0}.get(rung.label) if axis == "noise" else None
            assert seen["noise"] == want_noise, label


def test_mean_wind_directions_are_spread_over_the_episodes():
    env = make_vector_env("hover", 8, **LADDER["wind"][1][2].options)  # 6 m/s
    env.reset(seed=EVAL_SEED * SEED_SPACING)
    fleet = env.engine.fleet
    wind = fleet.air_velocity.copy()  # (8, 3) m/s, world ENU
    env.close()
    headings = np.degrees(np.arctan2(wind[:, 1], wind[:, 0]))
    assert np.ptp(headings) > 90 and np.allclose(np.linalg.norm(wind, axis=1), 6.0)


def test_the_table_has_every_rung_and_column_and_repeats(hover):
    net, config = hover
    ladder = climb("hover", net, config, ["delay", "mass"], episodes=6)
    assert [(r.axis, r.rung) for r in ladder.rows] == [
        (axis, rung.label) for axis in ("delay", "mass") for rung in LADDER[axis][1]
    ]
    for row in ladder.rows:
        assert row.episodes == 6 and row.task == "hover" and row.metric == "final position error"
        assert 0 <= row.success_rate <= 1 and 0 <= row.crash_rate <= 1
        assert sum(int(n.strip(",")) for n in row.outcomes.split()[1::2]) == 6
    by_rung = {(r.axis, r.rung): r for r in ladder.rows}
    assert by_rung["delay", "0 ms"].success_rate == 1.0  # the shipped policy, still air
    assert by_rung["delay", "40 ms"].success_rate < 1.0  # and what 40 ms does to it
    nominal = by_rung["delay", "0 ms"]  # flown once, reported on both axes
    assert by_rung["mass", "0 %"] == dataclasses.replace(nominal, axis="mass", rung="0 %")
    again = climb("hover", net, config, ["delay", "mass"], episodes=6)
    assert again.rows == ladder.rows
    rows = list(csv.DictReader(io.StringIO(csv_text([ladder]))))
    assert tuple(rows[0]) == COLUMNS and len(rows) == len(ladder.rows)
    table = markdown(ladder).splitlines()
    assert sum(line.startswith("| delay |") for line in table) == 4
    assert sum(line.startswith("| mass |") for line in table) == 5
    assert json.loads(json_text([ladder], 6))["policies"][0]["rows"][0]["rung"] == "0 ms"


def test_a_rung_is_the_evaluation_with_its_options(hover):
    net, config = hover
    ladder = climb("hover", net, config, ["mass"], episodes=5)
    for row, rung in zip(ladder.rows, LADDER["mass"][1], strict=True):
        result = evaluate(net, config, episodes=5, num_envs=5, env_options=rung.options)
        assert (row.success_rate, row.crash_rate) == (result.success_rate, result.crash_rate)
        assert row.metric_mean == result.metric_mean
    assert ladder.rows[0].success_rate < ladder.rows[2].success_rate  # −30 % mass vs nominal


def test_each_env_counts_its_own_episodes_however_long_they_last(hover):
    """With 40 ms of delay the hover policy's episodes end at different steps; each env
    must count its first episode, not a second one that ended before a long first."""
    net, config = hover
    options = LADDER["delay"][1][3].options
    result = evaluate(net, config, episodes=12, num_envs=12, env_options=options)
    env = make_vector_env("hover", 12, **config.task_options, **options)
    obs, _ = env.reset(seed=EVAL_SEED * SEED_SPACING)
    first: dict[int, str] = {}
    low, high = env.single_action_space.low, env.single_action_space.high
    while len(first) < 12:
        obs, _, terminated, truncated, info = env.step(np.clip(net.mean_action(obs), low, high))
        for i in np.flatnonzero(terminated | truncated):
            first.setdefault(int(i), str(info["final_info"]["outcome"][i]))
    env.close()
    assert result.outcomes == dict(Counter(first.values()))
    assert len(set(first.values())) > 1  # the test needs episodes of different lengths
    crashes = sum(n for k, n in result.outcomes.items() if k in ("crashed", "flipped"))
    assert result.crash_rate == crashes / 12


def test_write_makes_the_tables_and_the_plot(hover, tmp_path):
    net, config = hover
    ladder = climb("hover", net, config, ["motor"], episodes=2)
    paths = write([ladder], 2, tmp_path / "out")
    assert [p.name for p in paths] == [f"robustness.{e}" for e in ("md", "csv", "json", "png")]
    assert paths[3].read_bytes()[:4] == b"\x89PNG"
    assert "| motor | 60 % |" in paths[0].read_text()


@pytest.mark.parametrize(
    "args, message",
    [
        (["missing.pt"], "no checkpoint at"),
        (["junk.pt"], "is not a quadsitl checkpoint"),
        ([str(HOVER), "--axes", "gusts"], f"unknown axis 'gusts'; axes: {', '.join(AXES)}"),
        ([str(HOVER), "--episodes", "0"], "must be ≥ 1, got 0"),
        ([str(HOVER), "--out", "a_file"], "is a file, not a folder"),
    ],
)
def test_bad_input_is_one_line_and_writes_nothing(args, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "junk.pt").write_text("not a checkpoint")
    (tmp_path / "a_file").write_text("")
    before = sorted(tmp_path.iterdir())
    with pytest.raises(SystemExit) as exit_:
        main(["robustness", *args])
    assert exit_.value.code == 2
    error = capsys.readouterr().err.strip().splitlines()[-1]
    assert message in error and error.startswith("quadsitl robustness: error:")
    assert sorted(tmp_path.iterdir()) == before


def test_the_nominal_rung_is_what_quadsitl_eval_prints(hover):
    """30 episodes: eval flies them in its 25 envs, the ladder in 30; the figures agree
    (to the float rounding of a forward pass batched differently)."""
    net, config = hover
    nominal = climb("hover", net, config, ["wind"], episodes=30).rows[0]
    result = evaluate(net, config, episodes=30)  # as `quadsitl eval --episodes 30` calls it
    assert (nominal.success_rate, nominal.crash_rate) == (result.success_rate, result.crash_rate)
    assert nominal.outcomes == ", ".join(f"{k} {v}" for k, v in sorted(result.outcomes.items()))
    assert nominal.metric_mean == pytest.approx(result.metric_mean, rel=1e-5)


def test_an_evaluation_does_not_depend_on_how_many_envs_fly_it(hover):
    """Episode k starts from the seed EVAL_SEED·SEED_SPACING + k in any batch: the same
    flights, to float rounding (a forward pass of 6 rows or of 2 rounds differently)."""
    net, config = hover
    options = LADDER["delay"][1][3].options  # 40 ms: episodes of different lengths
    one = evaluate(net, config, episodes=6, num_envs=6, env_options=options, keep_trajectories=6)
    two = evaluate(net, config, episodes=6, num_envs=4, env_options=options, keep_trajectories=6)
    assert one.outcomes == two.outcomes and one.success_rate == two.success_rate
    assert one.mean_return == pytest.approx(two.mean_return, rel=1e-5)
    assert one.metric_mean == pytest.approx(two.metric_mean, rel=1e-5)
    assert len(one.trajectories) == len(two.trajectories) == 6
    for a, b in zip(one.trajectories, two.trajectories, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-4)  # m
