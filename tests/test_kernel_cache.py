"""The compiled physics is cached on disk: a second process loads it, it does not
compile it again (a cache key that changed from process to process once cost every
simulator, env and test 15–30 s of compiling)."""

from __future__ import annotations

import json
import subprocess
import sys

PROBE = """
import json
import numpy as np
from quadsitl.physics import Fleet, kernel
from quadsitl.physics.wind import Wind

for n in (1, 40):  # the single-vehicle and the batched builds
    fleet = Fleet(n)
    fleet.step(np.full((n, 4), fleet.hover_rotor_speed[0]))
    fleet.set_wind(Wind(speed=5.0, turbulence="light"), seed=1)
    fleet.step(np.full((n, 4), fleet.hover_rotor_speed[0]))
builds = ("single_step", "batch_step", "single_step_wind", "batch_step_wind")
print(json.dumps({b: sum(getattr(kernel, b).stats.cache_misses.values()) for b in builds}))
"""


def _misses() -> dict[str, int]:
    result = subprocess.run(
        [sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=600, check=True
    )
    return json.loads(result.stdout.strip().splitlines()[-1])


def test_a_second_process_loads_the_compiled_kernels_from_the_cache():
    _misses()  # compiles what is not cached yet
    assert _misses() == dict.fromkeys(
        ("single_step", "batch_step", "single_step_wind", "batch_step_wind"), 0
    )


def test_an_edit_to_any_compiled_source_drops_the_cached_machine_code(tmp_path, monkeypatch):
    """numba would keep a kernel compiled against the old version of a file it inlines."""
    from quadsitl import compiled_cache as C

    monkeypatch.setattr(C, "PACKAGE", tmp_path)
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    for entry in C.COMPILED_SOURCES:
        path = tmp_path / entry
        if path.suffix != ".py":
            path = path / "module.py"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("X = 1\n")
    cached = tmp_path / "physics" / "__pycache__" / "kernel.step-10.py311.nbi"
    cached.parent.mkdir()

    def cache_it() -> None:
        cached.write_bytes(b"machine code")

    cache_it()
    assert C.drop_stale() and not cached.exists()  # no stamp yet: nothing is trusted
    cache_it()
    assert not C.drop_stale() and cached.exists()  # nothing changed: kept
    (tmp_path / "tasks" / "module.py").write_text("X = 2\n")  # a file the kernel reads
    assert C.drop_stale() and not cached.exists()
    cache_it()
    (tmp_path / "physics" / "new.py").write_text("Y = 1\n")  # a new source counts too
    assert C.drop_stale() and not cached.exists()


def test_the_stamp_covers_every_module_compiled_code_imports():
    """Every module that defines compiled functions, and every project module they
    import (directly or not), is among the hashed sources."""
    import re
    from pathlib import Path

    from quadsitl import compiled_cache as C

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import house

    known = house.modules()
    compiled = re.compile(r"^(import numba|from numba|@(R\.)?jit\b|@_jit\b)", re.M)
    stack = [n for n, p in known.items() if compiled.search(p.read_text(encoding="utf-8"))]
    assert "quadsitl.physics.kernel" in stack and "quadsitl.tasks.hover" in stack
    reached: set[str] = set()
    while stack:
        name = stack.pop()
        if name not in reached:
            reached.add(name)
            stack += house.imports_of(name, known[name], known)
    hashed = set(C.source_files())
    assert {known[name] for name in reached if name.startswith("quadsitl")} <= hashed
