"""``quadsitl demo --physics``: the table of a take-off, hover and landing, read as a
user reads it."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

from quadsitl.demo import run_demo

ROOT = Path(__file__).resolve().parents[1]


def _rows(text: str) -> list[tuple[float, float, float, str]]:
    """(t s, altitude m, mean rotor speed rad/s, contact) of each table row."""
    rows = []
    for line in text.splitlines():
        words = line.split()
        if len(words) == 5 and re.fullmatch(r"\d+\.\d\d", words[0]):
            rows.append((float(words[0]), float(words[1]), float(words[3]), words[4]))
    return rows


def test_the_rotors_stop_once_the_vehicle_has_landed(capsys):
    """As PX4's land detector: landed, the motors stop (it disarms); they do not keep
    pushing on the ground at the descent's thrust."""
    assert run_demo(altitude=1.5, print_every=0.1) == 0
    text = capsys.readouterr().out
    hover = float(re.search(r"hover Ω_h = ([\d.]+) rad/s", text).group(1))
    rows = _rows(text)
    flown = next(i for i, row in enumerate(rows) if row[3] == "airborne")
    touchdown = next(row[0] for row in rows[flown:] if row[3] == "on_ground")
    after = [row for row in rows if row[0] >= touchdown + 0.5]
    assert after and all(row[3] == "on_ground" for row in after)
    assert all(row[2] < 0.1 * hover for row in after), after[:5]
    assert re.search(r"^landed at [\d.]+ s: motors off$", text, re.M)


def test_the_readmes_physics_example_prints_what_the_readme_says():
    """Readable figures and contact names, each line quoted in the README after it (not
    ``-4.63e-24`` and ``[2 2 2]``)."""
    readme = (ROOT / "README.md").read_text()
    section = readme.split("## The physics in one paragraph", 1)[1]
    block = section.split("```python runnable\n", 1)[1].split("```", 1)[0]
    result = subprocess.run(
        [sys.executable, "-c", block], capture_output=True, text=True, timeout=60, cwd=ROOT
    )
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines and all(f"`{line}`" in section for line in lines), lines
    assert not re.search(r"e-\d\d|\[\d \d", result.stdout)
