"""The options of ``quadsitl train``, ``quadsitl eval``, ``quadsitl robustness``,
``quadsitl plot``, ``quadsitl sweep`` and ``quadsitl export`` (policies/export/cli.py):
parsed here, and checked as they are parsed (counts, step budgets); run by
:mod:`policies.commands`, which imports torch only when one of them runs."""

from __future__ import annotations

import argparse
import math

from policies.config import ALGORITHMS, MAX_TOTAL_STEPS, TASK_NAMES
from policies.export import cli as export_cli
from policies.ladder import AXES


def add_parsers(commands: argparse._SubParsersAction) -> None:
    """Add the policy commands, in the order ``quadsitl --help`` lists them."""
    _add_train_parser(commands)
    _add_eval_parser(commands)
    _add_robustness_parser(commands)
    _add_plot_parser(commands)
    _add_sweep_parser(commands)
    export_cli.add_parser(commands)


def _add_train_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``quadsitl train``: task, algorithm, preset, backend, step budget and run folder."""
    train = commands.add_parser(
        "train",
        help="train a policy (GAE, PPO or TRPO) on a task",
        description="Train a policy. Writes runs/TASK-ALGO-PRESET-seedN/ (-mavlink appended "
        "through the wire): config.json, metrics.csv, checkpoints/best.pt and last.pt.",
    )
    train.add_argument(
        "--task",
        required=True,
        help=f"{', '.join(TASK_NAMES)}, or any registered Gymnasium env id with a Box action "
        "space (e.g. Pendulum-v1)",
    )
    train.add_argument("--algo", required=True, help=f"one of {', '.join(ALGORITHMS)}")
    train.add_argument(
        "--preset",
        default="paper",
        help="paper (Table I), fast, or robust (fast, in a randomised world: wind, "
        "turbulence, delay, airframe spread; docs/training.md) (default: paper)",
    )
    train.add_argument("--seed", type=_count(0), default=0, help="random seed ≥ 0 (default: 0)")
    _add_backend_option(train)
    train.add_argument(
        "--vehicles-per-sim",
        type=_count(1),
        help="with --backend mavlink: vehicles (envs) in each simulator process; with "
        "--backend px4|ardupilot --ray: envs (autopilots) in each Ray actor (default: 64, at most "
        "--num-envs)",
    )
    train.add_argument(
        "--ray",
        nargs="?",
        const="local",
        metavar="ADDR",
        help="with --backend mavlink: start the simulators as Ray actors spread over a Ray "
        "cluster (ADDR, e.g. 10.0.0.1:6379; without it: RAY_ADDRESS's cluster, else a "
        "private local Ray), see docs/distributed.md; with --backend px4|ardupilot: the envs and "
        "their autopilots, see docs/autopilots.md",
    )
    px4 = train.add_argument_group("with --backend px4 or ardupilot")
    px4.add_argument(
        "--action-level",
        choices=("velocity", "attitude", "rates"),
        help="the setpoints the policy sends the autopilot (default: velocity)",
    )
    px4.add_argument(
        "--px4-build",
        metavar="DIR",
        help="PX4's SITL build folder (build/px4_sitl_default); default: the in-repository "
        "fake PX4",
    )
    px4.add_argument(
        "--ardupilot-build",
        metavar="PATH",
        help="ArduCopter's SITL build (build/sitl, or its bin/arducopter); default: the "
        "in-repository fake ArduCopter",
    )
    px4.add_argument(
        "--first-instance",
        type=_count(0),
        help="the envs fly autopilot instances I .. I + num-envs - 1 (default: 0)",
    )
    px4.add_argument(
        "--control-rate",
        type=float,
        metavar="HZ",
        help="setpoints (env steps) a simulated second, 5 .. 250 for PX4 (its 4 ms rounds), "
        "5 .. 800 for ArduPilot, a whole number of lockstep frames each (default: 50)",
    )
    px4.add_argument(
        "--sensor-noise",
        type=float,
        help="scale of the sensor noise the autopilot's estimator sees, 0 .. 100 (default: "
        "1; ArduPilot: its SITL barometers' noise, 0.2 m at 1)",
    )
    train.add_argument(
        "--steps",
        type=_steps,
        help="environment steps, at least one batch and at most 1e10; 2000000 or 2e6 "
        "(default: the preset's)",
    )
    train.add_argument("--num-envs", type=_count(1), help="parallel envs (default: the preset's)")
    train.add_argument(
        "--set",
        nargs="+",
        default=[],
        metavar="KEY=VALUE",
        help="other training options, e.g. entropy_coef=0.01 steps_per_env=128 "
        "anneal_lr=true learning_rate=3e-4 (policies/config.py: TrainConfig; "
        "docs/training.md)",
    )
    train.add_argument("--runs", default="runs", help="folder of run folders (default: runs)")
    train.add_argument(
        "--init",
        metavar="CHECKPOINT",
        help="start from CHECKPOINT's weights instead of random ones (fine-tuning, e.g. a "
        "still-air policy in the robust preset's weather): same task, algorithm family and "
        "hidden size; the run may observe more (observe_integral); see docs/training.md",
    )
    existing = train.add_mutually_exclusive_group()
    existing.add_argument(
        "--resume",
        action="store_true",
        help="continue the run in the run folder from its last.pt, appending to metrics.csv",
    )
    existing.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the run in the run folder (without this or --resume, an existing run "
        "is refused)",
    )
    train.add_argument(
        "--tensorboard",
        action="store_true",
        help="also log every metrics.csv column to RUN/tensorboard (tensorboard --logdir runs)",
    )
    train.add_argument("--quiet", action="store_true", help="no progress bar")


def _add_eval_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``quadsitl eval``: deterministic episodes of one checkpoint or its export."""
    evaluate = commands.add_parser(
        "eval",
        help="evaluate a checkpoint with deterministic episodes",
        description="Run deterministic episodes; prints success rate, return and the task's "
        "metric, and a line `success_rate: X`.",
    )
    evaluate.add_argument(
        "checkpoint",
        help="a .pt file written by quadsitl train, or its export: a .onnx file or a C .h "
        "header (with its .contract.json beside it)",
    )
    evaluate.add_argument(
        "--episodes", type=_count(1), default=100, help="episodes, ≥ 1 (default: 100)"
    )
    evaluate.add_argument(
        "--task",
        help="task to evaluate on (default: the trained one; needed for an ONNX file not "
        "written by quadsitl export)",
    )
    evaluate.add_argument(
        "--start",
        default="trained",
        choices=("trained", "task"),
        help="trained: the randomised starts the policy was trained on (the evaluation "
        "standard, docs/training.md); task: the task's own start, with no start noise (the "
        "paper's) (default: trained)",
    )
    _add_backend_option(evaluate)
    evaluate.add_argument(
        "--rerun",
        nargs="?",
        const="",
        metavar="RRD",
        help="record the first env's episodes in Rerun (a viewer, or the file RRD)",
    )


def _add_backend_option(parser: argparse.ArgumentParser) -> None:
    """Add ``--backend`` (train's and eval's): where the physics runs."""
    parser.add_argument(
        "--backend",
        default="inprocess",
        choices=("inprocess", "mavlink", "px4", "ardupilot"),
        help="physics in-process, in quadsitl sim processes over MAVLink, or flown through "
        "PX4 (OFFBOARD) or ArduCopter (GUIDED) by their setpoints (docs/autopilots.md, "
        "'Training through the flight stack')",
    )


def _add_robustness_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``quadsitl robustness``: the robustness ladder over policies."""
    robustness = commands.add_parser(
        "robustness",
        help="the robustness ladder: success under turbulence, wind, delay, mass, a weak "
        "motor and sensor noise",
        description="Fly each policy on every rung of each axis (deterministic episodes "
        "on fixed test seeds, all episodes of a rung in one vector env); prints a table "
        "per policy and writes OUT/robustness.md, .csv, .json and .png (success against "
        "rung, one panel per axis, one line per policy).",
    )
    robustness.add_argument(
        "checkpoint",
        nargs="+",
        help="policies: .pt files written by quadsitl train, or their exports (.onnx, .h)",
    )
    robustness.add_argument(
        "--episodes",
        type=_count(1),
        default=100,
        help="episodes per rung, ≥ 1 (default: 100)",
    )
    robustness.add_argument(
        "--axes",
        nargs="+",
        metavar="AXIS",
        help=f"axes to climb (default: all): {', '.join(AXES)}",
    )
    robustness.add_argument(
        "--out",
        default="robustness",
        help="folder for the tables and the plot, made if missing (default: robustness)",
    )


def _add_plot_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``quadsitl plot``: learning curves of run folders."""
    plot = commands.add_parser(
        "plot",
        help="learning curves (mean ± std over seeds) of run folders",
    )
    plot.add_argument("runs", nargs="+", help="run folders (any tasks, algorithms, seeds)")
    plot.add_argument(
        "-o", "--output", default="plots", help="folder for the PNGs (default: plots)"
    )
    plot.add_argument(
        "--force", action="store_true", help="replace PNGs that already exist in the folder"
    )


def _add_sweep_parser(commands: argparse._SubParsersAction) -> None:
    """Add ``quadsitl sweep``: a grid or search over training runs on Ray Tune."""
    sweep = commands.add_parser(
        "sweep",
        help="a grid or search over training runs on Ray Tune (docs/distributed.md)",
        description="Each trial is one `quadsitl train` run in its own folder under --runs; "
        "Tune schedules them, shows a progress table, stops searches early (ASHA) and "
        "resumes an interrupted sweep.",
    )
    sweep.add_argument(
        "--grid",
        nargs="+",
        default=[],
        metavar="KEY=VALUES",
        help="grid axes: task=hover,land algo=ppo,trpo seed=0..2 learning_rate=1e-4,3e-4 ... "
        "(each value once; at most 10,000 trials)",
    )
    sweep.add_argument(
        "--search",
        nargs="+",
        default=[],
        metavar="KEY=DIST",
        help="search axes: KEY=loguniform:LOW:HIGH, uniform:LOW:HIGH, randint:LOW:HIGH or "
        "choice:V1,V2 (stopped early by ASHA on mean_return)",
    )
    sweep.add_argument(
        "--samples", type=_count(1), default=1, help="samples of the search (default: 1)"
    )
    sweep.add_argument(
        "--steps", type=_steps, help="environment steps of every trial (at most 1e10)"
    )
    sweep.add_argument("--runs", default="runs", help="folder of the trials' runs (default: runs)")
    sweep.add_argument(
        "--name",
        default="sweep",
        help="the sweep's name, one folder name under RUNS/sweeps (default: sweep)",
    )
    sweep.add_argument(
        "--cpus", type=_count(1), help="CPUs of the private local Ray (default: all)"
    )
    sweep.add_argument(
        "--address",
        help="join the Ray cluster at ADDRESS (ray start --head); default: the cluster in "
        "RAY_ADDRESS, else a private local Ray",
    )
    sweep.add_argument("--resume", action="store_true", help="finish an interrupted sweep")
    sweep.add_argument(
        "--test-episodes",
        type=_count(0),
        default=0,
        help="after training, test each run's best checkpoint on N deterministic episodes "
        "and add the algorithms-comparison table to the results (default: 0, no test)",
    )


def _count(low: int):  # type: ignore[no-untyped-def]
    """An argparse type: an integer ≥ ``low``, else a clear usage error."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be ≥ {low}, got {value}")
        return value

    return parse


def _steps(text: str) -> int:
    """An argparse type: a step budget, 1..MAX_TOTAL_STEPS, as ``2000000`` or ``2e6``."""
    try:
        value = int(text)
    except ValueError:
        try:
            number = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number of steps") from None
        if not math.isfinite(number) or number != int(number):
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of steps") from None
        value = int(number)
    if not 1 <= value <= MAX_TOTAL_STEPS:
        raise argparse.ArgumentTypeError(f"must be ≥ 1 and at most {MAX_TOTAL_STEPS:,}, got {text}")
    return value
