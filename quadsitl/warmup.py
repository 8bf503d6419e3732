"""Compile the compiled code once, into numba's on-disk cache: ``python -m quadsitl.warmup``.

``make venv`` runs it after installing, so that the first ``quadsitl sim``, the first env
and the first test start in about two seconds instead of spending half a minute
compiling (each kernel is compiled once per source version and then loaded from
``__pycache__``). Running it again costs only the loading. It compiles what a simulator
loads before its clock starts (:func:`quadsitl.simulator.runner.compile_for_sim`), a fleet
of one stepped with a (4,) command, commands given as strided views, and what the envs
use: every task's single and vector env, in still air and in wind.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np


def main() -> int:
    import gymnasium as gym

    import quadsitl  # noqa: F401  (registers the envs)
    from quadsitl.physics import Fleet
    from quadsitl.physics.wind import Wind
    from quadsitl.registration import task_env_spec
    from quadsitl.simulator.runner import compile_for_sim
    from quadsitl.tasks import TASKS

    def fleets_of_one() -> None:
        for weather in (None, Wind(speed=3.0, turbulence="light")):
            single = Fleet(1)  # a fleet of one takes a (4,) command too: a version of its own
            if weather is not None:
                single.set_wind(weather)
            single.step(np.zeros(4))

    def strided_commands() -> None:
        # Commands that are strided views (a column slice of a wider array) are taken as
        # they are, in still air: a version of the kernels of their own.
        wide = np.zeros((2, 2 * 4))
        Fleet(1).step(wide[0, ::2])
        Fleet(1).step(wide[:1, ::2])
        Fleet(2).step(wide[:, ::2])

    def task_envs(name: str) -> None:
        wind = {"speed": 3.0, "turbulence": "light"}
        still_and_windy: tuple[dict[str, Any], ...] = ({}, {"wind": wind})
        for options in still_and_windy:
            env = gym.make(task_env_spec(name), disable_env_checker=True, **options)
            env.reset(seed=0)
            env.step(np.zeros(4, np.float32))
            env.close()
            vector = gym.make_vec(
                task_env_spec(name), num_envs=2, vectorization_mode="vector_entry_point", **options
            )
            vector.reset(seed=0)
            vector.step(np.zeros((2, 4), np.float32))
            vector.close()

    stages: list[tuple[str, Callable[[], None]]] = [
        (
            "the simulator, one vehicle in wind",
            lambda: compile_for_sim(1, "paper", Wind(speed=3.0, turbulence="light")),
        ),
        ("the simulator, a fleet", lambda: compile_for_sim(2, "paper")),
        ("a fleet of one", fleets_of_one),
        ("commands given as strided views", strided_commands),
        *[(f"the {name} envs", partial(task_envs, name)) for name in TASKS],
    ]
    started = time.perf_counter()
    print(
        "quadsitl: compiling the physics and controllers once (numba's cache; a minute or "
        "two on an idle machine, several on a busy one)...",
        flush=True,
    )
    for k, (what, stage) in enumerate(stages, 1):
        before = time.perf_counter()
        stage()
        took = time.perf_counter() - before
        print(f"quadsitl:   [{k}/{len(stages)}] {what} ({took:.0f} s)", flush=True)
    print(f"quadsitl: compiled in {time.perf_counter() - started:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
