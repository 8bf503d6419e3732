"""The house's seams, as docs/architecture.md states them: its table of who may import
whom and its table of who never imports whom (not even through another module), read
from the document and checked on the real import graph of quadsitl/, gcs_tools/ and
policies/. Every import of a file counts, a function's and ``TYPE_CHECKING``'s too, and
importing ``a.b.c`` runs ``a`` and ``a.b`` first. The simulator also runs with policies
and gcs_tools unimportable, and the clients and the ground station import with the
server and the flight software unimportable."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from collections import deque
from functools import cache
from pathlib import Path

import pytest

from gcs_tools.demo import free_udp_port

ROOT = Path(__file__).resolve().parents[1]
ARCHITECTURE = ROOT / "docs" / "architecture.md"
PACKAGES = ("quadsitl", "gcs_tools", "policies")
FOREIGN = ("pymavlink",)  # outside libraries a rule names
MAY_IMPORT = "### Who may import whom"
NEVER_IMPORTS = "### Who never imports whom"
EVERYTHING = "everything"


# --- the import graph ---------------------------------------------------------------------
def _imported(source: str, package: str) -> set[str]:
    """Absolute names of every module ``source`` imports, written in ``package``:
    ``from a.b import c`` gives ``a.b`` and ``a.b.c`` (``c`` may be a module), and a
    relative import is resolved against ``package``."""
    names = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            parts = package.split(".")
            base = parts[: len(parts) - node.level + 1] if node.level else []
            module = ".".join([*base, *([node.module] if node.module else [])])
            names.add(module)
            names |= {f"{module}.{alias.name}" for alias in node.names}
    return names


@cache
def _modules() -> dict[str, str]:
    """Dotted name -> path from the repository root, of every module of the packages."""
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
            found[name.removesuffix(".__init__")] = path.relative_to(ROOT).as_posix()
    return found


def _edges(source: str, package: str, modules: dict[str, str]) -> set[str]:
    """The modules (and foreign libraries) that running ``source``, written in
    ``package``, imports directly: each name imported, and the packages above it."""
    edges = set()
    for imported in _imported(source, package):
        parts = imported.split(".")
        if parts[0] in FOREIGN:
            edges.add(parts[0])
        edges |= {p for i in range(len(parts)) if (p := ".".join(parts[: i + 1])) in modules}
    return edges


@cache
def _graph() -> dict[str, frozenset[str]]:
    """Module -> what importing it imports directly (:func:`_edges`)."""
    modules = _modules()
    graph = {}
    for name, path in modules.items():
        package = name if path.endswith("__init__.py") else name.rpartition(".")[0]
        source = (ROOT / path).read_text(encoding="utf-8")
        graph[name] = frozenset(_edges(source, package, modules) - {name})
    return graph


# --- the rules, as the document states them -------------------------------------------------
def _table(heading: str) -> list[list[list[str]]]:
    """The rows of the first table under ``heading``: each cell's code spans."""
    lines = ARCHITECTURE.read_text(encoding="utf-8").splitlines()
    if heading not in lines:
        raise AssertionError(f"docs/architecture.md has no {heading!r}")
    rows = []
    for line in lines[lines.index(heading) + 1 :]:
        if line.startswith("|"):
            rows.append(
                [
                    re.findall(r"`([^`]+)`", cell) or [cell.strip()]
                    for cell in line.strip("|").split("|")
                ]
            )
        elif rows:
            break
    if len(rows) < 3:
        raise AssertionError(f"docs/architecture.md: no table under {heading!r}")
    return rows[2:]  # after the header and its rule


def _room_of(name: str, rooms: list[str]) -> str | None:
    """The room (a path of the table) that holds module ``name``: its file, or the
    longest folder above it; a foreign library is its own room."""
    if name in FOREIGN:
        return name
    path = _modules()[name]
    holding = [r for r in rooms if path == r or (r.endswith("/") and path.startswith(r))]
    return max(holding, key=len, default=None)


def _allowed() -> dict[str, tuple[str, set[str]]]:
    """Room -> (its row's label, the rooms it may import); the rooms of a row share it."""
    rows = _table(MAY_IMPORT)
    base = set(rows[0][0])
    allowed = {}
    for row in rows:
        rooms, may = row[0], set(row[2])
        label = ", ".join(rooms)
        for room in rooms:
            allowed[room] = (label, may | base | set(rooms))
    return allowed


def _never() -> list[tuple[str, str, str]]:
    """(room, a room it never imports, why), one per pair the document names."""
    return [
        (room, other, " ".join(why))
        for rooms, others, why in _table(NEVER_IMPORTS)
        for room in rooms
        for other in others
    ]


def _chain(start: str, forbidden: str, rooms: list[str]) -> list[str] | None:
    """The shortest import chain from module ``start`` into room ``forbidden``, or None."""
    graph, parent = _graph(), {start: ""}
    queue = deque([start])
    while queue:
        name = queue.popleft()
        if _room_of(name, rooms) == forbidden:
            chain = [name]
            while parent[chain[-1]]:
                chain.append(parent[chain[-1]])
            return chain[::-1]
        for other in sorted(graph.get(name, ())):
            if other not in parent:
                parent[other] = name
                queue.append(other)
    return None


# --- the tests ------------------------------------------------------------------------------
def test_every_form_of_import_is_seen():
    forms = {
        "import quadsitl.viz.sim_view": "quadsitl.viz.sim_view",
        "from quadsitl import viz": "quadsitl.viz",
        "from quadsitl.viz import sim_view": "quadsitl.viz.sim_view",
        "from .. import viz": "quadsitl.viz",
        "from ..viz.sim_view import SimView": "quadsitl.viz.sim_view",
        "def f():\n    from . import server": "quadsitl.simulator.server",
        "if TYPE_CHECKING:\n    from quadsitl.viz import sim_view": "quadsitl.viz.sim_view",
    }
    for source, module in forms.items():
        assert module in _imported(source, "quadsitl.simulator"), source


def test_importing_a_module_runs_the_packages_above_it():
    edges = _edges("from quadsitl.tasks.engine import TaskEngine", "quadsitl.envs", _modules())
    assert {"quadsitl", "quadsitl.tasks", "quadsitl.tasks.engine"} <= edges
    assert "pymavlink" in _edges("from pymavlink import mavutil", "quadsitl.viz", _modules())


def test_every_module_lies_in_a_room_of_the_table():
    rooms = list(_allowed())
    homeless = sorted(path for name, path in _modules().items() if _room_of(name, rooms) is None)
    assert not homeless, f"add these to the table under {MAY_IMPORT!r} in docs/architecture.md"


def test_every_room_the_rules_name_exists():
    named = set(_allowed()) | {room for rule in _never() for room in rule[:2]}
    for _, may in _allowed().values():
        named |= may - {EVERYTHING, "nothing else"}
    missing = sorted(r for r in named if r not in FOREIGN and not (ROOT / r).exists())
    assert not missing


@pytest.mark.parametrize("label", sorted({label for label, _ in _allowed().values()}))
def test_a_room_imports_only_what_the_table_allows(label):
    allowed = _allowed()
    rooms = list(allowed)
    offences = []
    for name, imported in sorted(_graph().items()):
        room = _room_of(name, rooms)
        if room is None or allowed[room][0] != label or EVERYTHING in allowed[room][1]:
            continue
        for other in sorted(imported):
            other_room = _room_of(other, rooms)
            if other_room not in allowed[room][1]:
                offences.append(f"{_modules()[name]} imports {other} ({other_room})")
    assert not offences, "\n".join(offences)


@pytest.mark.parametrize(
    ("room", "forbidden", "why"), _never(), ids=[f"{r}-never-{f}" for r, f, _ in _never()]
)
def test_a_room_never_imports_what_the_rules_forbid(room, forbidden, why):
    rooms = list(_allowed())
    offences = []
    for name in sorted(_modules()):
        if _room_of(name, rooms) != room:
            continue
        chain = _chain(name, forbidden, rooms)
        if chain is not None:
            offences.append(" -> ".join(_modules().get(n, n) for n in chain))
    assert not offences, f"{room} imports {forbidden} ({why}):\n" + "\n".join(offences)


def test_in_quadsitl_only_the_wire_imports_pymavlink():
    importers = {
        path
        for name, path in _modules().items()
        if path.startswith("quadsitl/") and "pymavlink" in _graph()[name]
    }
    assert importers and all(path.startswith("quadsitl/wire/") for path in importers), importers


def test_the_files_the_architecture_names_exist():
    named = set(
        re.findall(
            r"`((?:quadsitl|gcs_tools|policies|benchmarks|tests)/[\w/]+\.py)`",
            ARCHITECTURE.read_text(),
        )
    )
    assert named and not sorted(p for p in named if not (ROOT / p).exists())


def _runs(code: str) -> subprocess.CompletedProcess[str]:
    # 600 s: a hang guard, not a speed (a simulator whose compiled kernels are not yet in
    # numba's cache compiles them first: minutes on a loaded machine)
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=600, cwd=ROOT
    )


def test_the_clients_and_the_ground_station_import_without_the_server_or_the_flight_software():
    modules = [
        n
        for n, p in _modules().items()
        if p.startswith(("quadsitl/lockstep_client/", "gcs_tools/"))
    ]
    code = (
        "import sys\n"
        "sys.modules['quadsitl.simulator'] = None  # any import of them now fails\n"
        "sys.modules['quadsitl.flight_software'] = None\n"
        f"for name in {sorted(modules)!r}:\n"
        "    __import__(name)\n"
    )
    result = _runs(code)
    assert result.returncode == 0, result.stderr


def test_the_simulator_runs_with_policies_and_gcs_tools_unimportable():
    port = free_udp_port()
    code = (
        "import sys\n"
        "sys.modules['policies'] = None  # any import of them now fails\n"
        "sys.modules['gcs_tools'] = None\n"
        "import quadsitl, quadsitl.envs, quadsitl.tasks, quadsitl.viz.sim_view\n"
        "from quadsitl.cli import main\n"
        f"sys.exit(main(['sim', '--duration', '2', '--logs', 'none', '--gcs', 'none',"
        f" '--api', 'udpout:127.0.0.1:{port}']))\n"
    )
    result = _runs(code)
    assert result.returncode == 0, result.stderr
    assert "quadsitl sim: system 1" in result.stdout and "timing:" in result.stderr
