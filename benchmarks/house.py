"""How easy the house is to live in: the code's own measures, printed against targets.

* ``house_files_to_add_a_task``: code files that name the worked-example task
  (``figure_eight``, added as docs/tasks.md says): the files one touches to add a task
  (target 3: its module, the task list and its env classes' statements);
* ``house_largest_file_lines``: lines of the largest module of quadsitl/, policies/ and
  gcs_tools/ (target ≤ 400);
* ``house_longest_function_lines``: lines of the longest function (nested ones counted
  inside theirs too), each over the target printed (target ≤ 80);
* ``house_import_cycles``: import cycles between modules, ``TYPE_CHECKING`` imports
  included (target 0), each printed;
* ``house_rotor_speed_conversions``: places where a motor command in [0, 1] is turned
  into rad/s (target 1: ``quadsitl/wire/units.py``);
* ``house_reflective_dispatch``: handler lookups by a name built at run time
  (``getattr(self, f"…")``, ``dir(self)``; target 0).

``--suite`` also times ``make test`` with one core kept busy by a spin loop, as a
loaded laptop (target ≤ 480 s): about eight minutes more.
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("quadsitl", "policies", "gcs_tools")
CODE = ("quadsitl", "policies", "benchmarks")  # where a task may be named
EXAMPLE_TASK = "figure_eight"
# Ω = u·Ω_max written out: a product with the maximum rotor speed (clamps, thrust limits
# and battery sag use Ω_max otherwise, in the physics and the flight software).
CONVERSION = re.compile(
    r"(max_rotor_speed|OMEGA_MAX\]|omega_max|max_speed)\b[^=\n]*\*"
    r"|\*[^=\n]*(max_rotor_speed|OMEGA_MAX\]|omega_max\b|max_speed)"
)
# Files whose products with Ω_max are not u -> Ω (the telemetry's throttle and PWM turn
# rad/s back into a fraction).
NOT_CONVERSIONS = (
    "physics/",
    "controller.py",
    "cascade.py",
    "vehicle.py",
    "telemetry_pose.py",
    "telemetry_status.py",
)
REFLECTION = re.compile(r'getattr\([^,]+, *f"_|getattr\(self, *f"|dir\(self\)|for \w+ in dir\(')


def modules() -> dict[str, Path]:
    """Dotted name -> file of every module of the packages."""
    found = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
            found[name.removesuffix(".__init__")] = path
    return found


def imports_of(name: str, path: Path, known: dict[str, Path]) -> set[str]:
    """The project modules ``name`` imports at its top level or under an ``if`` (such as
    ``if TYPE_CHECKING:``) or ``try``; ``from pkg import sub`` imports ``pkg.sub``."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    stack = list(ast.parse(path.read_text(encoding="utf-8")).body)
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.If, ast.Try)):
            stack += node.body + node.orelse + getattr(node, "finalbody", [])
            stack += [n for h in getattr(node, "handlers", []) for n in h.body]
        elif isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parts, base] if base else parts)
            subs = {f"{base}.{a.name}" for a in node.names} & known.keys()
            found |= subs if len(subs) == len(node.names) else subs | {base}
    return {module for module in found if module in known and module != name}


def import_cycles() -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm)."""
    known = modules()
    graph = {name: imports_of(name, path, known) for name, path in known.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        for other in graph[node]:
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while not component or component[-1] != node:
                component.append(stack.pop())
            if len(component) > 1:
                cycles.append(sorted(component))

    sys.setrecursionlimit(10_000)
    for node in graph:
        if node not in index:
            visit(node)
    return cycles


def files_naming(task: str) -> list[Path]:
    """The code files that name ``task`` or its env's class name as a word."""
    env_name = "".join(part.capitalize() for part in task.split("_"))
    word = re.compile(rf"\b({re.escape(task)}|{re.escape(env_name)})\b")
    return sorted(
        path.relative_to(ROOT)
        for folder in CODE
        for path in (ROOT / folder).rglob("*.py")
        if path.name != "house.py" and word.search(path.read_text(encoding="utf-8"))
    )


def lines_matching(pattern: re.Pattern[str], skip: tuple[str, ...] = ()) -> list[str]:
    """``file:line`` of every line of quadsitl/ that matches ``pattern``."""
    hits = []
    for path in sorted((ROOT / "quadsitl").rglob("*.py")):
        where = str(path.relative_to(ROOT))
        if any(part in where for part in skip):
            continue
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if pattern.search(line) and "rotor_speed(" not in line:
                hits.append(f"{where}:{number}")
    return hits


def suite_seconds() -> float:
    """Wall seconds of ``make test`` with one core kept busy."""
    spin = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        start = time.perf_counter()
        subprocess.run(["make", "test"], cwd=ROOT, check=True)
        return time.perf_counter() - start
    finally:
        spin.kill()


def function_lengths() -> list[tuple[int, str]]:
    """(lines, ``file:line name``) of every function of the packages, longest first."""
    found = []
    for path in modules().values():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = (node.end_lineno or node.lineno) - node.lineno + 1
                found.append((lines, f"{path.relative_to(ROOT)}:{node.lineno} {node.name}"))
    return sorted(found, reverse=True)


def report(name: str, value: float, target: str, ok: bool, details: list[str] = ()) -> None:
    print(f"{name}: {value:g} (target {target}, {'meets' if ok else 'MISSES'})")
    for line in details:
        print(f"  {line}")


def main() -> None:
    files = files_naming(EXAMPLE_TASK)
    report("house_files_to_add_a_task", len(files), "3", len(files) <= 3, [str(f) for f in files])
    sizes = {
        path: len(path.read_text(encoding="utf-8").splitlines()) for path in modules().values()
    }
    big = sorted(sizes, key=sizes.get, reverse=True)
    over = [f"{p.relative_to(ROOT)}: {sizes[p]}" for p in big if sizes[p] > 400]
    report("house_largest_file_lines", sizes[big[0]], "≤ 400", sizes[big[0]] <= 400, over)
    lengths = function_lengths()
    long = [f"{where}: {lines}" for lines, where in lengths if lines > 80]
    report("house_longest_function_lines", lengths[0][0], "≤ 80", lengths[0][0] <= 80, long)
    cycles = import_cycles()
    report("house_import_cycles", len(cycles), "0", not cycles, [" ".join(c) for c in cycles])
    conversions = lines_matching(CONVERSION, NOT_CONVERSIONS)
    report(
        "house_rotor_speed_conversions", len(conversions), "1", len(conversions) == 1, conversions
    )
    reflective = lines_matching(REFLECTION)
    report("house_reflective_dispatch", len(reflective), "0", not reflective, reflective)
    if "--suite" in sys.argv:
        seconds = suite_seconds()
        report("house_make_test_seconds_loaded", round(seconds), "≤ 480", seconds <= 480)


if __name__ == "__main__":
    main()
