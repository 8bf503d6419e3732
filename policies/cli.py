"""``quadsitl train``, ``quadsitl eval``, ``quadsitl robustness``, ``quadsitl plot``,
``quadsitl sweep`` and ``quadsitl export`` (policies/export/cli.py): parsed here, run
lazily (torch is imported only by these commands)."""

from __future__ import annotations

import argparse
import math
import shlex
import sys
from pathlib import Path

from policies.config import ALGORITHMS, MAX_TOTAL_STEPS, TASK_NAMES, TrainConfig
from policies.export import cli as export_cli
from policies.ladder import AXES


def add_parsers(commands: argparse._SubParsersAction) -> None:
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
    train.add_argument("--preset", default="paper", help="paper (Table I) or fast (default: paper)")
    train.add_argument("--seed", type=_count(0), default=0, help="random seed ≥ 0 (default: 0)")
    train.add_argument(
        "--backend",
        default="inprocess",
        choices=("inprocess", "mavlink"),
        help="physics in-process, or in quadsitl sim processes over MAVLink",
    )
    train.add_argument(
        "--vehicles-per-sim",
        type=_count(1),
        help="with --backend mavlink: vehicles (envs) in each simulator process (default: 64)",
    )
    train.add_argument(
        "--ray",
        nargs="?",
        const="local",
        metavar="ADDR",
        help="with --backend mavlink: start the simulators as Ray actors spread over a Ray "
        "cluster (ADDR, e.g. 10.0.0.1:6379; without it: RAY_ADDRESS's cluster, else a "
        "private local Ray); see docs/distributed.md",
    )
    train.add_argument(
        "--steps",
        type=_steps,
        help="environment steps, at least one batch and at most 1e10; 2000000 or 2e6 "
        "(default: the preset's)",
    )
    train.add_argument("--num-envs", type=_count(1), help="parallel envs (default: the preset's)")
    train.add_argument("--runs", default="runs", help="folder of run folders (default: runs)")
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
        "--backend",
        default="inprocess",
        choices=("inprocess", "mavlink"),
        help="physics in-process, or in quadsitl sim processes over MAVLink",
    )
    evaluate.add_argument(
        "--rerun",
        nargs="?",
        const="",
        metavar="RRD",
        help="record the first env's episodes in Rerun (a viewer, or the file RRD)",
    )

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
    export_cli.add_parser(commands)


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


def run(args: argparse.Namespace) -> int:
    import torch

    torch.set_num_threads(1)  # small networks: one thread is fastest, and deterministic
    if args.command == "train":
        return _train(args)
    if args.command == "eval":
        return _eval(args)
    if args.command == "sweep":
        return _sweep(args)
    if args.command == "export":
        return export_cli.run(args)
    if args.command == "robustness":
        return _robustness(args)
    return _plot(args)


def _sweep(args: argparse.Namespace) -> int:
    from policies.plots import learning_curves
    from policies.sweep import results_text, run_sweep
    from policies.sweep_spec import parse_grid, parse_search

    grid, search = parse_grid(args.grid), parse_search(args.search)
    fixed = {"total_steps": args.steps} if args.steps else {}
    try:
        import ray  # noqa: F401
    except ImportError:
        raise ValueError("quadsitl sweep needs Ray Tune: pip install 'quadsitl[sweep]'") from None
    out = Path(args.runs) / "sweeps" / args.name
    resume = f"resume with: {_resume_command(args)}"
    try:
        results = run_sweep(
            grid,
            search,
            fixed,
            Path(args.runs),
            args.name,
            args.samples,
            args.cpus,
            args.address,
            args.resume,
            args.test_episodes,
        )
    except KeyboardInterrupt:  # a second Ctrl-C, while Tune was saving its state
        print(f"quadsitl sweep: interrupted; {resume}", file=sys.stderr)
        return 130
    text = results_text(results)
    (out / "results.md").write_text(text)
    runs = [Path(r["run"]) for r in results if r["finished"]]
    curves = learning_curves(
        [r for r in runs if (r / "metrics.csv").is_file()], out, overwrite=True
    )
    print(text, end="")
    print(f"results: {out / 'results.md'}; curves: {', '.join(str(c) for c in curves) or '-'}")
    if any(not r["finished"] and not r["error"] for r in results):
        print(f"quadsitl sweep: interrupted; {resume}", file=sys.stderr)
        return 130
    return 1 if any(r["error"] for r in results) else 0


def _resume_command(args: argparse.Namespace) -> str:
    """The ``quadsitl sweep ... --resume`` command that finishes this sweep."""
    words = ["quadsitl", "sweep"]
    for option, values in (("--grid", args.grid), ("--search", args.search)):
        if values:
            words += [option, *values]
    for option, value in (
        ("--samples", args.samples if args.samples != 1 else None),
        ("--steps", args.steps),
        ("--runs", args.runs),
        ("--name", args.name),
        ("--cpus", args.cpus),
        ("--address", args.address),
        ("--test-episodes", args.test_episodes or None),
    ):
        if value is not None:
            words += [option, str(value)]
    return shlex.join([*words, "--resume"])


def _train(args: argparse.Namespace) -> int:
    from policies.config import make_config
    from policies.train import check_writable, train

    config = make_config(
        args.task,
        args.algo,
        args.preset,
        args.seed,
        backend=args.backend,
        vehicles_per_sim=args.vehicles_per_sim,
        ray=args.ray,
        total_steps=args.steps,
        num_envs=args.num_envs,
    )
    run_dir = Path(args.runs) / config.run_name
    mode = "resume" if args.resume else "overwrite" if args.overwrite else "new"
    check_writable(run_dir)  # before anything starts (train checks too, for other callers)
    if config.ray:
        from quadsitl.envs.ray_simulators import ray_target

        target, where = ray_target(config.ray)
        if target == "local":
            where += " (--ray ADDR or RAY_ADDRESS joins a cluster)"
        print(f"quadsitl train: simulators on {where}", file=sys.stderr)
    print(
        f"quadsitl train: {config.iterations} iterations of {config.batch_size} steps -> {run_dir}",
        file=sys.stderr,
    )
    result = train(
        config, run_dir, progress=not args.quiet, mode=mode, tensorboard=args.tensorboard
    )
    last = run_dir / "checkpoints" / "last.pt"
    if result.interrupted:
        saved = (
            f"{last} saved at iteration {result.iterations}"
            if last.is_file()
            else ("no checkpoint saved yet")
        )
        print(f"quadsitl train: interrupted; {saved}; continue with --resume", file=sys.stderr)
        return 130
    print(
        f"{result.env_steps:,} steps in {result.seconds:.1f} s; last 100 episodes: return "
        f"{result.final_return:.1f}, success {result.final_success:.0%}"
    )
    print("\n".join(_next_steps(config, run_dir, result.best_success)))
    return 1 if result.diverged else 0


def _next_steps(config: TrainConfig, run_dir: Path, best_success: float) -> list[str]:
    """Which checkpoint to use, and the command that evaluates it."""
    folder = run_dir / "checkpoints"
    best, last = folder / "best.pt", folder / "last.pt"
    if not best.is_file():
        lines = [f"checkpoint: {last} (the network at the end; no validation ran)"]
        chosen = last
    else:
        lines = [
            f"best checkpoint: {best} (validation success {best_success:.0%}; use this one)",
            f"last checkpoint: {last} (the network at the end, to --resume from)",
        ]
        chosen = best
    if config.task in TASK_NAMES and chosen.is_file():
        lines.append(f"next: quadsitl eval {shlex.quote(str(chosen))}")
    return lines


def _eval(args: argparse.Namespace) -> int:
    from policies.evaluate import evaluate
    from policies.export.runtimes import load_policy

    net, config = load_policy(args.checkpoint, args.task)
    on_step = None
    view = None
    if args.rerun is not None:
        from quadsitl.viz.episode_view import EpisodeView

        view = EpisodeView(f"eval {Path(args.checkpoint).name}", args.rerun or None)

        def on_step(engine, reward, outcome=None):  # type: ignore[no-untyped-def]
            view.reset(engine, outcome) if reward is None else view.step(engine)

    try:
        result = evaluate(net, config, args.task, args.episodes, args.backend, on_step=on_step)
    finally:
        if view is not None:
            view.close()
    print("\n".join(result.lines()))
    return 0


def _robustness(args: argparse.Namespace) -> int:
    """Every input checked (policies, axes, the output folder) before any episode flies;
    nothing is written unless every ladder ran."""
    from policies.export.runtimes import load_policy
    from policies.ladder import check_axes
    from policies.robustness import check_task, climb, markdown, seeds_text, write

    axes = check_axes(args.axes)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file, not a folder (nothing was written)")
    paths = [Path(p) for p in args.checkpoint]
    names = [p.stem for p in paths]
    if len(set(names)) < len(names):  # two best.pt: tell them apart by their paths
        names = [str(p) for p in paths]
    policies = [load_policy(path) for path in paths]
    for name, (_, config) in zip(names, policies, strict=True):
        check_task(name, config)
    print(f"robustness ladder: {args.episodes} episodes a rung, {seeds_text(args.episodes)}")
    ladders = []
    for name, (net, config) in zip(names, policies, strict=True):
        ladder = climb(name, net, config, axes, args.episodes)
        print(markdown(ladder))
        print(f"robustness_ladder_seconds: {ladder.seconds:.1f} ({name})")
        ladders.append(ladder)
    for path in write(ladders, args.episodes, out):
        print(path)
    return 0


def _plot(args: argparse.Namespace) -> int:
    from policies.plots import learning_curves

    runs = [Path(r) for r in args.runs]
    for path in learning_curves(runs, Path(args.output), overwrite=args.force):
        print(path)
    return 0
