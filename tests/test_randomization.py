"""Domain randomisation (``randomize``) and exact airframe scales (``airframe_scale``)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import quadsitl  # noqa: F401  (registers the ids)
from quadsitl.perturbations.randomization import AIRFRAME_COLUMNS, DEFAULT_AIRFRAME_SPREAD
from quadsitl.physics import PAPER
from quadsitl.physics import layout as L
from quadsitl.registration import ENV_IDS
from quadsitl.tasks import features as F

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")


def _vector(num_envs: int, **options):
    return gym.make_vec(
        "QuadSITL/Hover-v0", num_envs=num_envs, vectorization_mode="vector_entry_point", **options
    )


@pytest.mark.parametrize("env_id", list(ENV_IDS.values()))
def test_gymnasium_check_env_randomized(env_id):
    check_env(gym.make(env_id, randomize=True).unwrapped, skip_render_check=True)


def test_default_draws_stay_in_their_bounds_with_the_uniform_mean_and_spread():
    n = 4000
    vec = _vector(n, randomize=True)
    vec.reset(seed=0)
    engine = vec.unwrapped.engine
    nominal = PAPER.to_params(-math.inf)
    for name, f in DEFAULT_AIRFRAME_SPREAD.items():
        for column in AIRFRAME_COLUMNS[name]:
            scale = engine.fleet.params[:, column] / nominal[column]
            assert scale.min() >= 1 - f and scale.max() <= 1 + f, name
            # U(1 − f, 1 + f): mean 1, standard deviation f/√3.
            assert abs(scale.mean() - 1) < 4 * f / math.sqrt(3 * n), name
            assert abs(scale.std() / (f / math.sqrt(3)) - 1) < 0.05, name
    # The inertia axes share one draw (the vehicle is scaled, not reshaped).
    inertia = engine.fleet.params[:, L.P_INERTIA] / nominal[L.P_INERTIA]
    np.testing.assert_allclose(inertia[:, 0], inertia[:, 2])
    untouched = [L.P_OMEGA_MAX, L.P_GRAVITY, L.P_GEAR_HEIGHT, L.P_ROTOR_RADIUS]
    assert (engine.fleet.params[:, untouched] == nominal[untouched]).all()
    winds = engine.fleet.winds
    speeds = np.array([w.speed for w in winds])
    directions = np.array([w.from_deg for w in winds])
    assert speeds.min() >= 0 and speeds.max() <= 5 and abs(speeds.mean() - 2.5) < 0.1
    assert abs(speeds.std() / (5 / math.sqrt(12)) - 1) < 0.05
    assert directions.min() >= 0 and directions.max() <= 360
    light = np.mean([w.turbulence == "light" for w in winds])
    assert abs(light - 0.5) < 4 * 0.5 / math.sqrt(n)
    line = engine.delay
    for steps in (line.observation_steps, line.action_steps):  # 0, 1 or 2 steps of 0.01 s
        assert set(steps) == {0, 1, 2} and abs(steps.mean() - 1) < 0.05


def test_draws_repeat_with_the_seed_and_env_i_is_the_single_env_seeded_s_plus_i():
    options = {"randomize": {**DEFAULT_AIRFRAME_SPREAD, "wind": {"turbulence": ["moderate"]}}}
    vec = _vector(16, **options)
    vec.reset(seed=7)
    engine = vec.unwrapped.engine
    params = engine.fleet.params.copy()
    assert len(np.unique(params[:, L.P_MASS])) == 16  # every env its own vehicle
    actions = np.random.default_rng(0).normal(0, 0.3, (15, 4)).astype(np.float32)
    trace = np.array([vec.step(np.repeat(a[None], 16, axis=0))[0] for a in actions])
    vec.reset(seed=7)
    np.testing.assert_array_equal(engine.fleet.params, params)
    for i in (0, 9):
        env = gym.make("QuadSITL/Hover-v0", disable_env_checker=True, **options)
        env.reset(seed=7 + i)
        single = env.unwrapped.engine
        np.testing.assert_array_equal(single.fleet.params[0], params[i])
        assert single.fleet.winds[0] == engine.fleet.winds[i]
        # The same draws and turbulence; the observations agree to rounding (the
        # batch's weather is vectorised, a single vehicle's not: ~1e-15 in the air).
        alone = np.array([env.step(a)[0] for a in actions])
        np.testing.assert_allclose(alone, trace[:, i], rtol=1e-5, atol=1e-7)
    vec.reset(seed=8)
    assert not np.array_equal(engine.fleet.params, params)


def _climb_rate(scale: dict, thrust_ratio: float, seconds: float = 1.0) -> float:
    """m/s after ``seconds`` holding each rotor at √thrust_ratio × the nominal hover
    speed (thrust_ratio × the nominal vehicle's weight), from a hover start."""
    env = gym.make("QuadSITL/Hover-v0", airframe_scale=scale, disable_env_checker=True)
    env.reset(seed=0)
    engine = env.unwrapped.engine
    action = engine.hover_speed * (math.sqrt(thrust_ratio) - 1) / engine.options.beta
    for _ in range(round(seconds / engine.control_period)):
        env.step(np.full(4, action, np.float32))
    return float(engine.fleet.velocity[0, 2])


def test_a_vehicle_30_percent_heavier_needs_30_percent_more_hover_thrust():
    assert abs(_climb_rate({"mass": 1.3}, 1.3)) < 1e-6  # held
    assert _climb_rate({"mass": 1.3}, 1.0) < -1.5  # nominal hover thrust: it sinks
    assert _climb_rate({"mass": 1.3}, 1.25) < -0.2
    assert _climb_rate({"mass": 1.3}, 1.35) > 0.2
    assert abs(_climb_rate({}, 1.0)) < 1e-6  # and the nominal vehicle on nominal thrust
    # The heavier vehicle starts at its own hover speed; the motors' limit stays.
    env = gym.make("QuadSITL/Hover-v0", airframe_scale={"mass": 1.3})
    obs, _ = env.reset(seed=0)
    expected = PAPER.hover_rotor_speed * math.sqrt(1.3) / PAPER.max_rotor_speed
    np.testing.assert_allclose(obs[F.OBS_ROTORS], expected, rtol=1e-6)
    assert env.action_space == gym.make("QuadSITL/Hover-v0").action_space  # Eq. 19: nominal


def test_airframe_scale_is_exact_every_episode_and_randomisation_draws_around_it():
    vec = _vector(200, airframe_scale={"mass": 0.7, "inertia": 1.15}, randomize={"mass": 0.1})
    for seed in (0, 1):
        vec.reset(seed=seed)
        params = vec.unwrapped.engine.fleet.params
        mass = params[:, L.P_MASS] / PAPER.mass
        assert mass.min() >= 0.7 * 0.9 and mass.max() <= 0.7 * 1.1
        assert abs(mass.mean() - 0.7) < 0.01
        np.testing.assert_allclose(params[:, L.P_JXX], 1.15 * PAPER.inertia[0])
    env = gym.make("QuadSITL/Land-v0", airframe_scale={"mass": 1.15})
    for seed in range(3):
        env.reset(seed=seed)
        assert env.unwrapped.engine.fleet.params[0, L.P_MASS] == 1.15 * PAPER.mass


def test_drawn_wind_flies_as_the_same_fixed_wind():
    """A draw that can only give one wind flies exactly as that wind given outright."""
    actions = np.random.default_rng(1).normal(0, 0.3, (20, 4)).astype(np.float32)
    runs = []
    for options in (
        {"wind": {"speed": 4.0, "from_deg": 270.0}},
        {"randomize": {"wind": {"speed": (4, 4), "from_deg": (270, 270), "turbulence": [None]}}},
    ):
        env = gym.make("QuadSITL/Hover-v0", **options)
        env.reset(seed=2)
        runs.append(np.array([env.step(a)[0] for a in actions]))
    np.testing.assert_array_equal(runs[0], runs[1])
    assert np.abs(runs[0][-1, F.OBS_POS]).max() > 0.05  # and the wind did push it


def test_param_randomization_is_the_airframe_part_of_randomize():
    draws = []
    for options in ({"param_randomization": {"mass": 0.2}}, {"randomize": {"mass": 0.2}}):
        vec = _vector(8, **options)
        vec.reset(seed=4)
        draws.append(vec.unwrapped.engine.fleet.params.copy())
    np.testing.assert_array_equal(draws[0], draws[1])


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"randomize": {"colour": 0.1}}, r"cannot randomise \['colour'\]"),
        ({"randomize": {"mass": 1.5}}, r"randomize\['mass'\] must be a number in \[0, 1\)"),
        ({"randomize": {"mass": float("nan")}}, "must be a number in"),
        ({"randomize": "everything"}, "randomize must be True, 'default' or a dict"),
        ({"randomize": {"wind": {"speed": (5, 1)}}}, "wind speed must be a finite"),
        ({"randomize": {"wind": {"speed": (-1, 1)}}}, "must be >= 0 m/s"),
        ({"randomize": {"wind": {"turbulence": ["gale"]}}}, "unknown turbulence severity"),
        ({"randomize": {"delay": {"action": (0, 9.0)}}}, "action delay 9 s is not shorter"),
        ({"randomize": {"sensor_noise": 1.0}}, "no sensor models"),
        ({"randomize": True, "wind": {"speed": 2}}, "wind is both fixed"),
        ({"randomize": True, "delay": {"action": 0.02}}, "delay is both fixed"),
        ({"randomize": True, "param_randomization": {"mass": 0.1}}, "not both"),
        ({"airframe_scale": {"mass": 0.0}}, r"airframe_scale\['mass'\] must be a factor"),
        ({"airframe_scale": {"mass": float("inf")}}, "must be a factor"),
        ({"airframe_scale": {"arm_length": 2}}, "cannot scale 'arm_length'"),
        ({"airframe_scale": 1.3}, "airframe_scale must be a dict"),
    ],
)
def test_bad_randomisation_is_refused_with_one_line(options, message):
    with pytest.raises(ValueError, match=message) as error:
        gym.make("QuadSITL/Hover-v0", **options)
    assert "\n" not in str(error.value)
