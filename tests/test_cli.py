"""The console command, run as a user runs it."""

from __future__ import annotations

import subprocess
import sys

from quadsitl import __version__


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "quadsitl.cli", *args], capture_output=True, text=True, timeout=120
    )


def test_version_and_help():
    assert _run("--version").stdout.strip() == f"quadsitl {__version__}"
    result = _run("--help")
    assert result.returncode == 0
    assert "demo" in result.stdout


def test_demo_takes_off_hovers_and_lands():
    result = _run("demo", "--altitude", "1.5")
    assert result.returncode == 0, result.stderr
    assert "final state: on_ground" in result.stdout
    altitudes = [
        float(line.split()[1])
        for line in result.stdout.splitlines()
        if line[:6].strip().replace(".", "").isdigit()
    ]
    assert max(altitudes) > 1.4


def test_demo_rejects_bad_options():
    result = _run("demo", "--airframe", "bogus")
    assert result.returncode == 2
    assert "unknown airframe" in result.stderr
