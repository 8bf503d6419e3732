"""How an env starts its autopilots: a real PX4 or ArduCopter from its SITL build, or the
in-repository fakes (:mod:`quadsitl.fake_stacks`), and what each is asked for on its
MAVLink link (docs/autopilots.md, "Training through the flight stack")."""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from quadsitl.bridges.ardupilot_udp import PARAMETER_FOLDER, parameter_file
from quadsitl.bridges.px4_airframe import parameter_folder
from quadsitl.bridges.px4_hil import ROUND_US
from quadsitl.wire.dialect import mavlink as mav

STACKS = ("px4", "ardupilot")
# ArduCopter's parameters for training through GUIDED, over the airframe's own file
OFFBOARD_PARAMETERS = PARAMETER_FOLDER / "offboard.parm"


@dataclass(frozen=True)
class AutopilotCommand:
    """How an autopilot instance starts: ``argv`` (``{port}``, ``{instance}`` and
    ``{link}``, its MAVLink link's port, are filled in) with ``environment`` added to
    this process's; ``own_folder``: it runs in a new folder of its own (it writes its
    parameters and logs there), where its output goes to ``autopilot.log``;
    ``streams_us``: message id -> interval (µs) asked for on its MAVLink link;
    ``files``: name -> text, written into its own folder before it starts;
    ``estimate_lag_ms``: how much older than a step's end its estimate may be stamped (a
    real PX4 stamps its estimator's output; ArduPilot's is read once its held frame has
    come, :meth:`~quadsitl.envs.lockstep_sides.ArduPilotSide.sent_all`)."""

    argv: list[str]
    environment: dict[str, str] = field(default_factory=dict)
    own_folder: bool = False
    streams_us: dict[int, int] = field(default_factory=dict)
    estimate_lag_ms: int = 0
    files: dict[str, str] = field(default_factory=dict)


def autopilot_command(
    autopilot: Any, airframe: str = "iris", stack: str = "px4", sensor_noise: float = 1.0
) -> AutopilotCommand:
    """``autopilot`` as a command for ``stack``: None, the in-repository fake; a path, a
    SITL build (PX4's ``build/px4_sitl_default``; ArduPilot's ``build/sitl`` or its
    ``arducopter``, its own sensor models' noise scaled by ``sensor_noise``); a list, the
    argv of anything else; or an :class:`AutopilotCommand` as it is."""
    if stack not in STACKS:
        raise ValueError(f"stack must be one of {', '.join(STACKS)}, got {stack!r}")
    if autopilot is None:
        return fake_command(airframe, stack)
    if isinstance(autopilot, AutopilotCommand):
        return autopilot
    if isinstance(autopilot, (str, os.PathLike)):
        if stack == "ardupilot":
            return arducopter_command(autopilot, airframe, sensor_noise)
        return px4_build_command(autopilot, airframe)
    return AutopilotCommand([str(a) for a in autopilot])


def fake_command(airframe: str = "iris", stack: str = "px4") -> AutopilotCommand:
    """The in-repository fake of ``stack`` (:mod:`quadsitl.fake_stacks`) as a process;
    the fake ArduCopter, as ArduCopter, sends only the streams asked for."""
    module = f"quadsitl.fake_stacks.offboard_{stack}"
    argv = [sys.executable, "-m", module, "-i", "{instance}", "--port", "{port}",
            "--airframe", airframe]  # fmt: skip
    if stack == "ardupilot":
        return AutopilotCommand(argv, streams_us=dict(ARDUPILOT_STREAMS_US))
    return AutopilotCommand(argv)


# What a real PX4 sends its onboard link by default is too slow for 50 Hz control (its
# "onboard" MAVLink mode: LOCAL_POSITION_NED at 30 Hz); the env asks for every round's.
PX4_STREAMS_US = {
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: ROUND_US,
    mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: ROUND_US,
}
PX4_ESTIMATE_LAG_MS = 12  # PX4 publishes its estimate a few rounds after the IMU's


def px4_build_command(build: str | os.PathLike[str], airframe: str = "iris") -> AutopilotCommand:
    """A real PX4 from its SITL build folder, on quadsitl's parameter file for
    ``airframe`` (airframe none_iris: PX4's quad X without a simulator of its own), as
    docs/autopilots.md starts it by hand."""
    build = Path(build).expanduser().resolve()
    binary, etc = build / "bin" / "px4", build / "etc"
    if not (binary.is_file() and etc.is_dir()):
        raise ValueError(f"{build} is not a PX4 SITL build (no bin/px4 and etc/ in it)")
    folder = parameter_folder(airframe)
    if folder is None:
        raise ValueError(f"no PX4 parameter file ships for airframe {airframe!r}")
    path = f"{folder}{os.pathsep}{os.environ.get('PATH', '')}"
    return AutopilotCommand(
        [str(binary), "-d", "-i", "{instance}", str(etc)],
        {"PATH": path, "PX4_SIM_MODEL": "none_iris"},
        own_folder=True,
        streams_us=dict(PX4_STREAMS_US),
        estimate_lag_ms=PX4_ESTIMATE_LAG_MS,
    )


# ArduCopter sends a stream at most once per main loop (400 Hz), and refuses an interval
# shorter than its scheduler can keep (GCS_Common.cpp): 200 Hz, under a step's 20 ms.
ARDUPILOT_STREAMS_US = {
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 5000,
    mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 5000,
}
ARDUPILOT_SPEEDUP = 1000  # --speedup: no wall-clock pacing (lockstep paces it)


# ArduPilot's SITL models its own sensors from the JSON state; of their noise parameters
# only the barometers' default is not 0 (SITL_Baro.cpp: SIM_BARO_RND 0.2 m, as SIM_BAR2_).
BARO_NOISE_M = 0.2


def arducopter_command(
    build: str | os.PathLike[str], airframe: str = "iris", sensor_noise: float = 1.0
) -> AutopilotCommand:
    """A real ArduCopter from its SITL build (``build/sitl``, or ``bin/arducopter``
    itself) on the JSON interface, with quadsitl's parameter files for ``airframe`` and
    for training (OFFBOARD_PARAMETERS) and one scaling its sensors' noise by
    ``sensor_noise`` (``noise.parm``: the barometers', BARO_NOISE_M at 1), its MAVLink on
    SERIAL0 as a UDP client of the env (``udpclient``), SERIAL1 and SERIAL2 off (their
    TCP ports are not needed, and a port taken would stall its start)."""
    path = Path(build).expanduser().resolve()
    binary = path if path.is_file() else path / "bin" / "arducopter"
    if not binary.is_file():
        raise ValueError(f"{build} is not an ArduCopter SITL build (no bin/arducopter in it)")
    parameters = parameter_file(airframe)
    if parameters is None:
        raise ValueError(f"no ArduCopter parameter file ships for airframe {airframe!r}")
    noise = BARO_NOISE_M * sensor_noise
    defaults = f"{parameters},{OFFBOARD_PARAMETERS},noise.parm"  # (the last in its folder)
    return AutopilotCommand(
        [str(binary), "--model", "JSON", "--defaults", defaults,
         "-I", "{instance}", "-w", "--speedup", str(ARDUPILOT_SPEEDUP),
         "--serial0", "udpclient:127.0.0.1:{link}", "--serial1", "none", "--serial2", "none"],
        own_folder=True,
        streams_us=dict(ARDUPILOT_STREAMS_US),
        files={"noise.parm": f"SIM_BARO_RND {noise:g}\nSIM_BAR2_RND {noise:g}\n"},
    )  # fmt: skip
