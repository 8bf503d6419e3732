"""What runs ``quadsitl train``, ``eval``, ``robustness``, ``plot``, ``sweep`` and
``export``, once :mod:`policies.cli` has parsed their options: each command's
modules (and torch) are imported only when it runs, and each prints what it made and
what to do next.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from policies.config import FLIGHT_STACKS, TASK_NAMES, TrainConfig
from policies.export import cli as export_cli
from policies.folders import check_writable, os_error_sentence
from policies.interrupt import second_interrupt_stops


def run(args: argparse.Namespace) -> int:
    """Run the parsed training command ``args.command``; its exit status. A second
    Ctrl-C while it stops ends it at once (:mod:`policies.interrupt`); a sweep's Ctrl-C
    is Ray Tune's. A file or folder that cannot be written is a one-line ValueError."""
    try:
        if args.command == "sweep":
            return _run(args)
        with second_interrupt_stops(f"quadsitl {args.command}"):
            return _run(args)
    except OSError as error:  # a write the checks before could not foresee (disk full)
        raise ValueError(os_error_sentence(error)) from None


def _run(args: argparse.Namespace) -> int:
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
    from policies.config import make_config, parse_settings
    from policies.train import train

    config = make_config(
        args.task,
        args.algo,
        args.preset,
        args.seed,
        backend=args.backend,
        vehicles_per_sim=args.vehicles_per_sim,
        ray=args.ray,
        action_level=args.action_level,
        px4_build=args.px4_build,
        ardupilot_build=args.ardupilot_build,
        first_instance=args.first_instance,
        sensor_noise=args.sensor_noise,
        control_rate=args.control_rate,
        total_steps=args.steps,
        num_envs=args.num_envs,
        init_from=args.init,
        **parse_settings(args.set),
    )
    run_dir = Path(args.runs) / config.run_name
    mode = "resume" if args.resume else "overwrite" if args.overwrite else "new"
    check_writable(run_dir)  # before anything starts (train checks too, for other callers)
    if config.init_from:  # a missing or foreign file, before the first line (train checks the fit)
        from policies import checkpoint

        checkpoint.load(config.init_from)
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
        backend = f" --backend {config.backend}" if config.backend in FLIGHT_STACKS else ""
        lines.append(f"next: quadsitl eval {shlex.quote(str(chosen))}{backend}")
    return lines


def _eval(args: argparse.Namespace) -> int:
    from policies.evaluate import evaluate
    from policies.export.runtimes import load_policy

    net, config = load_policy(args.checkpoint, args.task)
    on_step = None
    view = None
    if args.rerun is not None:
        from policies.checkpoint import policy_name
        from quadsitl.viz.episode_view import EpisodeView

        view = EpisodeView(f"eval {policy_name(args.checkpoint)}", args.rerun or None)

        def on_step(engine, reward, outcome=None):  # type: ignore[no-untyped-def]
            view.reset(engine, outcome) if reward is None else view.step(engine)

    try:
        result = evaluate(
            net,
            config,
            args.task,
            args.episodes,
            args.backend,
            on_step=on_step,
            env_options=start_options(config.task_options, args.start),
        )
    finally:
        if view is not None:
            view.close(wait=True)  # the recording is complete when eval says it is done
    print("\n".join(result.lines()))
    return 0


def start_options(trained: dict, start: str) -> dict:  # type: ignore[type-arg]
    """Task options over the trained ones for ``quadsitl eval --start``: none for
    ``trained``; for ``task``, every start noise (``init_*``) at zero."""
    if start == "trained":
        return {}
    return {name: 0.0 for name in trained if name.startswith("init_")}


def _robustness(args: argparse.Namespace) -> int:
    """Every input checked (policies, axes, the output folder) before any episode flies;
    nothing is written unless every ladder ran."""
    from policies.checkpoint import policy_name
    from policies.export.runtimes import load_policy
    from policies.ladder import check_axes
    from policies.robustness import check_task, climb, markdown, seeds_text, write

    axes = check_axes(args.axes)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file, not a folder (nothing was written)")
    check_writable(out, "the robustness tables")
    paths = [Path(p) for p in args.checkpoint]
    names = [policy_name(p) for p in paths]  # RUN-best for a run's best.pt
    if len(set(names)) < len(names):  # the same name twice: tell them apart by their paths
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
    check_writable(Path(args.output), "the plots")
    for path in learning_curves(runs, Path(args.output), overwrite=args.force):
        print(path)
    return 0
