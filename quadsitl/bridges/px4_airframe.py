"""The PX4 parameters that make PX4's airframe quadsitl's: rotor geometry, thrust model,
hover thrust and what a simulated vehicle needs (docs/autopilots.md, "PX4").

PX4's SITL start script sources ``px4-rc.params`` from the ``PATH`` after the airframe's
defaults ("user defined params for instances can be in PATH", ROMFS
``init.d-posix/rcS``), so a folder holding one is all a user adds:
``PATH=quadsitl/bridges/px4/iris:$PATH``. The shipped files are
:func:`parameter_script` of their preset, which a test holds them to.
"""

from __future__ import annotations

from pathlib import Path

from quadsitl.physics.airframe import Airframe, get_airframe

PARAMETER_ROOT = Path(__file__).resolve().parent / "px4"
SCRIPT_NAME = "px4-rc.params"
SHIPPED = ("iris", "paper-x-fast")  # presets PX4's stock gains fly (0.18 s motors do not)
GPS_DELAY_MS = 120  # EKF2_GPS_DELAY: the GPS model's latency (GpsParams.latency)


def parameter_folder(airframe: str) -> Path | None:
    """The folder to put first on PX4's PATH for preset ``airframe`` (None: none ships)."""
    folder = PARAMETER_ROOT / airframe
    return folder if (folder / SCRIPT_NAME).is_file() else None


def rotor_parameters(airframe: Airframe) -> list[tuple[str, float]]:
    """CA_ROTOR_COUNT and CA_ROTORi_PX/PY/KM of PX4's control allocation for the
    airframe's rotor i (PX4's motor i drives it): positions in m, body FRD; KM the
    torque-to-thrust ratio kq/kt, positive for a rotor turning counter-clockwise seen
    from above (quadsitl's rotor_yaw_sign −1)."""
    out: list[tuple[str, float]] = [("CA_ROTOR_COUNT", len(airframe.rotor_xy))]
    ratio = airframe.torque_coeff / airframe.thrust_coeff
    for i, ((x, y), sign) in enumerate(
        zip(airframe.rotor_xy, airframe.rotor_yaw_sign, strict=True)
    ):
        out += [
            (f"CA_ROTOR{i}_PX", round(x * airframe.arm_length, 4)),
            (f"CA_ROTOR{i}_PY", round(-y * airframe.arm_length, 4)),  # FLU left -> FRD right
            (f"CA_ROTOR{i}_KM", round(-sign * ratio, 4)),
        ]
    return out


def parameters(airframe: Airframe) -> list[tuple[str, float]]:
    """Every parameter the shipped file sets, in its order."""
    motors = [(f"PWM_MAIN_FUNC{i + 1}", 101 + i) for i in range(len(airframe.rotor_xy))]
    return [
        ("CA_AIRFRAME", 0),  # multicopter
        *rotor_parameters(airframe),
        *motors,  # outputs 1..4 are motors 1..4
        ("THR_MDL_FAC", 1.0),  # thrust ∝ output²: rotor speed is linear in the output
        ("MPC_THR_HOVER", round(airframe.hover_thrust_fraction, 3)),
        ("EKF2_GPS_DELAY", GPS_DELAY_MS),
        ("COM_CPU_MAX", -1),  # a busy machine's CPU load must not block arming
        ("SYS_HAS_MAG", 1),
        ("SYS_HAS_BARO", 1),
        ("SYS_HAS_GPS", 1),
    ]


def parameter_script(name: str) -> str:
    """The ``px4-rc.params`` of preset ``name``."""
    lines = [
        "#!/bin/sh",
        f'# PX4 on quadsitl\'s "{name}" airframe, through simulator_mavlink:',
        f"#   quadsitl sim --flight-stack px4 --airframe {name}",
        "#   PATH=/path/to/this/folder:$PATH PX4_SIM_MODEL=none_iris px4",
        "# PX4's rcS sources this file after the airframe's defaults. Each line:",
        "# docs/autopilots.md, PX4.",
    ]
    for parameter, value in parameters(get_airframe(name)):
        lines.append(f"param set {parameter} {value:g}")
    return "\n".join(lines) + "\n"
