"""Package seams: the core of ``quadsitl`` imports neither ``policies`` nor ``gcs_tools``
(only the command line, which composes everything, may), and ``quadsitl.mavlink`` does
not import ``quadsitl.viz``."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

from gcs_tools.demo import free_udp_port

ROOT = Path(__file__).resolve().parents[1]
COMPOSER = ROOT / "quadsitl" / "cli.py"


def _imports(path: Path) -> set[str]:
    """Absolute names of every module ``path`` imports (at any depth of the file)."""
    package = path.relative_to(ROOT).with_suffix("").parts[:-1]
    return _imported(path.read_text(), ".".join(package))


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


def test_every_form_of_import_is_seen():
    forms = {
        "import quadsitl.viz.sim_view": "quadsitl.viz.sim_view",
        "from quadsitl import viz": "quadsitl.viz",
        "from quadsitl.viz import sim_view": "quadsitl.viz.sim_view",
        "from .. import viz": "quadsitl.viz",
        "from ..viz.sim_view import SimView": "quadsitl.viz.sim_view",
        "def f():\n    from . import server": "quadsitl.mavlink.server",
    }
    for source, module in forms.items():
        assert module in _imported(source, "quadsitl.mavlink"), source


def test_the_core_imports_neither_policies_nor_gcs_tools():
    offenders = {}
    for path in (ROOT / "quadsitl").rglob("*.py"):
        if path == COMPOSER:
            continue
        bad = {n for n in _imports(path) if n.split(".")[0] in ("policies", "gcs_tools")}
        if bad:
            offenders[str(path.relative_to(ROOT))] = bad
    assert not offenders


def test_mavlink_does_not_import_viz():
    offenders = {}
    for path in (ROOT / "quadsitl" / "mavlink").rglob("*.py"):
        bad = {n for n in _imports(path) if n == "quadsitl.viz" or n.startswith("quadsitl.viz.")}
        if bad:
            offenders[path.name] = bad
    assert not offenders


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
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=ROOT
    )
    assert result.returncode == 0, result.stderr
    assert "quadsitl sim: system 1" in result.stdout and "timing:" in result.stderr
