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
