"""Replay speed of the flight stacks' own logs: a one-hour PX4 ULog and a one-hour
ArduPilot DataFlash log to Rerun recordings (target ≥ 1,000,000 log samples/s each).

The hour is made from the real flights of tests/data/ (PX4 and ArduCopter flying
quadsitl): the log's data messages repeated, each copy's time stamps moved on by the
flight's length, until an hour is logged. A sample is one logged message (a ULog data
or text message, a DataFlash message): ``*_replay_samples_per_s`` is the log's messages
over the seconds ``quadsitl replay LOG -o LOG.rrd`` takes (reading, the views, writing
the recording). Also the read alone; Rerun's write alone of as many time-series rows
(synthetic series of the recording's lengths into a fresh file: the floor of a convert
on this machine, before any log is read); and, where a Rerun viewer runs here (headless,
a software renderer without a GPU), the seconds it takes to open the hour's recording
and draw it.

    python benchmarks/flight_logs.py [--hours 1] [--no-viewer]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from gcs_tools.dataflash_reader import read_dataflash  # noqa: E402
from gcs_tools.log_scan import ULOG_DATA, gather, scan_dataflash, scan_ulog  # noqa: E402
from gcs_tools.replay import convert  # noqa: E402
from gcs_tools.ulog_reader import HEADER_BYTES, read_ulog  # noqa: E402

DATA = ROOT / "tests" / "data"
PX4_LOG, ARDUPILOT_LOG = DATA / "px4_mission.ulg", DATA / "ardupilot_mission.bin"


def repeated(data: np.ndarray, offsets: np.ndarray, lengths: np.ndarray, stamps: np.ndarray,
             span_us: int, copies: int) -> list[bytes]:  # fmt: skip
    """``copies`` copies of the messages at ``offsets`` (``lengths`` bytes each), the
    little-endian uint64 time stamps at ``stamps`` (file offsets) moved on by
    ``span_us`` per copy."""
    keep = np.zeros(len(data), dtype=bool)
    for at, length in zip(offsets.tolist(), lengths.tolist(), strict=True):
        keep[at : at + length] = True
    block = data[keep]
    new_position = np.cumsum(keep) - 1  # where each kept byte lands in the block
    where = new_position[stamps]
    windows = where[:, None] + np.arange(8)
    original = block[windows].copy().view("<u8").ravel()
    out = []
    for copy in range(1, copies + 1):
        moved = block.copy()
        moved[windows] = (original + np.uint64(copy * span_us)).view(np.uint8).reshape(-1, 8)
        out.append(moved.tobytes())
    return out


def ulog_hours(source: Path, target: Path, hours: float) -> None:
    """A ULog of ``hours``: the source's header, definitions and subscriptions once,
    its data and text messages over and over."""
    data = np.fromfile(source, dtype=np.uint8)
    records, _, _ = scan_ulog(data, HEADER_BYTES)
    kinds = records[:, 2]
    moving = np.isin(kinds, [ULOG_DATA, ord("L")])
    stamp_at = np.where(kinds == ULOG_DATA, records[:, 0] + 5, records[:, 0] + 4)[moving]
    data_stamps = gather(data, records[kinds == ULOG_DATA, 0] + 5, 8, 8).view("<u8")
    span = int(data_stamps.max() - data_stamps.min()) + 1000
    copies = max(int(hours * 3600e6 / span) - 1, 0)
    with open(target, "wb") as out:
        out.write(data.tobytes())
        for block in repeated(data, records[moving, 0], records[moving, 1] + 3, stamp_at,
                              span, copies):  # fmt: skip
            out.write(block)


def dataflash_hours(source: Path, target: Path, hours: float) -> None:
    """A DataFlash log of ``hours``: the source's messages (formats and all) over and
    over, each TimeUS moved on."""
    data = np.fromfile(source, dtype=np.uint8)
    records, _, _ = scan_dataflash(data)
    log = read_dataflash(source)
    by_type = {
        int(kind): fmt
        for kind, fmt in ((r, log.formats.get(n)) for r, n in _type_names(data, records))
        if fmt is not None
    }
    lengths = np.array([by_type[k].length if k in by_type else 89 for k in records[:, 1]])
    timed = np.array([k in by_type and by_type[k].columns[0] == "TimeUS" for k in records[:, 1]])
    tables = [log.rows(name) for name in log.names]
    stamps = [
        rows["TimeUS"] for rows in tables if rows is not None and "TimeUS" in rows.dtype.names
    ]
    span = int(max(s.max() for s in stamps) - min(s.min() for s in stamps)) + 1000
    copies = max(int(hours * 3600e6 / span) - 1, 0)
    keep = records[:, 1] != 128  # the formats once
    with open(target, "wb") as out:
        out.write(data.tobytes())
        for block in repeated(data, records[keep, 0], lengths[keep],
                              records[keep & timed, 0] + 3, span, copies):  # fmt: skip
            out.write(block)


def _type_names(data: np.ndarray, records: np.ndarray) -> list[tuple[int, str]]:
    """(type, name) of each FMT message."""
    out = []
    for at in records[records[:, 1] == 128, 0].tolist():
        name = bytes(data[at + 5 : at + 9]).decode("ascii", "replace").rstrip("\x00")
        out.append((int(data[at + 3]), name))
    return out


def measure(label: str, log: Path, read: Callable[[Path], object], viewer: bool) -> None:
    start = time.perf_counter()
    read(log)
    read_s = time.perf_counter() - start
    rrd = log.with_suffix(".rrd")
    result = convert(log, rrd)  # once to compile the scan (numba's cache), then timed
    start = time.perf_counter()
    result = convert(log, rrd)
    seconds = time.perf_counter() - start
    messages = result.stats.messages
    print(f"{label}: {log.stat().st_size / 1e6:.0f} MB, {messages:,} messages; read alone "
          f"{read_s:.2f} s ({messages / read_s:,.0f}/s)")  # fmt: skip
    rate = messages / seconds
    verdict = "met" if rate >= 1e6 else "BELOW"
    print(f"{label}_replay_samples_per_s: {rate:,.0f} (convert {seconds:.2f} s; target "
          f"1,000,000: {verdict}); recording {rrd.stat().st_size / 1e6:.0f} MB")  # fmt: skip
    floor = write_alone(result.entities, log.with_suffix(".floor.rrd"))
    print(f"{label}: Rerun's write alone of its {floor[0]:,} time-series rows (same "
          f"lengths, no reading): {floor[1]:.2f} s, the floor of a convert here")  # fmt: skip
    if viewer:
        open_in_viewer(label, rrd)


def write_alone(entities: dict[str, int], rrd: Path) -> tuple[int, float]:
    """(rows, seconds) to send and write series of the recording's lengths (every
    entity of more than 1,000 rows: the time series) into a fresh recording: what
    Rerun's encoder costs before any log is read."""
    import rerun as rr

    lengths = [n for n in entities.values() if n > 1000]
    rec = rr.RecordingStream("floor")
    rec.save(str(rrd))
    start = time.perf_counter()
    for k, n in enumerate(lengths):
        times = (np.arange(n, dtype=np.int64) * 4000).astype("datetime64[us]")
        values = np.sin(np.arange(n) * 0.01) + np.random.default_rng(k).normal(0, 0.1, n)
        index = rr.TimeColumn("time", timestamp=times)
        rec.send_columns(f"s/{k}", indexes=[index], columns=rr.Scalars.columns(scalars=values))
    rec.flush()
    rec.disconnect()
    return sum(lengths), time.perf_counter() - start


def open_in_viewer(label: str, rrd: Path) -> None:
    """Seconds for a fresh headless viewer to load the recording and draw it."""
    try:
        from headless_viewer import HeadlessViewer
    except ImportError:
        return
    try:
        viewer = HeadlessViewer()
    except (OSError, SystemExit, RuntimeError) as error:
        print(f"{label}_viewer_open_s: not measured (no viewer here: {error})")
        return
    try:
        start = time.perf_counter()
        viewer.screenshot(rrd, rrd.with_suffix(".png"))
        print(f"{label}_viewer_open_s: {time.perf_counter() - start:.1f} s (loaded and drawn,"
              " software rendering)")  # fmt: skip
    finally:
        viewer.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=1.0)
    parser.add_argument("--no-viewer", action="store_true", help="skip the viewer's time")
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT / "benchmarks"))
    with tempfile.TemporaryDirectory() as folder:
        ulog = Path(folder) / "hour.ulg"
        ulog_hours(PX4_LOG, ulog, args.hours)
        measure("ulog", ulog, read_ulog, not args.no_viewer)
        if ARDUPILOT_LOG.exists():
            dataflash = Path(folder) / "hour.bin"
            dataflash_hours(ARDUPILOT_LOG, dataflash, args.hours)
            measure("dataflash", dataflash, read_dataflash, not args.no_viewer)


if __name__ == "__main__":
    main()
