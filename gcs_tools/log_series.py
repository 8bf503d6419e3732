"""A flight stack's log, column by column, into the entities a telemetry log's replay
shows (:mod:`quadsitl.viz.flight_view` says what each entity means): the ULog and
DataFlash views (:mod:`gcs_tools.ulog_view`, :mod:`gcs_tools.dataflash_view`) call these
with whole arrays, so that a log of a million rows converts at numpy's speed.

Frames: the logs' NED positions and FRD bodies become ENU and FLU on screen, as for a
.tlog. Each quantity has up to three traces, one colour each
(:mod:`quadsitl.viz.series_colors`): the estimate (``roll``), the setpoint
(``roll_setpoint``) and, where the log holds the simulator's own state, the truth
(``roll_truth``). Rows whose value is not finite are left out (PX4 writes NaN for a
setpoint it does not use): what a log lacks is absent, never plotted as zero.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from gcs_tools.replay_scene import System
from quadsitl import frames
from quadsitl.viz.flight_view import SEVERITY, state_samples
from quadsitl.viz.scene import pose_from_ned

AXES = ("roll", "pitch", "yaw")
FARTHEST_M = 1e6  # a local position beyond is not one (a damaged log's garbage)


def suffixed(name: str, role: str) -> str:
    """``roll`` -> ``roll_setpoint``; ``altitude`` + "" -> ``altitude``."""
    return f"{name}_{role}" if role else name


def scalar(system: System, entity: str, stamps: np.ndarray, values: np.ndarray) -> None:
    """One time series, its non-finite rows left out."""
    values = np.asarray(values, dtype=np.float64)
    keep = np.isfinite(values)
    system.columns.extend(entity, "scalar", stamps[keep], values[keep])


def position(
    system: System,
    stamps: np.ndarray,
    ned: np.ndarray,
    velocity_ned: np.ndarray | None = None,
    role: str = "",
) -> None:
    """Position (N, 3) and velocity (N, 3), NED m and m/s, into the altitude, climb-rate
    and horizontal-velocity panels. The estimate (``role`` "") also poses the vehicle
    and draws its track; the truth draws the true track."""
    keep = np.isfinite(ned).all(axis=1) & (np.abs(ned) < FARTHEST_M).all(axis=1)
    stamps, enu = stamps[keep], frames.ned_to_enu(ned[keep])
    scalar(system, f"plots/altitude/{suffixed('altitude', role)}", stamps, enu[:, 2])
    if velocity_ned is not None:
        velocity = frames.ned_to_enu(velocity_ned[keep])
        scalar(system, f"plots/climb_rate/{suffixed('climb', role)}", stamps, velocity[:, 2])
        scalar(system, f"plots/velocity/{suffixed('east', role)}", stamps, velocity[:, 0])
        scalar(system, f"plots/velocity/{suffixed('north', role)}", stamps, velocity[:, 1])
    if not len(enu):
        return
    if role == "truth":
        system.truth_track.append(enu)  # a block (see replay_scene.track_points)
    elif not role:
        system.columns.extend("world/vehicle", "translation", stamps, enu)
        system.track.append(enu)


def position_setpoint(
    system: System, stamps: np.ndarray, ned: np.ndarray, velocity_ned: np.ndarray | None
) -> None:
    """A local position (and velocity) target, NED: the altitude, climb-rate and
    velocity setpoints, and the commanded point in 3-D. NaN parts (not commanded) are
    left out each on its own."""
    enu = frames.ned_to_enu(ned)
    scalar(system, "plots/altitude/setpoint", stamps, enu[:, 2])
    given = np.isfinite(enu).all(axis=1)
    system.columns.extend("world/setpoint", "point", stamps[given], enu[given])
    if velocity_ned is not None:
        velocity = frames.ned_to_enu(velocity_ned)
        scalar(system, "plots/climb_rate/setpoint", stamps, velocity[:, 2])
        scalar(system, "plots/velocity/east_setpoint", stamps, velocity[:, 0])
        scalar(system, "plots/velocity/north_setpoint", stamps, velocity[:, 1])


def attitude(system: System, stamps: np.ndarray, q_ned_frd: np.ndarray, role: str = "") -> None:
    """Attitude quaternions (N, 4: w, x, y, z; body FRD in NED): roll, pitch, yaw in
    degrees, unwrapped; the estimate also turns the vehicle in 3-D."""
    q = np.asarray(q_ned_frd, dtype=np.float64)
    keep = np.isfinite(q).all(axis=1) & (np.abs(q).sum(axis=1) > 0)
    stamps, q = stamps[keep], q[keep]
    angles = np.degrees(frames.euler_from_quat(q)).reshape(-1, 3)
    euler(system, stamps, angles, role)
    if not role:
        _, rotation = pose_from_ned(np.zeros((len(q), 3)), q)
        system.columns.extend("world/vehicle", "rotation", stamps, rotation)


def euler(system: System, stamps: np.ndarray, degrees: np.ndarray, role: str = "") -> None:
    """Roll, pitch, yaw (N, 3) in degrees into the attitude panel, unwrapped (continuous
    through ±180°, as the live view draws them)."""
    for k, axis in enumerate(AXES):
        values = np.asarray(degrees[:, k], dtype=np.float64)
        keep = np.isfinite(values)
        unwrapped = np.unwrap(values[keep], period=360.0)
        scalar(system, f"plots/attitude/{suffixed(axis, role)}", stamps[keep], unwrapped)


def rates(system: System, stamps: np.ndarray, degrees_s: np.ndarray, role: str = "") -> None:
    """Body rates (N, 3: roll, pitch, yaw), deg/s."""
    for k, axis in enumerate(AXES):
        scalar(system, f"plots/rates/{suffixed(axis, role)}", stamps, degrees_s[:, k])


def rotors(system: System, stamps: np.ndarray, outputs: np.ndarray) -> None:
    """Motor outputs (N, motors), each a series: the replay shows them as multiples of
    their hover value (:meth:`~gcs_tools.replay_scene.Columns.normalise_rotors`)."""
    for k in range(outputs.shape[1]):
        scalar(system, f"plots/rotors/rotor_{k + 1}", stamps, outputs[:, k])


def imu(system: System, stamps: np.ndarray, accel: np.ndarray, gyro_rad: np.ndarray) -> None:
    """What the IMU read, body FRD: specific force m/s², rates rad/s (shown in deg/s)."""
    for k, axis in enumerate("xyz"):
        scalar(system, f"plots/accelerometer/{axis}", stamps, accel[:, k])
        scalar(system, f"plots/gyroscope/{axis}", stamps, np.degrees(gyro_rad[:, k]))
    for axis in "xyz":  # the longest series of a log: into the recording at once
        system.columns.finish(f"plots/accelerometer/{axis}")
        system.columns.finish(f"plots/gyroscope/{axis}")


def geo_track(system: System, stamps: np.ndarray, lat: np.ndarray, lon: np.ndarray) -> None:
    """The map's track (degrees); rows without a position (0, 0 or NaN) left out."""
    keep = np.isfinite(lat) & np.isfinite(lon) & ((lat != 0) | (lon != 0))
    points = np.stack([lat[keep], lon[keep]], axis=1)
    system.columns.extend("map/track", "geo", stamps[keep], points)


def flight_state(
    system: System, stamps: Sequence[int], armed: Sequence[bool], modes: Sequence[str]
) -> None:
    """The flight-state band and its events from (armed, mode) reports, as the live
    view draws them from heartbeats: at each change of state and at the last report
    (a report repeating the state would only add a point on the band's line)."""
    last: tuple[bool, str] | None = None
    count = len(stamps)
    for row, (stamp, is_armed, mode) in enumerate(zip(stamps, armed, modes, strict=True)):
        state = (bool(is_armed), str(mode))
        if state == last and row < count - 1:
            continue
        for sample in state_samples(last, state):
            system.columns.add(int(stamp), sample)
        last = state


def events(
    system: System,
    stamps: Sequence[int] | np.ndarray,
    texts: Sequence[str],
    severities: Sequence[int],
) -> None:
    """Log messages as events, each at its MAV_SEVERITY-style level (0..7)."""
    levels = [SEVERITY[min(max(int(s), 0), 7)] for s in severities]
    system.columns.extend("events", "text", np.asarray(stamps, np.int64), list(texts), levels)


SPECTRUM_SEGMENT_S = 1.0  # s of samples per FFT: the frequency resolution (1 Hz)
MOST_SPECTRA = 120  # per axis: a longer log averages more segments into each spectrum


def spectra(system: System, stamps: np.ndarray, values: np.ndarray, sensor: str) -> None:
    """Amplitude spectral density of a sensor's three axes ((N, 3), at its logged rate),
    each spectrum at the end of the span it covers: the view shows the span the time
    cursor is in. Welch's method: Hann-windowed segments of SPECTRUM_SEGMENT_S, mean
    removed, their power averaged over as many consecutive segments as keep a log to
    MOST_SPECTRA spectra per axis (1 s each for a flight under two minutes; a bar chart
    is one log call, Rerun sends no columns of them). Units: the sensor's per √Hz.
    Nothing for a log below 20 samples/s (no vibration to see)."""
    if len(stamps) < 64:
        return
    rate = 1e6 / float(np.median(np.diff(stamps)))
    size = int(rate * SPECTRUM_SEGMENT_S)
    if rate < 20.0 or size < 16 or len(stamps) < size:
        return
    segments = len(stamps) // size
    per_spectrum = -(-segments // MOST_SPECTRA)
    count = segments // per_spectrum
    used = count * per_spectrum * size
    window = np.hanning(size)
    scale = 2.0 / (rate * np.sum(window**2))
    frequencies = np.fft.rfftfreq(size, 1.0 / rate)[1:]  # without DC
    ends = stamps[per_spectrum * size - 1 : used : per_spectrum * size][:count]
    for k, axis in enumerate("xyz"):
        blocks = values[:used, k].reshape(count * per_spectrum, size).astype(np.float64)
        blocks = (blocks - blocks.mean(axis=1, keepdims=True)) * window
        power = np.abs(np.fft.rfft(blocks, axis=1))[:, 1:] ** 2 * scale
        density = np.sqrt(power.reshape(count, per_spectrum, -1).mean(axis=1))
        bars = np.stack([np.broadcast_to(frequencies, density.shape), density], axis=1)
        system.columns.extend(f"spectrum/{sensor}/{axis}", "spectrum", ends, bars)


def vibration(
    system: System,
    stamps: np.ndarray,
    levels: dict[str, np.ndarray],
    thresholds: tuple[float, float],
    armed_us: tuple[int, int] | None,
    source: str,
) -> None:
    """Vibration levels (``levels``: series name -> m/s²) in the vibration panel with
    the stack's own thresholds as lines (``warning``, ``bad``), and a one-line verdict
    (the 95th percentile while armed, else over the log) among the system's notes and
    events."""
    for name, values in levels.items():
        scalar(system, f"plots/vibration/{name}", stamps, values)
    span = stamps[[0, -1]] if len(stamps) else stamps
    for name, level in zip(("warning", "bad"), thresholds, strict=True):
        scalar(system, f"plots/vibration/{name}", span, np.full(len(span), level))
    flying = np.ones(len(stamps), dtype=bool)
    if armed_us is not None:
        flying = (stamps >= armed_us[0]) & (stamps <= armed_us[1])
    worst = max(
        (float(np.nanpercentile(v[flying], 95)) for v in levels.values() if flying.any()),
        default=float("nan"),
    )
    if not np.isfinite(worst):
        return
    warning, bad = thresholds
    verdict, severity = ("good", 6) if worst < warning else ("high", 4)
    if worst >= bad:
        verdict, severity = "too high", 3
    over = " while armed" if armed_us else ""
    note = (
        f"vibration {verdict}: {worst:.2f} m/s² (95th percentile{over}; {source}: good "
        f"below {warning:g}, too high above {bad:g})"
    )
    system.notes.append(note)
    events(system, [int(stamps[-1])], [note], [severity])
