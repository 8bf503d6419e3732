"""The task list is the one place a task is named: a task is its module, one line and
its env classes.

``files_naming(word)`` counts the files of the project's code that name a task; for a
task added as docs/tasks.md says, they are its module, the task list and the class
statements of its envs, no more.
"""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

import quadsitl
from quadsitl.registration import ENV_IDS, ENV_IDS_V1, TASK_NAMES, task_env_name
from quadsitl.tasks import TASKS

ROOT = Path(__file__).resolve().parents[1]
CODE = ("quadsitl", "policies", "benchmarks")  # the project's code, tests and docs aside
HOUSE = ROOT / "benchmarks" / "house.py"  # measures this count, so it names the example


def files_naming(task: str) -> list[Path]:
    """The code files that name ``task`` (``figure_eight``) or its env (``FigureEight``)
    as a word: the files one touches to add that task."""
    word = re.compile(rf"\b({re.escape(task)}|{re.escape(task_env_name(task))})\b")
    return sorted(
        path.relative_to(ROOT)
        for folder in CODE
        for path in (ROOT / folder).rglob("*.py")
        if path != HOUSE and word.search(path.read_text(encoding="utf-8"))
    )


def test_a_task_added_as_documented_is_named_in_three_files():
    assert files_naming("figure_eight") == [
        Path("quadsitl/envs/task_envs.py"),
        Path("quadsitl/registration.py"),
        Path("quadsitl/tasks/figure_eight.py"),
    ]


def test_every_env_class_is_a_class_statement_its_entry_point_names():
    """``grep "class HoverEnv"`` finds each env, and Gymnasium's entry points load it."""
    import gymnasium as gym

    from quadsitl.envs import VECTOR_VERSION_CLASSES, VERSION_CLASSES

    sources = "".join(p.read_text(encoding="utf-8") for p in (ROOT / "quadsitl").rglob("*.py"))
    for version, ids in ((0, ENV_IDS), (1, ENV_IDS_V1)):
        for name, env_id in ids.items():
            spec = gym.spec(env_id)
            for tables, entry in (
                (VERSION_CLASSES, spec.entry_point),
                (VECTOR_VERSION_CLASSES, spec.vector_entry_point),
            ):
                cls = tables[version][name]
                assert re.search(rf"^class {cls.__name__}\(", sources, re.M), cls.__name__
                module, _, attribute = str(entry).partition(":")
                assert getattr(importlib.import_module(module), attribute) is cls
                assert (cls.task_name, cls.version) == (TASKS[task_name(name)].name, version)
            assert VERSION_CLASSES[version][name].__doc__.startswith(f"# {env_id}")


def test_a_task_without_its_env_classes_is_named_at_import():
    from quadsitl.envs import task_envs

    class Base:
        pass

    with pytest.raises(ImportError, match=r"class HoverEnv\(Base, task='hover'\): \.\.\."):
        task_envs._by_version(Base, "Env")


def task_name(env_name: str) -> str:
    return next(t for t in TASK_NAMES if task_env_name(t) == env_name)


def test_every_task_module_is_in_the_task_list():
    """A task module left out of the list would be silently missing from every table."""
    defining = {
        path.stem
        for path in (ROOT / "quadsitl" / "tasks").glob("*.py")
        if re.search(r"^TASK = S\.TaskSpec\(", path.read_text(encoding="utf-8"), re.M)
    }
    assert defining == set(TASK_NAMES)


def test_ids_classes_and_tables_follow_the_list_in_its_order():
    from policies.comparison import FAST_BUDGET
    from policies.config import FAST_STEPS, STARTS
    from policies.evaluate import TASK_METRICS
    from quadsitl.envs import ENV_CLASSES, VECTOR_CLASSES

    assert list(TASKS) == list(TASK_NAMES)
    for table in (TASK_METRICS, STARTS, FAST_STEPS, FAST_BUDGET):
        assert list(table) == list(TASK_NAMES)
    names = [task_env_name(t) for t in TASK_NAMES]
    assert list(ENV_IDS) == list(ENV_CLASSES) == list(VECTOR_CLASSES) == names
    for name, task in zip(names, TASKS.values(), strict=True):
        assert ENV_CLASSES[name].task_name == VECTOR_CLASSES[name].task_name == task.name
        assert ENV_IDS[name] == task.env_id
        assert getattr(quadsitl.envs, f"{name}Env") is ENV_CLASSES[name]
