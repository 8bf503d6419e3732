"""``quadsitl fly``: a mission file flown against a real ``quadsitl sim`` process."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from gcs_tools.client import mav
from gcs_tools.mission_file import read_mission
from gcs_tools.scripted_flight import planned_path
from quadsitl.geo import Home
from quadsitl.wire.addresses import free_udp_port
from tests.conftest import cli, refused_here, run_cli, running_sim, wait_until_listening

MISSIONS = Path(__file__).resolve().parent.parent / "docs" / "missions"


def test_a_qgroundcontrol_plan_flies_against_a_running_sim():
    port = free_udp_port()
    with running_sim(f"sim --gcs none --api udpout:127.0.0.1:{port} --speed 8 --logs none") as sim:
        flown = run_cli(
            "fly", str(MISSIONS / "square.plan"), "--connect", f"udpin:127.0.0.1:{port}"
        )
    assert flown.returncode == 0, flown.stdout + flown.stderr + sim.output
    assert "flying 8 items" in flown.stdout
    errors = re.search(r"waypoint error \(closest approach\): ([\d., ]+) m", flown.stdout)
    assert errors is not None, flown.stdout
    closest = [float(x) for x in errors.group(1).split(",")]
    assert len(closest) == 4 and max(closest) < 0.3  # take-off target and three waypoints
    assert "landed: True" in flown.stdout
    # the plan's camera items were taken as a payload-less vehicle takes them
    assert "skipped (no payload)" in sim.output


def test_fly_signs_for_a_vehicle_with_signing_on(tmp_path):
    mission = tmp_path / "hop.txt"
    mission.write_text("0 0 2\n2 0 2\n")
    port = free_udp_port()
    sim = subprocess.Popen(
        cli(
            f"sim --gcs none --api udpout:127.0.0.1:{port} --speed 8 --logs none "
            "--signing-passphrase",
            "correct horse",
        ),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    wait_until_listening(sim)  # its udpout link
    connect = ("--connect", f"udpin:127.0.0.1:{port}", "--timeout", "60")
    try:
        unsigned = run_cli("fly", str(mission), *connect)
        signed = run_cli("fly", str(mission), *connect, "--signing-passphrase", "correct horse")
    finally:
        sim.terminate()
        sim_output = sim.communicate(timeout=15)[0]
    assert unsigned.returncode == 1 and "quadsitl fly: failed:" in unsigned.stderr
    assert "signing: rejected" in sim_output
    assert signed.returncode == 0, signed.stdout + signed.stderr + sim_output
    assert "landed: True" in signed.stdout


def test_plan_items_are_read_as_qgroundcontrol_wrote_them():
    items = read_mission(MISSIONS / "square.plan")
    assert isinstance(items, list)
    assert [item.command for item in items] == [22, 16, 178, 2000, 16, 2001, 16, 21]
    assert items[0].frame == mav.MAV_FRAME_GLOBAL_RELATIVE_ALT and items[0].altitude == 5
    assert items[2].params == (1.0, 3.0, -1.0, 0.0)  # DO_CHANGE_SPEED to 3 m/s
    path = planned_path(items, Home())
    assert path.targets.round(1).tolist() == [[0, 0, 5], [10, 0, 5], [10, 10, 7], [0, 10, 5]]
    assert path.polyline[-1].round(1).tolist() == [0, 0, 0]


def test_the_waypoint_list_is_the_demos_mission_format():
    waypoints = read_mission(MISSIONS / "square.txt")
    assert isinstance(waypoints, tuple)
    assert [(w.east, w.north, w.up, w.hold) for w in waypoints][2] == (10, 10, 7, 1)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ('{"fileType": "Plan", "mission": {"items": []}}', "the plan has no mission items"),
        ('{"fileType": "Fence"}', "is not a QGroundControl plan"),
        ("{not json", "is not valid JSON"),
        ("1 2\n", "mission.txt:1: a waypoint is EAST NORTH UP [HOLD]"),
        ("0 0 0\n", "the first waypoint sets the take-off height"),
    ],
)
def test_a_bad_mission_file_is_one_line_and_flies_nothing(tmp_path, content, message):
    path = tmp_path / "mission.txt"
    path.write_text(content)
    result = refused_here("fly", str(path), "--connect", "udpin:127.0.0.1:0")
    assert result.returncode == 2
    assert result.stderr.startswith("quadsitl fly: error: ") and message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.stderr


def test_a_missing_file_is_a_clear_error(tmp_path):
    result = refused_here("fly", str(tmp_path / "nope.plan"))
    assert (
        result.returncode == 2 and "cannot read" in result.stderr and "nope.plan" in result.stderr
    )


def test_an_item_without_params_names_its_number(tmp_path):
    path = tmp_path / "bad.plan"
    path.write_text('{"fileType": "Plan", "mission": {"items": [{"command": 22, "frame": 3}]}}')
    with pytest.raises(ValueError, match="mission item 1 needs command, frame and params"):
        read_mission(path)
