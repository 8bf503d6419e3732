"""The engine's stages, built once from what the options ask (a stage that does nothing
where an option is off), and the world's perturbations they use: a delay line that
steps nothing itself, motor faults that heal and strike on schedule."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from quadsitl.perturbations.delay import Delay, DelayLine
from quadsitl.perturbations.faults import FailingMotors, MotorFault
from quadsitl.physics import Fleet
from quadsitl.physics import layout as L
from quadsitl.tasks import TaskEngine, TaskOptions, get_task
from quadsitl.tasks import stages as G

PERTURBATIONS = Path(__file__).resolve().parents[1] / "quadsitl" / "perturbations"


def _engine(**options) -> TaskEngine:
    engine = TaskEngine(get_task("hover"), 3, TaskOptions(**options))
    engine.seed([0, 1, 2])
    engine.reset_envs(np.ones(3, bool))
    return engine


def test_the_perturbations_import_only_the_physics():
    """The room for the world's perturbations stands on the physics alone: the tasks
    and the flight software both use it, and it uses neither."""
    modules = sorted(PERTURBATIONS.glob("*.py"))
    assert {m.stem for m in modules} >= {
        "delay",
        "randomization",
        "faults",
        "sensor_faults",
        "motor_faults",
    }
    allowed = ("quadsitl.physics", "quadsitl.frames", "quadsitl.perturbations")
    for module in modules:
        for node in ast.walk(ast.parse(module.read_text(encoding="utf-8"))):
            names = []
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            elif isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            for name in names:
                if name.startswith("quadsitl"):
                    assert name.startswith(allowed), f"{module.name} imports {name}"


def test_an_option_that_is_off_is_a_stage_that_does_nothing():
    plain = _engine()
    assert plain._stages == ()  # each does nothing: none is called
    assert type(plain._physics) is G.Undelayed and plain._motors == ()
    obs = np.zeros((3, 34), np.float32)
    kept = G.HiddenPosition(obs)
    truth = G.Truth(plain.task.observe, plain.fleet, plain.goal, 34)
    assert G.acting(G.Stage(), truth, kept, G.Undelayed(plain.fleet, 5)) == (kept,)
    every = _engine(
        proximity_reward={"weight": 1.0, "radius": 1.0},
        sensor_noise=1.0,
        delay={"observation": 0.02},
        observe_position=False,
        observe_integral=True,
    )
    assert [type(stage) for stage in every._stages] == [
        G.ProximityReward,
        G.Sensors,
        G.Delayed,
        G.HiddenPosition,
        G.Integral,
    ]
    # The same stages, whatever an episode does: a reset and a step change none.
    stages = every._stages
    every.step(np.zeros((3, 4)))
    every.reset_envs(np.array([True, False, True]))
    assert every._stages is stages


def test_reset_and_step_run_the_same_stages_in_the_same_order():
    engine = _engine(sensor_noise=1.0, delay={"observation": 0.02}, observe_integral=True)
    calls: list[tuple[str, str]] = []

    class Spy(G.Stage):
        def __init__(self, name: str) -> None:
            self.name = name

        def start(self, rows, rngs) -> None:
            calls.append(("start", self.name))

        def reset(self, rows) -> None:
            calls.append(("reset", self.name))

        def step(self) -> None:
            calls.append(("step", self.name))

    engine._stages = (*engine._stages, Spy("a"), Spy("b"))
    engine.step(np.zeros((3, 4)))
    engine.reset_envs(np.array([False, True, False]))
    assert calls == [
        ("step", "a"),
        ("step", "b"),
        ("start", "a"),
        ("start", "b"),
        ("reset", "a"),
        ("reset", "b"),
    ]


def test_the_delay_line_hands_out_the_pieces_of_a_period_and_steps_nothing():
    """Actuation delay 2 physics steps, observation delay 1, 5 physics steps a period:
    the period's first two steps fly the previous command, the rest the new one, and
    the observation kept is taken after the fourth step."""
    dt = 0.01
    line = DelayLine(Delay(observation=(dt, dt), action=(2 * dt, 2 * dt)), 2, dt, 5, 3)
    rows = np.arange(2)
    line.reset(rows, np.zeros((2, 3), np.float32), 100.0)
    given = np.full((2, 4), 300.0)
    pieces = list(line.pieces(given, np.array([1, 1])))
    assert [count for _, count, _ in pieces] == [2, 2, 1]
    np.testing.assert_array_equal(pieces[0][0], np.full((2, 4), 100.0))  # the hover
    np.testing.assert_array_equal(pieces[1][0], given)
    np.testing.assert_array_equal(pieces[2][0], given)
    assert [taken.tolist() for _, _, taken in pieces] == [[], [0, 1], []]
    line.keep(np.array([0, 1]), np.array([[1, 2, 3], [4, 5, 6]], np.float32))
    obs = np.full((2, 3), 9.0, np.float32)  # the end of the period: not what is seen
    line.delay_observations(obs, np.array([1, 1]))
    np.testing.assert_array_equal(obs, [[1, 2, 3], [4, 5, 6]])


def test_a_delayed_stage_takes_its_observations_from_the_sensors():
    """The mid-period observations of a delayed env are the sensing stage's (here the
    truth's: the task's observation of the state then), not a call into the engine."""
    engine = _engine(delay={"observation": 0.02})
    physics = engine._physics
    assert isinstance(physics, G.Delayed) and engine._stages == (physics,)
    assert type(physics.sensing) is G.Truth
    before = engine.fleet.state.copy()
    engine.step(np.zeros((3, 4)))
    assert not np.array_equal(engine.fleet.state, before)
    seen = physics.sensing.observed(np.arange(3))
    assert seen.shape == engine.obs.shape


def test_failing_motors_strike_when_due_and_heal_at_a_new_episode():
    fleet = Fleet(2)
    motors = FailingMotors(fleet, (MotorFault(motor=2, efficiency=0.5, at=0.1),), 0.05)
    active = np.ones(2, bool)
    motors.strike(np.array([2, 2]), active)  # the second period starts at 0.05 s: not yet
    assert (fleet.params[:, L.P_ROTOR_EFFICIENCY] == 1.0).all()
    motors.strike(np.array([3, 2]), np.array([True, True]))  # env 0 reaches 0.1 s
    np.testing.assert_array_equal(fleet.params[0, L.P_ROTOR_EFFICIENCY], [1.0, 0.5, 1.0, 1.0])
    assert (fleet.params[1, L.P_ROTOR_EFFICIENCY] == 1.0).all()
    motors.heal(np.array([0]))
    assert (fleet.params[:, L.P_ROTOR_EFFICIENCY] == 1.0).all()


@pytest.mark.parametrize("n", [1, 5])
def test_still_air_and_the_world_are_one_rk4_step(n):
    """The world build with still air, healthy rotors and no ground effect flies what
    the still-air build flies, bit for bit: one RK4 step, the world a compile-time flag."""
    from quadsitl.physics import kernel
    from quadsitl.physics.fleet import STILL_AIR

    rng = np.random.default_rng(n)
    fleet = Fleet(n)
    state = fleet.state.copy()
    state[:, L.I_PZ] = rng.uniform(0.0, 2.0, n)
    state[:, L.RATES] = rng.normal(0.0, 1.0, (n, 3))
    fleet.reset(state)
    commands = fleet.hover_rotor_speed[0] + rng.normal(0.0, 50.0, (20, n, 4))
    builds = {
        "still": (kernel.single_step if n == 1 else kernel.batch_step, ()),
        "world": (kernel.single_step_wind if n == 1 else kernel.batch_step_wind, STILL_AIR),
    }
    ends = {}
    for name, (step, weather) in builds.items():
        s, c, t = fleet.state.copy(), fleet.contact.copy(), fleet.touchdown_speed.copy()
        for cmd in commands:
            assert step(s, fleet.params, cmd, c, t, 0.01, 3, *weather) == -1
        ends[name] = (s, c)
    np.testing.assert_array_equal(ends["still"][0], ends["world"][0])
    np.testing.assert_array_equal(ends["still"][1], ends["world"][1])
