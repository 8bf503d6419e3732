"""The console command, run as a user runs it."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

from quadsitl import __version__
from tests.conftest import refused_here


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
    result = _run("demo", "--physics", "--altitude", "1.5")
    assert result.returncode == 0, result.stderr
    assert "final state: on_ground" in result.stdout
    altitudes = [
        float(line.split()[1])
        for line in result.stdout.splitlines()
        if line[:6].strip().replace(".", "").isdigit()
    ]
    assert max(altitudes) > 1.4


def test_demo_rejects_bad_options():
    result = refused_here("demo", "--physics", "--airframe", "bogus")
    assert result.returncode == 2
    assert "unknown airframe" in result.stderr


def test_mission_demo_flies_and_reports_tracking(tmp_path):
    result = _run("demo", "--speed", "8", "--logs", str(tmp_path))
    assert result.returncode == 0, result.stdout + result.stderr
    assert "waypoint error" in result.stdout and "path tracking error" in result.stdout
    assert str(tmp_path) in result.stdout and "QGroundControl" in result.stdout
    # the commands it prints run as typed in a shell whose venv is not activated
    shell = {**os.environ, "PATH": _path_without_venv()}
    opener = next(line for line in result.stdout.splitlines() if "open it with:" in line)
    viewer = opener.split("open it with:")[1].split()[0]
    quadsitl = result.stdout.split("run `")[1].split(" sim`")[0]
    for command in (f"{viewer} --version", f"{quadsitl} sim --help"):
        ran = subprocess.run(["bash", "-c", command], env=shell, capture_output=True, timeout=60)
        assert ran.returncode == 0, f"{command!r} does not run as printed: {ran.stderr!r}"


def _path_without_venv() -> str:
    scripts = str(Path(sys.executable).parent)
    return os.pathsep.join(p for p in os.environ["PATH"].split(os.pathsep) if p != scripts)


def test_printed_commands_name_the_venv_script_unless_path_finds_it(monkeypatch):
    from quadsitl.console import runnable

    scripts = Path(sys.executable).parent
    monkeypatch.setenv("PATH", _path_without_venv())
    printed = runnable("quadsitl", "quadsitl.cli")
    assert Path(printed).absolute() == (scripts / "quadsitl").absolute()
    monkeypatch.setenv("PATH", f"{scripts}{os.pathsep}{_path_without_venv()}")
    assert runnable("quadsitl", "quadsitl.cli") == "quadsitl"
    assert runnable("no-such-script", "quadsitl.cli") == f"{sys.executable} -m quadsitl.cli"


def test_sim_stops_cleanly_on_sigint_and_sigterm(tmp_path):
    for sig in (signal.SIGINT, signal.SIGTERM):
        process = subprocess.Popen(
            [sys.executable, "-m", "quadsitl.cli", "sim", "--logs", str(tmp_path)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        assert process.stdout is not None
        banner = process.stdout.readline()  # printed once the signal handlers are in place
        assert banner.startswith("quadsitl sim:"), banner
        process.send_signal(sig)
        _out, err = process.communicate(timeout=10)
        assert process.returncode == 0, err
        assert "timing:" in err and "Traceback" not in err


def test_sim_port_in_use_is_a_clear_error():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        result = _run("sim", "--gcs", f"udpin:127.0.0.1:{port}", "--logs", "none")
    assert result.returncode == 2
    assert "cannot open" in result.stderr and str(port) in result.stderr


def test_sim_rejects_bad_options():
    assert "unknown parameter" in refused_here("sim", "--param", "NOPE=1", "--logs", "none").stderr
    assert "LAT,LON,ALT" in refused_here("sim", "--home", "1,2", "--logs", "none").stderr
    assert "kind must be" in refused_here("sim", "--gcs", "serial:x:1", "--logs", "none").stderr
    # 300 Hz physics cannot step a 250 Hz controller every whole number of steps
    rates = refused_here("sim", "--physics-rate", "300", "--control-rate", "250", "--logs", "none")
    assert rates.returncode == 2
    assert "not a whole multiple of the control rate 250 Hz" in rates.stderr


def test_sim_banner_says_when_a_policy_flies_the_vehicle():
    checkpoint = Path(__file__).resolve().parent.parent / "policies/checkpoints/hover.pt"
    common = ("sim", "--gcs", "udpin:127.0.0.1:0", "--api", "none", "--logs", "none")
    flown = _run(*common, "--duration", "1", "--autopilot", str(checkpoint))
    assert flown.returncode == 0, flown.stderr
    banner = flown.stdout.splitlines()[:2]
    assert banner[1] == (
        f"quadsitl sim: flown by the policy in {checkpoint}, not the cascaded controller"
    )
    plain = _run(*common, "--duration", "0.5")
    assert plain.returncode == 0 and "flown by" not in plain.stdout
